// FBKSD 2.x's name for the header of fbksd::SamplesPipe and
// fbksd::SampleBuffer: renderers written for 2.x include it.
#pragma once

#include <fbksd/renderer/samples.h>
