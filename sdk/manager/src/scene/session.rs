//! One technique session's state machine: the layout, the budget, the
//! ownership of every ring slot, the clocks, and the verdict. It reacts to
//! one message at a time from the technique or the renderer (the runner's
//! event loop in the parent module feeds it) and says when the run ends.

use super::conn::{refuse, spawn_reader, Event, RendererConn};
use crate::process::{CpuClock, ExitInfo};
use fbksd_core::layout::CompiledLayout;
use fbksd_core::protocol::{
    write_frame, Amount, ErrorKind, FromRenderer, FromTechnique, Hello, Role, ToRenderer, ToTechnique, PROTOCOL_VERSION,
};
use fbksd_core::shm::{Ring, RingSpec};
use fbksd_core::{SceneInfo, Tile};
use fbksd_exchange::record::RunStatus;
use std::collections::VecDeque;
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::sync::mpsc::Sender;
use std::time::{Duration, Instant};

#[derive(Debug, Clone, Copy)]
pub(super) enum Slot {
    Free,
    Producing { id: u64, tile: Tile },
    Rendering { tile: Tile },
    Consuming,
}

pub(super) struct Active {
    /// One bit per pixel: delivered by a pixel tile in this request.
    pub(super) covered: Vec<u64>,
    pub(super) input: bool,
    pub(super) spp: u64,
    pub(super) pixel_expected: u64,
    pub(super) free_expected: u64,
    pub(super) pixel_acquired: u64,
    pub(super) free_acquired: u64,
    pub(super) delivered: u64,
    pub(super) renderer_done: bool,
}

impl Active {
    pub(super) fn expected(&self) -> u64 {
        self.pixel_expected + self.free_expected
    }
}

pub(super) type End = Option<(RunStatus, String)>;

/// The technique's waiting clock: the wall time it waits for the renderer
/// (inside a request with no tile in its hands, or while the renderer takes
/// its layout), which is not its time, and the CPU time it burns meanwhile
/// (in other threads: work moved out of the tile callbacks), which is.
pub(super) struct WaitClock {
    cpu: Option<CpuClock>,
    since: Option<(Instant, Option<Duration>)>,
    /// Wall time spent waiting (closed intervals).
    pub(super) waiting: Duration,
    /// CPU time the technique used while waiting (closed intervals).
    pub(super) cpu_while_waiting: Duration,
}

impl WaitClock {
    pub(super) fn new(cpu: Option<CpuClock>) -> WaitClock {
        WaitClock { cpu, since: None, waiting: Duration::ZERO, cpu_while_waiting: Duration::ZERO }
    }

    fn cpu_now(&self) -> Option<Duration> {
        self.cpu.as_ref().and_then(|c| c())
    }

    /// Starts waiting (no change when already waiting).
    pub(super) fn start(&mut self) {
        if self.since.is_none() {
            self.since = Some((Instant::now(), self.cpu_now()));
        }
    }

    /// Stops waiting at `at` (no change when not waiting).
    pub(super) fn stop_at(&mut self, at: Instant) {
        if let Some((since, cpu_then)) = self.since.take() {
            self.waiting += at.saturating_duration_since(since);
            if let (Some(then), Some(now)) = (cpu_then, self.cpu_now()) {
                self.cpu_while_waiting += now.saturating_sub(then);
            }
        }
    }

    pub(super) fn stop(&mut self) {
        self.stop_at(Instant::now());
    }
}

/// The run's cost: the CPU time of the technique (every thread and
/// process) and of the renderer from the technique's hello to its result
/// (see `fbksd_exchange::record::Times`). Where either clock cannot be
/// read, nothing is measured (`spent` stays `None`).
pub(super) struct CostClock {
    technique: Option<CpuClock>,
    renderer: Option<CpuClock>,
    started: Option<(Option<Duration>, Option<Duration>)>,
    /// The technique's and the renderer's CPU time, once stopped.
    pub(super) spent: Option<(Duration, Duration)>,
}

impl CostClock {
    pub(super) fn new(technique: Option<CpuClock>, renderer: Option<CpuClock>) -> CostClock {
        CostClock { technique, renderer, started: None, spent: None }
    }

    fn read(clock: &Option<CpuClock>) -> Option<Duration> {
        clock.as_ref().and_then(|c| c())
    }

    /// Starts at the technique's hello (once).
    pub(super) fn start(&mut self) {
        if self.started.is_none() {
            self.started = Some((Self::read(&self.technique), Self::read(&self.renderer)));
        }
    }

