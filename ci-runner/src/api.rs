//! The server's runner API, as a runner sees it.
//!
//! Every call that carries a job's outcome (log, files, results, finish)
//! is retried across connection failures and 5xx answers for
//! [`JOB_PATIENCE`], so a server restarted mid-job loses nothing: the job's
//! token lives in the server's database and is valid again once it is back.
//! A 410 means the job is no longer this runner's (cancelled, finished, or
//! requeued after a lost lease): the runner stops working on it.

use fbksd_exchange::runner_api::{
    Claim, ClaimRequest, Finished, Outcome, ReferenceRequest, ReferenceStatus, Registration, RunnerCredentials,
    StatusReport, Upload,
};
use std::time::Duration;

/// How long a job's calls keep trying while the server is unreachable.
pub const JOB_PATIENCE: Duration = Duration::from_secs(15 * 60);

/// Why a call failed.
#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    /// HTTP 410: the job is no longer this runner's.
    #[error("the server no longer holds this job for this runner (cancelled, finished, or its lease was lost)")]
    JobGone,
    /// A 4xx answer other than 410.
    #[error("the server refused {what} (HTTP {status}): {body}")]
    Refused {
        /// What was asked.
        what: String,
        /// HTTP status.
        status: u16,
        /// The server's explanation.
        body: String,
    },
    /// No usable answer within the patience.
    #[error("the server did not answer {what} within {patience:?}: {last}")]
    Unreachable {
        /// What was asked.
        what: String,
        /// How long it kept trying.
        patience: Duration,
        /// The last error.
        last: String,
    },
}

/// The server's runner API.
#[derive(Debug, Clone)]
pub struct Api {
    http: reqwest::Client,
    base: String,
}

impl Api {
    /// A client of the server at `base` (e.g. `http://127.0.0.1:8096`).
    pub fn new(base: &str) -> Api {
        let http = reqwest::Client::builder()
            .connect_timeout(Duration::from_secs(10))
            .build()
            .expect("a reqwest client with default TLS");
        Api { http, base: base.trim_end_matches('/').to_string() }
    }

    fn url(&self, path: &str) -> String {
        format!("{}/api/v1/{path}", self.base)
    }

    /// Sends the request `build` makes, retrying connection failures and
    /// 5xx answers for `patience`.
    async fn send(
        &self,
        what: &str,
        patience: Duration,
        build: impl Fn() -> reqwest::RequestBuilder,
    ) -> Result<reqwest::Response, ApiError> {
        let deadline = tokio::time::Instant::now() + patience;
        let mut pause = Duration::from_millis(250);
        loop {
            let last = match build().timeout(Duration::from_secs(120)).send().await {
                Ok(r) if r.status() == reqwest::StatusCode::GONE => return Err(ApiError::JobGone),
                Ok(r) if r.status().is_client_error() => {
                    let status = r.status().as_u16();
                    let body = r.text().await.unwrap_or_default();
                    return Err(ApiError::Refused { what: what.into(), status, body });
                }
                Ok(r) if r.status().is_server_error() => format!("HTTP {}", r.status()),
                Ok(r) => return Ok(r),
                Err(e) => format!("{e}"),
            };
            if tokio::time::Instant::now() + pause > deadline {
                return Err(ApiError::Unreachable { what: what.into(), patience, last });
            }
            tracing::warn!("{what}: {last}; trying again in {pause:?}");
            tokio::time::sleep(pause).await;
            pause = (pause * 2).min(Duration::from_secs(5));
        }
    }

    /// Registers a runner with the server's registration token.
    pub async fn register(
        &self,
        registration_token: &str,
        name: &str,
        machine: &serde_json::Value,
    ) -> Result<RunnerCredentials, ApiError> {
        let body =
            Registration { registration_token: registration_token.into(), name: name.into(), machine: machine.clone() };
        let response =
            self.send("registration", JOB_PATIENCE, || self.http.post(self.url("runners")).json(&body)).await?;
        response.json().await.map_err(|e| unreadable("registration", e))
    }

    /// Asks for a job as `request` says; `None` when none came.
    pub async fn claim(&self, runner_token: &str, request: &ClaimRequest) -> Result<Option<Claim>, ApiError> {
        let response = self
            .send("a claim", Duration::from_secs(30), || {
                self.http.post(self.url("runners/jobs")).bearer_auth(runner_token).json(request)
            })
            .await?;
        if response.status() == reqwest::StatusCode::NO_CONTENT {
            return Ok(None);
        }
        response.json().await.map(Some).map_err(|e| unreadable("a claim", e))
    }

