//! `fbksd-server [--config server.toml]`: starts the FBKSD service. With no
//! configuration it serves http://127.0.0.1:8096 with SQLite and a mail
//! outbox in ./fbksd-data, and prints the first administrator's one-time
//! password. `fbksd-server baselines [LIST]` publishes the baseline
//! techniques through the running service (see `fbksd_server::baselines`).
//! `fbksd-server backup DIR` and `restore DIR` save and bring back a
//! service (see `fbksd_server::backup`). `FBKSD_LOG_FORMAT=json` logs one
//! JSON object per line.

use clap::Parser;
use std::path::PathBuf;

#[derive(Parser)]
#[command(version, about = "The FBKSD online service")]
struct Args {
    /// A TOML configuration file (environment variables FBKSD_SERVER_* override it).
    #[arg(long, global = true)]
    config: Option<PathBuf>,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Submits, benchmarks and publishes the baseline techniques through the
    /// running server, under the `baselines` account; skips those already on
    /// the current board, and waits for the others.
    Baselines {
        /// The list of technique folders, one per line, relative to the list.
        #[arg(default_value = "sdk/techniques/baselines.txt")]
        list: PathBuf,
        /// The server's URL (default: http:// and the configured bind address).
        #[arg(long)]
        url: Option<String>,
    },
    /// Copies the database and the files the service cannot make again
    /// into DIR (new, or empty), while the service runs.
    Backup {
        /// Where the backup goes.
        dir: PathBuf,
    },
    /// Restores a backup into the configured data directory and database,
    /// which must be empty; then start the server as usual.
    Restore {
        /// The backup.
        dir: PathBuf,
    },
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    // FBKSD_LOG_FORMAT=json: one JSON object per line, for log collectors.
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into());
    match std::env::var("FBKSD_LOG_FORMAT").as_deref() {
        Ok("json") => tracing_subscriber::fmt().json().with_env_filter(filter).init(),
        Ok("text") | Err(_) => tracing_subscriber::fmt().with_env_filter(filter).init(),
        Ok(other) => anyhow::bail!("FBKSD_LOG_FORMAT={other:?}: use json or text"),
    }
    let args = Args::parse();
    let config = fbksd_server::config::Config::load(args.config.as_deref())?;
    match args.command {
        Some(Command::Baselines { list, url }) => return fbksd_server::baselines::submit(&config, &list, url).await,
        Some(Command::Backup { dir }) => {
            fbksd_server::backup::backup(&config, &dir).await?;
            println!("backup of {} written to {}", config.data_dir.display(), dir.display());
            return Ok(());
        }
        Some(Command::Restore { dir }) => {
            fbksd_server::backup::restore(&config, &dir).await?;
            println!("{} restored into {}: start the server", dir.display(), config.data_dir.display());
            return Ok(());
        }
        None => {}
    }
    let app = fbksd_server::Application::build(config).await?;
    let config = app.config();
    println!("FBKSD server: {} (data in {})", app.url(), config.data_dir.display());
    println!("Open {}/register to create an account, or log in at {}/login.", app.url(), app.url());
    if config.smtp_url.0.is_empty() {
        println!(
            "Mail goes to the file outbox {} (no smtp_url is set); the links of each mail are also printed here.",
            config.outbox_dir().display()
        );
    }
    if let Some((email, password)) = app.admin_credentials() {
        println!("administrator created: {email} / {password} (shown once: logging in leads to the form that replaces it, and nothing else opens until it is replaced)");
    }
    if let Some(token) = app.runner_registration_token() {
        println!("runner registration token: {token} (shown once; an administrator can rotate it)");
    }
    app.run().await?;
    Ok(())
}
