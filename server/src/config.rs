//! Configuration in layers: built-in defaults, then an optional TOML file,
//! then environment variables `FBKSD_SERVER_<KEY>` (for example
//! `FBKSD_SERVER_DATABASE_URL`, `FBKSD_SERVER_SMTP_URL`). With nothing set
//! the server listens on 127.0.0.1:8096 and keeps everything in
//! `./fbksd-data` (SQLite database, mail outbox).

use figment::providers::{Env, Format, Serialized, Toml};
use figment::Figment;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A secret that never prints (database URLs with passwords, SMTP credentials).
#[derive(Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(transparent)]
pub struct Secret(pub String);

impl fmt::Debug for Secret {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(if self.0.is_empty() { "\"\"" } else { "\"[redacted]\"" })
    }
}

/// The server's configuration.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Address to listen on (`host:port`; port 0 picks a free one).
    pub bind: String,
    /// Address to serve `/metrics` on, apart from `bind` (`host:port`):
    /// what faces the public then has no `/metrics`, and only what
    /// reaches this address (Prometheus on the cluster's network) reads
    /// the service's counters. Empty serves it on `bind`, for a server
    /// only its own machine reaches (README's local start).
    pub metrics_bind: String,
    /// Where the server keeps its data: the SQLite database, the mail
    /// outbox, git repositories and results.
    pub data_dir: PathBuf,
    /// `sqlite://…` or `postgres://…`; empty means SQLite in `data_dir`.
    pub database_url: Secret,
    /// The URL users reach the server at, for links in e-mails; empty
    /// means `http://<bind>`.
    pub public_url: String,
    /// `smtp://user:password@host:port` (STARTTLS) or `smtps://…`; empty
    /// means the file outbox `data_dir/outbox`.
    pub smtp_url: Secret,
    /// Sender of the server's e-mails.
    pub mail_from: String,
    /// How long a browser session lasts, in hours.
    pub session_hours: u64,
    /// The token runners register with; empty means one is generated at
    /// the first start and printed once.
    pub runner_registration_token: Secret,
    /// Largest push, in bytes.
    pub max_push_bytes: u64,
    /// A job's lease: a runner that does not heartbeat for this long loses
    /// the job, which is queued again.
    pub lease_seconds: u64,
    /// Longest one attempt of a job may run, in seconds, however its
    /// runner heart-beats: past it the job fails as a timeout and its runner
    /// is told to stop (a runner cannot hold a job for ever); 0: no limit.
    pub max_job_seconds: u64,
    /// How many times a job is handed to a runner before it fails as an
    /// infrastructure error.
    pub max_attempts: u64,
    /// Longest a runner's claim waits for a job, in seconds.
    pub long_poll_seconds: u64,
    /// The most seeds a published run is given when a tie on the board
    /// rests on it that more seeds could settle ([`crate::seeds`]): each
    /// round doubles the seeds of the runs behind the tie up to this; 0:
    /// never ask for more seeds.
    pub max_seeds: u32,
    /// Whether a runner whose latest calibration lies off its class's
    /// ([`crate::leaderboard::CALIBRATION_DRIFT_LIMIT`]) is held back from
    /// the season's benchmarks until it is back. Off only where the
    /// machine's speed is not what is tested (the runner's end-to-end
    /// tests, on machines whose speed moves by half for minutes).
    pub hold_drifted_runners: bool,
    /// How long at most a season's benchmark waits for runners held back
    /// for their calibration, in minutes: after that a held runner takes it
    /// (and the drift rule ranks its set at equal spp only if its
    /// calibration still lies off its class's). The class's calibration is
    /// the median of the season's published sets, so without a bound a
    /// season whose first sets were measured during a slow spell held its
    /// only runner back for good once the spell was over.
    pub max_drift_hold_minutes: u64,
    /// Largest log a job may write, in bytes.
    pub max_log_bytes: u64,
    /// Largest upload of one job (results and files together), in bytes.
    pub max_upload_bytes: u64,
    /// Queued jobs (builds and runs) a user may have before new runs are refused.
    pub max_queued_jobs_per_user: u64,
    /// Projects one account may own (each is a repository on disk and a
    /// row in every list): past it, creating one is refused.
    pub max_projects_per_user: u64,
    /// MiB the repositories of one account's projects may hold on disk
    /// together: a push that would take them past it is refused, nothing
    /// written. Projects bound the count, this the size (each project
    /// could otherwise grow by `max_push_bytes` per push, for ever).
    pub max_repository_mib_per_user: u64,
    /// Benchmark runs a user may request per 24 hours; infrastructure
    /// failures and runs cancelled before they started do not count.
    pub max_runs_per_day: u64,
    /// Failed log-ins per e-mail address (API and form; a success gives
    /// its attempt back), e.g. `"10 per 15m"`: guessing one password.
    pub login_limit_per_address: RateLimit,
    /// Log-in attempts per client address: one machine trying many accounts.
    pub login_limit_per_ip: RateLimit,
    /// Account mails (registration, verification link again, password
    /// reset) per e-mail address: nobody's mailbox is flooded through us.
    pub mail_limit_per_address: RateLimit,
    /// Account mails per client address.
    pub mail_limit_per_ip: RateLimit,
    /// The request header holding the client's address when the server
    /// sits behind a reverse proxy that sets it (e.g. `X-Forwarded-For`:
    /// its last entry is taken); empty means the connection's peer address.
    pub client_ip_header: String,
    /// The reverse proxies whose `client_ip_header` is believed: addresses
    /// or networks, comma-separated (`"10.0.0.0/8, 127.0.0.1"`). A request
    /// from any other peer is counted by the peer's own address, so a
    /// client that reaches the server without the proxy cannot name itself
    /// anyone (and slip its per-address limits). Required with
    /// `client_ip_header`.
    pub trusted_proxies: Networks,
}

