// fbksd::IQA and fbksd::Img (thesis appendix A.5.4–A.5.5): write an image
// quality metric as a program. Header-only over the C ABI.
//
// Usage: ./<iqa_exec> [options] <ref-img-path> <test-img-path>
//   -h, --help                    this help
//   --info                        the metric's description (IQA info.json)
//   --value-file <path>           write the value there instead of stdout
//   --map-file <path.png>         write the error map (metrics that have one)
// The value is printed as {"<acronym>": value}. Images are read as 32-bit
// float (the original read half floats).
#pragma once

#include <fbksd/core/definitions.h>
#include <fbksd/core/sdk.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <string>

namespace fbksd {

//! A three-channel float image, scanline order.
class Img {
public:
    //! An empty image: zero size, data() is null.
    Img() = default;
    //! An uninitialised image of the given size.
    Img(int width, int height) : m_width(width), m_height(height), m_data(new float[size(width, height)]) {}
    //! An image of the given size with every value `v`.
    explicit Img(int width, int height, float v) : Img(width, height) {
        std::fill(m_data.get(), m_data.get() + size(width, height), v);
    }
    //! An image taking ownership of `data` (width × height × 3 floats).
    explicit Img(int width, int height, std::unique_ptr<float[]> data)
        : m_width(width), m_height(height), m_data(std::move(data)) {}
    //! An image copying `data` (width × height × 3 floats).
    explicit Img(int width, int height, const float* data) : Img(width, height) {
        std::memcpy(m_data.get(), data, size(width, height) * sizeof(float));
    }
    Img(const Img& o) : Img(o.m_width, o.m_height) {
        if (o.m_data)
            std::memcpy(m_data.get(), o.m_data.get(), size(m_width, m_height) * sizeof(float));
    }
    Img(Img&&) = default;
    Img& operator=(Img o) {
        std::swap(m_width, o.m_width);
        std::swap(m_height, o.m_height);
        std::swap(m_data, o.m_data);
        return *this;
    }

    int width() const { return m_width; }
    int height() const { return m_height; }
    float* data() { return m_data.get(); }
    const float* data() const { return m_data.get(); }
    //! The RGB values of pixel (x, y).
    float* operator()(int x, int y) { return m_data.get() + ((size_t)y * m_width + x) * 3; }
    const float* operator()(int x, int y) const { return m_data.get() + ((size_t)y * m_width + x) * 3; }
    //! Channel c of pixel (x, y).
    float& operator()(int x, int y, int c) { return (*this)(x, y)[c]; }
    const float& operator()(int x, int y, int c) const { return (*this)(x, y)[c]; }

    //! Maps values to the [0, 256) range like exrtools' exrtopng: the sRGB
    //! curve on values clamped to [0, 1], times 255 (NaN becomes 0).
    void toneMap() {
        size_t n = size(m_width, m_height);
        for (size_t i = 0; i < n; ++i) {
            float v = m_data[i];
            v = (v == v) ? std::min(std::max(v, 0.f), 1.f) : 0.f;
            v = v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.f / 2.4f) - 0.055f;
            m_data[i] = std::min(v * 255.f, 255.f);
        }
    }

private:
    static size_t size(int width, int height) { return (size_t)std::max(width, 0) * (size_t)std::max(height, 0) * 3; }

    int m_width = 0;
    int m_height = 0;
    std::unique_ptr<float[]> m_data;
};

//! A metric program's command line, inputs and report. Create one, in main().
class IQA {
public:
    //! Parses the command line (answering --help and --info itself) and
    //! reads both images; throws fbksd::sdk::Error (a std::runtime_error) if they
    //! cannot be read or differ in size.
    IQA(int argc, char const* const* argv, const std::string& acronym, const std::string& fullName,
        const std::string& reference, bool lowerIsBetter, bool hasErrorMap) {
        sdk::check(fbksd_iqa_new(argc, argv, acronym.c_str(), fullName.c_str(), reference.c_str(), lowerIsBetter,
                                    hasErrorMap, &m_iqa));
    }
    IQA(const IQA&) = delete;
    IQA& operator=(const IQA&) = delete;
    ~IQA() { fbksd_iqa_free(m_iqa); }

    //! The reference and test images.
    void loadInputImages(Img& refImg, Img& testImg) {
        refImg = image(FBKSD_IQA_IMAGE_REFERENCE);
        testImg = image(FBKSD_IQA_IMAGE_TEST);
    }
    //! Reports the value (metrics without an error map).
    void report(float value) { sdk::check(fbksd_iqa_report(m_iqa, value, nullptr, 0, 0)); }
    //! Reports the value and the error map (values in [0, 1), larger is worse).
    void report(float value, const Img& errorMap) {
        sdk::check(fbksd_iqa_report(m_iqa, value, errorMap.data(), (uint32_t)errorMap.width(),
                                       (uint32_t)errorMap.height()));
    }

private:
    Img image(FbksdIqaImage which) {
        uint32_t width = 0, height = 0;
        const float* data = fbksd_iqa_image(m_iqa, which, &width, &height);
        if (!data)
            throw sdk::Error(FBKSD_STATUS_INVALID_ARGUMENT, fbksd_last_error());
        return Img((int)width, (int)height, data);
    }

    FbksdIqa* m_iqa = nullptr;
};

} // namespace fbksd
