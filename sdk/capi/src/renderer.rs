//! The renderer side: [`fbksd_server_run`] serves the manager from C
//! callbacks, and sample pipes ([`fbksd_pipe_open`]) carry the samples.
//!
//! As in the original C++ API, a pipe is opened from any thread with just
//! an image window and a sample count — no handle to the request — and the
//! evaluate callback may return before the samples are rendered (A.4 starts
//! a thread and returns). So the library keeps the request in progress in
//! one process-wide slot, and a request is complete when pipes holding all
//! its samples (`spp` per pixel plus `remaining`) have been closed, not
//! when the callback returns. One server runs per process.
//!
//! How a pipe's window maps to a tile: a window of `area` pixels opened for
//! `area × spp` samples of a request with `spp > 0` is a pixel tile (sample
//! `s` of pixel `(x, y)` at `((y − y0) · width + (x − x0)) · spp + s`); any
//! other pipe holds pixel-free samples (the original used the whole image
//! as their window). The two cannot be confused: `remaining` is less than
//! one sample per pixel.

use crate::client::FbksdTile;
use crate::layout::FbksdLayout;
use crate::scene_info::FbksdSceneInfo;
use crate::{free_handle, guard, handle, invalid, last_error, FbksdStatus};
use fbksd_core::layout::{CompiledLayout, Element, ElementIo};
use fbksd_core::{SceneInfo, Tile, TileRect};
use fbksd_renderer::{Evaluation, RenderingServer, SamplesPipe};
use std::ffi::c_void;
use std::sync::{Condvar, Mutex};

/// One request for samples, as the evaluate callback sees it.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct FbksdRequest {
    /// Samples per pixel (may be 0).
    pub spp: u64,
    /// Samples not tied to pixels, fewer than one per pixel (may be 0).
    pub remaining: u64,
    /// The most samples one pipe may hold.
    pub pipe_size: u64,
    /// Whether the technique writes INPUT random parameters.
    pub input: bool,
    /// Index of the request within the technique's session (for seeding).
    pub index: u64,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
}

/// Where each layout element sits in a sample, for writing samples fast.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct FbksdSampleMap {
    /// Floats per sample.
    pub sample_size: u32,
    /// Offset of each random parameter (IMAGE_X … LIGHT_Y), −1 if absent.
    pub parameter: [i32; 7],
    /// Whether each random parameter is INPUT (written by the technique).
    pub parameter_is_input: [bool; 7],
    /// Offset of feature `f` (COLOR_R … DIFFUSE_COLOR_B, numbered 0–27)
    /// with intersection number `n` at index `2f + n`, −1 if absent.
    pub feature: [i32; 56],
}

impl FbksdSampleMap {
    fn of(layout: &CompiledLayout) -> Self {
        let mut map = FbksdSampleMap {
            sample_size: layout.sample_size() as u32,
            parameter: [-1; 7],
            parameter_is_input: [false; 7],
            feature: [-1; 56],
        };
        for (offset, (element, io)) in layout.elements().iter().enumerate() {
            match *element {
                Element::Parameter(p) => {
                    map.parameter[p.index()] = offset as i32;
                    map.parameter_is_input[p.index()] = *io == ElementIo::Input;
                }
                Element::Feature(f, n) => map.feature[2 * f.index() + n as usize] = offset as i32,
            }
        }
        map
    }
}

/// Returns the preferred tile side in pixels.
pub type FbksdTileSizeCallback = Option<extern "C" fn(user: *mut c_void) -> u32>;
/// Fills `info` (at least "width" and "height").
pub type FbksdSceneInfoCallback = Option<extern "C" fn(user: *mut c_void, info: *mut FbksdSceneInfo) -> FbksdStatus>;
/// Accepts (OK) or rejects the technique's layout (with [`crate::fbksd_set_last_error`]).
pub type FbksdSetParametersCallback =
    Option<extern "C" fn(user: *mut c_void, layout: *const FbksdLayout) -> FbksdStatus>;
/// Starts producing a request's samples; may return before they are all produced.
pub type FbksdEvaluateCallback = Option<extern "C" fn(user: *mut c_void, request: *const FbksdRequest) -> FbksdStatus>;
/// A notification.
pub type FbksdEventCallback = Option<extern "C" fn(user: *mut c_void)>;

