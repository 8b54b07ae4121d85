//! The FBKSD manager: runs techniques against renderers and keeps the score.
//!
//! The manager is the trusted party of a benchmark run. It starts the
//! renderer once per scene and the technique once per (scene, budget), meets
//! them in a fresh rendezvous directory, validates the technique's layout,
//! enforces the sample budget and the time limit, hands tiles between the
//! two (it never touches sample data itself), measures time honestly, and
//! ends every run with a typed [`RunStatus`].
//!
//! - [`scene::SceneRunner`]: one scene, one renderer, successive runs.
//! - [`benchmark::Benchmark`]: techniques × scenes × budgets into a results
//!   directory ([`fbksd_exchange::results`]).
//! - [`process`]: supervised child processes (CPU time and peak memory by `wait4`).
//! - [`evaluation`]: metric values and error maps of a results directory.
//! - [`more_seeds`]: more seeds for the runs behind ties too close to call.
//!
//! What its records, results directories and scene metadata look like is
//! [`fbksd_exchange`]'s, shared with the CLI, the renderers, the runner and
//! the server.
//!
//! ```no_run
//! use fbksd_manager::{Benchmark, TechniqueSpec, SceneSpec, Limits};
//! let bench = Benchmark {
//!     techniques: vec![TechniqueSpec { name: "box".into(), argv: vec!["./box-filter".into()] }],
//!     scenes: vec![SceneSpec {
//!         name: "gradient".into(),
//!         renderer_argv: vec!["fbksd-analytic-renderer".into(), "gradient.json".into()],
//!         spps: vec![1, 4, 16],
//!     }],
//!     results: "results".into(),
//!     limits: Limits::default(),
//!     launcher: std::sync::Arc::new(fbksd_manager::LocalLauncher),
//!     repeats: 1,
//! };
//! let records = bench.run(|_| {}).unwrap();
//! ```
#![deny(missing_docs)]

pub mod benchmark;
pub mod evaluation;
pub mod more_seeds;
pub mod process;
pub mod scene;

pub use benchmark::{Benchmark, Progress, SceneSpec, TechniqueSpec};
pub use fbksd_exchange::record::{FailureReason, RunRecord, RunStatus, Times};
pub use process::{LaunchSpec, Launcher, LocalLauncher, ProcessRole, Running};
pub use scene::{Limits, RunOutcome, SceneRunner, TechniqueLaunch};

use std::time::Duration;

/// The wall-time limit of one run unless overridden (`fbksd run --time-limit`).
pub const DEFAULT_TIME_LIMIT: Duration = Duration::from_secs(30 * 60);
