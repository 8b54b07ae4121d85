// FBKSD 2.x's name for the header of fbksd::Img: metrics written for 2.x
// include it.
#pragma once

#include <fbksd/iqa/iqa.h>