/// A renderer's callbacks; `user` is passed to each. Only `scene_info` and
/// `evaluate_samples` are required.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct FbksdServerCallbacks {
    /// Passed through to every callback.
    pub user: *mut c_void,
    /// Preferred tile side (16 if null); called once at start.
    pub tile_size: FbksdTileSizeCallback,
    /// The scene's info; called once at start.
    pub scene_info: FbksdSceneInfoCallback,
    /// Called with each technique's layout (any layout accepted if null).
    pub set_parameters: FbksdSetParametersCallback,
    /// Called for each request, on a thread of the library's.
    pub evaluate_samples: FbksdEvaluateCallback,
    /// Called when a request's last pipe is closed (may be null).
    pub last_tile_consumed: FbksdEventCallback,
    /// Called when the manager has no more work, before `fbksd_server_run` returns (may be null).
    pub finish: FbksdEventCallback,
}

/// The request in progress, shared by the evaluate thread and pipe openers.
struct Current {
    /// The request; valid while `serve_request` waits for it (see there).
    eval: *const Evaluation,
    spp: u64,
    width: u32,
    height: u32,
    expected: u64,
    /// Samples in pipes opened so far (closed or not).
    reserved: u64,
    /// Samples in closed pipes.
    delivered: u64,
    open: u64,
}

// SAFETY: `eval` is only dereferenced while `serve_request` keeps the
// Evaluation alive, and Evaluation is Sync (pipes are opened concurrently).
unsafe impl Send for Current {}

static CURRENT: Mutex<Option<Current>> = Mutex::new(None);
static PROGRESS: Condvar = Condvar::new();

/// A pipe: one slot of the shared ring, owned by the renderer until closed (opaque).
pub struct FbksdPipe {
    pipe: Option<SamplesPipe<'static>>,
    tile: FbksdTile,
    map: FbksdSampleMap,
}

/// A `*mut c_void` that may cross threads: the C side owns its thread safety.
#[derive(Clone, Copy)]
struct User(*mut c_void);
unsafe impl Send for User {}
unsafe impl Sync for User {}

/// Serves the manager that started this process (`FBKSD_RENDEZVOUS`)
/// until it says finish, calling `callbacks`. Blocks; returns OK when the
/// manager is done, an error status and message otherwise.
#[no_mangle]
pub extern "C" fn fbksd_server_run(callbacks: *const FbksdServerCallbacks) -> FbksdStatus {
    guard(|| {
        // SAFETY: a non-null pointer to the caller's callbacks, read once.
        let c = *unsafe { callbacks.as_ref() }.ok_or_else(|| invalid("callbacks is null"))?;
        let user = User(c.user);
        let scene_info = c.scene_info.ok_or_else(|| invalid("callbacks.scene_info is null"))?;
        let evaluate = c.evaluate_samples.ok_or_else(|| invalid("callbacks.evaluate_samples is null"))?;
        let mut info = FbksdSceneInfo(SceneInfo::new());
        if scene_info(user.0, &mut info) != FbksdStatus::Ok {
            return Err((FbksdStatus::SceneInfo, format!("the scene-info callback failed: {}", last_error())));
        }
        let mut server = RenderingServer::new()
            .on_get_scene_info(move || info.0.clone())
            .on_evaluate_samples(move |eval| serve_request(eval, evaluate, c.last_tile_consumed, user));
        if let Some(tile_size) = c.tile_size {
            server = server.on_get_tile_size(move || tile_size(user.0));
        }
        if let Some(set_parameters) = c.set_parameters {
            server = server.on_set_parameters(move |layout| {
                let view = FbksdLayout::of(layout.source());
                match set_parameters(user.0, &view) {
                    FbksdStatus::Ok => Ok(()),
                    _ => Err(last_error().into()),
                }
            });
        }
        if let Some(finish) = c.finish {
            server = server.on_finish(move || finish(user.0));
        }
        server.run().map_err(|e| {
            let status = match e {
                fbksd_renderer::RendererError::NoRendezvous => FbksdStatus::Connection,
                _ => FbksdStatus::Failed,
            };
            (status, e.to_string())
        })
    })
}

type BoxError = Box<dyn std::error::Error + Send + Sync>;

