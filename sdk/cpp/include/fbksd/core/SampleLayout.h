// fbksd::SampleLayout: which values each sample carries, in memory order,
// and which random parameters the technique writes itself (INPUT).
#pragma once

#include <fbksd/core/sdk.h>

namespace fbksd {

//! The layout of a sample in memory: `layout("IMAGE_X", SampleLayout::INPUT)("COLOR_R")("WORLD_X")[1]`.
class SampleLayout {
public:
    enum ElementIO : bool { OUTPUT = false, INPUT = true };

    SampleLayout() = default;
    //! A copy of the C API's layout (renderers receive the technique's this way).
    explicit SampleLayout(const FbksdLayout* layout) {
        size_t n = fbksd_layout_len(layout);
        for (size_t i = 0; i < n; ++i) {
            FbksdElement e;
            sdk::check(fbksd_layout_element(layout, i, &e));
            m_elements.push_back(Element{e.name, e.input ? INPUT : OUTPUT, (int)e.number});
        }
        m_roughness = fbksd_layout_roughness_threshold(layout);
    }

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

    //! Whether every element is one of `names` (the elements a renderer
    //! supports) and no element appears twice with the same number.
    bool isValid(const std::set<std::string>& names) const {
        std::set<std::pair<std::string, int>> seen;
        for (const auto& e : m_elements)
            if (!names.count(e.name) || !seen.insert({e.name, e.number}).second)
                return false;
        return true;
    }

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

} // namespace fbksd
