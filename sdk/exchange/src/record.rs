//! What one run produced: its typed status and its measurements.

use serde::{Deserialize, Serialize};
use std::fmt;

/// How a run ended. Every status but `ok` comes with a message saying why.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunStatus {
    /// The technique sent a valid result.
    Ok,
    /// The technique asked for more samples than its budget.
    OverBudget,
    /// The run exceeded its wall-time limit.
    Timeout,
    /// The technique died (signal or non-zero exit) before sending a result.
    Crashed,
    /// The technique was killed for going over its memory limit (sandboxed runs).
    OutOfMemory,
    /// The technique exited cleanly without sending a result.
    NoResult,
    /// The result has the wrong size or holds NaN/Inf values.
    InvalidOutput,
    /// The technique's sample layout is invalid.
    InvalidLayout,
    /// The technique broke the protocol (message out of order, bad slot…).
    ProtocolError,
    /// The renderer failed to start, crashed, or delivered wrong samples.
    RendererFailed,
    /// The technique could not be started.
    LaunchFailed,
}

impl RunStatus {
    /// The status as written in logs and indexes.
    pub fn as_str(self) -> &'static str {
        match self {
            RunStatus::Ok => "ok",
            RunStatus::OverBudget => "over_budget",
            RunStatus::Timeout => "timeout",
            RunStatus::Crashed => "crashed",
            RunStatus::OutOfMemory => "out_of_memory",
            RunStatus::NoResult => "no_result",
            RunStatus::InvalidOutput => "invalid_output",
            RunStatus::InvalidLayout => "invalid_layout",
            RunStatus::ProtocolError => "protocol_error",
            RunStatus::RendererFailed => "renderer_failed",
            RunStatus::LaunchFailed => "launch_failed",
        }
    }
}

/// Why a build or benchmark job failed, as the service reports it: the
/// server stores it, the runner decides it. Each comes with a message the
/// author can act on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FailureReason {
    /// The repository failed its checks or did not build.
    BuildFailed,
    /// A build or run exceeded its wall-time limit.
    Timeout,
    /// A container hit its memory limit.
    OutOfMemory,
    /// The technique died.
    Crashed,
    /// The technique's output was wrong (size, NaN, layout, budget, protocol).
    InvalidOutput,
    /// The job wrote more than its limits allow (build directory, clone,
    /// output, upload): the author's, counted like any failure.
    OverLimit,
    /// Not the author's fault: the runner, Docker or the server failed.
    InfrastructureError,
}

impl FailureReason {
    /// The name as written in the API and the database.
    pub fn as_str(self) -> &'static str {
        match self {
            FailureReason::BuildFailed => "build_failed",
            FailureReason::Timeout => "timeout",
            FailureReason::OutOfMemory => "out_of_memory",
            FailureReason::Crashed => "crashed",
            FailureReason::InvalidOutput => "invalid_output",
            FailureReason::OverLimit => "over_limit",
            FailureReason::InfrastructureError => "infrastructure_error",
        }
    }
}

impl RunStatus {
    /// The job failure reason a run that ended with this status stands for.
    pub fn failure_reason(self) -> FailureReason {
        match self {
            RunStatus::Timeout => FailureReason::Timeout,
            RunStatus::OutOfMemory => FailureReason::OutOfMemory,
            RunStatus::Crashed | RunStatus::NoResult | RunStatus::RendererFailed => FailureReason::Crashed,
            RunStatus::InvalidOutput | RunStatus::InvalidLayout | RunStatus::OverBudget | RunStatus::ProtocolError => {
                FailureReason::InvalidOutput
            }
            RunStatus::LaunchFailed | RunStatus::Ok => FailureReason::InfrastructureError,
        }
    }
}