/// Runs one request: publishes it, calls the C callback, and waits until
/// pipes holding all its samples are closed.
fn serve_request(
    eval: &Evaluation,
    evaluate: extern "C" fn(*mut c_void, *const FbksdRequest) -> FbksdStatus,
    last_tile_consumed: FbksdEventCallback,
    user: User,
) -> Result<(), BoxError> {
    let (width, height) = (eval.width(), eval.height());
    let expected = eval.spp * width as u64 * height as u64 + eval.remaining;
    *CURRENT.lock().unwrap() =
        Some(Current { eval, spp: eval.spp, width, height, expected, reserved: 0, delivered: 0, open: 0 });
    // Whatever happens below, `eval` must not be reachable once we return.
    struct Clear;
    impl Drop for Clear {
        fn drop(&mut self) {
            *CURRENT.lock().unwrap_or_else(|p| p.into_inner()) = None;
        }
    }
    let _clear = Clear;

    let request = FbksdRequest {
        spp: eval.spp,
        remaining: eval.remaining,
        pipe_size: eval.pipe_size,
        input: eval.input,
        index: eval.request,
        width,
        height,
    };
    let status = evaluate(user.0, &request);
    // Even on failure, pipes still open borrow `eval`: wait for them.
    let mut current = CURRENT.lock().unwrap();
    loop {
        let c = current.as_ref().expect("cleared only here");
        let done = c.open == 0 && (status != FbksdStatus::Ok || c.delivered >= c.expected);
        if done {
            break;
        }
        current = PROGRESS.wait(current).unwrap();
    }
    drop(current);
    if status != FbksdStatus::Ok {
        return Err(format!("the evaluate callback failed: {}", last_error()).into());
    }
    if let Some(f) = last_tile_consumed {
        f(user.0);
    }
    Ok(())
}

/// Opens a pipe for `num_samples` samples in the window
/// `[begin_x, end_x) × [begin_y, end_y)` of the request in progress
/// (see the module notes for how the window is read), blocking until a slot
/// is free. Any thread may open pipes, concurrently; each must be closed
/// with [`fbksd_pipe_close`].
#[no_mangle]
pub extern "C" fn fbksd_pipe_open(
    begin_x: i64,
    begin_y: i64,
    end_x: i64,
    end_y: i64,
    num_samples: i64,
    out: *mut *mut FbksdPipe,
) -> FbksdStatus {
    guard(|| {
        let out = handle(out, "out")?;
        let usage = |m: String| (FbksdStatus::Usage, m);
        let (eval, tile) = {
            let mut current = CURRENT.lock().unwrap();
            let c = current.as_mut().ok_or_else(|| {
                usage("no request in progress: open pipes while a request's samples are still due".into())
            })?;
            if num_samples < 0 {
                return Err(invalid(&format!("a pipe of {num_samples} samples")));
            }
            let area = (end_x - begin_x).max(0) * (end_y - begin_y).max(0);
            let tile = if c.spp > 0 && area > 0 && num_samples as u64 == area as u64 * c.spp {
                let inside = 0 <= begin_x && end_x <= c.width as i64 && 0 <= begin_y && end_y <= c.height as i64;
                if !inside {
                    return Err(invalid(&format!(
                        "window [{begin_x}, {end_x}) × [{begin_y}, {end_y}) leaves the {}×{} image",
                        c.width, c.height
                    )));
                }
                let rect = TileRect { x0: begin_x as u32, y0: begin_y as u32, x1: end_x as u32, y1: end_y as u32 };
                Tile::Pixels { rect, spp: c.spp as u32 }
            } else {
                Tile::Samples { count: num_samples as u64 }
            };
            if c.reserved + tile.sample_count() > c.expected {
                return Err(usage(format!(
                    "a pipe of {} samples exceeds the request: {} of its {} samples are already in pipes",
                    tile.sample_count(),
                    c.reserved,
                    c.expected
                )));
            }
            c.reserved += tile.sample_count();
            c.open += 1;
            (c.eval, tile)
        };
        // SAFETY: serve_request keeps the Evaluation alive until `open`
        // drops back to 0, which happens only when this pipe is closed (or
        // fails to open, below).
        let eval: &'static Evaluation = unsafe { &*eval };
        let opened = eval.pipe(tile);
        let mut pipe = match opened {
            Ok(p) => p,
            Err(e) => {
                if let Some(c) = CURRENT.lock().unwrap_or_else(|p| p.into_inner()).as_mut() {
                    c.reserved -= tile.sample_count();
                }
                close_one(0);
                return Err((FbksdStatus::Failed, format!("opening a pipe: {e}")));
            }
        };
        let (begin_x, end_x, begin_y, end_y, spp) = match tile {
            Tile::Pixels { rect, spp } => (rect.x0, rect.x1, rect.y0, rect.y1, spp),
            Tile::Samples { .. } => (0, 0, 0, 0, 0),
        };
        let map = FbksdSampleMap::of(eval.layout());
        let data = pipe.raw().as_mut_ptr();
        let count = tile.sample_count();
        let tile =
            FbksdTile { begin_x, end_x, begin_y, end_y, spp, sample_size: map.sample_size as usize, count, data };
        *out = Box::into_raw(Box::new(FbksdPipe { pipe: Some(pipe), tile, map }));
        Ok(())
    })
}

