// The NFOR filter (Bitterli et al., EGSR 2016) as a library: per-pixel
// half-buffer statistics in, a denoised RGB image out. main.cpp owns the
// FBKSD protocol; this header owns the filter's inputs and parameters
// (README.md explains every value).
#pragma once

#include <string>
#include <vector>

namespace nfor {

//! Feature channels fed to the regression: normal xyz, albedo rgb, depth.
constexpr int kFeatureChannels = 7;
//! Feature groups prefiltered separately (each with its own NL-means weights).
constexpr int kFeatureGroups = 3;
constexpr int kGroupBegin[kFeatureGroups + 1] = {0, 3, 6, 7};

//! One candidate filter: NL-means colour weights with bandwidth k and patch radius f.
struct Candidate {
    float k;
    int patchRadius;
};

struct Params {
    int windowRadius = 9;
    std::vector<Candidate> candidates = {{0.25f, 1}, {0.25f, 3}, {0.5f, 1}, {0.5f, 3}};
    //! Candidate used at 1 spp, where there are no half buffers to select with.
    Candidate singleBuffer = {0.5f, 3};
    //! Ridge on the slopes, relative to the sum of the regression weights.
    float ridge = 1e-3f;
    int prefilterRadius = 5;
    int prefilterPatch = 3;
    float prefilterK = 0.5f;
    int selectionRadius = 5;
    int selectionPatch = 3;
    float selectionK = 1.0f;
    //! Box radius of the half-buffer / sample-variance ratio.
    int varianceRatioRadius = 7;
};

//! Per-pixel statistics, planar (channel c of pixel i at [c * width * height + i]).
//! Index 0 is the half of even samples, 1 the odd one; `...Var` is the
//! variance of that half's mean. With spp == 1, only index 0 is filled
//! (the variances are then estimated spatially).
struct Input {
    int width = 0;
    int height = 0;
    int spp = 0;
    std::vector<float> color[2], colorVar[2];
    std::vector<float> feature[2], featureVar[2];
};

//! Denoises; returns width × height × RGB, scan-line order, always finite.
//! `log` receives one line per stage (timings and diagnostics).
std::vector<float> denoise(const Input& in, const Params& params, std::string* log = nullptr);

} // namespace nfor
