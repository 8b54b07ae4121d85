//! Debug mode: a manager inside the technique's own process.
//!
//! `--fbksd-renderer "<renderer> <args> <scene>" --fbksd-spp N
//! [--fbksd-output result.exr]` starts the renderer and a manager thread,
//! so the technique can be launched directly (under a debugger, say) with
//! no time limit. The result is written to `--fbksd-output`
//! (default `fbksd-debug.exr`) and a one-line summary goes to stderr.

use crate::ClientError;
#[cfg(feature = "debug-mode")]
use fbksd_manager::{Limits, RunOutcome, SceneRunner, TechniqueLaunch};
use std::path::{Path, PathBuf};

#[cfg_attr(not(feature = "debug-mode"), allow(dead_code))]
pub(crate) struct RunArgs {
    renderer: Vec<String>,
    spp: u64,
    output: PathBuf,
}

pub(crate) enum DebugArgs {
    Version,
    Run(RunArgs),
}

impl DebugArgs {
    /// `None` when no `--fbksd-*` option is present (normal mode).
    pub(crate) fn parse(args: impl IntoIterator<Item = String>) -> Result<Option<Self>, ClientError> {
        let mut renderer = None;
        let mut spp = None;
        let mut output = PathBuf::from("fbksd-debug.exr");
        let mut args = args.into_iter().skip(1);
        let value =
            |name: &str, v: Option<String>| v.ok_or_else(|| ClientError::Debug(format!("{name} needs a value")));
        while let Some(arg) = args.next() {
            match arg.as_str() {
                "--fbksd-version" => return Ok(Some(DebugArgs::Version)),
                "--fbksd-renderer" => renderer = Some(value("--fbksd-renderer", args.next())?),
                "--fbksd-spp" => {
                    let v = value("--fbksd-spp", args.next())?;
                    spp = Some(v.parse::<u64>().ok().filter(|n| *n > 0).ok_or_else(|| {
                        ClientError::Debug(format!("--fbksd-spp takes a positive whole number, got {v:?}"))
                    })?);
                }
                "--fbksd-output" => output = PathBuf::from(value("--fbksd-output", args.next())?),
                _ => {}
            }
        }
        match (renderer, spp) {
            (None, None) => Ok(None),
            (Some(r), Some(spp)) => {
                let renderer =
                    shell_words::split(&r).map_err(|e| ClientError::Debug(format!("--fbksd-renderer {r:?}: {e}")))?;
                if renderer.is_empty() {
                    return Err(ClientError::Debug("--fbksd-renderer is empty".into()));
                }
                Ok(Some(DebugArgs::Run(RunArgs { renderer, spp, output })))
            }
            (Some(_), None) => Err(ClientError::Debug("--fbksd-renderer needs --fbksd-spp".into())),
            (None, Some(_)) => Err(ClientError::Debug("--fbksd-spp needs --fbksd-renderer".into())),
        }
    }
}

/// The manager thread of a debug-mode run. Only techniques built with the
/// `debug-mode` feature (on by default) link the manager for it.
#[cfg(feature = "debug-mode")]
pub(crate) struct DebugManager {
    dir: PathBuf,
    thread: std::thread::JoinHandle<()>,
}

#[cfg(feature = "debug-mode")]
impl DebugManager {
    pub(crate) fn start(args: RunArgs) -> Result<Self, ClientError> {
        let limits = Limits { time_limit: None, ..Limits::default() };
        let mut runner = SceneRunner::new(args.renderer, None, limits)?;
        let dir = runner.dir().to_path_buf();
        let thread = std::thread::Builder::new().name("fbksd-debug-manager".into()).spawn(move || {
            let outcome = runner.run(args.spp, &TechniqueLaunch::External, Path::new("/dev/null"));
            report(&outcome, &args.output);
            let _ = runner.finish();
        })?;
        Ok(DebugManager { dir, thread })
    }

    pub(crate) fn dir(&self) -> &Path {
        &self.dir
    }

    pub(crate) fn finish(self) {
        let _ = self.thread.join();
    }
}

/// Without the `debug-mode` feature there is no manager to start.
#[cfg(not(feature = "debug-mode"))]
pub(crate) struct DebugManager {
    never: std::convert::Infallible,
}

#[cfg(not(feature = "debug-mode"))]
impl DebugManager {
    pub(crate) fn start(_: RunArgs) -> Result<Self, ClientError> {
        Err(ClientError::Debug(
            "this technique was built without debug mode: build it with fbksd-client's `debug-mode` feature \
             (on by default), or run it with `fbksd run`"
                .into(),
        ))
    }

    pub(crate) fn dir(&self) -> &Path {
        match self.never {}
    }

    pub(crate) fn finish(self) {
        match self.never {}
    }
}

#[cfg(feature = "debug-mode")]
fn report(outcome: &RunOutcome, output: &Path) {
    let mut line = format!(
        "fbksd debug: {} — {} of {} samples, technique {:.1} ms, render {:.1} ms",
        outcome.status,
        outcome.used_samples,
        outcome.samples_budget,
        outcome.times.technique_ms,
        outcome.times.render_ms
    );
    if !outcome.message.is_empty() {
        line += &format!(": {}", outcome.message);
    }
    if let Some(image) = &outcome.image {
        match fbksd_iqa::image::write_exr(output, outcome.width, outcome.height, image) {
            Ok(()) => line += &format!("; result written to {}", output.display()),
            Err(e) => line += &format!("; cannot write the result: {e}"),
        }
    }
    eprintln!("{line}");
}