    /// Asks for a reference this runner lacks: where it is on the service
    /// (asking queues a reference job when none is stored or building).
    pub async fn request_reference(
        &self,
        runner_token: &str,
        request: &ReferenceRequest,
    ) -> Result<ReferenceStatus, ApiError> {
        let what = format!("the reference of {}", request.scene);
        let response = self
            .send(&what, JOB_PATIENCE, || {
                self.http.post(self.url("runners/references")).bearer_auth(runner_token).json(request)
            })
            .await?;
        response.json().await.map_err(|e| unreadable(&what, e))
    }

    /// Downloads the file `name` of the stored reference `key`.
    pub async fn reference_file(&self, runner_token: &str, key: &str, name: &str) -> Result<Vec<u8>, ApiError> {
        let what = format!("{name} of reference {key}");
        let response = self
            .send(&what, JOB_PATIENCE, || {
                self.http.get(self.url(&format!("runners/references/{key}/files/{name}"))).bearer_auth(runner_token)
            })
            .await?;
        Ok(response.bytes().await.map_err(|e| unreadable(&what, e))?.to_vec())
    }

    /// Says what the runner prepares before it takes jobs (`None`: ready);
    /// shown on the server's home page.
    pub async fn status(&self, runner_token: &str, preparing: Option<&str>) -> Result<(), ApiError> {
        self.report(runner_token, StatusReport { preparing: preparing.map(str::to_string), machine: None }).await
    }

    /// Tells the server this runner is ready, and what its machine is now.
    pub async fn ready(&self, runner_token: &str, machine: &serde_json::Value) -> Result<(), ApiError> {
        self.report(runner_token, StatusReport { preparing: None, machine: Some(machine.clone()) }).await
    }

    async fn report(&self, runner_token: &str, body: StatusReport) -> Result<(), ApiError> {
        self.send("a status report", Duration::from_secs(30), || {
            self.http.post(self.url("runners/status")).bearer_auth(runner_token).json(&body)
        })
        .await
        .map(drop)
    }

    /// Extends a job's lease (one attempt: heartbeats repeat anyway).
    pub async fn heartbeat(&self, job: &Claim) -> Result<(), ApiError> {
        self.send("a heartbeat", Duration::ZERO, || self.job_request(job, reqwest::Method::POST, "heartbeat"))
            .await
            .map(drop)
    }

    /// Appends text to a job's log.
    pub async fn log(&self, job: &Claim, text: &str) -> Result<(), ApiError> {
        let text = text.to_string();
        self.send("a log", JOB_PATIENCE, || self.job_request(job, reqwest::Method::POST, "log").body(text.clone()))
            .await
            .map(drop)
    }

    /// Uploads one result file.
    pub async fn put_file(&self, job: &Claim, name: &str, bytes: Vec<u8>) -> Result<(), ApiError> {
        let what = format!("the file {name}");
        self.send(&what, JOB_PATIENCE, || {
            self.job_request(job, reqwest::Method::PUT, &format!("files/{name}")).body(bytes.clone())
        })
        .await
        .map(drop)
    }

    /// Whether the server already holds the viewer's pixels of reference
    /// `hash`; when not, they go with the job's files.
    pub async fn has_reference(&self, job: &Claim, hash: &str, buffer: Option<&str>) -> Result<bool, ApiError> {
        let what = format!("reference {hash}{}", buffer.map(|b| format!(" ({b} buffer)")).unwrap_or_default());
        let path = match buffer {
            None => format!("references/{hash}"),
            Some(b) => format!("references/{hash}?buffer={b}"),
        };
        match self.send(&what, JOB_PATIENCE, || self.job_request(job, reqwest::Method::GET, &path)).await {
            Ok(_) => Ok(true),
            Err(ApiError::Refused { status: 404, .. }) => Ok(false),
            Err(e) => Err(e),
        }
    }

    /// Uploads the results (runs, metrics, scenes, provenance).
    pub async fn put_results(&self, job: &Claim, upload: &Upload) -> Result<(), ApiError> {
        self.send("the results", JOB_PATIENCE, || self.job_request(job, reqwest::Method::PUT, "results").json(upload))
            .await
            .map(drop)
    }

    /// Ends the job; returns the private results URL of a benchmark's result set.
    pub async fn finish(&self, job: &Claim, outcome: &Outcome) -> Result<Option<String>, ApiError> {
        let response = self
            .send("the job's end", JOB_PATIENCE, || {
                self.job_request(job, reqwest::Method::POST, "finish").json(outcome)
            })
            .await?;
        let body: Finished = response.json().await.map_err(|e| unreadable("the job's end", e))?;
        Ok(body.results_url)
    }

    fn job_request(&self, job: &Claim, method: reqwest::Method, what: &str) -> reqwest::RequestBuilder {
        self.http.request(method, self.url(&format!("jobs/{}/{what}", job.job.id))).bearer_auth(&job.token)
    }
}

fn unreadable(what: &str, e: reqwest::Error) -> ApiError {
    ApiError::Refused { what: what.into(), status: 200, body: format!("unreadable answer: {e}") }
}
