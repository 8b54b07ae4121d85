//! One scene: a rendezvous directory, a renderer process, and the technique
//! sessions run against it one after another. The per-session state machine
//! is in [`session`]; this module owns processes, connections and the clock.
//!
//! [`SceneRunner::run`] is the manager's event loop for one run. Every
//! input — a message from either peer, a connection, a process exit, the
//! clock — arrives on one channel, so the state machine in [`Session`] is
//! single-threaded and every end of a run is decided in one place.

mod conn;
mod session;

use crate::process::{log_tail, report_to, ExitInfo, LaunchSpec, Launcher, LocalLauncher, ProcessRole, Running};
use conn::{accept_loop, refuse, spawn_reader, Event, Inbox, RendererConn};
use fbksd_core::protocol::{write_frame, FromRenderer, Hello, Role, ToRenderer, PROTOCOL_VERSION};
use fbksd_core::scene_info::keys;
use fbksd_core::{rendezvous, SceneInfo};
use fbksd_exchange::record::{RunStatus, Times};
use session::{CostClock, Session, WaitClock};
use std::collections::VecDeque;
use std::os::unix::fs::PermissionsExt;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{channel, Sender};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Default size of one ring slot. Large enough that a hand-off costs far
/// less than moving the tile's samples; small enough that the ring stays a
/// few tens of MB.
pub const DEFAULT_SLOT_BYTES: u64 = 8 << 20;

/// How long a technique has after its result (or a renderer after `finish`)
/// to exit before it is killed.
const EXIT_GRACE: Duration = Duration::from_secs(5);

/// Limits that apply to every run.
#[derive(Debug, Clone)]
pub struct Limits {
    /// Wall-time limit of one run (technique start → result); `None` = no limit.
    pub time_limit: Option<Duration>,
    /// How long a renderer may take to start and load its scene.
    pub renderer_start: Duration,
    /// Bytes per ring slot (at least one pixel's samples at the full budget).
    pub slot_bytes: u64,
    /// Where rendezvous directories go; `None` for [`rendezvous::default_parent`].
    pub rendezvous_parent: Option<PathBuf>,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            time_limit: Some(crate::DEFAULT_TIME_LIMIT),
            renderer_start: Duration::from_secs(300),
            slot_bytes: DEFAULT_SLOT_BYTES,
            rendezvous_parent: None,
        }
    }
}

/// How the technique process comes to be.
#[derive(Debug, Clone)]
pub enum TechniqueLaunch {
    /// The manager starts this command.
    Command(Vec<String>),
    /// The technique is already running and connects by itself (debug mode).
    External,
}

/// What a run produced.
#[derive(Debug, Clone)]
pub struct RunOutcome {
    /// The typed status.
    pub status: RunStatus,
    /// Why (empty for `ok`).
    pub message: String,
    /// The result image (`width × height × 3`), when one was received with the right size.
    pub image: Option<Vec<f32>>,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// The budget in samples.
    pub samples_budget: u64,
    /// Samples delivered.
    pub used_samples: u64,
    /// Floats per sample of the technique's layout (0 before it set one).
    pub sample_floats: u32,
    /// Requests made.
    pub requests: u64,
    /// Times.
    pub times: Times,
    /// Peak RSS of the technique.
    pub peak_memory_bytes: u64,
}

impl Default for RunOutcome {
    /// Nothing measured yet (and `ok` until something goes wrong).
    fn default() -> Self {
        RunOutcome {
            status: RunStatus::Ok,
            message: String::new(),
            image: None,
            width: 0,
            height: 0,
            samples_budget: 0,
            used_samples: 0,
            sample_floats: 0,
            requests: 0,
            times: Times::default(),
            peak_memory_bytes: 0,
        }
    }
}

