//! `fbksd-server`: the FBKSD online service (thesis chapter 5, without
//! GitLab). It owns accounts, the database and user data; later it also
//! hosts git repositories, runs pipelines and serves the runner API and the
//! results pages.
//!
//! [`Application::build`] wires a [`config::Config`] into a running server:
//! it opens the database ([`db`]: embedded SQLite by default, PostgreSQL
//! for several server instances; one portable schema, migrated at start),
//! the mail transport ([`mail`]: a file outbox unless SMTP is configured)
//! and the HTTP routes ([`routes`]). Tests start it on port 0.
//!
//! ```no_run
//! # async fn run() -> anyhow::Result<()> {
//! let config = fbksd_server::config::Config::load(None)?;
//! let app = fbksd_server::Application::build(config).await?;
//! println!("listening on port {}", app.port());
//! app.run().await?;
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

pub mod accounts;
pub mod admin;
mod app;
pub mod backup;
pub mod baselines;
pub mod config;
pub mod db;
pub mod error;
pub mod git;
pub mod jobs;
pub mod leaderboard;
pub mod mail;
pub mod measure_again;
pub mod pipelines;
pub mod planner;
pub mod projects;
pub mod references;
pub mod results;
pub mod routes;
pub mod runners;
pub mod seeds;
pub mod slots;
pub mod telemetry;
pub mod throttle;
pub mod versioned;
pub mod viewer;

pub use app::{AppState, Application};

/// Milliseconds since the Unix epoch: how the database stores times.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_millis() as i64)
}
