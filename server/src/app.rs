//! Wiring: configuration → database, mailer, router, listener.

use crate::accounts::{self, Email, Password};
use crate::config::Config;
use crate::mail::Mailer;
use std::future::IntoFuture;
use std::sync::Arc;
use tokio::net::TcpListener;

/// Everything a request handler may use.
#[derive(Clone)]
pub struct AppState {
    /// The database.
    pub pool: sqlx::AnyPool,
    /// Outgoing mail.
    pub mailer: Mailer,
    /// The configuration the server started with.
    pub config: Arc<Config>,
    /// Base URL for links in e-mails, without a trailing slash.
    pub public_url: String,
    /// The hosted git repositories.
    pub git: crate::git::GitHost,
    /// Whether the database is PostgreSQL (row locking for claims).
    pub postgres: bool,
    /// Wakes runners' long polls when a job is queued on this instance
    /// (other instances' jobs are found by polling).
    pub job_queued: Arc<tokio::sync::Notify>,
    /// Leaderboards kept in memory.
    pub boards: crate::leaderboard::BoardCache,
    /// Public leaderboards rendered for anonymous readers.
    pub public_boards: crate::routes::PublicBoards,
    /// Rate limits on log-ins and account mail.
    pub throttle: crate::throttle::Throttle,
    /// Metrics for operators (`/metrics`).
    pub telemetry: crate::telemetry::Telemetry,
    /// Techniques' descriptions read from their commits, kept.
    pub checked: crate::pipelines::CheckedCommits,
}

impl AppState {
    /// The URL git clones a project from.
    pub fn clone_url(&self, project: &str) -> String {
        format!("{}/git/{project}.git", self.public_url)
    }
}

/// A server ready to run: its listener is bound.
pub struct Application {
    listener: TcpListener,
    router: axum::Router,
    /// `metrics_bind`'s listener and its router, when it is set.
    metrics: Option<(TcpListener, axum::Router)>,
    admin: Option<(String, String)>,
    registration_token: Option<String>,
    url: String,
    config: Arc<Config>,
}

impl Application {
    /// Opens the data directory, database and mail transport, creates the
    /// first administrator if there is none, and binds the listener.
    pub async fn build(mut config: Config) -> anyhow::Result<Application> {
        std::fs::create_dir_all(&config.data_dir)
            .map_err(|e| anyhow::anyhow!("data directory {}: {e}", config.data_dir.display()))?;
        // Resolved once: git configuration, hooks, child processes and the
        // database see this path from other working directories (a bare
        // repository resolves a relative `core.hooksPath` inside itself).
        config.data_dir = std::fs::canonicalize(&config.data_dir)
            .map_err(|e| anyhow::anyhow!("data directory {}: {e}", config.data_dir.display()))?;
        let pool = crate::db::connect(&config.database_url()).await.map_err(|e| anyhow::anyhow!("database: {e}"))?;
        let mailer = Mailer::from_config(&config)?;
        let listener =
            TcpListener::bind(&config.bind).await.map_err(|e| anyhow::anyhow!("bind {}: {e}", config.bind))?;
        let address = listener.local_addr()?;
        let public_url = if config.public_url.is_empty() {
            format!("http://{address}")
        } else {
            config.public_url.trim_end_matches('/').to_string()
        };

        // The first start creates an administrator with a one-time password.
        let admin = if accounts::has_admin(&pool).await? {
            None
        } else {
            let (email, password) =
                ("admin@localhost.localdomain".to_string(), accounts::random_token()[..20].to_string());
            let parsed = (Email::parse(&email), Password::parse(&password));
            let (Ok(e), Ok(p)) = parsed else { anyhow::bail!("bootstrap administrator credentials are invalid") };
            let user =
                accounts::create_user(&pool, &e, &p, true, true).await.map_err(|e| anyhow::anyhow!("{}", e.message))?;
            // Printed to the log: it must be replaced before it can do anything.
            accounts::require_password_change(&pool, &user.id).await?;
            Some((email, password))
        };

        // The service accounts exist before registration opens (their domain is reserved too).
        for address in [crate::references::ACCOUNT, crate::baselines::ACCOUNT] {
            let email = Email::parse(address).map_err(|e| anyhow::anyhow!("{}", e.message))?;
            match accounts::ensure_service_account(&pool, &email).await {
                Ok(_) => {}
                Err(e) if e.code == "email_taken" => tracing::error!(
                    "{}; it was registered before the address was reserved: remove that account, \
                     or nothing it publishes (references, baselines) can be made",
                    e.message
                ),
                Err(e) => tracing::warn!("creating the service account {address}: {}", e.message),
            }
        }

        let registration_token =
            crate::runners::ensure_registration_token(&pool, &config.runner_registration_token.0).await?;
        let git =
            crate::git::GitHost::open(&config.data_dir, config.max_push_bytes, &crate::pipelines::pre_receive_hook())
                .map_err(|e| anyhow::anyhow!("git repositories in {}: {e}", config.data_dir.display()))?;
        let postgres = config.database_url().starts_with("postgres");
        keep_private(&config.data_dir)
            .map_err(|e| anyhow::anyhow!("data directory {}: {e}", config.data_dir.display()))?;

        // Leases expire, and attempts run out of time, even when no runner polls.
        let sweeper = pool.clone();
        // 0: no limit.
        let max_job_ms = match config.max_job_seconds {
            0 => None,
            s => Some(i64::try_from(s).unwrap_or(i64::MAX / 1000).saturating_mul(1000)),
        };
        tokio::spawn(async move {
            loop {
                tokio::time::sleep(std::time::Duration::from_secs(1)).await;
                if let Err(e) = crate::jobs::expire_leases(&sweeper).await {
                    tracing::warn!("expiring leases: {e}");
                }
                let Some(max) = max_job_ms else { continue };
                if let Err(e) = crate::jobs::stop_overdue(&sweeper, max).await {
                    tracing::warn!("stopping jobs past max_job_seconds: {e}");
                }
            }
        });

        let url = public_url.clone();
        let config = Arc::new(config);
        let state = AppState {
            pool,
            mailer,
            config: config.clone(),
            public_url,
            git,
            postgres,
            job_queued: Arc::new(tokio::sync::Notify::new()),
            boards: Default::default(),
            public_boards: Default::default(),
            throttle: crate::throttle::Throttle::new(&config),
            telemetry: Default::default(),
            checked: Default::default(),
        };
        // What ended jobs or a crash left in `uploads/`: at start, then hourly.
        let housekeeper = state.clone();
        tokio::spawn(async move {
            loop {
                match crate::pipelines::sweep_uploads(&housekeeper).await {
                    Ok(0) => {}
                    Ok(n) => tracing::info!("removed the uploads of {n} jobs that are not running"),
                    Err(e) => tracing::warn!("sweeping uploads: {}", e.message),
                }
                tokio::time::sleep(std::time::Duration::from_secs(3600)).await;
            }
        });
        // Each time the board changes (a publish here, on another instance,
        // or a seeds job's repeats added), ties that more seeds could settle
        // get seeds jobs, and sets measured off their runner class's
        // calibration are measured again.
        let planner = state.clone();
        tokio::spawn(async move {
            let mut planned = None;
            loop {
                if let Err(e) = crate::planner::plan_if_changed(&planner, &mut planned).await {
                    tracing::warn!("planning the board's jobs: {}", e.message);
                }
                tokio::time::sleep(std::time::Duration::from_secs(2)).await;
            }
        });
        let metrics = if config.metrics_bind.is_empty() {
            None
        } else {
            let listener = TcpListener::bind(&config.metrics_bind)
                .await
                .map_err(|e| anyhow::anyhow!("bind {} (metrics_bind): {e}", config.metrics_bind))?;
            Some((listener, crate::routes::metrics_router().with_state(state.clone())))
        };
        let router = crate::routes::router(state);
        Ok(Application { listener, router, metrics, admin, registration_token, url, config })
    }