/// One pipe fewer open, `samples` more delivered.
fn close_one(samples: u64) {
    if let Some(c) = CURRENT.lock().unwrap_or_else(|p| p.into_inner()).as_mut() {
        c.open -= 1;
        c.delivered += samples;
    }
    PROGRESS.notify_all();
}

/// The pipe's tile: its window, spp, sample size, count and the samples to write.
#[no_mangle]
pub extern "C" fn fbksd_pipe_tile(pipe: *const FbksdPipe, out: *mut FbksdTile) -> FbksdStatus {
    guard(|| {
        // SAFETY: a non-null handle comes from fbksd_pipe_open.
        let p = unsafe { pipe.as_ref() }.ok_or_else(|| invalid("pipe is null"))?;
        *handle(out, "out")? = p.tile;
        Ok(())
    })
}

/// Where each element sits in the pipe's samples.
#[no_mangle]
pub extern "C" fn fbksd_pipe_sample_map(pipe: *const FbksdPipe, out: *mut FbksdSampleMap) -> FbksdStatus {
    guard(|| {
        // SAFETY: a non-null handle comes from fbksd_pipe_open.
        let p = unsafe { pipe.as_ref() }.ok_or_else(|| invalid("pipe is null"))?;
        *handle(out, "out")? = p.map;
        Ok(())
    })
}

/// Hands the pipe's samples to the technique and frees the pipe (null is ignored).
#[no_mangle]
pub extern "C" fn fbksd_pipe_close(pipe: *mut FbksdPipe) -> FbksdStatus {
    if pipe.is_null() {
        return FbksdStatus::Ok;
    }
    let status = guard(|| {
        let p = handle(pipe, "pipe")?;
        let count = p.tile.count;
        let finished = p.pipe.take().map(SamplesPipe::finish);
        // Counted as delivered even if the hand-over failed: the request
        // fails anyway, and the evaluate thread must stop waiting.
        close_one(count);
        match finished {
            Some(Err(e)) => Err((FbksdStatus::Failed, format!("closing a pipe: {e}"))),
            _ => Ok(()),
        }
    });
    free_handle(pipe);
    status
}

/// Feature and parameter numbering of [`FbksdSampleMap`], checked against the core.
#[cfg(test)]
mod tests {
    use super::*;
    use fbksd_core::{Feature, RandomParameter};

    #[test]
    fn the_map_numbers_elements_as_the_core_does() {
        assert_eq!(RandomParameter::ALL.len(), 7);
        assert_eq!(Feature::ALL.len() * 2, 56);
        let layout = fbksd_core::layout::SampleLayout::new()
            .with("COLOR_G")
            .with_io("IMAGE_Y", ElementIo::Input)
            .with_number("NORMAL_Z", 1)
            .compile()
            .unwrap();
        let map = FbksdSampleMap::of(&layout);
        assert_eq!(map.sample_size, 3);
        assert_eq!(map.feature[2 * Feature::ColorG.index()], 0);
        assert_eq!(map.parameter[RandomParameter::ImageY.index()], 1);
        assert!(map.parameter_is_input[RandomParameter::ImageY.index()]);
        assert_eq!(map.feature[2 * Feature::NormalZ.index() + 1], 2);
        assert_eq!(map.parameter[RandomParameter::ImageX.index()], -1);
    }
}