impl RunOutcome {
    /// The outcome of a finished session: its end, honest times, memory and samples.
    fn measured(mut self, s: &mut Session, started: Instant, status: RunStatus, message: String) -> RunOutcome {
        let end = s.result_at.unwrap_or_else(Instant::now);
        let wall = end - started;
        s.clock.stop_at(end);
        let waiting = s.clock.waiting;
        let background = s.clock.cpu_while_waiting;
        s.cost.stop();
        let (technique_cpu, render_cpu) = s.cost.spent.map_or((0.0, 0.0), |(t, r)| (ms(t), ms(r)));
        self.times = Times {
            technique_ms: ms(wall.saturating_sub(waiting) + background),
            waiting_ms: ms(waiting),
            background_cpu_ms: ms(background),
            render_ms: ms(s.render_time),
            wall_ms: ms(wall),
            startup_ms: s.hello_at.map_or(0.0, |h| ms(h - started)),
            cpu_ms: s.exit.as_ref().map_or(0.0, |e| ms(e.cpu_time)),
            technique_cpu_ms: technique_cpu,
            render_cpu_ms: render_cpu,
        };
        self.peak_memory_bytes = s.exit.as_ref().map_or(0, |e| e.peak_rss);
        self.used_samples = s.used + s.active.as_ref().map_or(0, |a| a.delivered);
        self.sample_floats = s.layout.as_ref().map_or(0, |l| l.sample_size() as u32);
        self.requests = s.requests;
        self.image = s.image.take();
        self.status = status;
        self.message = message;
        self
    }
}

/// A scene's rendezvous directory and renderer, reused across runs.
pub struct SceneRunner {
    dir: tempfile::TempDir,
    launcher: Arc<dyn Launcher>,
    renderer_argv: Vec<String>,
    renderer_log: Option<PathBuf>,
    limits: Limits,
    tx: Sender<Event>,
    inbox: Inbox,
    renderer: Option<RendererConn>,
    renderer_error: Option<String>,
    generation: u64,
    sessions: u64,
    early_techniques: Vec<(UnixStream, Hello)>,
    seed: u64,
}

