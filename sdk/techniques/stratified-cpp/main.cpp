// Stratified sampler in C++, laid out as a submission repository: the
// technique writes the position of every sample (INPUT random parameters)
// and the renderer only evaluates them.
//
// Per pixel with n samples: the image position is multi-jittered (Chiu,
// Shirley and Wang 1994) when n is a square — one sample per cell of a
// k × k grid and, at once, one per column and per row of the n × n grid, so
// both 1D projections are stratified too — otherwise N-rooks (one sample
// per row and per column of the n × n grid); lens (u, v) and time are Latin
// hypercube samples, each dimension shuffled independently. Random
// numbers come from a counter-based hash of (pixel, request, dimension), so
// a run is reproducible and tiles can arrive in any order.
#include <fbksd/client/BenchmarkClient.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <vector>

using namespace fbksd;

namespace {

// SplitMix64: a well-mixed 64-bit hash of a counter.
uint64_t mix(uint64_t z) {
    z += 0x9e3779b97f4a7c15ull;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

// A stream of uniform numbers in [0, 1) for one pixel and dimension.
struct Stream {
    uint64_t state;
    Stream(int64_t x, int64_t y, uint64_t dimension) : state(mix(mix((uint64_t)x * 73856093u ^ (uint64_t)y) + dimension)) {}
    float next() {
        state = mix(state);
        return (float)(state >> 40) * (1.0f / 16777216.0f);
    }
    uint64_t below(uint64_t n) { return (uint64_t)(next() * (float)n) % n; }
};

// A random permutation of 0..n-1 (Fisher–Yates).
std::vector<uint32_t> permutation(uint32_t n, Stream& rng) {
    std::vector<uint32_t> p(n);
    for (uint32_t i = 0; i < n; ++i)
        p[i] = i;
    for (uint32_t i = n; i > 1; --i)
        std::swap(p[i - 1], p[rng.below(i)]);
    return p;
}

// n values in [0, 1), one per stratum, in shuffled order.
std::vector<float> latinHypercube(uint32_t n, Stream& rng) {
    std::vector<uint32_t> order = permutation(n, rng);
    std::vector<float> v(n);
    for (uint32_t i = 0; i < n; ++i)
        v[i] = ((float)order[i] + rng.next()) / (float)n;
    return v;
}

// base + offset for offset in [0, 1), kept below base + 1 (float rounding
// would otherwise put some samples into the next pixel).
float within(int64_t base, float offset) {
    float v = (float)base + offset;
    return std::min(v, std::nextafter((float)(base + 1), (float)base));
}

// Element order of the layout below.
enum { X = 0, Y, U, V, T, R, G, B };

} // namespace

int main(int argc, char* argv[])
{
    BenchmarkClient client(argc, argv);
    SceneInfo scene = client.getSceneInfo();
    const auto w = scene.get<int64_t>("width");
    const auto h = scene.get<int64_t>("height");
    const auto spp = scene.get<int64_t>("max_spp");

    SampleLayout layout;
    layout("IMAGE_X", SampleLayout::INPUT)("IMAGE_Y", SampleLayout::INPUT);
    layout("LENS_U", SampleLayout::INPUT)("LENS_V", SampleLayout::INPUT)("TIME", SampleLayout::INPUT);
    layout("COLOR_R")("COLOR_G")("COLOR_B");
    client.setSampleLayout(layout);

    const auto n = (uint32_t)spp;
    const auto k = (uint32_t)std::lround(std::sqrt((double)n));
    const bool grid = k * k == n; // multi-jittered; N-rooks otherwise
    std::vector<double> sums(w * h * 3, 0.0);

    client.evaluateInputSamples(
        SPP(spp),
        [&](const BufferTile& tile) {
            for (auto y = tile.beginY(); y < tile.endY(); ++y)
                for (auto x = tile.beginX(); x < tile.endX(); ++x) {
                    Stream image(x, y, 0), lens(x, y, 1), time(x, y, 2);
                    // Fine position of each sample: sub-column (x) and sub-row (y).
                    std::vector<uint32_t> fineX(n), fineY(n);
                    if (grid) {
                        // Sample s sits in cell (s % k, s / k); within each cell
                        // column the sub-columns are a permutation, likewise rows.
                        for (uint32_t column = 0; column < k; ++column) {
                            std::vector<uint32_t> p = permutation(k, image);
                            for (uint32_t row = 0; row < k; ++row)
                                fineX[row * k + column] = column * k + p[row];
                        }
                        for (uint32_t row = 0; row < k; ++row) {
                            std::vector<uint32_t> p = permutation(k, image);
                            for (uint32_t column = 0; column < k; ++column)
                                fineY[row * k + column] = row * k + p[column];
                        }
                    } else {
                        fineX = permutation(n, image);
                        for (uint32_t s = 0; s < n; ++s)
                            fineY[s] = s;
                    }
                    std::vector<float> u = latinHypercube(n, lens), v = latinHypercube(n, lens);
                    std::vector<float> t = latinHypercube(n, time);
                    for (uint32_t s = 0; s < n; ++s) {
                        float* sample = tile(x, y, s);
                        sample[X] = within(x, ((float)fineX[s] + image.next()) / (float)n);
                        sample[Y] = within(y, ((float)fineY[s] + image.next()) / (float)n);
                        sample[U] = u[s];
                        sample[V] = v[s];
                        sample[T] = t[s];
                    }
                }
        },
        [&](const BufferTile& tile) {
            for (auto y = tile.beginY(); y < tile.endY(); ++y)
                for (auto x = tile.beginX(); x < tile.endX(); ++x) {
                    double* pixel = &sums[(y * w + x) * 3];
                    for (int64_t s = 0; s < tile.spp(); ++s) {
                        const float* sample = tile(x, y, s);
                        // The renderer must have used our positions.
                        if (sample[X] < x || sample[X] >= x + 1 || sample[Y] < y || sample[Y] >= y + 1)
                            throw std::runtime_error("a sample came back outside its pixel");
                        pixel[0] += sample[R];
                        pixel[1] += sample[G];
                        pixel[2] += sample[B];
                    }
                }
        });

    float* result = client.getResultBuffer();
    for (int64_t i = 0; i < w * h * 3; ++i)
        result[i] = (float)(sums[i] / (double)spp);
    client.sendResult();
    return 0;
}
