//! The C ABI over the Rust technique API ([`fbksd_client`]): what C, the
//! C++ headers and other languages link (`libfbksd.so`, `libfbksd.a`).
//!
//! Conventions, for every function:
//! - It returns an [`FbksdStatus`]; on failure, [`fbksd_last_error`] gives
//!   a message for this thread, valid until the thread's next call.
//! - No panic crosses the boundary: a panic becomes [`FbksdStatus::Panic`]
//!   with its message.
//! - Handles are opaque; each `*_new` has its `*_free`; null handles are
//!   refused with [`FbksdStatus::InvalidArgument`].
//!
//! The header `include/fbksd/fbksd.h` is generated from this file by
//! cbindgen and committed; a test fails when it is stale (rerun it with
//! `FBKSD_REGENERATE_HEADER=1` to refresh it).
#![deny(missing_docs)]
// Every exported function checks its pointers itself; the C caller cannot mark them unsafe.
#![allow(clippy::not_unsafe_ptr_arg_deref)]

use fbksd_client::{BenchmarkClient, BufferTile, BufferTileMut, ElementIo, SampleLayout, Spp};
use std::cell::RefCell;
use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

/// The outcome of a call.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FbksdStatus {
    /// Success.
    Ok = 0,
    /// A null pointer, bad UTF-8, or a value out of range.
    InvalidArgument = 1,
    /// Not started by a manager (and not in debug mode), or the connection failed.
    Connection = 2,
    /// The sample layout is invalid.
    Layout = 3,
    /// The manager refused a request (budget, order of calls, …); the run is over.
    Refused = 4,
    /// A scene-info key is missing or has another type.
    SceneInfo = 5,
    /// A call out of order (e.g. samples before a layout, or after the result).
    Usage = 6,
    /// Anything else (protocol, shared memory).
    Failed = 7,
    /// A bug: the library panicked (the message says where).
    Panic = 8,
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_error(message: &str) {
    let c = CString::new(message.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = c);
}

/// The message of the last failed call on this thread ("" if none).
#[no_mangle]
pub extern "C" fn fbksd_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}

/// Runs `f`, turning errors and panics into a status and a message.
fn guard(f: impl FnOnce() -> Result<(), (FbksdStatus, String)>) -> FbksdStatus {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => FbksdStatus::Ok,
        Ok(Err((status, message))) => {
            set_error(&message);
            status
        }
        Err(panic) => {
            let what = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".into());
            set_error(&format!("internal error (panic): {what}"));
            FbksdStatus::Panic
        }
    }
}

fn client_error(e: fbksd_client::ClientError) -> (FbksdStatus, String) {
    use fbksd_client::ClientError as E;
    let status = match &e {
        E::NoRendezvous | E::Debug(_) | E::Connection(_) | E::Closed => FbksdStatus::Connection,
        E::Layout(_) => FbksdStatus::Layout,
        E::Refused { .. } => FbksdStatus::Refused,
        E::SceneInfo(_) => FbksdStatus::SceneInfo,
        E::Usage(_) => FbksdStatus::Usage,
        _ => FbksdStatus::Failed,
    };
    (status, e.to_string())
}

fn invalid(what: &str) -> (FbksdStatus, String) {
    (FbksdStatus::InvalidArgument, what.to_string())
}

/// A C string argument as `&str`.
fn text<'a>(p: *const c_char, what: &str) -> Result<&'a str, (FbksdStatus, String)> {
    if p.is_null() {
        return Err(invalid(&format!("{what} is null")));
    }
    // SAFETY: the caller passes a NUL-terminated string that outlives the call.
    unsafe { CStr::from_ptr(p) }.to_str().map_err(|_| invalid(&format!("{what} is not UTF-8")))
}

/// A connection to the benchmark manager (opaque).
pub struct FbksdClient {
    /// `None` once the result is sent.
    client: Option<BenchmarkClient>,
}

impl FbksdClient {
    fn get(&mut self) -> Result<&mut BenchmarkClient, (FbksdStatus, String)> {
        self.client.as_mut().ok_or((FbksdStatus::Usage, "the result was already sent".into()))
    }
}

/// Turns a handle pointer into a reference, refusing null.
fn handle<'a, T>(p: *mut T, what: &str) -> Result<&'a mut T, (FbksdStatus, String)> {
    // SAFETY: a non-null handle comes from this library and is used by one thread at a time.
    unsafe { p.as_mut() }.ok_or_else(|| invalid(&format!("{what} is null")))
}

