//! What FBKSD's programs exchange, in one place so both ends of every
//! exchange serialise the same types.
//!
//! The manager writes results directories that the CLI, the runner and the
//! server read; renderers and the runner agree on scene metadata and on when
//! a cached reference is current; the runner and the server talk over the
//! runner API. Each of those contracts is a type here, and nothing here runs
//! a process, touches a database or speaks HTTP:
//!
//! - [`record`]: how one run ended and what it measured.
//! - [`results`]: the results directory's layout, its file names and index.
//! - [`scenes`]: scene metadata, scene digests and the reference-cache rule.
//! - [`technique`]: a technique repository's `info.json`.
//! - [`environments`]: what each environment a technique builds in holds.
//! - [`cost`]: what a run costs on the equal-time axis.
//! - [`stats`]: intervals and spreads over a run's repeats, the paired test.
//! - [`ranking`]: techniques ranked by mean rank over the index, at equal
//!   samples and at equal time, with ties where differences are noise.
//! - [`runner_api`]: the messages of the runner API, job kinds and states.
//! - [`pixels`]: the viewer's pixel files (exact floats, small on the wire).
//! - [`viewer`]: the results viewer's document.
//! - [`disk`]: how much room files take, counted one way by the runner
//!   and the server.
#![deny(missing_docs)]

pub mod cost;
pub mod disk;
pub mod environments;
pub mod pixels;
pub mod ranking;
pub mod record;
pub mod results;
pub mod runner_api;
pub mod scenes;
pub mod stats;
pub mod technique;
pub mod viewer;

pub use record::{FailureReason, RunRecord, RunStatus, Times};
pub use results::MetricInfo;
