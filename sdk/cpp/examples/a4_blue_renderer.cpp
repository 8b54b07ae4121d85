// Thesis appendix A.4, "Renderer Example": a renderer that always produces
// blue images, as printed, with only its evident typos fixed:
//  - setLayout's empty body `{}` (lost in print);
//  - `w` and `h`, never declared, are the image size g_width and g_height
//    (cast to int where std::min compares them with an int);
//  - the evaluate lambda captures `thread` by reference (`[&]`, not `[]`);
//  - the last evaluate thread is joined before main returns (a joinable
//    std::thread destroyed at exit terminates the program).
// Not fixed, because it is logic rather than a typo: the remainder loop
// under-produces when `remainder` is a multiple of `tileSize`.
#include <fbksd/renderer/RenderingServer.h>
#include <fbksd/renderer/samples.h>
#include <iostream>
#include <thread>
#include <cmath>
using namespace fbksd;
namespace
{
// Fixed image size and SPP.
// In a real renderer, this would be loaded from the scene file.
const int64_t g_width = 1000;
const int64_t g_height = 1000;
const int64_t g_spp = 1;
// Returns a SceneInfo with information about the scene.
SceneInfo getSceneInfo()
{
    SceneInfo info;
    info.set<int64_t>("width", g_width);
    info.set<int64_t>("height", g_height);
    info.set<int64_t>("max_spp", g_spp);
    info.set<int64_t>("max_samples", g_width * g_height * g_spp);
    return info;
}
void setLayout(const SampleLayout& layout)
{}
void evaluateSamples(int64_t spp, int64_t remainder, int tileSize)
{
    if(spp)
    {
        // break the image in tiles 16x16
        int nTilesX = std::ceil(float(g_width) / 16);
        int nTilesY = std::ceil(float(g_height) / 16);
        for(int tileY = 0; tileY < nTilesY; ++tileY)
        for(int tileX = 0; tileX < nTilesX; ++tileX)
        {
            int beginX = tileX*16;
            int beginY = tileY*16;
            int endX = std::min((tileX+1)*16, (int)g_width);
            int endY = std::min((tileY+1)*16, (int)g_height);
            int numPixels = (endX - beginX) * (endY - beginY);
            SamplesPipe pipe({beginX, beginY}, {endX, endY}, spp * numPixels);
            for(int y = beginY; y < endY; ++y)
            for(int x = beginX; x < endX; ++x)
            {
                pipe.seek(x, y);
                for(int64_t s = 0; s < spp; ++s)
                {
                    SampleBuffer sampleBuffer = pipe.getBuffer();
                    sampleBuffer.set(IMAGE_X, x);
                    sampleBuffer.set(IMAGE_Y, y);
                    sampleBuffer.set(COLOR_R, 0.0);
                    sampleBuffer.set(COLOR_G, 0.0);
                    sampleBuffer.set(COLOR_B, 1.0);
                    pipe << sampleBuffer;
                }
            }
        }
    }
    if(remainder)
    {
        // divide the remaining samples in tiles of maximum size.
        int nTiles = std::ceil(float(remainder) / tileSize);
        for(int tile = 0; tile < nTiles; ++tile)
        {
            int numSamples = tile == 0 ? remainder % tileSize : tileSize;
            SamplesPipe pipe({0, 0}, {g_width, g_height}, numSamples);
            for(int i = 0; i < numSamples; ++i)
            {
                SampleBuffer sampleBuffer = pipe.getBuffer();
                int x = drand48() * g_width;
                int y = drand48() * g_height;
                sampleBuffer.set(IMAGE_X, x);
                sampleBuffer.set(IMAGE_Y, y);
                sampleBuffer.set(COLOR_R, 0.0);
                sampleBuffer.set(COLOR_G, 0.0);
                sampleBuffer.set(COLOR_B, 1.0);
                pipe << sampleBuffer;
            }
        }
    }
}
void finish()
{
    std::cout << "Done." << std::endl;
}
} // namespace
int main(int argc, char* argv[])
{
    // STEP 1: Crate rendering server object.
    RenderingServer server;
    // STEP 2: Set the callback functions or methods
    // In our case, we'll break images in 16x16 tiles.
    server.onGetTileSize([](){return 16;});
    // getSceneInfo() will be called when the server need information
    // about the scene being rendered.
    server.onGetSceneInfo(&getSceneInfo);
    // onSetParameters() will be called to inform the renderer about sample layout requirements.
    server.onSetParameters(&setLayout);
    // evaluateSamples() will be called each time the server requires samples.
    // The sample data transfer between client and server is asynchronous.
    // In this case we must run evaluteSamples() in another thread.
    std::unique_ptr<std::thread> thread;
    server.onEvaluateSamples([&](int64_t spp, int64_t remainder, int tileSize){
        if(thread && thread->joinable())
            thread->join();
        thread.reset(new std::thread(evaluateSamples, spp, remainder, tileSize));
    });
    // finish() will be called when the server is done with the current scene.
    server.onFinish(&finish);
    // STEP 3: Run the server.
    // This is a blocking call that will return only when the benchmark server decides.
    server.run();
    if(thread && thread->joinable())
        thread->join();
    return 0;
}