/// Connects to the manager that started this process; with the debug
/// arguments in `argv` (`--fbksd-renderer`, `--fbksd-spp`, …) it starts
/// its own manager instead. On success `*out` owns the connection.
#[no_mangle]
pub extern "C" fn fbksd_client_new(argc: c_int, argv: *const *const c_char, out: *mut *mut FbksdClient) -> FbksdStatus {
    guard(|| {
        let out = handle(out, "out")?;
        let mut args = Vec::new();
        if argc > 0 {
            if argv.is_null() {
                return Err(invalid("argv is null"));
            }
            for i in 0..argc as usize {
                // SAFETY: argv holds argc valid pointers.
                let p = unsafe { *argv.add(i) };
                args.push(text(p, "an argv entry")?.to_string());
            }
        }
        let client = BenchmarkClient::from_args(args).map_err(client_error)?;
        *out = Box::into_raw(Box::new(FbksdClient { client: Some(client) }));
        Ok(())
    })
}

/// Closes the connection and frees the handle (null is ignored).
#[no_mangle]
pub extern "C" fn fbksd_client_free(client: *mut FbksdClient) {
    if !client.is_null() {
        // SAFETY: the handle came from fbksd_client_new and is freed once.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(client) })));
    }
}

/// Looks up scene-info key `key` as `T`.
fn scene_value<T: fbksd_core::scene_info::FromSceneValue>(
    client: *mut FbksdClient,
    key: *const c_char,
) -> Result<T, (FbksdStatus, String)> {
    let c = handle(client, "client")?.get()?;
    let key = text(key, "key")?;
    c.scene_info().get::<T>(key).map_err(|e| (FbksdStatus::SceneInfo, format!("scene info: {e}")))
}

/// Scene-info integer (e.g. "width", "height", "max_spp").
#[no_mangle]
pub extern "C" fn fbksd_scene_info_int(client: *mut FbksdClient, key: *const c_char, out: *mut i64) -> FbksdStatus {
    guard(|| {
        let v = scene_value::<i64>(client, key)?;
        *handle(out, "out")? = v;
        Ok(())
    })
}

/// Scene-info number.
#[no_mangle]
pub extern "C" fn fbksd_scene_info_float(client: *mut FbksdClient, key: *const c_char, out: *mut f64) -> FbksdStatus {
    guard(|| {
        let v = scene_value::<f64>(client, key)?;
        *handle(out, "out")? = v;
        Ok(())
    })
}

/// Scene-info boolean.
#[no_mangle]
pub extern "C" fn fbksd_scene_info_bool(client: *mut FbksdClient, key: *const c_char, out: *mut bool) -> FbksdStatus {
    guard(|| {
        let v = scene_value::<bool>(client, key)?;
        *handle(out, "out")? = v;
        Ok(())
    })
}

/// Scene-info string, copied NUL-terminated into `buf` (`len` bytes).
/// `*needed` (if not null) receives the size the string needs, NUL
/// included; a too-small buffer is [`FbksdStatus::InvalidArgument`].
#[no_mangle]
pub extern "C" fn fbksd_scene_info_string(
    client: *mut FbksdClient,
    key: *const c_char,
    buf: *mut c_char,
    len: usize,
    needed: *mut usize,
) -> FbksdStatus {
    guard(|| {
        let v = scene_value::<String>(client, key)?;
        let bytes = v.as_bytes();
        if !needed.is_null() {
            // SAFETY: checked non-null; the caller's out parameter.
            unsafe { *needed = bytes.len() + 1 };
        }
        if buf.is_null() || len < bytes.len() + 1 {
            return Err(invalid(&format!("buffer of {len} bytes is too small for {} bytes", bytes.len() + 1)));
        }
        // SAFETY: buf holds len ≥ bytes.len() + 1 bytes.
        unsafe {
            std::ptr::copy_nonoverlapping(bytes.as_ptr(), buf as *mut u8, bytes.len());
            *buf.add(bytes.len()) = 0;
        }
        Ok(())
    })
}

/// Whether scene info has `key` (false for a null client or key).
#[no_mangle]
pub extern "C" fn fbksd_scene_info_has(client: *mut FbksdClient, key: *const c_char) -> bool {
    let mut has = false;
    guard(|| {
        let c = handle(client, "client")?.get()?;
        has = c.scene_info().value(text(key, "key")?).is_some();
        Ok(())
    });
    has
}

/// A sample layout under construction (opaque).
pub struct FbksdLayout {
    layout: SampleLayout,
}

/// A new, empty layout (roughness threshold 0.1). Free it with [`fbksd_layout_free`].
#[no_mangle]
pub extern "C" fn fbksd_layout_new() -> *mut FbksdLayout {
    Box::into_raw(Box::new(FbksdLayout { layout: SampleLayout::new() }))
}

