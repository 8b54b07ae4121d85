// Thesis appendix A.2 (sampling technique example), unchanged but for the
// line breaks the PDF extraction lost, and its layout's first line, which
// the extraction garbled: IMAGE_X and IMAGE_Y as INPUT, like the others.
// randomFloat() is declared, not defined, by the example: it lives in
// random_float.cpp. As printed, the consumer sums elements 0-2 of each
// sample, which with this layout are IMAGE_X, IMAGE_Y and LENS_U, not the
// colour (elements 7-9): the example runs, but its image is not the scene.
// The listing uses IMAGE_X ... LIGHT_Y without declaring them; 2.x's client
// header did not declare them either (they are the renderer's names), and
// 2.x's own samplers defined these indices themselves, as done here.
#include <fbksd/client/BenchmarkClient.h>
using namespace fbksd;

enum { IMAGE_X, IMAGE_Y, LENS_U, LENS_V, TIME, LIGHT_X, LIGHT_Y };

// Function this sampler uses to generate random sample positions.
float randomFloat();

int main(int argc, char* argv[])
{
    // STEP 1: Instantiate the client object and get scene information.
    BenchmarkClient client(argc, argv);
    SceneInfo scene = client.getSceneInfo();
    const auto w = scene.get<int64_t>("width");
    const auto h = scene.get<int64_t>("height");
    const auto spp = scene.get<int64_t>("max_spp");

    // STEP 2: Set the sample layout.
    SampleLayout layout;
    layout("IMAGE_X", SampleLayout::INPUT)
          ("IMAGE_Y", SampleLayout::INPUT)
          ("LENS_U", SampleLayout::INPUT)
          ("LENS_V", SampleLayout::INPUT)
          ("TIME", SampleLayout::INPUT)
          ("LIGHT_X", SampleLayout::INPUT)
          ("LIGHT_Y", SampleLayout::INPUT)
          ("COLOR_R")
          ("COLOR_G")
          ("COLOR_B");
    client.setSampleLayout(layout);
    float* result = client.getResultBuffer();

    // STEP 3: Request samples.
    client.evaluateSamples(SPP(spp),
        [&](const BufferTile& tile)
        {
            // Generate sample positions
            for(int64_t y = tile.beginY(); y < tile.endY(); ++y)
            for(int64_t x = tile.beginX(); x < tile.endX(); ++x)
            for(int s = 0; s < spp; ++s)
            {
                float* sample = tile(x, y, s);
                sample[IMAGE_X] = randomFloat() + x;
                sample[IMAGE_Y] = randomFloat() + y;
                sample[LENS_U] = randomFloat();
                sample[LENS_V] = randomFloat();
                sample[TIME] = randomFloat();
                sample[LIGHT_X] = randomFloat();
                sample[LIGHT_Y] = randomFloat();
            }
        },
        [&](const BufferTile& tile)
        {
            // Consume sample values
            for(auto y = tile.beginY(); y < tile.endY(); ++y)
            for(auto x = tile.beginX(); x < tile.endX(); ++x)
            {
                float* pixel = &result[y*w*3 + x*3];
                for(int s = 0; s < spp; ++s)
                {
                    float* sample = tile(x, y, s);
                    pixel[0] += sample[0];
                    pixel[1] += sample[1];
                    pixel[2] += sample[2];
                }
            }
        }
    );

    // STEP 4: Reconstruct the image.
    const float sppInv = 1.f / (float)spp;
    for(int64_t y = 0; y < h; ++y)
    for(int64_t x = 0; x < w; ++x)
    {
        float* pixel = &result[y*w*3 + x*3];
        pixel[0] *= sppInv;
        pixel[1] *= sppInv;
        pixel[2] *= sppInv;
    }

    // STEP 5: Send result and finish.
    client.sendResult();
    return 0;
}