    /// Stops at the result, or at the end of a run without one (once).
    pub(super) fn stop(&mut self) {
        let Some((Some(technique), Some(renderer))) = self.started else { return };
        if self.spent.is_some() {
            return;
        }
        if let (Some(t), Some(r)) = (Self::read(&self.technique), Self::read(&self.renderer)) {
            self.spent = Some((t.saturating_sub(technique), r.saturating_sub(renderer)));
        }
    }
}

/// The state of one technique session.
pub(super) struct Session {
    /// The token a spawned technique must present (none in debug mode).
    pub(super) token: Option<String>,
    pub(super) dir: PathBuf,
    /// Whether the launcher's processes run as other users (files open to them).
    pub(super) shared: bool,
    pub(super) id: u64,
    pub(super) generation: u64,
    /// Whether the manager started the technique (so it can wait for its exit).
    pub(super) spawned: bool,
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) spp: u64,
    pub(super) pipe_size: u64,
    pub(super) slot_bytes_default: u64,
    pub(super) info: SceneInfo,
    pub(super) result_file: String,
    pub(super) writer: Option<UnixStream>,
    pub(super) hello_at: Option<Instant>,
    pub(super) layout: Option<CompiledLayout>,
    pub(super) layout_pending: Option<(CompiledLayout, RingSpec)>,
    pub(super) ring: Option<RingSpec>,
    pub(super) budget: u64,
    pub(super) used: u64,
    pub(super) requests: u64,
    pub(super) active: Option<Active>,
    pub(super) slots: Vec<Slot>,
    pub(super) free: VecDeque<u32>,
    pub(super) queued: VecDeque<(u64, Tile)>,
    /// Slots in the technique's hands (producing or consuming).
    pub(super) held: usize,
    pub(super) clock: WaitClock,
    pub(super) cost: CostClock,
    /// The renderer's sample seed for this run.
    pub(super) seed: u64,
    pub(super) render_started: Option<Instant>,
    pub(super) render_time: Duration,
    pub(super) result_at: Option<Instant>,
    pub(super) image: Option<Vec<f32>>,
    pub(super) renderer_broken: bool,
    pub(super) exit: Option<ExitInfo>,
}

impl Session {
    pub(super) fn connect(&mut self, mut stream: UnixStream, hello: Hello, tx: &Sender<Event>) {
        if hello.role != Role::Technique {
            return refuse(&mut stream, "a renderer is already connected to this run");
        }
        if self.writer.is_some() {
            return refuse(&mut stream, "another technique is already connected to this run");
        }
        if self.token.is_some() && hello.session != self.token {
            return refuse(
                &mut stream,
                "this connection is not the technique started for the current run (FBKSD_SESSION missing or wrong)",
            );
        }
        let Ok(mut writer) = stream.try_clone() else {
            return;
        };
        let _ = writer.set_write_timeout(Some(Duration::from_secs(30)));
        // The cost starts before the welcome: until it arrives the technique can only wait.
        self.cost.start();
        let _ = write_frame(
            &mut writer,
            &ToTechnique::Welcome {
                version: PROTOCOL_VERSION,
                scene_info: self.info.clone(),
                result_file: self.result_file.clone(),
            },
        );
        let generation = self.generation;
        spawn_reader(stream, tx.clone(), move |m| Event::Technique(generation, m));
        self.writer = Some(writer);
        self.hello_at = Some(Instant::now());
    }

    fn send(&mut self, message: &ToTechnique) {
        if let Some(w) = self.writer.as_mut() {
            // A failed write surfaces as the reader's end of stream or the exit event.
            let _ = write_frame(w, message);
        }
    }

    /// Ends the session with an error the technique is told about too.
    fn refuse(&mut self, status: RunStatus, kind: ErrorKind, message: String) -> End {
        self.send(&ToTechnique::Error { kind, message: message.clone() });
        Some((status, message))
    }

    fn protocol_error(&mut self, message: String) -> End {
        self.refuse(RunStatus::ProtocolError, ErrorKind::Protocol, message)
    }

    fn renderer_failed(&mut self, message: String) -> End {
        self.renderer_broken = true;
        self.refuse(RunStatus::RendererFailed, ErrorKind::RendererFailed, message)
    }