/// Frees a layout (null is ignored).
#[no_mangle]
pub extern "C" fn fbksd_layout_free(layout: *mut FbksdLayout) {
    if !layout.is_null() {
        // SAFETY: the handle came from fbksd_layout_new and is freed once.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(layout) })));
    }
}

/// Appends element `name` (e.g. "COLOR_R", "IMAGE_X"); `input` marks a
/// random parameter the technique gives; `number` picks the intersection
/// of a numbered feature (0 or 1). Checked when the layout is set.
#[no_mangle]
pub extern "C" fn fbksd_layout_add(
    layout: *mut FbksdLayout,
    name: *const c_char,
    input: bool,
    number: u32,
) -> FbksdStatus {
    guard(|| {
        let l = handle(layout, "layout")?;
        let name = text(name, "name")?;
        if number > 0 && input {
            return Err(invalid("only random parameters can be INPUT, and they are not numbered"));
        }
        let io = if input { ElementIo::Input } else { ElementIo::Output };
        let current = std::mem::take(&mut l.layout);
        l.layout = if number > 0 { current.with_number(name, number) } else { current.with_io(name, io) };
        Ok(())
    })
}

/// Sets the Beckmann roughness threshold of the DIFFUSE_COLOR features.
#[no_mangle]
pub extern "C" fn fbksd_layout_set_roughness_threshold(layout: *mut FbksdLayout, threshold: f32) -> FbksdStatus {
    guard(|| {
        let l = handle(layout, "layout")?;
        let current = std::mem::take(&mut l.layout);
        l.layout = current.with_roughness_threshold(threshold);
        Ok(())
    })
}

/// Sends the layout to the manager (validated first: the message names the bad element).
#[no_mangle]
pub extern "C" fn fbksd_client_set_layout(client: *mut FbksdClient, layout: *const FbksdLayout) -> FbksdStatus {
    guard(|| {
        let c = handle(client, "client")?.get()?;
        // SAFETY: a non-null layout handle comes from fbksd_layout_new.
        let l = unsafe { layout.as_ref() }.ok_or_else(|| invalid("layout is null"))?;
        c.set_sample_layout(&l.layout).map_err(client_error)
    })
}

/// Floats per sample of the current layout (0 before one is set).
#[no_mangle]
pub extern "C" fn fbksd_client_sample_size(client: *mut FbksdClient) -> usize {
    let mut size = 0;
    guard(|| {
        size = handle(client, "client")?.get()?.sample_size();
        Ok(())
    });
    size
}

/// The result image the technique fills: `width × height × 3` floats,
/// row-major RGB; `*len` receives the number of floats. Null on failure.
#[no_mangle]
pub extern "C" fn fbksd_client_result_buffer(client: *mut FbksdClient, len: *mut usize) -> *mut f32 {
    let mut ptr = std::ptr::null_mut();
    guard(|| {
        let buffer = handle(client, "client")?.get()?.result_buffer();
        if !len.is_null() {
            // SAFETY: checked non-null; the caller's out parameter.
            unsafe { *len = buffer.len() };
        }
        ptr = buffer.as_mut_ptr();
        Ok(())
    });
    ptr
}

/// One tile of samples, as callbacks see it. Pixel tiles cover
/// `[begin_x, end_x) × [begin_y, end_y)` with `spp` samples per pixel,
/// stored pixel by pixel (row-major), each pixel's samples together, each
/// sample `sample_size` floats: sample `s` of pixel `(x, y)` starts at
/// `((((y − begin_y) · (end_x − begin_x)) + (x − begin_x)) · spp + s) · sample_size`.
/// Count-request tiles have no pixels (`spp` 0, empty rectangle).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct FbksdTile {
    /// First column.
    pub begin_x: u32,
    /// One past the last column.
    pub end_x: u32,
    /// First row.
    pub begin_y: u32,
    /// One past the last row.
    pub end_y: u32,
    /// Samples per pixel (0 for count tiles).
    pub spp: u32,
    /// Floats per sample.
    pub sample_size: usize,
    /// Number of samples.
    pub count: u64,
    /// The samples (writable only in producer callbacks).
    pub data: *mut f32,
}

/// A callback receiving a tile; `user` is passed through.
pub type FbksdTileCallback = Option<extern "C" fn(user: *mut c_void, tile: *const FbksdTile)>;

/// The C view of a client tile (read-only or writable: both have the same accessors).
macro_rules! c_tile {
    ($tile:expr, $data:expr) => {
        FbksdTile {
            begin_x: $tile.begin_x(),
            end_x: $tile.end_x(),
            begin_y: $tile.begin_y(),
            end_y: $tile.end_y(),
            spp: $tile.spp(),
            sample_size: $tile.sample_size(),
            count: $tile.len(),
            data: $data,
        }
    };
}

