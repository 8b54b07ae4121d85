// fbksd::RenderingServer (thesis appendix A.5.6): turns a renderer into a
// sample server for FBKSD, through callbacks. Header-only over the C ABI.
//
// The evaluate callback may return at once and render on other threads
// (as thesis example A.4 does): a request is complete when SamplesPipes
// holding all its samples have been released, not when the callback
// returns. An exception thrown by a callback fails the request (or the
// layout) with its message instead of terminating the renderer.
#pragma once

#include <fbksd/core/SampleLayout.h>
#include <fbksd/core/SceneInfo.h>
#include <fbksd/core/definitions.h>
#include <fbksd/core/sdk.h>
#include <fbksd/renderer/samples.h>

#include <cstdint>
#include <cstdlib>
#include <exception>
#include <functional>
#include <memory>
#include <string>

namespace fbksd {

class RenderingServer {
public:
    using GetTileSize = std::function<int()>;
    using GetSceneInfo = std::function<SceneInfo()>;
    using SetParameters = std::function<void(const SampleLayout& layout)>;
    using EvaluateSamples = std::function<void(int64_t spp, int64_t remainingCount, int pipeSize)>;
    using LastTileConsumed = std::function<void()>;
    using Finish = std::function<void()>;

    RenderingServer() = default;
    RenderingServer(const RenderingServer&) = delete;
    RenderingServer(RenderingServer&&) = default;
    ~RenderingServer() = default;

    //! Preferred tile side in pixels; called once when the renderer starts.
    void onGetTileSize(const GetTileSize& callback) { m_tileSize = callback; }
    //! The scene's information (width, height, max_spp, …); called once at start.
    void onGetSceneInfo(const GetSceneInfo& callback) { m_sceneInfo = callback; }
    //! Called with the technique's sample layout; throw to reject it.
    void onSetParameters(const SetParameters& callback) { m_setParameters = callback; }
    //! Called for each request: `spp` samples per pixel plus `remainingCount`
    //! pixel-free samples, in pipes of at most `pipeSize` samples.
    void onEvaluateSamples(const EvaluateSamples& callback) { m_evaluate = callback; }
    //! Called when the last pipe of a request has been released.
    void onLastTileConsumed(const LastTileConsumed& callback) { m_lastTile = callback; }
    //! Called when FBKSD has no more work, before run() returns.
    void onFinish(const Finish& callback) { m_finish = callback; }

    //! Serves FBKSD until it is done; throws fbksd::sdk::Error if the renderer
    //! was not started by FBKSD or the connection fails.
    void run() {
        FbksdServerCallbacks c{};
        c.user = this;
        c.tile_size = m_tileSize ? &tileSize : nullptr;
        c.scene_info = &sceneInfo;
        c.set_parameters = m_setParameters ? &setParameters : nullptr;
        c.evaluate_samples = &evaluate;
        c.last_tile_consumed = m_lastTile ? &lastTile : nullptr;
        c.finish = m_finish ? &finish : nullptr;
        sdk::check(fbksd_server_run(&c));
    }

private:
    // Exceptions must not unwind through the C library: report them as a status and message.
    template<typename F> static FbksdStatus safely(F f) {
        try {
            f();
            return FBKSD_STATUS_OK;
        } catch (const std::exception& e) {
            fbksd_set_last_error(e.what());
        } catch (...) {
            fbksd_set_last_error("unknown exception");
        }
        return FBKSD_STATUS_FAILED;
    }
    static uint32_t tileSize(void* user) {
        int size = 16;
        safely([&] { size = static_cast<RenderingServer*>(user)->m_tileSize(); });
        return size > 0 ? (uint32_t)size : 16u;
    }
    static FbksdStatus sceneInfo(void* user, FbksdSceneInfo* out) {
        return safely([&] {
            auto self = static_cast<RenderingServer*>(user);
            if (!self->m_sceneInfo)
                throw std::runtime_error("no onGetSceneInfo callback");
            SceneInfo info = self->m_sceneInfo();
            sdk::check(fbksd_scene_info_copy(out, info.handle()));
        });
    }
    static FbksdStatus setParameters(void* user, const FbksdLayout* layout) {
        return safely([&] { static_cast<RenderingServer*>(user)->m_setParameters(SampleLayout(layout)); });
    }
    static FbksdStatus evaluate(void* user, const FbksdRequest* r) {
        return safely([&] {
            auto self = static_cast<RenderingServer*>(user);
            if (!self->m_evaluate)
                throw std::runtime_error("no onEvaluateSamples callback");
            int pipeSize = r->pipe_size > (uint64_t)INT32_MAX ? INT32_MAX : (int)r->pipe_size;
            self->m_evaluate((int64_t)r->spp, (int64_t)r->remaining, pipeSize);
        });
    }
    static void lastTile(void* user) {
        safely([&] { static_cast<RenderingServer*>(user)->m_lastTile(); });
    }
    static void finish(void* user) {
        safely([&] { static_cast<RenderingServer*>(user)->m_finish(); });
    }

    GetTileSize m_tileSize;
    GetSceneInfo m_sceneInfo;
    SetParameters m_setParameters;
    EvaluateSamples m_evaluate;
    LastTileConsumed m_lastTile;
    Finish m_finish;
};

} // namespace fbksd
