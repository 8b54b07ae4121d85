//! The rendering server: connection to the manager, pipes and sample buffers.

use crate::plan::plan_tiles;
use fbksd_core::layout::{CompiledLayout, Element, ElementIo};
use fbksd_core::protocol::{read_frame, write_frame, FrameError, FromRenderer, Hello, Role, ToRenderer};
use fbksd_core::shm::{Ring, ShmError};
use fbksd_core::{rendezvous, Feature, RandomParameter, SceneInfo, SceneInfoError, Tile};
use std::collections::HashMap;
use std::io::BufReader;
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::thread::JoinHandle;

/// What can stop a renderer.
#[derive(Debug, thiserror::Error)]
pub enum RendererError {
    /// The process was not started by a manager.
    #[error("{} is not set: renderers are started by `fbksd run` (or a technique in debug mode)", rendezvous::ENV_VAR)]
    NoRendezvous,
    /// The control connection failed.
    #[error("control connection: {0}")]
    Connection(#[from] std::io::Error),
    /// A frame could not be read.
    #[error("control connection: {0}")]
    Frame(#[from] FrameError),
    /// The manager refused or sent something out of order.
    #[error("protocol error: {0}")]
    Protocol(String),
    /// The manager went away (the run ended).
    #[error("the manager closed the connection")]
    ManagerClosed,
    /// The scene info lacks a required key.
    #[error("scene info: {0}")]
    SceneInfo(#[from] SceneInfoError),
    /// The ring could not be mapped.
    #[error("{0}")]
    Shm(#[from] ShmError),
    /// A pipe asked for more samples than a slot holds.
    #[error("pipe of {samples} samples exceeds the pipe size {pipe_size}")]
    PipeTooLarge {
        /// Samples asked for.
        samples: u64,
        /// The request's pipe size.
        pipe_size: u64,
    },
}

type BoxError = Box<dyn std::error::Error + Send + Sync>;
type EvaluateFn = dyn Fn(&Evaluation) -> Result<(), BoxError> + Send + Sync;
type SetParametersFn = dyn FnMut(&CompiledLayout) -> Result<(), BoxError>;

/// A renderer's connection to the manager, built from callbacks.
pub struct RenderingServer {
    tile_size: Box<dyn FnMut() -> u32>,
    scene_info: Box<dyn FnMut() -> SceneInfo>,
    set_parameters: Box<SetParametersFn>,
    evaluate: Arc<EvaluateFn>,
    finish: Box<dyn FnMut()>,
}

impl Default for RenderingServer {
    fn default() -> Self {
        Self::new()
    }
}

impl RenderingServer {
    /// A server with default callbacks: 16-pixel tiles, empty scene info,
    /// any layout accepted, no samples produced.
    pub fn new() -> Self {
        RenderingServer {
            tile_size: Box::new(|| 16),
            scene_info: Box::new(SceneInfo::new),
            set_parameters: Box::new(|_| Ok(())),
            evaluate: Arc::new(|_| Err("this renderer has no evaluate_samples callback".into())),
            finish: Box::new(|| {}),
        }
    }

    /// Preferred tile side in pixels; called once at start.
    pub fn on_get_tile_size(mut self, f: impl FnMut() -> u32 + 'static) -> Self {
        self.tile_size = Box::new(f);
        self
    }

    /// The scene's info; called once at start. Must hold `width` and `height`.
    pub fn on_get_scene_info(mut self, f: impl FnMut() -> SceneInfo + 'static) -> Self {
        self.scene_info = Box::new(f);
        self
    }

    /// Called with the (validated) layout when a technique session starts.
    /// An error rejects the layout; the technique sees its message.
    pub fn on_set_parameters(mut self, f: impl FnMut(&CompiledLayout) -> Result<(), BoxError> + 'static) -> Self {
        self.set_parameters = Box::new(f);
        self
    }

    /// Called on a dedicated thread for each request. Returning an error
    /// ends the session with `renderer_failed` and the error's message.
    pub fn on_evaluate_samples(
        mut self,
        f: impl Fn(&Evaluation) -> Result<(), BoxError> + Send + Sync + 'static,
    ) -> Self {
        self.evaluate = Arc::new(f);
        self
    }

    /// Called when the manager has no more sessions, before `run` returns.
    pub fn on_finish(mut self, f: impl FnMut() + 'static) -> Self {
        self.finish = Box::new(f);
        self
    }

    /// Serves the manager named by `FBKSD_RENDEZVOUS` until it says finish.
    pub fn run(self) -> Result<(), RendererError> {
        let dir = rendezvous::from_env().ok_or(RendererError::NoRendezvous)?;
        self.run_at(&dir)
    }

    /// Serves the manager whose rendezvous directory is `dir`.
    pub fn run_at(mut self, dir: &Path) -> Result<(), RendererError> {
        let stream = UnixStream::connect(rendezvous::control_socket(dir))?;
        let mut reader = BufReader::new(stream.try_clone()?);
        let link = Arc::new(Link { writer: Mutex::new(stream), pending: Mutex::default(), next_id: AtomicU64::new(0) });
        link.send(&Hello::new(Role::Renderer))?;
        match read_frame::<_, ToRenderer>(&mut reader)? {
            Some(ToRenderer::Welcome { .. }) => {}
            None => return Err(RendererError::ManagerClosed),
            Some(other) => return Err(RendererError::Protocol(format!("expected welcome, got {other:?}"))),
        }
        let scene_info = (self.scene_info)();
        let (width, height) = (scene_info.width()?, scene_info.height()?);
        let tile_size = (self.tile_size)().max(1);
        link.send(&FromRenderer::Ready { tile_size, scene_info })?;

        let result = self.serve(dir, &mut reader, &link, width, height, tile_size);
        // Wake any pipe still waiting for a slot: the session is over.
        link.pending.lock().unwrap().clear();
        result
    }

    fn serve(
        &mut self,
        dir: &Path,
        reader: &mut BufReader<UnixStream>,
        link: &Arc<Link>,
        width: u32,
        height: u32,
        tile_size: u32,
    ) -> Result<(), RendererError> {
        let mut session: Option<(Arc<CompiledLayout>, Arc<Ring>)> = None;
        let mut worker: Option<JoinHandle<()>> = None;
        loop {
            let Some(message) = read_frame::<_, ToRenderer>(reader)? else {
                return Err(RendererError::ManagerClosed);
            };
            match message {
                ToRenderer::SetLayout { layout, ring } => {
                    join(&mut worker);
                    let accepted = (|| -> Result<_, BoxError> {
                        let compiled = layout.compile()?;
                        let ring = Ring::open(dir, ring)?;
                        (self.set_parameters)(&compiled)?;
                        Ok((Arc::new(compiled), Arc::new(ring)))
                    })();
                    match accepted {
                        Ok(s) => {
                            session = Some(s);
                            link.send(&FromRenderer::LayoutAccepted)?;
                        }
                        Err(e) => link.send(&FromRenderer::Failed { message: format!("layout rejected: {e}") })?,
                    }
                }
                ToRenderer::Evaluate { spp, remaining, pipe_size, input, request, seed } => {
                    join(&mut worker);
                    let Some((layout, ring)) = session.clone() else {
                        return Err(RendererError::Protocol("evaluate before set_layout".into()));
                    };
                    let eval = Evaluation {
                        spp,
                        remaining,
                        pipe_size,
                        input,
                        request: sample_stream(seed, request),
                        width,
                        height,
                        tile_size,
                        params: ParamTable::new(&layout),
                        layout,
                        ring,
                        link: link.clone(),
                    };
                    let evaluate = self.evaluate.clone();
                    worker = Some(std::thread::spawn(move || {
                        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| evaluate(&eval)));
                        let message = match outcome {
                            Ok(Ok(())) => FromRenderer::EvaluateDone,
                            Ok(Err(e)) => FromRenderer::Failed { message: e.to_string() },
                            Err(panic) => FromRenderer::Failed { message: format!("panicked: {}", panic_text(&panic)) },
                        };
                        let _ = eval.link.send(&message);
                    }));
                }
                ToRenderer::Granted { id, slot } => {
                    if let Some(waiter) = link.pending.lock().unwrap().remove(&id) {
                        let _ = waiter.send(slot);
                    }
                }
                ToRenderer::EndSession => {
                    join(&mut worker);
                    session = None;
                }
                ToRenderer::Finish => {
                    join(&mut worker);
                    (self.finish)();
                    return Ok(());
                }
                ToRenderer::Welcome { .. } => return Err(RendererError::Protocol("second welcome".into())),
            }
        }
    }
}

fn join(worker: &mut Option<JoinHandle<()>>) {
    if let Some(w) = worker.take() {
        let _ = w.join();
    }
}

fn panic_text(panic: &Box<dyn std::any::Any + Send>) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into())
}

