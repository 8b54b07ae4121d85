// A box filter with the habits of published 2.x denoisers: OpenMP for its
// loops, and OpenEXR 2's API and include paths for its image files. The
// result goes through a half-float RGBA file and back, so the image sent
// is the box filter's rounded to half precision.
#include <fbksd/client/BenchmarkClient.h>
#include <ImfArray.h>
#include <ImfRgbaFile.h>
#include <half.h>
#include <omp.h>
#include <unistd.h>
using namespace fbksd;

int main(int argc, char* argv[])
{
    BenchmarkClient client(argc, argv);
    SceneInfo scene = client.getSceneInfo();
    const int w = scene.get<int64_t>("width");
    const int h = scene.get<int64_t>("height");
    const int spp = scene.get<int64_t>("max_spp");

    SampleLayout layout;
    layout("COLOR_R")("COLOR_G")("COLOR_B");
    client.setSampleLayout(layout);
    float* result = client.getResultBuffer();

    std::vector<double> sums(size_t(w) * h * 3, 0.0);
    client.evaluateSamples(SPP(spp), [&](const BufferTile& tile)
    {
        for(auto y = tile.beginY(); y < tile.endY(); ++y)
        for(auto x = tile.beginX(); x < tile.endX(); ++x)
        for(int s = 0; s < spp; ++s)
        {
            const float* sample = tile(x, y, s);
            for(int c = 0; c < 3; ++c)
                sums[(y * w + x) * 3 + c] += sample[c];
        }
    });

    Imf::Array2D<Imf::Rgba> pixels(h, w);
    #pragma omp parallel for
    for(int y = 0; y < h; ++y)
        for(int x = 0; x < w; ++x)
        {
            const double* sum = &sums[(size_t(y) * w + x) * 3];
            pixels[y][x] = Imf::Rgba(half(float(sum[0] / spp)), half(float(sum[1] / spp)),
                                     half(float(sum[2] / spp)), half(1.f));
        }

    const std::string path = "/tmp/openexr-omp-box-" + std::to_string(getpid()) + ".exr";
    {
        Imf::RgbaOutputFile file(path.c_str(), w, h, Imf::WRITE_RGBA);
        file.setFrameBuffer(&pixels[0][0], 1, w);
        file.writePixels(h);
    }
    Imf::Array2D<Imf::Rgba> back(h, w);
    {
        Imf::RgbaInputFile file(path.c_str());
        file.setFrameBuffer(&back[0][0], 1, w);
        file.readPixels(0, h - 1);
    }
    std::remove(path.c_str());

    #pragma omp parallel for
    for(int y = 0; y < h; ++y)
        for(int x = 0; x < w; ++x)
        {
            float* pixel = &result[(size_t(y) * w + x) * 3];
            pixel[0] = back[y][x].r;
            pixel[1] = back[y][x].g;
            pixel[2] = back[y][x].b;
        }
    std::cerr << "openexr-omp-box: " << omp_get_max_threads() << " OpenMP threads" << std::endl;
    client.sendResult();
    return 0;
}