    pub(super) fn timeout_verdict(&self, limit: Duration) -> (RunStatus, String) {
        let limit = humantime::format_duration(limit);
        if self.writer.is_none() {
            return (RunStatus::Timeout, format!("the technique did not connect within the time limit of {limit}"));
        }
        if self.layout_pending.is_some() {
            return (
                RunStatus::RendererFailed,
                format!("the time limit of {limit} expired while the renderer was still accepting the layout"),
            );
        }
        match &self.active {
            Some(a) if self.held == 0 => (
                RunStatus::RendererFailed,
                format!(
                    "the time limit of {limit} expired while the technique waited for the renderer ({} of {} samples delivered)",
                    a.delivered,
                    a.expected()
                ),
            ),
            _ => (RunStatus::Timeout, format!("the technique exceeded the time limit of {limit}")),
        }
    }

    fn hand_to_technique(&mut self, message: ToTechnique) {
        if self.held == 0 {
            self.clock.stop();
        }
        self.held += 1;
        self.send(&message);
    }

    fn take_back_from_technique(&mut self) {
        self.held -= 1;
        if self.held == 0 && self.active.is_some() {
            self.clock.start();
        }
    }

    fn slot_state(&self, slot: u32) -> Option<Slot> {
        self.slots.get(slot as usize).copied()
    }

    pub(super) fn on_technique(
        &mut self,
        message: FromTechnique,
        renderer: &mut RendererConn,
        result: &std::fs::File,
    ) -> End {
        match message {
            FromTechnique::SetLayout { layout } => {
                if self.layout.is_some() || self.layout_pending.is_some() {
                    return self.protocol_error("set_layout may be called only once per run".into());
                }
                let compiled = match layout.compile() {
                    Ok(c) => c,
                    Err(e) => return self.refuse(RunStatus::InvalidLayout, ErrorKind::InvalidLayout, e.to_string()),
                };
                let sample_bytes = compiled.sample_size() as u64 * 4;
                let slot_count = std::thread::available_parallelism().map_or(2, |n| n.get()).clamp(2, 7) as u32 * 2 + 2;
                // A slot holds at least one pixel at the full budget, so any SPP
                // tile fits; it need not hold more than the whole budget spread
                // over the ring (small images get small rings).
                let whole_budget = (self.budget * sample_bytes).div_ceil(slot_count as u64);
                let slot_bytes = self
                    .slot_bytes_default
                    .min(whole_budget)
                    .max(self.spp.max(1) * sample_bytes)
                    .next_multiple_of(4096);
                let spec = RingSpec { session: self.id, slot_count, slot_bytes };
                let created = Ring::create_file(&self.dir, spec, self.shared).map(drop).map_err(|e| e.to_string());
                if let Err(e) = created {
                    return self.renderer_failed(format!("cannot create the sample ring: {e}"));
                }
                self.pipe_size = spec.slot_samples(compiled.sample_size());
                self.slots = vec![Slot::Free; slot_count as usize];
                self.free = (0..slot_count).collect();
                renderer.send(&ToRenderer::SetLayout { layout: compiled.source().clone(), ring: spec });
                self.ring = Some(spec);
                self.layout_pending = Some((compiled, spec));
                // The technique now waits for the renderer: not its time.
                self.clock.start();
                None
            }
            FromTechnique::Evaluate { amount, input } => self.start_request(amount, input, renderer),
            FromTechnique::Produced { slot } => {
                let Some(Slot::Producing { id, tile }) = self.slot_state(slot) else {
                    return self
                        .protocol_error(format!("produced slot {slot}, which the technique was not asked to fill"));
                };
                self.slots[slot as usize] = Slot::Rendering { tile };
                self.take_back_from_technique();
                renderer.send(&ToRenderer::Granted { id, slot });
                None
            }
            FromTechnique::Consumed { slot } => {
                let Some(Slot::Consuming) = self.slot_state(slot) else {
                    return self.protocol_error(format!("consumed slot {slot}, which the technique did not hold"));
                };
                self.slots[slot as usize] = Slot::Free;
                self.free.push_back(slot);
                self.take_back_from_technique();
                if let Some((id, tile)) = self.queued.pop_front() {
                    self.grant(id, tile, renderer);
                }
                self.check_complete()
            }
            FromTechnique::SendResult { width, height, channels } => {
                if self.active.is_some() {
                    return self.protocol_error("send_result during a sample request".into());
                }
                if (width, height, channels) != (self.width, self.height, 3) {
                    return self.refuse(
                        RunStatus::InvalidOutput,
                        ErrorKind::InvalidOutput,
                        format!(
                            "the result is {width}×{height}×{channels} but the scene is {}×{}×3",
                            self.width, self.height
                        ),
                    );
                }
                // Read before the technique is told its result is accepted: it waits for that answer.
                self.cost.stop();
                self.result_at = Some(Instant::now());
                let mut bytes = vec![0u8; self.width as usize * self.height as usize * 12];
                if let Err(e) = std::os::unix::fs::FileExt::read_exact_at(result, &mut bytes, 0) {
                    return self.refuse(
                        RunStatus::InvalidOutput,
                        ErrorKind::InvalidOutput,
                        format!("the result buffer could not be read (was it truncated?): {e}"),
                    );
                }
                let pixels: Vec<f32> =
                    bytes.chunks_exact(4).map(|b| f32::from_ne_bytes([b[0], b[1], b[2], b[3]])).collect();
                let bad = pixels.iter().filter(|v| !v.is_finite()).count();
                let first_bad = pixels.iter().position(|v| !v.is_finite());
                self.image = Some(pixels);
                self.send(&ToTechnique::ResultAccepted);
                if let Some(i) = first_bad {
                    let px = i / 3;
                    return Some((
                        RunStatus::InvalidOutput,
                        format!(
                            "the result has {bad} NaN or infinite values (first at pixel x={}, y={}); the image is kept for inspection",
                            px % self.width as usize,
                            px / self.width as usize
                        ),
                    ));
                }
                Some((RunStatus::Ok, String::new()))
            }
        }
    }