struct Link {
    writer: Mutex<UnixStream>,
    pending: Mutex<HashMap<u64, mpsc::SyncSender<u32>>>,
    next_id: AtomicU64,
}

impl Link {
    fn send<T: serde::Serialize>(&self, message: &T) -> std::io::Result<()> {
        write_frame(&mut *self.writer.lock().unwrap(), message)
    }
}

/// Where each random parameter sits and who writes it: the hot path of
/// [`SampleBuffer::set_param`] is one table read.
#[derive(Clone, Copy)]
struct ParamTable([(u16, bool); 7]);

const ABSENT: u16 = u16::MAX;

impl ParamTable {
    fn new(layout: &CompiledLayout) -> Self {
        let mut t = [(ABSENT, false); 7];
        for (i, (element, io)) in layout.elements().iter().enumerate() {
            if let Element::Parameter(p) = element {
                t[p.index()] = (i as u16, *io == ElementIo::Input);
            }
        }
        ParamTable(t)
    }
}

/// The stream a renderer seeds a request's samples from: distinct for
/// every (seed, request) below 2³² each, and the request index itself for
/// seed 0.
pub fn sample_stream(seed: u64, request: u64) -> u64 {
    request.wrapping_add(seed << 32)
}

/// One request, as seen by the evaluate callback.
pub struct Evaluation {
    /// Samples per pixel to produce (may be 0).
    pub spp: u64,
    /// Extra samples not tied to pixels (may be 0).
    pub remaining: u64,
    /// The most samples one pipe may hold.
    pub pipe_size: u64,
    /// Whether the technique writes INPUT random parameters.
    pub input: bool,
    /// The sample stream of this request, for seeding: the request's index
    /// within the technique session, offset by the run's seed
    /// ([`sample_stream`]), so every repeat of a run draws other samples
    /// while seed 0 keeps the streams of a single run.
    pub request: u64,
    width: u32,
    height: u32,
    tile_size: u32,
    params: ParamTable,
    layout: Arc<CompiledLayout>,
    ring: Arc<Ring>,
    link: Arc<Link>,
}