impl fmt::Display for RunStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Times of one run, in milliseconds.
///
/// **CPU times** (`technique_cpu_ms`, `render_cpu_ms`) are what the
/// equal-time comparison charges ([`crate::cost`]): the CPU time of the
/// technique (every thread of every process it started) and of the
/// renderer, from the technique's first protocol message (its hello) to its
/// result. What came before the hello (process start, imports, loading a
/// model) is start-up (`startup_ms`), shown but not charged: nothing
/// scene-dependent is known before the hello, so nothing can be gained by
/// working earlier.
///
/// Beside them, the wall-clock times as the original measured them:
/// `technique` is wall time from starting the technique to its result,
/// minus the time it spent waiting for the renderer (inside a request with
/// no tile in its hands, or while the renderer accepts its layout), plus
/// the CPU time it used while waiting (`background_cpu_ms`); start-up is
/// included. `technique_ms + waiting_ms − background_cpu_ms` is the wall
/// time.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Times {
    /// Technique time: `wall − waiting`.
    pub technique_ms: f64,
    /// Time the technique waited for the renderer.
    pub waiting_ms: f64,
    /// CPU time the technique used while it waited (work in other threads
    /// while it held no tile), charged to `technique_ms`: work cannot hide
    /// in the renderer's time.
    #[serde(default)]
    pub background_cpu_ms: f64,
    /// Time the renderer spent on requests: from each request to the
    /// renderer's `evaluate_done`. It includes time the renderer waited for
    /// a free slot, i.e. for the technique to consume tiles.
    pub render_ms: f64,
    /// Start of the technique process → result (or end of run).
    pub wall_ms: f64,
    /// Start of the technique process → its hello.
    pub startup_ms: f64,
    /// User + system CPU time of the technique process, start-up included.
    pub cpu_ms: f64,
    /// CPU time of the technique, every thread and process, hello → result.
    #[serde(default)]
    pub technique_cpu_ms: f64,
    /// CPU time of the renderer over the same span (0 where the CPU times
    /// could not be read, e.g. for a technique started by hand).
    #[serde(default)]
    pub render_cpu_ms: f64,
}

/// Everything recorded about one run; written as `<spp>_0_log.json`.
///
/// The first six fields are the original FBKSD log's, kept for
/// compatibility (`exec_time` is the technique time in ms).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// When the run started (RFC 3339, UTC).
    pub date: String,
    /// The budget in samples per pixel.
    pub spp_budget: u64,
    /// The budget in samples.
    pub samples_budget: u64,
    /// Samples delivered to the technique.
    pub used_samples: u64,
    /// Floats per sample of the technique's layout (0 when it set none):
    /// the renderer's cost per sample depends on it.
    #[serde(default)]
    pub sample_floats: u32,
    /// Whether the run ended without a valid result.
    pub aborted: bool,
    /// Technique time in milliseconds (see [`Times`]).
    pub exec_time: f64,
    /// The typed status.
    pub status: RunStatus,
    /// Why, for every status but `ok` (empty for `ok`).
    pub message: String,
    /// Scene name.
    pub scene: String,
    /// Technique name.
    pub technique: String,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// All times.
    pub times: Times,
    /// Peak resident memory of the technique process, in bytes.
    pub peak_memory_bytes: u64,
    /// Number of sample requests the technique made.
    pub requests: u64,
    /// The result image, relative to the log's directory, when one was received.
    pub image: Option<String>,
    /// The technique's output, relative to the log's directory.
    pub technique_log: String,
    /// The renderer's sample seed (0 for a run's first repeat).
    #[serde(default)]
    pub seed: u64,
    /// Which repeat of the (technique, scene, budget) this is (0 first).
    #[serde(default)]
    pub repeat: u32,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_run_status_stands_for_a_failure_reason() {
        assert_eq!(RunStatus::Timeout.failure_reason(), FailureReason::Timeout);
        assert_eq!(RunStatus::OutOfMemory.failure_reason(), FailureReason::OutOfMemory);
        assert_eq!(RunStatus::Crashed.failure_reason(), FailureReason::Crashed);
        assert_eq!(RunStatus::InvalidOutput.failure_reason(), FailureReason::InvalidOutput);
        assert_eq!(RunStatus::OverBudget.failure_reason(), FailureReason::InvalidOutput);
        assert_eq!(RunStatus::LaunchFailed.failure_reason(), FailureReason::InfrastructureError);
        assert_eq!(serde_json::to_value(FailureReason::OutOfMemory).unwrap(), "out_of_memory");
    }
}
