// The FBKSD 2.x C++ technique API (thesis appendix A.5), source-compatible,
// as a header-only layer over the C ABI (<fbksd/fbksd.h>, libfbksd).
//
// Differences a user may notice: errors throw fbksd::Error (a
// std::runtime_error carrying the C status and message) instead of
// aborting; an exception thrown by a callback stops delivering tiles and is
// rethrown from the evaluate call once the request is over.
#pragma once

#include <fbksd/core/SampleLayout.h>
#include <fbksd/core/SceneInfo.h>
#include <fbksd/core/definitions.h>

#include <cstdint>
#include <exception>
#include <functional>
#include <string>
#include <utility>

namespace fbksd {

//! A number of samples per pixel.
struct SPP {
    explicit SPP(int64_t value) : value(value) {}
    int64_t value;
};

//! A tile of samples: pixels [beginX, endX) × [beginY, endY), `tile(x, y, s)` is sample s of pixel (x, y).
class BufferTile {
public:
    explicit BufferTile(const FbksdTile* tile) : m_tile(tile) {}
    int64_t beginX() const { return m_tile->begin_x; }
    int64_t endX() const { return m_tile->end_x; }
    int64_t beginY() const { return m_tile->begin_y; }
    int64_t endY() const { return m_tile->end_y; }
    //! Samples per pixel in this tile.
    int64_t spp() const { return m_tile->spp; }
    //! Number of samples in this tile.
    int64_t size() const { return (int64_t)m_tile->count; }
    //! Sample `s` of pixel (x, y).
    float* operator()(int64_t x, int64_t y, int64_t s) const {
        size_t width = m_tile->end_x - m_tile->begin_x;
        size_t index = ((size_t)(y - m_tile->begin_y) * width + (size_t)(x - m_tile->begin_x)) * m_tile->spp + (size_t)s;
        return m_tile->data + index * m_tile->sample_size;
    }
    //! Sample `i` in storage order.
    float* operator[](int64_t i) const { return m_tile->data + (size_t)i * m_tile->sample_size; }

private:
    const FbksdTile* m_tile;
};

//! The connection to the benchmark server. Create one per process.
class BenchmarkClient {
public:
    using TileConsumer = std::function<void(const BufferTile&)>;
    using TileProducer = std::function<void(const BufferTile&)>;
    using TileConsumer2 = std::function<void(int64_t count, float* samples)>;
    using TileProducer2 = std::function<void(int64_t count, float* samples)>;

    //! Connects; with argc/argv, the debug options --fbksd-renderer and --fbksd-spp work.
    BenchmarkClient(int argc = 0, char* argv[] = nullptr) {
        detail::check(fbksd_client_new(argc, (const char* const*)argv, &m_client));
    }
    BenchmarkClient(const BenchmarkClient&) = delete;
    BenchmarkClient(BenchmarkClient&& o) noexcept : m_client(o.m_client) { o.m_client = nullptr; }
    ~BenchmarkClient() { fbksd_client_free(m_client); }

    SceneInfo getSceneInfo() { return SceneInfo(fbksd_client_scene_info(m_client)); }

    void setSampleLayout(const SampleLayout& layout) {
        FbksdLayout* l = fbksd_layout_new();
        FbksdStatus status = FBKSD_STATUS_OK;
        for (const auto& e : layout.elements()) {
            status = fbksd_layout_add(l, e.name.c_str(), e.io == SampleLayout::INPUT, (uint32_t)e.number);
            if (status != FBKSD_STATUS_OK)
                break;
        }
        if (status == FBKSD_STATUS_OK)
            status = fbksd_layout_set_roughness_threshold(l, layout.getRoughnessThreshold());
        if (status == FBKSD_STATUS_OK)
            status = fbksd_client_set_layout(m_client, l);
        fbksd_layout_free(l);
        detail::check(status);
    }

    //! The result image (width × height × RGB, scan-line order); owned by the client.
    float* getResultBuffer() {
        size_t len = 0;
        float* buffer = fbksd_client_result_buffer(m_client, &len);
        if (!buffer)
            throw Error(FBKSD_STATUS_USAGE, fbksd_last_error());
        return buffer;
    }

    //! Requests `spp` samples per pixel.
    void evaluateSamples(SPP spp, const TileConsumer& consumer) {
        Callbacks c{nullptr, &consumer, nullptr, nullptr, nullptr};
        finish(c, fbksd_client_evaluate_samples(m_client, (uint64_t)spp.value, &consumeTile, &c));
    }
    //! Requests `numSamples` samples anywhere on the image.
    void evaluateSamples(int64_t numSamples, const TileConsumer2& consumer) {
        Callbacks c{nullptr, nullptr, nullptr, &consumer, nullptr};
        finish(c, fbksd_client_evaluate_sample_count(m_client, (uint64_t)numSamples, &consumeRaw, &c));
    }
    //! Requests samples whose INPUT parameters `producer` writes first.
    void evaluateInputSamples(SPP spp, const TileProducer& producer, const TileConsumer& consumer) {
        Callbacks c{&producer, &consumer, nullptr, nullptr, nullptr};
        finish(c, fbksd_client_evaluate_input_samples(m_client, (uint64_t)spp.value, &produceTile, &consumeTile, &c));
    }
    //! Count form of evaluateInputSamples.
    void evaluateInputSamples(int64_t numSamples, const TileProducer2& producer, const TileConsumer2& consumer) {
        Callbacks c{nullptr, nullptr, &producer, &consumer, nullptr};
        finish(c, fbksd_client_evaluate_input_sample_count(m_client, (uint64_t)numSamples, &produceRaw, &consumeRaw, &c));
    }
    //! The original examples also spell the SPP producer form evaluateSamples.
    void evaluateSamples(SPP spp, const TileProducer& producer, const TileConsumer& consumer) {
        evaluateInputSamples(spp, producer, consumer);
    }
    void evaluateSamples(int64_t numSamples, const TileProducer2& producer, const TileConsumer2& consumer) {
        evaluateInputSamples(numSamples, producer, consumer);
    }

    //! Sends the result buffer; nothing more can be requested afterwards.
    void sendResult() { detail::check(fbksd_client_send_result(m_client)); }

private:
    struct Callbacks {
        const TileProducer* producer;
        const TileConsumer* consumer;
        const TileProducer2* producer2;
        const TileConsumer2* consumer2;
        std::exception_ptr error;
    };

    // Exceptions must not unwind through the C library: keep the first, skip the rest.
    template<typename F> static void safely(Callbacks* c, F f) {
        if (c->error)
            return;
        try {
            f();
        } catch (...) {
            c->error = std::current_exception();
        }
    }
    static void consumeTile(void* user, const FbksdTile* tile) {
        auto c = (Callbacks*)user;
        safely(c, [&] { (*c->consumer)(BufferTile(tile)); });
    }
    static void produceTile(void* user, const FbksdTile* tile) {
        auto c = (Callbacks*)user;
        safely(c, [&] { (*c->producer)(BufferTile(tile)); });
    }
    static void consumeRaw(void* user, const FbksdTile* tile) {
        auto c = (Callbacks*)user;
        safely(c, [&] { (*c->consumer2)((int64_t)tile->count, tile->data); });
    }
    static void produceRaw(void* user, const FbksdTile* tile) {
        auto c = (Callbacks*)user;
        safely(c, [&] { (*c->producer2)((int64_t)tile->count, tile->data); });
    }
    static void finish(Callbacks& c, FbksdStatus status) {
        if (c.error)
            std::rethrow_exception(c.error);
        detail::check(status);
    }

    FbksdClient* m_client = nullptr;
};

} // namespace fbksd
