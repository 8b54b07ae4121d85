//! The technique side: a connection to the manager, sample requests with
//! tile callbacks, the result buffer.

use crate::layout::FbksdLayout;
use crate::scene_info::FbksdSceneInfo;
use crate::{client_error, free_handle, guard, handle, invalid, text, FbksdStatus};
use fbksd_client::{BenchmarkClient, BufferTile, BufferTileMut, Spp};
use std::ffi::{c_char, c_int, c_void};

/// A connection to the benchmark manager (opaque).
pub struct FbksdClient {
    /// `None` once the result is sent.
    client: Option<BenchmarkClient>,
    /// Kept here so it outlives the connection.
    scene_info: FbksdSceneInfo,
}

impl FbksdClient {
    fn get(&mut self) -> Result<&mut BenchmarkClient, (FbksdStatus, String)> {
        self.client.as_mut().ok_or((FbksdStatus::Usage, "the result was already sent".into()))
    }
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
        let scene_info = FbksdSceneInfo(client.scene_info().clone());
        *out = Box::into_raw(Box::new(FbksdClient { client: Some(client), scene_info }));
        Ok(())
    })
}

/// Closes the connection and frees the handle (null is ignored).
#[no_mangle]
pub extern "C" fn fbksd_client_free(client: *mut FbksdClient) {
    free_handle(client)
}

/// The scene's information (width, height, max_spp, …), owned by the
/// client and valid until it is freed; null for a null client.
#[no_mangle]
pub extern "C" fn fbksd_client_scene_info(client: *const FbksdClient) -> *const FbksdSceneInfo {
    // SAFETY: a non-null handle comes from fbksd_client_new.
    unsafe { client.as_ref() }.map_or(std::ptr::null(), |c| &c.scene_info)
}

/// Sends the layout to the manager (validated first: the message names the bad element).
#[no_mangle]
pub extern "C" fn fbksd_client_set_layout(client: *mut FbksdClient, layout: *const FbksdLayout) -> FbksdStatus {
    guard(|| {
        let c = handle(client, "client")?.get()?;
        // SAFETY: a non-null layout handle comes from fbksd_layout_new.
        let l = unsafe { layout.as_ref() }.ok_or_else(|| invalid("layout is null"))?;
        c.set_sample_layout(l.source()).map_err(client_error)
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