    /// The URL users reach the server at (the configured public URL, or the bound address).
    pub fn url(&self) -> &str {
        &self.url
    }

    /// The configuration in force: the data directory is absolute.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The port the server listens on.
    pub fn port(&self) -> u16 {
        self.listener.local_addr().map_or(0, |a| a.port())
    }

    /// The address `/metrics` is served on when `metrics_bind` is set.
    pub fn metrics_address(&self) -> Option<std::net::SocketAddr> {
        self.metrics.as_ref().and_then(|(listener, _)| listener.local_addr().ok())
    }

    /// The administrator created by this start (e-mail, one-time password),
    /// if the database had none.
    pub fn admin_credentials(&self) -> Option<&(String, String)> {
        self.admin.as_ref()
    }

    /// The runner registration token generated by this start, if the
    /// database had none and none was configured.
    pub fn runner_registration_token(&self) -> Option<&str> {
        self.registration_token.as_deref()
    }

    /// Serves until the process is stopped. Connections time out
    /// (`routes::limits`): the first request's headers within
    /// `HEADER_READ_TIMEOUT`, then no silence longer than `IDLE_TIMEOUT`
    /// (or twice the runners' long poll, if that is longer).
    pub async fn run(self) -> std::io::Result<()> {
        use crate::routes::limits::{TimedListener, HEADER_READ_TIMEOUT, IDLE_TIMEOUT};
        use axum::serve::ListenerExt;
        // The peer address feeds the per-client rate limits (`throttle::ClientIp`).
        let service = self.router.into_make_service_with_connect_info::<std::net::SocketAddr>();
        let idle = IDLE_TIMEOUT.max(std::time::Duration::from_secs(2 * self.config.long_poll_seconds + 30));
        // `tap_io` (a no-op) is what gives a wrapped listener's connections their peer address.
        let listener = TimedListener::new(self.listener, HEADER_READ_TIMEOUT, idle).tap_io(|_| {});
        let public = axum::serve(listener, service).into_future();
        match self.metrics {
            Some((metrics_listener, metrics_router)) => {
                let metrics_listener = TimedListener::new(metrics_listener, HEADER_READ_TIMEOUT, IDLE_TIMEOUT);
                let metrics = axum::serve(metrics_listener, metrics_router).into_future();
                tokio::try_join!(public, metrics).map(|_| ())
            }
            None => public.await,
        }
    }
}

/// Owner-only modes for what the data directory holds: the database,
/// mail (sign-in links), repositories, uploads and result sets. Files
/// created later inside these directories are out of others' reach
/// whatever the umask.
fn keep_private(data_dir: &std::path::Path) -> std::io::Result<()> {
    use std::os::unix::fs::PermissionsExt;
    let private_dir = std::fs::Permissions::from_mode(0o700);
    std::fs::set_permissions(data_dir, private_dir.clone())?;
    for name in ["outbox", "results", "uploads", "git", "git-hooks", "git-spool"] {
        let dir = data_dir.join(name);
        std::fs::create_dir_all(&dir)?;
        std::fs::set_permissions(&dir, private_dir.clone())?;
    }
    // The SQLite database and its journals, the runner's token file, …
    for entry in std::fs::read_dir(data_dir)? {
        let entry = entry?;
        if entry.file_type()?.is_file() {
            std::fs::set_permissions(entry.path(), std::fs::Permissions::from_mode(0o600))?;
        }
    }
    Ok(())
}