impl Evaluation {
    /// The session's layout.
    pub fn layout(&self) -> &CompiledLayout {
        &self.layout
    }
    /// Image width.
    pub fn width(&self) -> u32 {
        self.width
    }
    /// Image height.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// A tile plan covering the request (see [`plan_tiles`]), for the
    /// machine's number of threads.
    pub fn plan(&self) -> Vec<Tile> {
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        plan_tiles(self.width, self.height, self.spp, self.remaining, self.tile_size, self.pipe_size, threads)
    }

    /// The plan, each tile with the index of its first pixel-free sample
    /// within the request (count tiles are numbered in plan order), so
    /// tiles can be filled in any order and still draw reproducible samples.
    pub fn plan_with_free_starts(&self) -> Vec<(Tile, u64)> {
        let mut next = 0u64;
        self.plan()
            .into_iter()
            .map(|t| {
                let first = next;
                if let Tile::Samples { count } = t {
                    next += count;
                }
                (t, first)
            })
            .collect()
    }

    /// Acquires a slot for `tile`, blocking until one is free (and, for
    /// INPUT layouts, until the technique has written its parameters).
    pub fn pipe(&self, tile: Tile) -> Result<SamplesPipe<'_>, RendererError> {
        let samples = tile.sample_count();
        if samples > self.pipe_size {
            return Err(RendererError::PipeTooLarge { samples, pipe_size: self.pipe_size });
        }
        let id = self.link.next_id.fetch_add(1, Ordering::Relaxed);
        let (tx, rx) = mpsc::sync_channel(1);
        self.link.pending.lock().unwrap().insert(id, tx);
        self.link.send(&FromRenderer::Acquire { id, tile })?;
        let slot = rx.recv().map_err(|_| RendererError::ManagerClosed)?;
        let floats = samples as usize * self.layout.sample_size();
        // SAFETY: the manager granted this slot to this pipe alone until `filled`.
        let data = unsafe { self.ring.slot_mut(slot, floats) };
        Ok(SamplesPipe { eval: self, slot, tile, data })
    }
}