fn tile_of(tile: &BufferTile<'_>) -> FbksdTile {
    c_tile!(tile, tile.data().as_ptr() as *mut f32)
}

fn tile_of_mut(tile: &mut BufferTileMut<'_>) -> FbksdTile {
    let data = tile.data_mut().as_mut_ptr();
    c_tile!(tile, data)
}

/// A tile of pixel-free samples (count requests): `len` floats at `data`.
fn raw_tile(data: *mut f32, len: usize, sample_size: usize) -> FbksdTile {
    let count = len.checked_div(sample_size).unwrap_or(0) as u64;
    FbksdTile { begin_x: 0, end_x: 0, begin_y: 0, end_y: 0, spp: 0, sample_size, count, data }
}

fn callback(
    f: FbksdTileCallback,
    what: &str,
) -> Result<extern "C" fn(*mut c_void, *const FbksdTile), (FbksdStatus, String)> {
    f.ok_or_else(|| invalid(&format!("{what} is null")))
}

/// Requests `spp` samples for every pixel; `consumer` receives each tile.
#[no_mangle]
pub extern "C" fn fbksd_client_evaluate_samples(
    client: *mut FbksdClient,
    spp: u64,
    consumer: FbksdTileCallback,
    user: *mut c_void,
) -> FbksdStatus {
    guard(|| {
        let c = handle(client, "client")?.get()?;
        let consume = callback(consumer, "consumer")?;
        c.evaluate_samples(Spp(spp), |tile| consume(user, &tile_of(tile))).map_err(client_error)
    })
}

/// Requests `count` samples anywhere on the image (the renderer places
/// them; IMAGE_X/IMAGE_Y say where); `consumer` receives them in chunks.
#[no_mangle]
pub extern "C" fn fbksd_client_evaluate_sample_count(
    client: *mut FbksdClient,
    count: u64,
    consumer: FbksdTileCallback,
    user: *mut c_void,
) -> FbksdStatus {
    guard(|| {
        let c = handle(client, "client")?.get()?;
        let size = c.sample_size();
        let consume = callback(consumer, "consumer")?;
        c.evaluate_sample_count(count, |data| consume(user, &raw_tile(data.as_ptr() as *mut f32, data.len(), size)))
            .map_err(client_error)
    })
}

/// Like [`fbksd_client_evaluate_samples`], but `producer` first writes the
/// INPUT parameters of each tile (adaptive sampling).
#[no_mangle]
pub extern "C" fn fbksd_client_evaluate_input_samples(
    client: *mut FbksdClient,
    spp: u64,
    producer: FbksdTileCallback,
    consumer: FbksdTileCallback,
    user: *mut c_void,
) -> FbksdStatus {
    guard(|| {
        let c = handle(client, "client")?.get()?;
        let (produce, consume) = (callback(producer, "producer")?, callback(consumer, "consumer")?);
        c.evaluate_input_samples(
            Spp(spp),
            |tile| produce(user, &tile_of_mut(tile)),
            |tile| consume(user, &tile_of(tile)),
        )
        .map_err(client_error)
    })
}

/// Like [`fbksd_client_evaluate_sample_count`], but `producer` first
/// writes the INPUT parameters of each chunk.
#[no_mangle]
pub extern "C" fn fbksd_client_evaluate_input_sample_count(
    client: *mut FbksdClient,
    count: u64,
    producer: FbksdTileCallback,
    consumer: FbksdTileCallback,
    user: *mut c_void,
) -> FbksdStatus {
    guard(|| {
        let c = handle(client, "client")?.get()?;
        let size = c.sample_size();
        let (produce, consume) = (callback(producer, "producer")?, callback(consumer, "consumer")?);
        c.evaluate_input_sample_count(
            count,
            |data| produce(user, &raw_tile(data.as_mut_ptr(), data.len(), size)),
            |data| consume(user, &raw_tile(data.as_ptr() as *mut f32, data.len(), size)),
        )
        .map_err(client_error)
    })
}

/// Sends the result buffer to the manager. The client can do nothing
/// more afterwards but be freed.
#[no_mangle]
pub extern "C" fn fbksd_client_send_result(client: *mut FbksdClient) -> FbksdStatus {
    guard(|| {
        let c = handle(client, "client")?;
        let client = c.client.take().ok_or((FbksdStatus::Usage, "the result was already sent".to_string()))?;
        client.send_result().map_err(client_error)
    })
}