/// Addresses and networks, written `"10.0.0.0/8, 127.0.0.1"` (an address
/// alone is its own network).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Networks(pub Vec<ipnet::IpNet>);

impl Networks {
    /// Whether `ip` is in one of them.
    pub fn contain(&self, ip: std::net::IpAddr) -> bool {
        self.0.iter().any(|net| net.contains(&ip))
    }
}

impl fmt::Display for Networks {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let nets: Vec<String> = self.0.iter().map(ToString::to_string).collect();
        f.write_str(&nets.join(", "))
    }
}

impl std::str::FromStr for Networks {
    type Err = String;
    fn from_str(text: &str) -> Result<Networks, String> {
        let networks = text.split(',').map(str::trim).filter(|part| !part.is_empty()).map(|part| {
            part.parse::<ipnet::IpNet>()
                .or_else(|_| part.parse::<std::net::IpAddr>().map(ipnet::IpNet::from))
                .map_err(|_| format!("{part:?} is not an address or a network like \"10.0.0.0/8\""))
        });
        Ok(Networks(networks.collect::<Result<_, _>>()?))
    }
}

impl Serialize for Networks {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for Networks {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Networks, D::Error> {
        String::deserialize(d)?.parse().map_err(serde::de::Error::custom)
    }
}

/// At most `count` events per `window`, refilled evenly (a burst of
/// `count`, then one per `window / count`). Written `"10 per 15m"`
/// (humantime durations), or `"off"` for no limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RateLimit {
    /// Events per window; 0 means no limit.
    pub count: u32,
    /// The window.
    pub window: Duration,
}

impl RateLimit {
    /// `count` events per `window`.
    pub const fn new(count: u32, window: Duration) -> RateLimit {
        RateLimit { count, window }
    }
    /// No limit.
    pub const OFF: RateLimit = RateLimit::new(0, Duration::ZERO);
}

impl fmt::Display for RateLimit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.count == 0 {
            return f.write_str("off");
        }
        write!(f, "{} per {}", self.count, humantime::format_duration(self.window))
    }
}

impl std::str::FromStr for RateLimit {
    type Err = String;
    fn from_str(text: &str) -> Result<RateLimit, String> {
        let text = text.trim();
        if text == "off" {
            return Ok(RateLimit::OFF);
        }
        let bad = |why: String| format!("{text:?} is not a rate limit like \"10 per 15m\" or \"off\": {why}");
        let (count, window) = text.split_once(" per ").ok_or_else(|| bad("no \" per \"".into()))?;
        let count: u32 = count.trim().parse().map_err(|e| bad(format!("count: {e}")))?;
        let window = humantime::parse_duration(window.trim()).map_err(|e| bad(format!("window: {e}")))?;
        if count == 0 || window.is_zero() {
            return Err(bad("the count and the window must be positive (or say \"off\")".into()));
        }
        Ok(RateLimit { count, window })
    }
}

