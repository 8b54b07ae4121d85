// A sampler in the style of FBKSD 2.x samplers: #define'd sample indices,
// samples addressed through the templated point accessor (with 2.x's
// Point2l and with a point type of its own), 2.x's window and point types,
// and scene info merged with its own settings.
#include <fbksd/client/BenchmarkClient.h>
using namespace fbksd;

#define IMAGE_X  0
#define IMAGE_Y  1
#define LENS_U   2
#define LENS_V   3
#define TIME     4
#define LIGHT_X  5
#define LIGHT_Y  6
#define COLOR_R  7
#define COLOR_G  8
#define COLOR_B  9

struct Pixel { int x; int y; };

int main(int argc, char* argv[])
{
    BenchmarkClient client(argc, argv);
    SceneInfo settings;
    settings.set("sampler", std::string("pixel centre"));
    settings.set<int64_t>("max_spp", 0); // overridden by the scene's own value below
    SceneInfo scene = settings.merged(client.getSceneInfo());
    const int64_t w = scene.get<int64_t>("width");
    const int64_t h = scene.get<int64_t>("height");
    const int64_t spp = scene.get<int64_t>("max_spp");
    if(scene.get<std::string>("sampler") != "pixel centre" || spp <= 0)
        return 1;

    SampleLayout layout;
    layout("IMAGE_X")("IMAGE_Y")("LENS_U")("LENS_V")("TIME")("LIGHT_X")("LIGHT_Y")
          ("COLOR_R")("COLOR_G")("COLOR_B");
    for(int i = 0; i < 7; ++i)
        layout.setElementIO(i, SampleLayout::INPUT);
    const std::set<std::string> known = {"IMAGE_X", "IMAGE_Y", "LENS_U", "LENS_V", "TIME",
                                         "LIGHT_X", "LIGHT_Y", "COLOR_R", "COLOR_G", "COLOR_B"};
    if(!layout.isValid(known) || !layout.hasInput("TIME") || layout.hasInput("COLOR_R")
       || layout.getInputSize() != 7 || layout.getOutputSize() != 3)
        return 2;
    client.setSampleLayout(layout);
    float* result = client.getResultBuffer();

    // Strata of [0, 1) for lens, time and light, shuffled apart per dimension.
    std::vector<float> strata(spp);
    for(int64_t s = 0; s < spp; ++s)
        strata[s] = (float(s) + 0.5f) / float(spp);
    std::vector<float> reversed(strata.rbegin(), strata.rend());
    std::sort(reversed.begin(), reversed.end());

    const CropWindow image(Point2l(0, 0), Point2l(w, h));
    std::vector<Tile> tiles;
    client.evaluateInputSamples(SPP(spp),
        [&](const BufferTile& tile)
        {
            TilePkg package(Tile(CropWindow(Point2l(tile.beginX(), tile.beginY()), Point2l(tile.endX(), tile.endY())),
                                 int64_t(tiles.size()), tile.numPixels() * spp), true, true);
            if(!package.isValid || !(package.tile.window.end < TPoint2<int64_t>(w + 1, h + 1)))
                throw std::runtime_error("a tile outside the image");
            tiles.push_back(package.tile);
            for(int64_t y = tile.beginY(); y < tile.endY(); ++y)
            for(int64_t x = tile.beginX(); x < tile.endX(); ++x)
            for(int64_t s = 0; s < spp; ++s)
            {
                float* sample = tile(Point2l(x, y), s);
                sample[IMAGE_X] = float(x) + 0.5f;
                sample[IMAGE_Y] = float(y) + 0.5f;
                sample[LENS_U] = strata[s];
                sample[LENS_V] = reversed[s];
                sample[TIME] = strata[s];
                sample[LIGHT_X] = strata[(s + 1) % spp];
                sample[LIGHT_Y] = strata[(s + 2) % spp];
            }
        },
        [&](const BufferTile& tile)
        {
            for(int y = int(tile.beginY()); y < tile.endY(); ++y)
            for(int x = int(tile.beginX()); x < tile.endX(); ++x)
            {
                float* pixel = &result[(y * image.width() + x) * 3];
                for(int64_t s = 0; s < spp; ++s)
                {
                    const float* sample = tile(Pixel{x, y}, s);
                    pixel[0] += sample[COLOR_R];
                    pixel[1] += sample[COLOR_G];
                    pixel[2] += sample[COLOR_B];
                }
                for(int c = 0; c < 3; ++c)
                    pixel[c] /= float(spp);
            }
        });

    // A summary of the strata, as a sampler's log would print it.
    const TPoint3<float> lo(0.f, 0.f, 0.f), hi(1.f, 1.f, 1.f);
    const float mean = std::accumulate(strata.begin(), strata.end(), 0.f) / float(spp);
    if(!(lo < TPoint3<float>(strata.front(), mean, strata.back())) || !(TPoint3<float>(mean, mean, mean) < hi))
        return 3;
    std::cerr << "centre-sampler: " << tiles.size() << " tiles, strata rms "
              << std::sqrt(std::inner_product(strata.begin(), strata.end(), strata.begin(), 0.f) / float(spp))
              << std::endl;
    client.sendResult();
    return 0;
}