    fn start_request(&mut self, amount: Amount, input: bool, renderer: &mut RendererConn) -> End {
        let Some(layout) = &self.layout else {
            return self.protocol_error("evaluate before set_layout".into());
        };
        if self.active.is_some() {
            return self.protocol_error("evaluate while another request is in progress".into());
        }
        let layout_has_input = layout.has_input();
        if input && !layout_has_input {
            return self.refuse(
                RunStatus::ProtocolError,
                ErrorKind::BadRequest,
                "evaluate_input_samples needs INPUT random parameters in the layout".into(),
            );
        }
        if !input && layout_has_input {
            return self.refuse(
                RunStatus::ProtocolError,
                ErrorKind::BadRequest,
                "the layout has INPUT random parameters: request samples with evaluate_input_samples".into(),
            );
        }
        let pixels = self.width as u64 * self.height as u64;
        let (samples, what) = match amount {
            Amount::Spp(n) => (n.checked_mul(pixels), format!("{n} spp × {pixels} pixels")),
            Amount::Samples(n) => (Some(n), format!("{n} samples")),
        };
        let remaining = self.budget - self.used;
        let samples = match samples {
            Some(0) => {
                return self.refuse(RunStatus::ProtocolError, ErrorKind::BadRequest, "a request for 0 samples".into())
            }
            Some(s) if s <= remaining => s,
            _ => {
                return self.refuse(
                    RunStatus::OverBudget,
                    ErrorKind::OverBudget,
                    format!(
                        "requested {what} but only {remaining} of the budget of {} samples ({} spp) remain",
                        self.budget, self.spp
                    ),
                )
            }
        };
        // Count requests without INPUT come as whole spp plus a remainder, so
        // the renderer can stratify; with INPUT the technique places every sample.
        let (spp, free) = match amount {
            Amount::Spp(n) => (n, 0),
            Amount::Samples(n) if input => (0, n),
            Amount::Samples(n) => (n / pixels, n % pixels),
        };
        self.requests += 1;
        self.active = Some(Active {
            covered: if spp > 0 { vec![0; (pixels as usize).div_ceil(64)] } else { Vec::new() },
            input,
            spp,
            pixel_expected: spp * pixels,
            free_expected: free,
            pixel_acquired: 0,
            free_acquired: 0,
            delivered: 0,
            renderer_done: false,
        });
        debug_assert_eq!(spp * pixels + free, samples);
        self.clock.start();
        self.render_started = Some(Instant::now());
        renderer.send(&ToRenderer::Evaluate {
            spp,
            remaining: free,
            pipe_size: self.pipe_size,
            input,
            request: self.requests - 1,
            seed: self.seed,
        });
        None
    }

    fn grant(&mut self, id: u64, tile: Tile, renderer: &mut RendererConn) {
        let slot = self.free.pop_front().expect("grant with a free slot");
        if self.active.as_ref().is_some_and(|a| a.input) {
            self.slots[slot as usize] = Slot::Producing { id, tile };
            self.hand_to_technique(ToTechnique::Produce { slot, tile });
        } else {
            self.slots[slot as usize] = Slot::Rendering { tile };
            renderer.send(&ToRenderer::Granted { id, slot });
        }
    }