impl Serialize for RateLimit {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for RateLimit {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<RateLimit, D::Error> {
        String::deserialize(d)?.parse().map_err(serde::de::Error::custom)
    }
}

impl Default for Config {
    fn default() -> Self {
        Config {
            bind: "127.0.0.1:8096".into(),
            metrics_bind: String::new(),
            data_dir: PathBuf::from("fbksd-data"),
            database_url: Secret::default(),
            public_url: String::new(),
            smtp_url: Secret::default(),
            mail_from: "FBKSD <fbksd@localhost>".into(),
            session_hours: 24 * 14,
            runner_registration_token: Secret::default(),
            max_push_bytes: 64 << 20,
            lease_seconds: 60,
            max_job_seconds: 24 * 3600,
            max_attempts: 3,
            long_poll_seconds: 25,
            max_seeds: 12,
            hold_drifted_runners: true,
            max_drift_hold_minutes: 15,
            max_log_bytes: 4 << 20,
            max_upload_bytes: 256 << 20,
            max_queued_jobs_per_user: 3,
            max_runs_per_day: 10,
            max_projects_per_user: 100,
            max_repository_mib_per_user: 2048,
            login_limit_per_address: RateLimit::new(10, Duration::from_secs(15 * 60)),
            login_limit_per_ip: RateLimit::new(30, Duration::from_secs(60)),
            mail_limit_per_address: RateLimit::new(5, Duration::from_secs(3600)),
            mail_limit_per_ip: RateLimit::new(20, Duration::from_secs(3600)),
            client_ip_header: String::new(),
            trusted_proxies: Networks::default(),
        }
    }
}

/// A configuration that cannot be used; the message says which key and why.
#[derive(Debug, thiserror::Error)]
#[error("configuration: {0}")]
pub struct ConfigError(String);

impl Config {
    /// Defaults, then `file` (if given; it must exist), then the environment.
    pub fn load(file: Option<&Path>) -> Result<Config, ConfigError> {
        let mut figment = Figment::from(Serialized::defaults(Config::default()));
        if let Some(file) = file {
            if !file.is_file() {
                return Err(ConfigError(format!("{} does not exist", file.display())));
            }
            figment = figment.merge(Toml::file(file));
        }
        figment = figment.merge(Env::prefixed("FBKSD_SERVER_"));
        let config: Config = figment.extract().map_err(|e| ConfigError(e.to_string()))?;
        if !config.client_ip_header.is_empty() && config.trusted_proxies.0.is_empty() {
            return Err(ConfigError(format!(
                "client_ip_header is {:?} but trusted_proxies is empty: the header would be believed from any \
                 client, which could then name itself anyone; set trusted_proxies to the addresses of the \
                 proxies that set it (e.g. \"10.0.0.0/8\")",
                config.client_ip_header
            )));
        }
        Ok(config)
    }

    /// The database URL to use: the configured one, or SQLite in `data_dir`.
    pub fn database_url(&self) -> String {
        if self.database_url.0.is_empty() {
            format!("sqlite://{}?mode=rwc", self.data_dir.join("fbksd.sqlite3").display())
        } else {
            self.database_url.0.clone()
        }
    }

    /// The mail outbox directory (used when no SMTP URL is set).
    pub fn outbox_dir(&self) -> PathBuf {
        self.data_dir.join("outbox")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn secrets_never_print() {
        let config = Config { database_url: Secret("postgres://u:hunter2@db/fbksd".into()), ..Config::default() };
        assert!(!format!("{config:?}").contains("hunter2"));
    }

    #[test]
    fn a_file_overrides_defaults_and_unknown_keys_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("server.toml");
        std::fs::write(&file, "bind = \"0.0.0.0:9000\"\n").unwrap();
        let config = Config::load(Some(&file)).unwrap();
        assert_eq!(config.bind, "0.0.0.0:9000");
        assert_eq!(config.session_hours, 24 * 14);
        std::fs::write(&file, "bnid = \"0.0.0.0:9000\"\n").unwrap();
        let error = Config::load(Some(&file)).unwrap_err().to_string();
        assert!(error.contains("bnid"), "{error}");
        assert!(Config::load(Some(&dir.path().join("missing.toml"))).is_err());
    }

    #[test]
    fn a_client_ip_header_needs_the_proxies_it_is_believed_from() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("server.toml");
        std::fs::write(&file, "client_ip_header = \"X-Forwarded-For\"\n").unwrap();
        let refused = Config::load(Some(&file)).unwrap_err().to_string();
        assert!(refused.contains("trusted_proxies is empty"), "{refused}");
        std::fs::write(&file, "client_ip_header = \"X-Forwarded-For\"\ntrusted_proxies = \"10.0.0.0/8, 127.0.0.1\"\n")
            .unwrap();
        let proxies = Config::load(Some(&file)).unwrap().trusted_proxies;
        assert!(proxies.contain("10.1.2.3".parse().unwrap()) && proxies.contain("127.0.0.1".parse().unwrap()));
        assert!(!proxies.contain("127.0.0.2".parse().unwrap()));
        assert_eq!(proxies.to_string(), "10.0.0.0/8, 127.0.0.1/32");
        let bad = "10.0.0.0/33".parse::<Networks>().unwrap_err();
        assert_eq!(bad, "\"10.0.0.0/33\" is not an address or a network like \"10.0.0.0/8\"");
    }

    #[test]
    fn rate_limits_read_as_count_per_duration() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("server.toml");
        std::fs::write(&file, "login_limit_per_ip = \"5 per 2m\"\nmail_limit_per_ip = \"off\"\n").unwrap();
        let config = Config::load(Some(&file)).unwrap();
        assert_eq!(config.login_limit_per_ip, RateLimit::new(5, Duration::from_secs(120)));
        assert_eq!(config.mail_limit_per_ip, RateLimit::OFF);
        assert_eq!(config.login_limit_per_address, Config::default().login_limit_per_address);
        assert_eq!(Config::default().login_limit_per_address.to_string(), "10 per 15m");
        std::fs::write(&file, "login_limit_per_ip = \"5 a minute\"\n").unwrap();
        let error = Config::load(Some(&file)).unwrap_err().to_string();
        assert!(error.contains("10 per 15m"), "{error}");
    }
}
