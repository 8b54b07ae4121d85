// A box filter in the style of FBKSD 2.x techniques: only the client header,
// its own sample indices under `using namespace fbksd;`, the tile iterated
// sample by sample, and standard facilities used without their headers.
#include <fbksd/client/BenchmarkClient.h>
using namespace fbksd;

// The technique's own names for its layout's elements (2.x's client header
// declared none, so techniques did this).
enum { COLOR_R, COLOR_G, COLOR_B, DEPTH };

int main(int argc, char* argv[])
{
    BenchmarkClient client(argc, argv);
    SceneInfo scene = client.getSceneInfo();
    if(!scene.has<int64_t>("width") || !scene.has<int64_t>("max_spp"))
        return 1;
    const int64_t w = scene.get<int64_t>("width");
    const int64_t h = scene.get<int64_t>("height");
    SPP spp(1);
    spp = scene.get<int64_t>("max_spp");
    spp.setValue(spp.getValue());

    SampleLayout layout;
    layout("COLOR_R")("COLOR_G")("COLOR_B")("DEPTH");
    client.setSampleLayout(layout);
    float* result = client.getResultBuffer();

    std::vector<double> sums(w * h * 3, 0.0);
    float nearest = std::numeric_limits<float>::max();
    float farthest = std::numeric_limits<float>::lowest();
    client.evaluateSamples(spp, [&](const BufferTile& tile)
    {
        if(tile.getSampleSize() != 4 || tile.numPixels() != tile.width() * tile.height())
            throw std::runtime_error("unexpected tile shape");
        // Storage order: the samples of one pixel after another, row by row.
        int64_t i = 0;
        for(const auto sample : tile)
        {
            const int64_t pixel = i++ / tile.getSPP();
            const int64_t x = tile.beginX() + pixel % tile.width();
            const int64_t y = tile.beginY() + pixel / tile.width();
            double* sum = &sums[(y * w + x) * 3];
            sum[0] += sample[COLOR_R];
            sum[1] += sample[COLOR_G];
            sum[2] += sample[COLOR_B];
            nearest = std::min(nearest, sample[DEPTH]);
            farthest = std::max(farthest, sample[DEPTH]);
        }
    });

    for(int64_t i = 0; i < w * h * 3; ++i)
        result[i] = float(sums[i] / double(spp.getValue()));
    std::cerr << "iterating-box: depth in [" << nearest << ", " << farthest << "]" << std::endl;
    client.sendResult();
    return 0;
}
