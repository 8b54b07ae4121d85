// fbksd::SceneInfo: information about the scene (width, height, max_spp,
// …). Techniques read it from their client; renderers build one with set().
#pragma once

#include <fbksd/core/sdk.h>

namespace fbksd {

class SceneInfo {
public:
    //! An empty scene info (renderers fill it with set()).
    SceneInfo() : m_info(fbksd_scene_info_new()) {}
    //! A copy of the C API's scene info.
    explicit SceneInfo(const FbksdSceneInfo* info) : m_info(fbksd_scene_info_clone(info)) {}
    SceneInfo(const SceneInfo& o) : m_info(fbksd_scene_info_clone(o.m_info)) {}
    SceneInfo(SceneInfo&& o) noexcept : m_info(o.m_info) { o.m_info = nullptr; }
    SceneInfo& operator=(SceneInfo o) {
        std::swap(m_info, o.m_info);
        return *this;
    }
    ~SceneInfo() { fbksd_scene_info_free(m_info); }

    //! Whether the info `name` exists with type T.
    template<typename T> bool has(const std::string& name) const;

    //! The info `name` as T; T() (and a warning on stderr) if it does not exist.
    template<typename T> T get(const std::string& name) const;

    //! Sets the info `name` (integers, floating point, bool, strings).
    template<typename T> void set(const std::string& name, const T& value) { put(name, value); }

    //! This info with every item of `scene` added; `scene`'s win on equal keys.
    SceneInfo merged(const SceneInfo& scene) const {
        SceneInfo out(*this);
        sdk::check(fbksd_scene_info_merge(out.m_info, scene.m_info));
        return out;
    }

    //! The C API's handle (owned by this object).
    const FbksdSceneInfo* handle() const { return m_info; }
    FbksdSceneInfo* handle() { return m_info; }

private:
    template<typename T> void put(const std::string& name, const T& value) {
        if (std::is_same<T, bool>::value)
            sdk::check(fbksd_scene_info_set_bool(m_info, name.c_str(), value != T()));
        else if (std::is_integral<T>::value)
            sdk::check(fbksd_scene_info_set_int(m_info, name.c_str(), (int64_t)value));
        else
            sdk::check(fbksd_scene_info_set_float(m_info, name.c_str(), (double)value));
    }
    void put(const std::string& name, const std::string& value) {
        sdk::check(fbksd_scene_info_set_string(m_info, name.c_str(), value.c_str()));
    }
    void put(const std::string& name, const char* value) {
        sdk::check(fbksd_scene_info_set_string(m_info, name.c_str(), value));
    }

    template<typename T, typename F> T fetch(const std::string& name, F read) const {
        T value{};
        if (read(m_info, name.c_str(), &value) != FBKSD_STATUS_OK) {
            std::fprintf(stderr, "fbksd: scene info: %s\n", fbksd_last_error());
            return T();
        }
        return value;
    }

    FbksdSceneInfo* m_info;
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
    fbksd_scene_info_string(m_info, name.c_str(), nullptr, 0, &needed);
    if (needed == 0) {
        std::fprintf(stderr, "fbksd: scene info: %s\n", fbksd_last_error());
        return std::string();
    }
    std::vector<char> buffer(needed);
    if (fbksd_scene_info_string(m_info, name.c_str(), buffer.data(), buffer.size(), &needed) != FBKSD_STATUS_OK)
        return std::string();
    return std::string(buffer.data());
}

template<typename T> inline bool SceneInfo::has(const std::string& name) const {
    if (!fbksd_scene_info_has(m_info, name.c_str()))
        return false;
    // Typed check: the value must read as T.
    int64_t i;
    double d;
    bool b;
    size_t n = 0;
    if (std::is_same<T, bool>::value)
        return fbksd_scene_info_bool(m_info, name.c_str(), &b) == FBKSD_STATUS_OK;
    if (std::is_integral<T>::value)
        return fbksd_scene_info_int(m_info, name.c_str(), &i) == FBKSD_STATUS_OK;
    if (std::is_floating_point<T>::value)
        return fbksd_scene_info_float(m_info, name.c_str(), &d) == FBKSD_STATUS_OK;
    fbksd_scene_info_string(m_info, name.c_str(), nullptr, 0, &n);
    return n > 0;
}

} // namespace fbksd
