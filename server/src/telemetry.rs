//! What the service tells its operators: Prometheus metrics (served at
//! `/metrics`) and the readiness check (`/readyz`).
//!
//! Counters and histograms are this instance's (Prometheus adds up the
//! instances): HTTP latencies by route, job durations by kind and end,
//! failures by reason. Gauges that describe the shared state (queue length
//! by kind, running jobs, runners by health) are read from the database at
//! each scrape, so every instance reports the same.

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{exponential_buckets, Histogram};
use prometheus_client::registry::Registry;
use sqlx::Row;
use std::sync::Arc;

/// An HTTP answer: the route's pattern (never the raw path, whose ids would
/// make a series per job), the method ([`method_label`]) and the status.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct HttpLabels {
    /// `GET`, `POST`, …
    pub method: String,
    /// The route, e.g. `/api/v1/jobs/{id}`; `unmatched` for a 404 of the router.
    pub route: String,
    /// HTTP status.
    pub status: u16,
}

/// A request's method as a label: one of HTTP's own methods, or `other`.
/// Anyone may send any token as a method, and each label value is a series
/// kept for the life of the process: `curl -X AAAA…1` to `…100000` must not
/// make a hundred thousand of them.
pub fn method_label(method: &axum::http::Method) -> &'static str {
    const KNOWN: [&str; 9] = ["GET", "HEAD", "POST", "PUT", "DELETE", "PATCH", "OPTIONS", "CONNECT", "TRACE"];
    KNOWN.into_iter().find(|m| *m == method.as_str()).unwrap_or("other")
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct KindLabels {
    kind: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct JobEndLabels {
    kind: String,
    state: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct ReasonLabels {
    reason: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct HealthLabels {
    health: String,
}

type Histograms<L> = Family<L, Histogram, fn() -> Histogram>;

/// 1 ms to ~65 s.
fn latency_buckets() -> Histogram {
    Histogram::new(exponential_buckets(0.001, 2.0, 17))
}

/// 1 s to ~9 h.
fn job_buckets() -> Histogram {
    Histogram::new(exponential_buckets(1.0, 2.0, 16))
}

/// The service's metrics.
#[derive(Clone)]
pub struct Telemetry(Arc<Metrics>);

struct Metrics {
    registry: Registry,
    http: Histograms<HttpLabels>,
    job_seconds: Histograms<JobEndLabels>,
    failures: Family<ReasonLabels, Counter>,
    queued: Family<KindLabels, Gauge>,
    running: Family<KindLabels, Gauge>,
    runners: Family<HealthLabels, Gauge>,
    git_running: Family<KindLabels, Gauge>,
    git_started: Family<KindLabels, Counter>,
    git_refused: Counter,
    /// Git's counters are copied from [`crate::git::GitHost::activity`] at
    /// each scrape, one scrape at a time (two would add the same increase).
    git_copy: std::sync::Mutex<()>,
}

impl Default for Telemetry {
    fn default() -> Telemetry {
        let mut registry = Registry::with_prefix("fbksd");
        let metrics = Metrics {
            http: Family::new_with_constructor(latency_buckets as fn() -> Histogram),
            job_seconds: Family::new_with_constructor(job_buckets as fn() -> Histogram),
            failures: Family::default(),
            queued: Family::default(),
            running: Family::default(),
            runners: Family::default(),
            git_running: Family::default(),
            git_started: Family::default(),
            git_refused: Counter::default(),
            git_copy: Default::default(),
            registry: Registry::default(),
        };
        registry.register("http_request_duration_seconds", "HTTP answers by route", metrics.http.clone());
        registry.register(
            "job_duration_seconds",
            "Jobs from start to end, by kind and end (this instance's)",
            metrics.job_seconds.clone(),
        );
        registry.register("job_failures", "Failed job attempts by reason (this instance's)", metrics.failures.clone());
        registry.register("jobs_queued", "Jobs waiting for a runner, by kind", metrics.queued.clone());
        registry.register("jobs_running", "Jobs a runner holds, by kind", metrics.running.clone());
        registry.register(
            "runners",
            "Registered runners: healthy (heard from lately) or silent",
            metrics.runners.clone(),
        );
        registry.register(
            "git_processes",
            "Git processes now: serving clients (serve) or reading for the server (read)",
            metrics.git_running.clone(),
        );
        registry.register(
            "git_processes_started",
            "Git processes started by this instance: serving clients (serve) or reading for the server (read)",
            metrics.git_started.clone(),
        );
        registry.register(
            "git_requests_refused",
            "Git requests refused because their caller had as many running as it may (this instance's)",
            metrics.git_refused.clone(),
        );
        Telemetry(Arc::new(Metrics { registry, ..metrics }))
    }
}

impl Telemetry {
    /// Counts an HTTP answer.
    pub fn http(&self, labels: HttpLabels, seconds: f64) {
        self.0.http.get_or_create(&labels).observe(seconds);
    }

    /// Counts a job's end (`state`: succeeded, failed, requeued) after
    /// `seconds` of work, and a failure's reason.
    pub fn job_ended(&self, kind: &str, state: &str, seconds: f64, reason: Option<&str>) {
        let labels = JobEndLabels { kind: kind.into(), state: state.into() };
        self.0.job_seconds.get_or_create(&labels).observe(seconds.max(0.0));
        if let Some(reason) = reason {
            self.0.failures.get_or_create(&ReasonLabels { reason: reason.into() }).inc();
        }
    }

    /// The metrics in Prometheus' text format, the shared gauges read now.
    pub async fn render(&self, state: &crate::AppState) -> Result<String, sqlx::Error> {
        let rows = sqlx::query(
            "SELECT kind, state, COUNT(*) AS n FROM jobs WHERE state IN ('queued', 'running') GROUP BY kind, state",
        )
        .fetch_all(&state.pool)
        .await?;
        for kind in ["build", "benchmark", "seeds"] {
            self.0.queued.get_or_create(&KindLabels { kind: kind.into() }).set(0);
            self.0.running.get_or_create(&KindLabels { kind: kind.into() }).set(0);
        }
        for row in rows {
            let (kind, job_state, n): (String, String, i64) = (row.try_get(0)?, row.try_get(1)?, row.try_get(2)?);
            let family = if job_state == "queued" { &self.0.queued } else { &self.0.running };
            family.get_or_create(&KindLabels { kind }).set(n);
        }
        let now = crate::now_ms();
        let runners = crate::runners::all(&state.pool).await?;
        let healthy = runners.iter().filter(|r| r.healthy(&state.config, now)).count() as i64;
        self.0.runners.get_or_create(&HealthLabels { health: "healthy".into() }).set(healthy);
        self.0.runners.get_or_create(&HealthLabels { health: "silent".into() }).set(runners.len() as i64 - healthy);
        self.copy_git(state.git.activity());
        let mut text = String::new();
        prometheus_client::encoding::text::encode(&mut text, &self.0.registry).map_err(sqlx::Error::decode)?;
        Ok(text)
    }
}

impl Telemetry {
    fn copy_git(&self, git: crate::git::Activity) {
        let _one_at_a_time = self.0.git_copy.lock().unwrap_or_else(|e| e.into_inner());
        for (kind, now, started) in [("serve", git.serving, git.served), ("read", git.reading, git.read)] {
            let labels = KindLabels { kind: kind.into() };
            self.0.git_running.get_or_create(&labels).set(now as i64);
            let counter = self.0.git_started.get_or_create(&labels);
            counter.inc_by(started.saturating_sub(counter.get()));
        }
        self.0.git_refused.inc_by(git.refused.saturating_sub(self.0.git_refused.get()));
    }
}

/// Whether this instance can serve: its database answers and its data
/// directory takes a file. `Err` says what is wrong.
pub async fn ready(state: &crate::AppState) -> Result<(), String> {
    sqlx::query("SELECT 1").fetch_one(&state.pool).await.map_err(|e| format!("the database does not answer: {e}"))?;
    let uploads = state.config.data_dir.join("uploads");
    let probe = uploads.join(format!(".ready-{}", uuid::Uuid::new_v4()));
    tokio::fs::write(&probe, b"")
        .await
        .map_err(|e| format!("the data directory takes no file ({}): {e}", uploads.display()))?;
    let _ = tokio::fs::remove_file(&probe).await;
    Ok(())
}
