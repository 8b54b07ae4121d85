//! `fbksd-ci`: an FBKSD runner. See the library for what it does.

use clap::Parser;
use fbksd_ci::{Runner, RunnerConfig};

/// Builds and benchmarks the jobs of an fbksd-server in Docker sandboxes.
#[derive(Parser)]
#[command(version)]
struct Cli {
    #[command(flatten)]
    config: RunnerConfig,
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()))
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let runner = Runner::start(cli.config).await?;
    runner
        .run(async {
            let _ = tokio::signal::ctrl_c().await;
            tracing::info!("interrupted: stopping");
        })
        .await;
    Ok(())
}
