// The conformance technique, C++ edition: the twin of
// tests/src/bin/fbksd-conformance-technique.rs (see there for the scenarios
// and the dump format); keep the three editions equivalent.
#include <fbksd/client/BenchmarkClient.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

using namespace fbksd;

static const char* PARAMS[] = {"IMAGE_X", "IMAGE_Y", "LENS_U", "LENS_V", "TIME", "LIGHT_X", "LIGHT_Y"};
static const char* FEATURES[] = {
    "COLOR_R", "COLOR_G", "COLOR_B", "DIRECT_LIGHT_R", "DIRECT_LIGHT_G", "DIRECT_LIGHT_B", "DEPTH",
    "WORLD_X", "WORLD_Y", "WORLD_Z", "NORMAL_X", "NORMAL_Y", "NORMAL_Z",
    "TEXTURE_COLOR_R", "TEXTURE_COLOR_G", "TEXTURE_COLOR_B",
    "WORLD_X_NS", "WORLD_Y_NS", "WORLD_Z_NS", "NORMAL_X_NS", "NORMAL_Y_NS", "NORMAL_Z_NS",
    "TEXTURE_COLOR_R_NS", "TEXTURE_COLOR_G_NS", "TEXTURE_COLOR_B_NS",
    "DIFFUSE_COLOR_R", "DIFFUSE_COLOR_G", "DIFFUSE_COLOR_B"};
static const char* NUMBERED[] = {"WORLD_X", "WORLD_Y", "WORLD_Z", "NORMAL_X", "NORMAL_Y", "NORMAL_Z",
                                 "TEXTURE_COLOR_R", "TEXTURE_COLOR_G", "TEXTURE_COLOR_B"};

static void params(uint64_t x, uint64_t y, uint64_t s, float* p) {
    p[0] = (float)x + ((float)(s % 4) + 0.5f) / 4.0f;
    p[1] = (float)y + ((float)((3 * s) % 8) + 0.5f) / 8.0f;
    p[2] = (float)((x + 3 * y + s) % 8) / 8.0f;
    p[3] = (float)((x + s) % 4) / 4.0f;
    p[4] = (float)((y + 5 * s) % 16) / 16.0f;
    p[5] = (float)(s % 2) / 2.0f;
    p[6] = (float)((x * y + s) % 32) / 32.0f;
}

static FILE* g_out;

static void record(uint32_t bx, uint32_t ex, uint32_t by, uint32_t ey, uint32_t spp, uint32_t size, uint64_t count,
                   const float* data) {
    uint32_t head[6] = {bx, ex, by, ey, spp, size};
    std::fwrite(head, sizeof head, 1, g_out); // little-endian machines only, as the test
    std::fwrite(&count, sizeof count, 1, g_out);
    std::fwrite(data, sizeof(float), count * size, g_out);
}

int main(int argc, char* argv[]) {
    std::string scenario = std::getenv("FBKSD_CONFORMANCE");
    g_out = std::fopen(std::getenv("FBKSD_CONFORMANCE_OUT"), "wb");
    bool input = scenario.compare(0, 6, "input-") == 0;
    BenchmarkClient client(argc, argv);
    SceneInfo info = client.getSceneInfo();
    uint64_t w = info.get<int64_t>("width"), h = info.get<int64_t>("height");
    uint64_t maxSpp = info.get<int64_t>("max_spp");

    SampleLayout layout;
    for (const char* p : PARAMS)
        layout(p, input ? SampleLayout::INPUT : SampleLayout::OUTPUT);
    for (const char* f : FEATURES)
        layout(f);
    for (const char* n : NUMBERED)
        layout(n)[1];
    client.setSampleLayout(layout);
    uint32_t size = (uint32_t)layout.getSampleSize();

    auto dumpTile = [&](const BufferTile& t) {
        record((uint32_t)t.beginX(), (uint32_t)t.endX(), (uint32_t)t.beginY(), (uint32_t)t.endY(),
               (uint32_t)t.spp(), size, (uint64_t)t.size(), t[0]);
    };
    auto dumpSamples = [&](int64_t count, float* data) { record(0, 0, 0, 0, 0, size, (uint64_t)count, data); };

    if (scenario == "spp") {
        client.evaluateSamples(SPP(1), dumpTile);
        client.evaluateSamples(SPP(maxSpp - 1), dumpTile);
    } else if (scenario == "count") {
        client.evaluateSamples((int64_t)(w * h + 7), dumpSamples);
        client.evaluateSamples((int64_t)(maxSpp * w * h - (w * h + 7)), dumpSamples);
    } else if (scenario == "input-spp") {
        client.evaluateInputSamples(
            SPP(maxSpp),
            [&](const BufferTile& t) {
                for (int64_t y = t.beginY(); y < t.endY(); ++y)
                    for (int64_t x = t.beginX(); x < t.endX(); ++x)
                        for (int64_t s = 0; s < t.spp(); ++s)
                            params(x, y, s, t(x, y, s));
            },
            dumpTile);
    } else if (scenario == "input-count") {
        uint64_t k = 0;
        client.evaluateInputSamples(
            (int64_t)(maxSpp * w * h),
            [&](int64_t count, float* data) {
                for (int64_t i = 0; i < count; ++i, ++k)
                    params(k % w, (k / w) % h, k / (w * h), data + i * size);
            },
            dumpSamples);
    } else {
        std::fprintf(stderr, "unknown scenario %s\n", scenario.c_str());
        return 1;
    }
    std::fclose(g_out);
    client.sendResult();
    return 0;
}
