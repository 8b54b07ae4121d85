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
        // Colours for a terminal only: a log file or a container's log reads plain.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    let cli = Cli::parse();
    // Ctrl-C or a TERM (deploy/serve.sh's stop) ends the runner cleanly, also
    // while it starts: dropping the start kills a reference being made.
    let shutdown = async {
        let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
            .expect("a SIGTERM handler can be installed");
        tokio::select! {
            _ = tokio::signal::ctrl_c() => {}
            _ = term.recv() => {}
        }
        tracing::info!("interrupted: stopping");
    };
    tokio::pin!(shutdown);
    let runner = tokio::select! {
        runner = Runner::start(cli.config) => runner?,
        () = &mut shutdown => return Ok(()),
    };
    runner.run(shutdown).await;
    Ok(())
}
