// The FBKSD 2.x C++ technique API (thesis appendix A.5, and the rest of the
// 2.x client surface: the tile iterator, the point accessor, SPP's
// setters), source-compatible, as a header-only layer over the C ABI
// (<fbksd/fbksd.h>, libfbksd).
//
// Differences a user may notice: errors throw fbksd::sdk::Error (a
// std::runtime_error carrying the C status and message) instead of
// aborting; an exception thrown by a callback stops delivering tiles and is
// rethrown from the evaluate call once the request is over. Like 2.x, this
// header declares no RandomParameter or Feature names (IMAGE_X, COLOR_R,
// DEPTH, ...): techniques index samples with their own.
#pragma once

#include <fbksd/core/SampleLayout.h>
#include <fbksd/core/SceneInfo.h>
#include <fbksd/core/definitions.h>
#include <fbksd/core/sdk.h>

namespace fbksd {

//! A number of samples per pixel.
class SPP {
public:
    explicit SPP(int64_t value) : value(value) {}
    int64_t operator=(int64_t v) { return value = v; }
    void setValue(int64_t v) { value = v; }
    int64_t getValue() const { return value; }

    int64_t value;
};

//! A tile of samples: pixels [beginX, endX) x [beginY, endY), spp samples
//! each; `tile(x, y, s)` is sample s of pixel (x, y), and iterating the tile
//! visits every sample in storage order (`for (const auto sample : tile)`).
class BufferTile {
public:
    //! Walks a tile's samples in storage order; `*it` is one sample's floats.
    class SampleIterator {
    public:
        using iterator_category = std::forward_iterator_tag;
        using value_type = const float*;
        using difference_type = std::ptrdiff_t;
        using pointer = const float* const*;
        using reference = const float*;

        SampleIterator(const float* at, size_t stride) : m_at(at), m_stride(stride) {}
        const float* operator*() const { return m_at; }
        SampleIterator& operator++() {
            m_at += m_stride;
            return *this;
        }
        SampleIterator operator++(int) {
            SampleIterator before = *this;
            ++*this;
            return before;
        }
        bool operator==(const SampleIterator& o) const { return m_at == o.m_at; }
        bool operator!=(const SampleIterator& o) const { return m_at != o.m_at; }

    private:
        const float* m_at;
        size_t m_stride;
    };

    explicit BufferTile(const FbksdTile* tile) : m_tile(tile) {}
    int64_t beginX() const { return m_tile->begin_x; }
    int64_t endX() const { return m_tile->end_x; }
    int64_t beginY() const { return m_tile->begin_y; }
    int64_t endY() const { return m_tile->end_y; }
    int64_t width() const { return endX() - beginX(); }
    int64_t height() const { return endY() - beginY(); }
    int64_t numPixels() const { return width() * height(); }
    //! Samples per pixel in this tile.
    int64_t getSPP() const { return m_tile->spp; }
    int64_t spp() const { return m_tile->spp; }
    //! Floats per sample (the layout's size).
    int64_t getSampleSize() const { return (int64_t)m_tile->sample_size; }
    //! Number of samples in this tile.
    int64_t size() const { return (int64_t)m_tile->count; }

    //! Sample `s` of pixel (x, y).
    float* operator()(int64_t x, int64_t y, int64_t s) const {
        size_t index = ((size_t)(y - beginY()) * (size_t)width() + (size_t)(x - beginX())) * m_tile->spp + (size_t)s;
        return m_tile->data + index * m_tile->sample_size;
    }
    //! Sample `s` of the pixel at `p`, any point type with `.x` and `.y`.
    template<typename T> float* operator()(const T& p, int64_t s) const {
        return (*this)((int64_t)p.x, (int64_t)p.y, s);
    }
    //! Sample `i` in storage order.
    float* operator[](int64_t i) const { return m_tile->data + (size_t)i * m_tile->sample_size; }

    SampleIterator begin() const { return SampleIterator(m_tile->data, m_tile->sample_size); }
    SampleIterator end() const {
        return SampleIterator(m_tile->data + (size_t)m_tile->count * m_tile->sample_size, m_tile->sample_size);
    }

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
        sdk::check(fbksd_client_new(argc, (const char* const*)argv, &m_client));
    }
    BenchmarkClient(const BenchmarkClient&) = delete;
    BenchmarkClient(BenchmarkClient&& o) noexcept : m_client(o.m_client) { o.m_client = nullptr; }
    BenchmarkClient& operator=(const BenchmarkClient&) = delete;
    BenchmarkClient& operator=(BenchmarkClient&& o) noexcept {
        std::swap(m_client, o.m_client);
        return *this;
    }
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
        sdk::check(status);
    }

    //! The result image (width × height × RGB, scan-line order); owned by the client.
    float* getResultBuffer() {
        size_t len = 0;
        float* buffer = fbksd_client_result_buffer(m_client, &len);
        if (!buffer)
            throw sdk::Error(FBKSD_STATUS_USAGE, fbksd_last_error());
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
    void sendResult() { sdk::check(fbksd_client_send_result(m_client)); }

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
        sdk::check(status);
    }

    FbksdClient* m_client = nullptr;
};

} // namespace fbksd
