// NFOR as an FBKSD denoiser: requests the whole budget at once with colour,
// normal, albedo and depth per sample, reduces the samples of each pixel to
// the two half-buffer means (even and odd samples) and their variances, and
// runs the filter (nfor.cpp). The filter's log goes to stderr, which the
// benchmark keeps as the technique log.
#include "nfor.h"

#include <fbksd/client/BenchmarkClient.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

using namespace fbksd;

namespace {

constexpr int kChannels = 3 + nfor::kFeatureChannels;

// Non-finite sample values (a renderer's NaN, an infinite depth) become 0;
// magnitudes are capped so squares and sums stay finite in float.
float sanitize(float v)
{
    if (!std::isfinite(v))
        return 0.0f;
    return std::min(std::max(v, -1e15f), 1e15f);
}

} // namespace

int main(int argc, char* argv[])
{
    BenchmarkClient client(argc, argv);
    SceneInfo scene = client.getSceneInfo();
    const auto w = scene.get<int64_t>("width");
    const auto h = scene.get<int64_t>("height");
    const auto spp = scene.get<int64_t>("max_spp");
    const size_t N = (size_t)(w * h);

    // Order: colour, then the features in nfor::kGroupBegin's order.
    SampleLayout layout;
    layout("COLOR_R")("COLOR_G")("COLOR_B");
    layout("NORMAL_X")("NORMAL_Y")("NORMAL_Z");
    layout("TEXTURE_COLOR_R")("TEXTURE_COLOR_G")("TEXTURE_COLOR_B");
    layout("DEPTH");
    client.setSampleLayout(layout);

    nfor::Input in;
    in.width = (int)w;
    in.height = (int)h;
    in.spp = (int)spp;
    const int halves = spp >= 2 ? 2 : 1;
    for (int k = 0; k < halves; ++k) {
        in.color[k].assign(3 * N, 0.0f);
        in.colorVar[k].assign(3 * N, 0.0f);
        in.feature[k].assign(nfor::kFeatureChannels * N, 0.0f);
        in.featureVar[k].assign(nfor::kFeatureChannels * N, 0.0f);
    }

    client.evaluateSamples(SPP(spp), [&](const BufferTile& tile) {
        const int64_t n = tile.spp();
        std::vector<double> value((size_t)n * kChannels);
        for (auto y = tile.beginY(); y < tile.endY(); ++y)
            for (auto x = tile.beginX(); x < tile.endX(); ++x) {
                const size_t i = (size_t)(y * w + x);
                for (int64_t s = 0; s < n; ++s) {
                    const float* sample = tile(x, y, s);
                    for (int c = 0; c < kChannels; ++c)
                        value[s * kChannels + c] = sanitize(sample[c]);
                }
                const double counts[2] = {(double)((n + 1) / 2), (double)(n / 2)};
                for (int c = 0; c < kChannels; ++c) {
                    double sum[2] = {0, 0};
                    for (int64_t s = 0; s < n; ++s)
                        sum[s & 1] += value[s * kChannels + c];
                    const double mean = (sum[0] + sum[1]) / (double)n;
                    double sq = 0;
                    for (int64_t s = 0; s < n; ++s)
                        sq += (value[s * kChannels + c] - mean) * (value[s * kChannels + c] - mean);
                    const double sampleVar = n > 1 ? sq / (double)(n - 1) : 0.0;
                    for (int k = 0; k < halves; ++k) {
                        const float m = (float)(sum[k] / counts[k]), v = (float)(sampleVar / counts[k]);
                        if (c < 3) {
                            in.color[k][c * N + i] = m;
                            in.colorVar[k][c * N + i] = v;
                        } else {
                            in.feature[k][(c - 3) * N + i] = m;
                            in.featureVar[k][(c - 3) * N + i] = v;
                        }
                    }
                }
            }
    });

    std::string log;
    const std::vector<float> rgb = nfor::denoise(in, nfor::Params(), &log);
    std::fputs(log.c_str(), stderr);

    float* result = client.getResultBuffer();
    std::copy(rgb.begin(), rgb.end(), result);
    client.sendResult();
    return 0;
}
