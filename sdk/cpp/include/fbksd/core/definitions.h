// Shared definitions of the FBKSD 2.x C++ API (thesis appendix A.5):
// errors, the RandomParameter and Feature enums, Point2l. Header-only over
// the C ABI (<fbksd/fbksd.h>, libfbksd).
#pragma once

#include <fbksd/fbksd.h>

#include <cstdint>
#include <stdexcept>
#include <string>

namespace fbksd {

//! A failed call: the C API's status and its message. The original aborted instead.
class Error : public std::runtime_error {
public:
    Error(FbksdStatus status, const std::string& message) : std::runtime_error(message), status(status) {}
    FbksdStatus status;
};

namespace detail {
inline void check(FbksdStatus status) {
    if (status != FBKSD_STATUS_OK)
        throw Error(status, fbksd_last_error());
}
} // namespace detail

//! Random parameters; with them first in the layout, in this order, they
//! also index a sample (`sample[IMAGE_X]`), as in the original examples.
enum RandomParameter { IMAGE_X = 0, IMAGE_Y, LENS_U, LENS_V, TIME, LIGHT_X, LIGHT_Y, NUM_RANDOM_PARAMETERS };

//! Features a renderer computes. Numbered ones (WORLD, NORMAL,
//! TEXTURE_COLOR) also exist for the second intersection (number 1).
enum Feature {
    COLOR_R = 0, COLOR_G, COLOR_B,
    DIRECT_LIGHT_R, DIRECT_LIGHT_G, DIRECT_LIGHT_B,
    DEPTH,
    WORLD_X, WORLD_Y, WORLD_Z,
    NORMAL_X, NORMAL_Y, NORMAL_Z,
    TEXTURE_COLOR_R, TEXTURE_COLOR_G, TEXTURE_COLOR_B,
    WORLD_X_NS, WORLD_Y_NS, WORLD_Z_NS,
    NORMAL_X_NS, NORMAL_Y_NS, NORMAL_Z_NS,
    TEXTURE_COLOR_R_NS, TEXTURE_COLOR_G_NS, TEXTURE_COLOR_B_NS,
    DIFFUSE_COLOR_R, DIFFUSE_COLOR_G, DIFFUSE_COLOR_B,
    NUM_FEATURES
};

//! A 2D point with integer coordinates (pixel positions, image windows).
struct Point2l {
    int64_t x = 0;
    int64_t y = 0;
};

} // namespace fbksd
