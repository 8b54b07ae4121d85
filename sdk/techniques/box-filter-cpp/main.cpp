// Box filter in C++, laid out as a submission repository: CMakeLists.txt
// (find_package(fbksd)), info.json, and this file. Each pixel is the mean
// of its samples, accumulated in double precision.
#include <fbksd/client/BenchmarkClient.h>

#include <vector>

using namespace fbksd;

int main(int argc, char* argv[])
{
    BenchmarkClient client(argc, argv);
    SceneInfo scene = client.getSceneInfo();
    const auto w = scene.get<int64_t>("width");
    const auto h = scene.get<int64_t>("height");
    const auto spp = scene.get<int64_t>("max_spp");

    SampleLayout layout;
    layout("COLOR_R")("COLOR_G")("COLOR_B");
    client.setSampleLayout(layout);

    std::vector<double> sums(w * h * 3, 0.0);
    client.evaluateSamples(SPP(spp), [&](const BufferTile& tile) {
        for (auto y = tile.beginY(); y < tile.endY(); ++y)
            for (auto x = tile.beginX(); x < tile.endX(); ++x) {
                double* pixel = &sums[(y * w + x) * 3];
                for (int64_t s = 0; s < tile.spp(); ++s) {
                    const float* sample = tile(x, y, s);
                    pixel[0] += sample[0];
                    pixel[1] += sample[1];
                    pixel[2] += sample[2];
                }
            }
    });

    float* result = client.getResultBuffer();
    const double inv = 1.0 / (double)spp;
    for (size_t i = 0; i < sums.size(); ++i)
        result[i] = (float)(sums[i] * inv);
    client.sendResult();
    return 0;
}