    pub(super) fn on_renderer(&mut self, message: FromRenderer, renderer: &mut RendererConn) -> End {
        match message {
            FromRenderer::LayoutAccepted => {
                let Some((compiled, ring)) = self.layout_pending.take() else {
                    return self.renderer_failed("the renderer accepted a layout nobody set".into());
                };
                self.send(&ToTechnique::LayoutSet { ring, sample_size: compiled.sample_size() as u32 });
                self.layout = Some(compiled);
                self.clock.stop();
                None
            }
            FromRenderer::Failed { message } if self.layout_pending.is_some() => {
                self.layout_pending = None;
                self.refuse(
                    RunStatus::InvalidLayout,
                    ErrorKind::InvalidLayout,
                    format!("the renderer rejected the layout: {message}"),
                )
            }
            FromRenderer::Failed { message } => self.renderer_failed(format!("the renderer failed: {message}")),
            FromRenderer::Acquire { id, tile } => {
                if let Err(why) = self.check_tile(&tile) {
                    return self.renderer_failed(format!("the renderer asked for an invalid tile {tile:?}: {why}"));
                }
                if self.free.is_empty() {
                    self.queued.push_back((id, tile));
                } else {
                    self.grant(id, tile, renderer);
                }
                None
            }
            FromRenderer::Filled { slot, count } => {
                let Some(Slot::Rendering { tile }) = self.slot_state(slot) else {
                    return self.renderer_failed(format!("the renderer filled slot {slot}, which it did not hold"));
                };
                if count != tile.sample_count() {
                    return self.renderer_failed(format!(
                        "the renderer filled slot {slot} with {count} samples; its tile has {}",
                        tile.sample_count()
                    ));
                }
                self.slots[slot as usize] = Slot::Consuming;
                if let Some(a) = self.active.as_mut() {
                    a.delivered += count;
                }
                self.hand_to_technique(ToTechnique::Consume { slot, tile });
                None
            }
            FromRenderer::EvaluateDone => {
                let Some(a) = self.active.as_mut() else {
                    return self.renderer_failed("the renderer finished a request nobody made".into());
                };
                a.renderer_done = true;
                if let Some(t) = self.render_started.take() {
                    self.render_time += t.elapsed();
                }
                self.check_complete()
            }
            FromRenderer::Ready { .. } => self.renderer_failed("the renderer sent ready twice".into()),
        }
    }

    fn check_tile(&mut self, tile: &Tile) -> Result<(), String> {
        let Some(a) = self.active.as_mut() else {
            return Err("no request is in progress".into());
        };
        let n = tile.sample_count();
        if n == 0 || n > self.pipe_size {
            return Err(format!("{n} samples, pipe size is {}", self.pipe_size));
        }
        match tile {
            Tile::Pixels { rect, spp } => {
                if *spp as u64 != a.spp || !rect.is_inside(self.width, self.height) {
                    return Err(format!("request is {} spp on {}×{}", a.spp, self.width, self.height));
                }
                a.pixel_acquired += n;
                if a.pixel_acquired > a.pixel_expected {
                    return Err(format!("more pixel samples than the {} requested", a.pixel_expected));
                }
                for y in rect.y0..rect.y1 {
                    for x in rect.x0..rect.x1 {
                        let i = y as usize * self.width as usize + x as usize;
                        if a.covered[i / 64] & (1 << (i % 64)) != 0 {
                            return Err(format!("pixel ({x}, {y}) is in two tiles of the same request"));
                        }
                        a.covered[i / 64] |= 1 << (i % 64);
                    }
                }
            }
            Tile::Samples { .. } => {
                a.free_acquired += n;
                if a.free_acquired > a.free_expected {
                    return Err(format!("more free samples than the {} requested", a.free_expected));
                }
            }
        }
        Ok(())
    }

    fn check_complete(&mut self) -> End {
        let Some(a) = &self.active else { return None };
        if !a.renderer_done || self.slots.iter().any(|s| !matches!(s, Slot::Free | Slot::Rendering { .. })) {
            return None;
        }
        if self.slots.iter().any(|s| matches!(s, Slot::Rendering { .. })) || !self.queued.is_empty() {
            return self
                .renderer_failed("the renderer reported the request done with tiles acquired but never filled".into());
        }
        if a.delivered != a.expected() {
            let msg = format!("the renderer finished a request with {} of its {} samples", a.delivered, a.expected());
            return self.renderer_failed(msg);
        }
        let delivered = a.delivered;
        self.used += delivered;
        self.active = None;
        self.clock.stop();
        let remaining = self.budget - self.used;
        self.send(&ToTechnique::EvaluateDone { delivered, remaining });
        None
    }
}
