//! Wiring: configuration → database, mailer, router, listener.

use crate::accounts::{self, Email, Password};
use crate::config::Config;
use crate::mail::Mailer;
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
}

/// A server ready to run: its listener is bound.
pub struct Application {
    listener: TcpListener,
    router: axum::Router,
    admin: Option<(String, String)>,
    url: String,
}

impl Application {
    /// Opens the data directory, database and mail transport, creates the
    /// first administrator if there is none, and binds the listener.
    pub async fn build(config: Config) -> anyhow::Result<Application> {
        std::fs::create_dir_all(&config.data_dir)
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
            accounts::create_user(&pool, &e, &p, true, true).await.map_err(|e| anyhow::anyhow!("{}", e.message))?;
            Some((email, password))
        };

        let url = public_url.clone();
        let state = AppState { pool, mailer, config: Arc::new(config), public_url };
        Ok(Application { listener, router: crate::routes::router(state), admin, url })
    }

    /// The URL users reach the server at (the configured public URL, or the bound address).
    pub fn url(&self) -> &str {
        &self.url
    }

    /// The port the server listens on.
    pub fn port(&self) -> u16 {
        self.listener.local_addr().map_or(0, |a| a.port())
    }

    /// The administrator created by this start (e-mail, one-time password),
    /// if the database had none.
    pub fn admin_credentials(&self) -> Option<&(String, String)> {
        self.admin.as_ref()
    }

    /// Serves until the process is stopped.
    pub async fn run(self) -> std::io::Result<()> {
        axum::serve(self.listener, self.router).await
    }
}