impl SceneRunner {
    /// Creates the rendezvous directory for a renderer command (whose last
    /// argument is normally the scene file); the renderer starts on the
    /// first run. Its output goes to `renderer_log`, or is inherited when `None`.
    pub fn new(renderer_argv: Vec<String>, renderer_log: Option<PathBuf>, limits: Limits) -> std::io::Result<Self> {
        let parent = limits.rendezvous_parent.clone().unwrap_or_else(rendezvous::default_parent);
        let dir = tempfile::Builder::new().prefix("fbksd-run-").tempdir_in(parent)?;
        // Containers running as another user share this directory; the
        // directory's own name is unguessable and its parent is not listed to them.
        std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o700))?;
        let listener = UnixListener::bind(rendezvous::control_socket(dir.path()))?;
        let (tx, rx) = channel();
        let accept_tx = tx.clone();
        std::thread::Builder::new().name("fbksd-accept".into()).spawn(move || accept_loop(listener, accept_tx))?;
        Ok(SceneRunner {
            dir,
            launcher: Arc::new(LocalLauncher),
            renderer_argv,
            renderer_log,
            limits,
            tx,
            inbox: Inbox { rx, deferred: VecDeque::new() },
            renderer: None,
            renderer_error: None,
            generation: 0,
            sessions: 0,
            early_techniques: Vec::new(),
            seed: 0,
        })
    }

    /// Starts the renderer and the techniques with `launcher` instead of as
    /// local children. When its processes run as another user, the
    /// directory becomes traversable (not listable) and its files open to
    /// them: the directory's unguessable name and its parent are what keep
    /// other users out, and in a container only this directory is mounted.
    pub fn with_launcher(mut self, launcher: Arc<dyn Launcher>) -> std::io::Result<Self> {
        if launcher.shares_files_with_other_users() {
            std::fs::set_permissions(self.dir.path(), std::fs::Permissions::from_mode(0o711))?;
            let socket = rendezvous::control_socket(self.dir.path());
            std::fs::set_permissions(socket, std::fs::Permissions::from_mode(0o666))?;
        }
        self.launcher = launcher;
        Ok(self)
    }

    /// Sets the renderer's sample seed of the following runs (0 until set):
    /// repeats of a run differ only in their seed.
    pub fn set_seed(&mut self, seed: u64) {
        self.seed = seed;
    }

    /// The rendezvous directory (what `FBKSD_RENDEZVOUS` names).
    pub fn dir(&self) -> &Path {
        self.dir.path()
    }

    /// The renderer's scene info, starting the renderer if needed.
    pub fn scene_info(&mut self) -> Result<(SceneInfo, u32), String> {
        self.ensure_renderer()?;
        let r = self.renderer.as_ref().expect("renderer just started");
        Ok((r.scene_info.clone(), r.tile_size))
    }

    fn next_generation(&mut self) -> u64 {
        self.generation += 1;
        self.generation
    }

    fn ensure_renderer(&mut self) -> Result<(), String> {
        if self.renderer.is_some() {
            return Ok(());
        }
        let result = self.start_renderer();
        if let Err(e) = &result {
            self.renderer_error = Some(e.clone());
        }
        result
    }

    fn start_renderer(&mut self) -> Result<(), String> {
        let generation = self.next_generation();
        let on_exit = report_to(self.tx.clone(), move |info| Event::RendererExited(generation, info));
        let spec = LaunchSpec {
            role: ProcessRole::Renderer,
            argv: &self.renderer_argv,
            rendezvous: self.dir.path(),
            session_token: None,
            log: self.renderer_log.as_deref(),
        };
        let process = self
            .launcher
            .launch(&spec, Box::new(on_exit))
            .map_err(|e| format!("renderer {}: {e}", shell_words::join(&self.renderer_argv)))?;
        let deadline = Instant::now() + self.limits.renderer_start;
        let mut writer: Option<UnixStream> = None;
        let fail = |process: &dyn Running, why: String| {
            process.kill();
            Err(format!("{why}{}", log_note(self.renderer_log.as_deref())))
        };
        loop {
            let event = match self.inbox.next(Some(deadline)) {
                Some(e) => e,
                None => {
                    return fail(
                        process.as_ref(),
                        format!("the renderer did not become ready within {:?}", self.limits.renderer_start),
                    )
                }
            };
            match event {
                Event::Connected(stream, hello) if hello.role == Role::Renderer && writer.is_none() => {
                    let mut w = match stream.try_clone() {
                        Ok(w) => w,
                        Err(e) => return fail(process.as_ref(), format!("renderer connection: {e}")),
                    };
                    // A renderer that stops reading must not block the manager.
                    let _ = w.set_write_timeout(Some(Duration::from_secs(30)));
                    let _ = write_frame(&mut w, &ToRenderer::Welcome { version: PROTOCOL_VERSION });
                    spawn_reader(stream, self.tx.clone(), move |m| Event::Renderer(generation, m));
                    writer = Some(w);
                }
                Event::Connected(stream, hello) if hello.role == Role::Technique => {
                    self.early_techniques.push((stream, hello));
                }
                Event::Connected(mut stream, _) => {
                    refuse(&mut stream, "a renderer is already connected to this run");
                }
                Event::Renderer(g, Ok(Some(FromRenderer::Ready { tile_size, scene_info }))) if g == generation => {
                    if let Err(e) = scene_info.width().and(scene_info.height()) {
                        return fail(process.as_ref(), format!("the renderer's scene info is unusable: {e}"));
                    }
                    let writer = writer.take().expect("ready comes after connect");
                    self.renderer =
                        Some(RendererConn { process, writer, generation, tile_size: tile_size.max(1), scene_info });
                    return Ok(());
                }
                Event::Renderer(g, Ok(Some(FromRenderer::Failed { message }))) if g == generation => {
                    return fail(process.as_ref(), format!("the renderer failed to start: {message}"));
                }
                Event::Renderer(g, other) if g == generation => {
                    return fail(process.as_ref(), format!("the renderer sent {other:?} instead of ready"));
                }
                Event::RendererExited(g, info) if g == generation => {
                    return fail(
                        process.as_ref(),
                        format!("the renderer exited ({}) before it was ready", info.describe()),
                    );
                }
                _ => {} // stale events of earlier processes
            }
        }
    }

    fn drop_renderer(&mut self) {
        if let Some(r) = self.renderer.take() {
            r.process.kill();
        }
    }

    /// Runs one technique session with a budget of `spp` samples per pixel.
    pub fn run(&mut self, spp: u64, launch: &TechniqueLaunch, technique_log: &Path) -> RunOutcome {
        self.run_with_progress(spp, launch, technique_log, &mut |_, _| {})
    }

    /// As [`Self::run`], calling `progress(delivered, budget)` a few times a
    /// second while samples flow.
    pub fn run_with_progress(
        &mut self,
        spp: u64,
        launch: &TechniqueLaunch,
        technique_log: &Path,
        progress: &mut dyn FnMut(u64, u64),
    ) -> RunOutcome {
        let mut outcome = RunOutcome::default();
        if let Err(e) = self.ensure_renderer() {
            outcome.status = RunStatus::RendererFailed;
            outcome.message = e;
            return outcome;
        }
        self.sessions += 1;
        let session_id = self.sessions;
        let technique_generation = self.next_generation();
        let renderer = self.renderer.as_mut().expect("ensured");
        let (width, height) = (renderer.scene_info.width().unwrap(), renderer.scene_info.height().unwrap());
        let pixels = width as u64 * height as u64;
        outcome.width = width;
        outcome.height = height;
        outcome.samples_budget = spp.saturating_mul(pixels);

        let mut info = renderer.scene_info.clone();
        info.set(keys::MAX_SPP, spp as i64).set(keys::MAX_SAMPLES, outcome.samples_budget as i64);
        let result_file = format!("result-{session_id}.f32");
        let result_path = self.dir.path().join(&result_file);
        // The manager never maps the result: it reads it once, with pread,
        // so a technique that truncates the file cannot crash it.
        let result_buffer = match fbksd_core::shm::create_file(&result_path, pixels * 12).and_then(|f| {
            if self.launcher.shares_files_with_other_users() {
                f.set_permissions(std::fs::Permissions::from_mode(0o666))
                    .map_err(|source| fbksd_core::shm::ShmError::Io { path: result_path.clone(), source })?;
            }
            Ok(f)
        }) {
            Ok(f) => f,
            Err(e) => {
                outcome.status = RunStatus::LaunchFailed;
                outcome.message = format!("cannot create the result buffer: {e}");
                return outcome;
            }
        };
        let started = Instant::now();
        let token = match launch {
            TechniqueLaunch::Command(_) => match rendezvous::new_session_token() {
                Ok(t) => Some(t),
                Err(e) => return launch_failed(outcome, format!("cannot make a session token: {e}"), &result_path),
            },
            TechniqueLaunch::External => None,
        };
        let technique = match launch {
            TechniqueLaunch::Command(argv) => {
                let on_exit = report_to(self.tx.clone(), move |i| Event::TechniqueExited(technique_generation, i));
                let spec = LaunchSpec {
                    role: ProcessRole::Technique,
                    argv,
                    rendezvous: self.dir.path(),
                    session_token: token.as_deref(),
                    log: Some(technique_log),
                };
                match self.launcher.launch(&spec, Box::new(on_exit)) {
                    Ok(p) => Some(p),
                    Err(e) => return launch_failed(outcome, e.to_string(), &result_path),
                }
            }
            TechniqueLaunch::External => None,
        };
        let started = technique.as_ref().map_or(started, |t| t.started_at());

        let mut s = Session {
            token,
            dir: self.dir.path().to_path_buf(),
            shared: self.launcher.shares_files_with_other_users(),
            id: session_id,
            generation: technique_generation,
            spawned: technique.is_some(),
            width,
            height,
            spp,
            pipe_size: 0,
            slot_bytes_default: self.limits.slot_bytes,
            info,
            result_file,
            writer: None,
            hello_at: None,
            layout: None,
            layout_pending: None,
            ring: None,
            budget: outcome.samples_budget,
            used: 0,
            requests: 0,
            active: None,
            slots: Vec::new(),
            free: VecDeque::new(),
            queued: VecDeque::new(),
            held: 0,
            clock: WaitClock::new(technique.as_ref().and_then(|t| t.cpu_clock())),
            cost: CostClock::new(
                technique.as_ref().and_then(|t| t.tree_cpu_clock()),
                renderer.process.tree_cpu_clock(),
            ),
            seed: self.seed,
            render_started: None,
            render_time: Duration::ZERO,
            result_at: None,
            image: None,
            renderer_broken: false,
            exit: None,
        };
        for (stream, hello) in std::mem::take(&mut self.early_techniques) {
            s.connect(stream, hello, &self.tx);
        }

        let deadline = self.limits.time_limit.map(|l| started + l);
        let (status, message) = self.event_loop(&mut s, &result_buffer, deadline, progress);

        self.end_session(&mut s, technique.as_deref(), &result_path);
        outcome.measured(&mut s, started, status, message)
    }

    /// Cleans up after a session: the technique, then the renderer
    /// (restarted next time if the session left it mid-request), then the
    /// shared files.
    fn end_session(&mut self, s: &mut Session, technique: Option<&dyn Running>, result_path: &Path) {
        if let Some(p) = technique {
            p.kill();
            if s.exit.is_none() {
                s.exit = self.wait_technique_exit(s.generation, Duration::from_secs(2));
            }
        }
        // A renderer left inside a request or a layout change is restarted:
        // its late replies must not reach the next session.
        if s.renderer_broken || s.active.is_some() || s.layout_pending.is_some() {
            self.drop_renderer();
        } else if let Some(r) = self.renderer.as_mut() {
            r.send(&ToRenderer::EndSession);
        }
        let _ = std::fs::remove_file(result_path);
        if let Some(ring) = s.ring.take() {
            let _ = std::fs::remove_file(self.dir.path().join(ring.file_name()));
        }
    }

    fn wait_technique_exit(&mut self, generation: u64, within: Duration) -> Option<ExitInfo> {
        match self.inbox.wait_for(within, |e| matches!(e, Event::TechniqueExited(g, _) if *g == generation)) {
            Some(Event::TechniqueExited(_, info)) => Some(info),
            _ => None,
        }
    }

    fn wait_renderer_exit(&mut self, generation: u64, within: Duration) -> Option<ExitInfo> {
        match self.inbox.wait_for(within, |e| matches!(e, Event::RendererExited(g, _) if *g == generation)) {
            Some(Event::RendererExited(_, info)) => Some(info),
            _ => None,
        }
    }

    fn event_loop(
        &mut self,
        s: &mut Session,
        result: &std::fs::File,
        deadline: Option<Instant>,
        progress: &mut dyn FnMut(u64, u64),
    ) -> (RunStatus, String) {
        let mut last_report = Instant::now();
        // After the result (or after the technique hangs up) the technique
        // has a short grace to exit; the run's verdict is already known.
        let mut verdict: Option<(RunStatus, String)> = None;
        let mut grace_deadline: Option<Instant> = None;
        loop {
            let wake = [deadline, grace_deadline].into_iter().flatten().min();
            let Some(event) = self.inbox.next(wake) else {
                if let Some(v) = verdict {
                    return v;
                }
                if grace_deadline.is_some_and(|g| Instant::now() >= g) {
                    return (
                        RunStatus::NoResult,
                        "the technique closed its connection without sending a result".into(),
                    );
                }
                return s.timeout_verdict(self.limits.time_limit.unwrap_or_default());
            };
            let renderer = self.renderer.as_mut().expect("a session runs with a renderer");
            let end = match event {
                Event::Connected(stream, hello) => {
                    s.connect(stream, hello, &self.tx);
                    None
                }
                Event::Technique(g, message) if g == s.generation => match message {
                    Ok(Some(m)) => s.on_technique(m, renderer, result),
                    Ok(None) | Err(_) if verdict.is_some() => None,
                    Ok(None) => {
                        grace_deadline.get_or_insert(Instant::now() + Duration::from_secs(3));
                        None
                    }
                    Err(e) => Some((RunStatus::ProtocolError, format!("technique connection: {e}"))),
                },
                Event::Renderer(g, message) if g == renderer.generation => match message {
                    Ok(Some(m)) => {
                        let end = s.on_renderer(m, renderer);
                        if last_report.elapsed() >= Duration::from_millis(250) {
                            last_report = Instant::now();
                            progress(s.used + s.active.as_ref().map_or(0, |a| a.delivered), s.budget);
                        }
                        end
                    }
                    Ok(None) => {
                        s.renderer_broken = true;
                        let generation = renderer.generation;
                        // The exit status says more than the hang-up: wait a moment for it.
                        let why = match self.wait_renderer_exit(generation, Duration::from_secs(2)) {
                            Some(info) => {
                                format!("the renderer died ({}) during the run", info.describe())
                            }
                            None => "the renderer closed its connection".into(),
                        };
                        Some((RunStatus::RendererFailed, format!("{why}{}", log_note(self.renderer_log.as_deref()))))
                    }
                    Err(e) => {
                        s.renderer_broken = true;
                        Some((RunStatus::RendererFailed, format!("renderer connection: {e}")))
                    }
                },
                Event::TechniqueExited(g, info) if g == s.generation => {
                    let status = info.status;
                    let out_of_memory = info.out_of_memory;
                    s.exit = Some(info);
                    if let Some(v) = verdict {
                        return v;
                    }
                    Some(if out_of_memory {
                        (
                            RunStatus::OutOfMemory,
                            "the technique was killed for going over its memory limit before sending a result".into(),
                        )
                    } else if status.success() {
                        (RunStatus::NoResult, "the technique exited (exit code 0) without sending a result".into())
                    } else {
                        (
                            RunStatus::Crashed,
                            format!(
                                "the technique died ({}) before sending a result",
                                crate::process::describe_status(status)
                            ),
                        )
                    })
                }
                Event::RendererExited(g, info) if g == renderer.generation => {
                    s.renderer_broken = true;
                    Some((
                        RunStatus::RendererFailed,
                        format!(
                            "the renderer died ({}) during the run{}",
                            info.describe(),
                            log_note(self.renderer_log.as_deref())
                        ),
                    ))
                }
                _ => None,
            };
            if let Some(v) = end {
                if v.0 == RunStatus::Ok && s.exit.is_none() && s.spawned {
                    // Result accepted: give the technique its grace to exit.
                    verdict = Some(v);
                    grace_deadline = Some(Instant::now() + EXIT_GRACE);
                } else if verdict.is_none() {
                    return v;
                }
            }
        }
    }

    /// Tells the renderer to finish and waits briefly for it to exit;
    /// returns how it ended (CPU time, peak memory) when it did.
    pub fn finish(mut self) -> Option<ExitInfo> {
        let mut r = self.renderer.take()?;
        r.send(&ToRenderer::Finish);
        let exit = self.wait_renderer_exit(r.generation, EXIT_GRACE);
        if exit.is_none() {
            r.process.kill();
        }
        exit
    }
}

impl Drop for SceneRunner {
    fn drop(&mut self) {
        self.drop_renderer();
    }
}

/// "; renderer log (path):\n<last lines>", or nothing when there is no log.
fn log_note(log: Option<&Path>) -> String {
    let Some(log) = log else { return String::new() };
    let tail = log_tail(log, 20);
    if tail.is_empty() {
        String::new()
    } else {
        format!("; renderer log ({}):\n{tail}", log.display())
    }
}

fn launch_failed(mut outcome: RunOutcome, message: String, result_path: &Path) -> RunOutcome {
    let _ = std::fs::remove_file(result_path);
    outcome.status = RunStatus::LaunchFailed;
    outcome.message = message;
    outcome
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}