/// Keeps a session's shared memory mapped, for language bindings whose
/// arrays view a pipe's samples and may be kept after it is finished.
#[derive(Clone)]
pub struct MappingGuard(#[allow(dead_code)] Arc<Ring>);

impl Evaluation {
    /// A guard that keeps the shared memory mapped while it lives.
    pub fn mapping(&self) -> MappingGuard {
        MappingGuard(self.ring.clone())
    }
}

/// One slot of the ring, owned by the renderer while it writes a tile.
///
/// Call [`SamplesPipe::finish`] when every sample is written; a pipe dropped
/// without `finish` is abandoned and the request fails with a clear message.
pub struct SamplesPipe<'a> {
    eval: &'a Evaluation,
    slot: u32,
    tile: Tile,
    data: &'a mut [f32],
}

impl<'a> SamplesPipe<'a> {
    /// The tile this pipe holds.
    pub fn tile(&self) -> Tile {
        self.tile
    }
    /// Number of samples in the pipe.
    pub fn len(&self) -> u64 {
        self.tile.sample_count()
    }
    /// Whether the pipe holds no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The buffer of sample `index` (0-based, in tile order).
    #[inline]
    pub fn sample(&mut self, index: u64) -> SampleBuffer<'_> {
        let size = self.eval.layout.sample_size();
        let start = index as usize * size;
        SampleBuffer { data: &mut self.data[start..start + size], params: &self.eval.params, layout: &self.eval.layout }
    }

    /// The buffer of sample `s` of pixel `(x, y)` (pixel tiles only).
    #[inline]
    pub fn pixel_sample(&mut self, x: u32, y: u32, s: u32) -> SampleBuffer<'_> {
        let Tile::Pixels { rect, spp } = self.tile else { panic!("pixel_sample on a tile of free samples") };
        self.sample(Tile::sample_index(&rect, spp, x, y, s) as u64)
    }

    /// The raw floats of the tile (`len × sample_size`), for renderers that
    /// write whole samples at once.
    pub fn raw(&mut self) -> &mut [f32] {
        self.data
    }

    /// Hands the filled slot to the technique.
    pub fn finish(self) -> Result<(), RendererError> {
        let count = self.tile.sample_count();
        self.eval.link.send(&FromRenderer::Filled { slot: self.slot, count })?;
        Ok(())
    }
}

/// One sample in a pipe.
pub struct SampleBuffer<'a> {
    data: &'a mut [f32],
    params: &'a ParamTable,
    layout: &'a CompiledLayout,
}

impl SampleBuffer<'_> {
    /// Writes an OUTPUT random parameter and returns `value`; for an INPUT
    /// parameter writes nothing and returns the technique's value; for a
    /// parameter not in the layout returns `value`.
    #[inline]
    pub fn set_param(&mut self, p: RandomParameter, value: f32) -> f32 {
        match self.params.0[p.index()] {
            (ABSENT, _) => value,
            (i, true) => self.data[i as usize],
            (i, false) => {
                self.data[i as usize] = value;
                value
            }
        }
    }

    /// A random parameter's value in the buffer, if it is in the layout.
    #[inline]
    pub fn get_param(&self, p: RandomParameter) -> Option<f32> {
        match self.params.0[p.index()] {
            (ABSENT, _) => None,
            (i, _) => Some(self.data[i as usize]),
        }
    }

    /// Writes a feature (number 0) if the layout has it; returns `value`.
    #[inline]
    pub fn set(&mut self, f: Feature, value: f32) -> f32 {
        self.set_numbered(f, 0, value)
    }

    /// Writes a numbered feature if the layout has it; returns `value`.
    #[inline]
    pub fn set_numbered(&mut self, f: Feature, number: u8, value: f32) -> f32 {
        if let Some(i) = self.layout.feature_offset(f, number) {
            self.data[i] = value;
        }
        value
    }

    /// A feature's value in the buffer, if the layout has it.
    pub fn get(&self, f: Feature, number: u8) -> Option<f32> {
        self.layout.feature_offset(f, number).map(|i| self.data[i])
    }

    /// The sample's raw floats, in layout order.
    pub fn raw(&mut self) -> &mut [f32] {
        self.data
    }
}
