//! The technique side of FBKSD: the API a sampler or denoiser is written against.
//!
//! A technique creates a [`BenchmarkClient`], reads the [`SceneInfo`] (image
//! size, budget `max_spp`), sets a [`SampleLayout`], requests samples —
//! per pixel with [`Spp`] or as a count, optionally writing INPUT random
//! parameters first (adaptive sampling) — reconstructs the image into the
//! result buffer and sends it. Same concepts and names as the original
//! `fbksd::BenchmarkClient` (thesis appendix A), in Rust.
//!
//! ```no_run
//! use fbksd_client::{BenchmarkClient, SampleLayout, Spp};
//! let mut client = BenchmarkClient::from_args(std::env::args())?;
//! let info = client.scene_info().clone();
//! let (w, spp) = (info.get::<i64>("width")? as usize, info.get::<i64>("max_spp")? as u64);
//! client.set_sample_layout(&SampleLayout::new().with("COLOR_R").with("COLOR_G").with("COLOR_B"))?;
//! let mut sums = vec![0f32; client.result_buffer().len()];
//! client.evaluate_samples(Spp(spp), |tile| {
//!     for y in tile.begin_y()..tile.end_y() {
//!         for x in tile.begin_x()..tile.end_x() {
//!             for s in 0..tile.spp() {
//!                 let sample = tile.sample(x, y, s);
//!                 let p = (y as usize * w + x as usize) * 3;
//!                 for c in 0..3 { sums[p + c] += sample[c] / spp as f32; }
//!             }
//!         }
//!     }
//! })?;
//! client.result_buffer().copy_from_slice(&sums);
//! client.send_result()?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! **Debug mode.** Started with `--fbksd-renderer "<renderer> <args> <scene>"`
//! and `--fbksd-spp N` (optionally `--fbksd-output image.exr`), the client
//! runs a manager in-process, so a technique can be started directly, e.g.
//! under a debugger. `--fbksd-version` prints the SDK and protocol versions.
//! Debug mode is the `debug-mode` feature (on by default): the only reason
//! the client links the manager.
#![deny(missing_docs)]

mod debug;
mod tile;

pub use fbksd_core::layout::{ElementIo, SampleLayout};
pub use fbksd_core::protocol::ErrorKind;
pub use fbksd_core::{Feature, RandomParameter, SceneInfo};
pub use tile::{BufferTile, BufferTileMut};

use fbksd_core::layout::{CompiledLayout, LayoutError};
use fbksd_core::protocol::{read_frame, write_frame, Amount, FrameError, FromTechnique, Hello, Role, ToTechnique};
use fbksd_core::scene_info::{keys, SceneInfoError};
use fbksd_core::shm::{plain_file_name, Ring, SharedRegion, ShmError};
use fbksd_core::{rendezvous, Tile};
use std::io::BufReader;
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::sync::Arc;

/// A number of samples per pixel (the C++ API's `SPP`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Spp(pub u64);

