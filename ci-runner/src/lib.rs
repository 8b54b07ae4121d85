//! fbksd-ci: the runner that builds and benchmarks pushed techniques.
//!
//! A runner registers with an `fbksd-server`, long-polls it for jobs and
//! talks to it only over its HTTP API (a runner token to claim, a per-job
//! token for everything else). For each job it clones the repository at the
//! pinned commit, checks `info.json`, builds the technique in a sandboxed
//! container of its environment image (`cpp` or `python`), and for a
//! benchmark job runs it on the runner's scene pool: the manager (this
//! process, trusted) starts the renderer in the trusted renderer image and
//! the technique in the environment image, each in its own sandbox, sharing
//! only the run's rendezvous directory. Metrics are computed here, against
//! references no container ever sees, and uploaded with the images, logs and
//! provenance (image digests, scene and reference hashes, CPU model).
//!
//! - [`calibration`]: the fixed workload a runner times at start and between jobs.
//! - [`machine`]: the machine and its runner class, recorded with every result.
//! - [`config`]: the runner's settings (command line or environment).
//! - [`api`]: the server's runner API, with retries across server restarts.
//! - [`images`]: the image manifest written by `deploy/build-images.sh`.
//! - [`pool`]: the scene pool and its hashes.
//! - [`references`]: the pool's references, made once for the whole service
//!   (reference jobs) and downloaded by every other runner.
//! - [`sandbox`]: the container limits every piece of user code runs under.
//! - [`launcher`]: the manager's processes as sandboxed containers.
//! - [`job`]: one job, from clone to finish, with typed failure reasons.
//! - [`renderer_rates`]: the renderer's speed as a control inside every job:
//!   scenes measured while the machine was slow are measured again.
//! - [`runner`]: registration, the claim loop, heartbeats and clean-up.
#![deny(missing_docs)]

pub mod api;
pub mod calibration;
pub mod config;
pub mod images;
pub mod job;
pub mod launcher;
pub mod machine;
pub mod pool;
pub mod references;
pub mod renderer_rates;
pub mod runner;
pub mod sandbox;

pub use config::RunnerConfig;
pub use runner::Runner;
