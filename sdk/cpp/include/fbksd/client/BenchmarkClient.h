// The FBKSD 2.x C++ technique API (thesis appendix A.5), source-compatible,
// as a header-only layer over the C ABI (<fbksd/fbksd.h>, libfbksd).
//
// Differences a user may notice: errors throw fbksd::Error (a
// std::runtime_error carrying the C status and message) instead of
// aborting; an exception thrown by a callback stops delivering tiles and is
// rethrown from the evaluate call once the request is over.
#pragma once

#include <fbksd/fbksd.h>

#include <cstdint>
#include <cstdio>
#include <exception>
#include <functional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace fbksd {

//! A failed call: the C API's status and its message.
class Error : public std::runtime_error {
public:
    Error(FbksdStatus status, const std::string& message) : std::runtime_error(message), status(status) {}
    FbksdStatus status;
};

namespace detail {
inline void check(FbksdStatus status) {
    if (status != FBKSD_STATUS_OK)
        throw Error(status, fbksd_last_error());
}
} // namespace detail

//! Random parameters; with them first in the layout, in this order, they
//! also index a sample (`sample[IMAGE_X]`), as in the original examples.
enum RandomParameter { IMAGE_X = 0, IMAGE_Y, LENS_U, LENS_V, TIME, LIGHT_X, LIGHT_Y, NUM_RANDOM_PARAMETERS };

//! A number of samples per pixel.
struct SPP {
    explicit SPP(int64_t value) : value(value) {}
    int64_t value;
};

//! Information about the scene being rendered (width, height, max_spp, …).
class SceneInfo {
public:
    explicit SceneInfo(FbksdClient* client = nullptr) : m_client(client) {}

    //! Whether the info `name` exists with type T.
    template<typename T> bool has(const std::string& name) const;

    //! The info `name` as T; T() (and a warning on stderr) if it does not exist.
    template<typename T> T get(const std::string& name) const;

private:
    template<typename T, typename F> T fetch(const std::string& name, F read) const {
        T value{};
        if (!m_client || read(m_client, name.c_str(), &value) != FBKSD_STATUS_OK) {
            std::fprintf(stderr, "fbksd: scene info: %s\n", m_client ? fbksd_last_error() : "no client");
            return T();
        }
        return value;
    }
    FbksdClient* m_client;
};

template<> inline int64_t SceneInfo::get<int64_t>(const std::string& name) const {
    return fetch<int64_t>(name, fbksd_scene_info_int);
}
template<> inline int SceneInfo::get<int>(const std::string& name) const { return (int)get<int64_t>(name); }
template<> inline double SceneInfo::get<double>(const std::string& name) const {
    return fetch<double>(name, fbksd_scene_info_float);
}
template<> inline float SceneInfo::get<float>(const std::string& name) const { return (float)get<double>(name); }
template<> inline bool SceneInfo::get<bool>(const std::string& name) const {
    return fetch<bool>(name, fbksd_scene_info_bool);
}
template<> inline std::string SceneInfo::get<std::string>(const std::string& name) const {
    size_t needed = 0;
    if (!m_client)
        return std::string();
    fbksd_scene_info_string(m_client, name.c_str(), nullptr, 0, &needed);
    if (needed == 0)
        return std::string();
    std::vector<char> buffer(needed);
    if (fbksd_scene_info_string(m_client, name.c_str(), buffer.data(), buffer.size(), &needed) != FBKSD_STATUS_OK)
        return std::string();
    return std::string(buffer.data());
}

template<typename T> inline bool SceneInfo::has(const std::string& name) const {
    if (!m_client || !fbksd_scene_info_has(m_client, name.c_str()))
        return false;
    // Typed check: the value must read as T.
    int64_t i;
    double d;
    bool b;
    size_t n;
    if (std::is_same<T, bool>::value)
        return fbksd_scene_info_bool(m_client, name.c_str(), &b) == FBKSD_STATUS_OK;
    if (std::is_integral<T>::value)
        return fbksd_scene_info_int(m_client, name.c_str(), &i) == FBKSD_STATUS_OK;
    if (std::is_floating_point<T>::value)
        return fbksd_scene_info_float(m_client, name.c_str(), &d) == FBKSD_STATUS_OK;
    fbksd_scene_info_string(m_client, name.c_str(), nullptr, 0, &n);
    return n > 0;
}

//! The layout of a sample in memory: `layout("IMAGE_X", SampleLayout::INPUT)("COLOR_R")("WORLD_X")[1]`.
class SampleLayout {
public:
    enum ElementIO : bool { OUTPUT = false, INPUT = true };

    //! Appends element `name`.
    SampleLayout& operator()(const std::string& name, ElementIO io = OUTPUT) {
        m_elements.push_back(Element{name, io, 0});
        return *this;
    }
    //! Sets the intersection number (0 or 1) of the last element.
    SampleLayout& operator[](int num) {
        if (!m_elements.empty())
            m_elements.back().number = num;
        return *this;
    }
    //! Marks element `name` as INPUT or OUTPUT.
    SampleLayout& setElementIO(const std::string& name, ElementIO io) {
        for (auto& e : m_elements)
            if (e.name == name)
                e.io = io;
        return *this;
    }
    //! Marks element `index` as INPUT or OUTPUT.
    SampleLayout& setElementIO(int index, ElementIO io) {
        if (index >= 0 && index < (int)m_elements.size())
            m_elements[index].io = io;
        return *this;
    }
    //! Floats per sample.
    int getSampleSize() const { return (int)m_elements.size(); }
    //! Number of INPUT elements.
    int getInputSize() const {
        int n = 0;
        for (const auto& e : m_elements)
            n += e.io == INPUT;
        return n;
    }
    //! Number of OUTPUT elements.
    int getOutputSize() const { return getSampleSize() - getInputSize(); }
    //! Whether element `name` exists and is INPUT.
    bool hasInput(const std::string& name) const {
        for (const auto& e : m_elements)
            if (e.name == name && e.io == INPUT)
                return true;
        return false;
    }
    //! Whether any element is INPUT.
    bool hasInput() const { return getInputSize() > 0; }
    //! Beckmann roughness threshold of the DIFFUSE_COLOR features (default 0.1).
    void setRoughnessThreshold(float a) { m_roughness = a; }
    float getRoughnessThreshold() const { return m_roughness; }

    struct Element {
        std::string name;
        ElementIO io;
        int number;
    };
    const std::vector<Element>& elements() const { return m_elements; }

private:
    std::vector<Element> m_elements;
    float m_roughness = 0.1f;
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

    SceneInfo getSceneInfo() { return SceneInfo(m_client); }

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