/// Everything that can go wrong on the technique side.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// Not started by a manager and not in debug mode.
    #[error(
        "{} is not set: run this technique with `fbksd run`, or directly in debug mode with \
         --fbksd-renderer \"<renderer> <scene>\" --fbksd-spp <n>",
        rendezvous::ENV_VAR
    )]
    NoRendezvous,
    /// Bad debug-mode arguments.
    #[error("debug mode: {0}")]
    Debug(String),
    /// The connection to the manager failed.
    #[error("connection to the manager: {0}")]
    Connection(#[from] std::io::Error),
    /// A frame from the manager could not be read.
    #[error("connection to the manager: {0}")]
    Frame(#[from] FrameError),
    /// The manager refused a request; the run is over.
    #[error("the manager refused ({kind:?}): {message}")]
    Refused {
        /// The kind of refusal.
        kind: ErrorKind,
        /// Why.
        message: String,
    },
    /// The layout is invalid (checked before it is sent).
    #[error("invalid sample layout: {0}")]
    Layout(#[from] LayoutError),
    /// A call out of order (e.g. samples before a layout).
    #[error("{0}")]
    Usage(String),
    /// The manager broke the protocol.
    #[error("protocol error: {0}")]
    Protocol(String),
    /// The manager closed the connection.
    #[error("the manager closed the connection")]
    Closed,
    /// Scene info is missing a standard key.
    #[error("scene info: {0}")]
    SceneInfo(#[from] SceneInfoError),
    /// Shared memory could not be mapped.
    #[error("{0}")]
    Shm(#[from] ShmError),
}

/// Shared memory kept mapped (see [`BenchmarkClient::mappings`]).
#[derive(Clone)]
pub struct Mappings {
    _result: Arc<SharedRegion>,
    _ring: Option<Arc<Ring>>,
}

/// Connection to the benchmark manager. Create one per process.
pub struct BenchmarkClient {
    reader: BufReader<UnixStream>,
    writer: UnixStream,
    dir: std::path::PathBuf,
    scene_info: SceneInfo,
    width: u32,
    height: u32,
    result: Arc<SharedRegion>,
    layout: Option<(CompiledLayout, Arc<Ring>)>,
    remaining: u64,
    debug: Option<debug::DebugManager>,
}

impl BenchmarkClient {
    /// Connects like the C++ `BenchmarkClient(argc, argv)`: debug mode when
    /// the arguments hold `--fbksd-renderer`, else the manager named by the
    /// environment. `--fbksd-version` prints versions and exits.
    pub fn from_args(args: impl IntoIterator<Item = String>) -> Result<Self, ClientError> {
        match debug::DebugArgs::parse(args)? {
            Some(debug::DebugArgs::Version) => {
                println!("fbksd {} (protocol {})", env!("CARGO_PKG_VERSION"), fbksd_core::protocol::PROTOCOL_VERSION);
                std::process::exit(0);
            }
            Some(debug::DebugArgs::Run(args)) => {
                let manager = debug::DebugManager::start(args)?;
                let mut client = Self::connect_to(manager.dir())?;
                client.debug = Some(manager);
                Ok(client)
            }
            None => Self::connect(),
        }
    }

    /// Connects to the manager named by `FBKSD_RENDEZVOUS`.
    pub fn connect() -> Result<Self, ClientError> {
        let dir = rendezvous::from_env().ok_or(ClientError::NoRendezvous)?;
        Self::connect_to(&dir)
    }

    /// Connects to the manager whose rendezvous directory is `dir`.
    pub fn connect_to(dir: &Path) -> Result<Self, ClientError> {
        let mut writer = UnixStream::connect(rendezvous::control_socket(dir))?;
        let mut reader = BufReader::new(writer.try_clone()?);
        write_frame(&mut writer, &Hello::new(Role::Technique))?;
        let (scene_info, result_file) = match read_frame::<_, ToTechnique>(&mut reader)? {
            Some(ToTechnique::Welcome { scene_info, result_file, .. }) => (scene_info, result_file),
            Some(ToTechnique::Error { kind, message }) => return Err(ClientError::Refused { kind, message }),
            Some(other) => return Err(ClientError::Protocol(format!("expected welcome, got {other:?}"))),
            None => return Err(ClientError::Closed),
        };
        let (width, height) = (scene_info.width()?, scene_info.height()?);
        let remaining = scene_info.get::<i64>(keys::MAX_SAMPLES)?.max(0) as u64;
        let result_path = dir.join(plain_file_name(&result_file)?);
        let result = SharedRegion::open(&result_path, width as u64 * height as u64 * 12)?;
        Ok(BenchmarkClient {
            reader,
            writer,
            dir: dir.to_path_buf(),
            scene_info,
            width,
            height,
            result: Arc::new(result),
            layout: None,
            remaining,
            debug: None,
        })
    }

    /// Information about the scene: `width`, `height`, `max_spp`,
    /// `max_samples`, `has_motion_blur`, `has_dof`, … (see `sdk/PROTOCOL.md`).
    pub fn scene_info(&self) -> &SceneInfo {
        &self.scene_info
    }

    /// Samples left in the budget.
    pub fn remaining_samples(&self) -> u64 {
        self.remaining
    }

    /// Floats per sample of the current layout (0 before a layout is set).
    pub fn sample_size(&self) -> usize {
        self.layout.as_ref().map_or(0, |(l, _)| l.sample_size())
    }

    /// Sets the sample layout; once per run.
    pub fn set_sample_layout(&mut self, layout: &SampleLayout) -> Result<(), ClientError> {
        if self.layout.is_some() {
            return Err(ClientError::Usage("set_sample_layout may be called only once".into()));
        }
        let compiled = layout.compile()?;
        self.send(&FromTechnique::SetLayout { layout: layout.clone() })?;
        match self.receive()? {
            ToTechnique::LayoutSet { ring, sample_size } if sample_size as usize == compiled.sample_size() => {
                let ring = Arc::new(Ring::open(&self.dir, ring)?);
                self.layout = Some((compiled, ring));
                Ok(())
            }
            other => Err(ClientError::Protocol(format!("expected layout_set, got {other:?}"))),
        }
    }

    /// The result image: `width × height × 3` floats, scanline RGB. Write
    /// the final image here before [`Self::send_result`].
    pub fn result_buffer(&mut self) -> &mut [f32] {
        let n = self.width as usize * self.height as usize * 3;
        // SAFETY: the technique owns the result buffer until it sends the result.
        unsafe { self.result.floats_mut(0, n) }
    }

    /// Keeps the shared memory behind the result buffer and the tiles mapped
    /// for as long as the handle lives, even after the client is gone.
    /// Language bindings whose arrays view that memory (Python) hold one per
    /// array, so a view kept too long reads stale data instead of crashing.
    pub fn mappings(&self) -> Mappings {
        Mappings { _result: self.result.clone(), _ring: self.layout.as_ref().map(|(_, r)| r.clone()) }
    }

    /// Requests `spp` samples per pixel; `consumer` sees each tile.
    pub fn evaluate_samples(&mut self, spp: Spp, mut consumer: impl FnMut(&BufferTile<'_>)) -> Result<(), ClientError> {
        let size = self.sample_size();
        self.evaluate(Amount::Spp(spp.0), false, &mut |_, _| {}, &mut |tile, data| {
            consumer(&BufferTile::new(tile, data, size))
        })
    }

    /// Requests `count` samples anywhere in the image; `consumer` gets
    /// chunks of `len / sample_size()` samples each.
    pub fn evaluate_sample_count(&mut self, count: u64, mut consumer: impl FnMut(&[f32])) -> Result<(), ClientError> {
        self.evaluate(Amount::Samples(count), false, &mut |_, _| {}, &mut |_, data| consumer(data))
    }

    /// Requests `spp` samples per pixel whose INPUT parameters `producer`
    /// writes; `consumer` then sees each rendered tile.
    pub fn evaluate_input_samples(
        &mut self,
        spp: Spp,
        mut producer: impl FnMut(&mut BufferTileMut<'_>),
        mut consumer: impl FnMut(&BufferTile<'_>),
    ) -> Result<(), ClientError> {
        let size = self.sample_size();
        self.evaluate(
            Amount::Spp(spp.0),
            true,
            &mut |tile, data| producer(&mut BufferTileMut::new(tile, data, size)),
            &mut |tile, data| consumer(&BufferTile::new(tile, data, size)),
        )
    }

    /// Requests `count` samples whose INPUT parameters (IMAGE_X/IMAGE_Y
    /// included) `producer` writes, chunk by chunk; `consumer` reads them back.
    pub fn evaluate_input_sample_count(
        &mut self,
        count: u64,
        mut producer: impl FnMut(&mut [f32]),
        mut consumer: impl FnMut(&[f32]),
    ) -> Result<(), ClientError> {
        self.evaluate(Amount::Samples(count), true, &mut |_, data| producer(data), &mut |_, data| consumer(data))
    }

    fn evaluate(
        &mut self,
        amount: Amount,
        input: bool,
        producer: &mut dyn FnMut(Tile, &mut [f32]),
        consumer: &mut dyn FnMut(Tile, &[f32]),
    ) -> Result<(), ClientError> {
        let size = self.sample_size();
        if size == 0 {
            return Err(ClientError::Usage("set_sample_layout must come before requesting samples".into()));
        }
        self.send(&FromTechnique::Evaluate { amount, input })?;
        loop {
            match self.receive()? {
                ToTechnique::Produce { slot, tile } => {
                    let data = self.slot_mut(slot, tile, size)?;
                    producer(tile, data);
                    self.send(&FromTechnique::Produced { slot })?;
                }
                ToTechnique::Consume { slot, tile } => {
                    let data = self.slot_mut(slot, tile, size)?;
                    consumer(tile, data);
                    self.send(&FromTechnique::Consumed { slot })?;
                }
                ToTechnique::EvaluateDone { remaining, .. } => {
                    self.remaining = remaining;
                    return Ok(());
                }
                other => return Err(ClientError::Protocol(format!("unexpected {other:?} during a request"))),
            }
        }
    }

    #[allow(clippy::mut_from_ref)]
    fn slot_mut(&self, slot: u32, tile: Tile, size: usize) -> Result<&mut [f32], ClientError> {
        let (_, ring) = self.layout.as_ref().expect("checked by evaluate");
        let spec = ring.spec();
        let floats = tile.sample_count() as usize * size;
        if slot >= spec.slot_count || floats as u64 * 4 > spec.slot_bytes {
            return Err(ClientError::Protocol(format!("tile {tile:?} in slot {slot} does not fit the ring")));
        }
        // SAFETY: the manager handed this slot to the technique until it answers.
        Ok(unsafe { ring.slot_mut(slot, floats) })
    }

    /// Sends the result buffer as the final image and ends the run.
    pub fn send_result(mut self) -> Result<(), ClientError> {
        let (width, height) = (self.width, self.height);
        self.send(&FromTechnique::SendResult { width, height, channels: 3 })?;
        let answer = self.receive();
        if let Some(debug) = self.debug.take() {
            drop(self.writer.shutdown(std::net::Shutdown::Both));
            debug.finish();
        }
        match answer? {
            ToTechnique::ResultAccepted => Ok(()),
            other => Err(ClientError::Protocol(format!("expected result_accepted, got {other:?}"))),
        }
    }

    fn send(&mut self, message: &FromTechnique) -> Result<(), ClientError> {
        write_frame(&mut self.writer, message).map_err(ClientError::Connection)
    }

    /// The next message; a refusal becomes [`ClientError::Refused`].
    fn receive(&mut self) -> Result<ToTechnique, ClientError> {
        match read_frame::<_, ToTechnique>(&mut self.reader)? {
            Some(ToTechnique::Error { kind, message }) => Err(ClientError::Refused { kind, message }),
            Some(m) => Ok(m),
            None => Err(ClientError::Closed),
        }
    }
}
