//! The runner API: registration, claiming jobs (long poll), and reporting
//! on one job with its job token (heartbeat, log, results, files, end).
//!
//! The messages are `fbksd_exchange::runner_api`'s, which the runner
//! serialises too; that module lists the routes.
//! A job token that is no longer valid (job cancelled, requeued after a
//! lost lease, finished) gets 410: the runner must stop the job.

use super::{JobCaller, RunnerCaller};
use crate::routes::ApiError;
use crate::AppState;
use axum::body::Bytes;
use axum::extract::{Path, Query, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use fbksd_exchange::runner_api::{
    Claim, ClaimRequest, ClaimedJob, Finished, Lease, Outcome, ReferenceRequest, ReferenceStatus, ReferenceTask,
    Registration, RunnerCredentials, StatusReport,
};
use futures_util::StreamExt;
use std::time::{Duration, Instant};
use tokio::io::AsyncWriteExt;

/// `POST /api/v1/runners`.
pub async fn register(
    State(state): State<AppState>,
    Json(body): Json<Registration>,
) -> Result<(StatusCode, Json<RunnerCredentials>), ApiError> {
    let (id, token) =
        crate::runners::register(&state.pool, &body.registration_token, &body.name, &body.machine).await?;
    Ok((StatusCode::CREATED, Json(RunnerCredentials { id, token })))
}

/// `POST /api/v1/runners/status`: a runner says what it prepares (shown on
/// the home page while jobs wait), or that it is ready.
pub async fn status(
    State(state): State<AppState>,
    RunnerCaller(runner_id): RunnerCaller,
    Json(body): Json<StatusReport>,
) -> Result<StatusCode, ApiError> {
    let preparing = body.preparing.map(|p| p.chars().take(300).collect::<String>());
    crate::runners::set_status(&state.pool, &runner_id, preparing.as_deref()).await?;
    if let Some(machine) = &body.machine {
        crate::runners::set_machine(&state.pool, &runner_id, machine).await?;
    }
    Ok(StatusCode::NO_CONTENT)
}

/// `POST /api/v1/runners/jobs`: the next job, waiting up to `wait_seconds`
/// (capped by the server) for one; 204 when none came. Reference jobs of
/// the runner's scenes go first.
pub async fn claim(
    State(state): State<AppState>,
    RunnerCaller(runner_id): RunnerCaller,
    body: Option<Json<ClaimRequest>>,
) -> Result<Response, ApiError> {
    let request = body.map(|b| b.0).unwrap_or_default();
    let wait = request.wait_seconds.min(state.config.long_poll_seconds);
    let deadline = Instant::now() + Duration::from_secs(wait);
    let lease_ms = state.config.lease_seconds as i64 * 1000;
    let (pool, postgres) = (&state.pool, state.postgres);
    let held = if state.config.hold_drifted_runners {
        let waited_ms = state.config.max_drift_hold_minutes as i64 * 60_000;
        crate::runners::held_season(pool, &state.boards, &runner_id)
            .await?
            .map(|season| crate::jobs::Held { season, unless_queued_before_ms: crate::now_ms() - waited_ms })
    } else {
        None
    };
    loop {
        // Expired leases are queued again by the server's sweeper (every second).
        let notified = state.job_queued.notified();
        let mut claimed =
            crate::jobs::claim_reference(pool, postgres, &runner_id, lease_ms, &request.reference_keys).await?;
        if claimed.is_none() && !request.references_only {
            claimed = crate::jobs::claim(pool, postgres, &runner_id, lease_ms, &request, held).await?;
        }
        if let Some(claimed) = claimed {
            let job = claimed.job;
            // A new attempt starts clean: an earlier one's files never count for it.
            crate::pipelines::discard_attempt(&state, &job.id).await?;
            let reference = match &job.reference_key {
                Some(key) => crate::references::status(pool, &state.config.data_dir, key)
                    .await?
                    .map(|s| ReferenceTask { key: s.key, scene: s.scene }),
                None => None,
            };
            return Ok(Json(Claim {
                repository: state.clone_url(&job.project),
                commit: job.commit_sha,
                job: ClaimedJob {
                    id: job.id,
                    project: job.project,
                    kind: job.kind,
                    attempts: job.attempts,
                    season: job.season,
                },
                token: claimed.token,
                lease_seconds: state.config.lease_seconds,
                results_url: state.public_url.clone(),
                reference,
                more_seeds: job.more_seeds,
            })
            .into_response());
        }
        let now = Instant::now();
        if now >= deadline {
            return Ok(StatusCode::NO_CONTENT.into_response());
        }
        // Woken by a job queued here, or polling for jobs queued on other instances.
        let _ = tokio::time::timeout((deadline - now).min(Duration::from_secs(1)), notified).await;
    }
}

/// `POST /api/v1/runners/references`: a runner lacks a reference; where
/// it is on the service (a reference job is queued when none is stored or
/// building).
pub async fn request_reference(
    State(state): State<AppState>,
    RunnerCaller(_): RunnerCaller,
    Json(body): Json<ReferenceRequest>,
) -> Result<Json<ReferenceStatus>, ApiError> {
    Ok(Json(crate::references::request(&state, &body).await?))
}

/// `GET /api/v1/runners/references/{key}/files/{name}`: a stored reference's file.
pub async fn reference_file(
    State(state): State<AppState>,
    RunnerCaller(_): RunnerCaller,
    Path((key, name)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    let path = crate::references::file(&state.pool, &state.config.data_dir, &key, &name).await?;
    let bytes = tokio::fs::read(&path).await.map_err(ApiError::internal)?;
    Ok(([(axum::http::header::CONTENT_TYPE, "application/octet-stream")], bytes).into_response())
}

/// `POST /api/v1/jobs/{id}/heartbeat`: extends the lease.
pub async fn heartbeat(State(state): State<AppState>, job: JobCaller) -> Result<Json<Lease>, ApiError> {
    crate::jobs::heartbeat(&state.pool, &job.job_id, state.config.lease_seconds as i64 * 1000).await?;
    Ok(Json(Lease { lease_seconds: state.config.lease_seconds }))
}

/// `POST /api/v1/jobs/{id}/log`: appends text to the job's log.
pub async fn append_log(State(state): State<AppState>, job: JobCaller, body: Bytes) -> Result<StatusCode, ApiError> {
    let text = String::from_utf8_lossy(&body);
    let max = state.config.max_log_bytes as i64;
    if crate::jobs::append_log(&state.pool, &job.job_id, job.attempt, &text, max).await? {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(ApiError::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "log_too_large",
            format!(
                "the job's log reached its limit of {} bytes: it was kept up to there, send no more",
                state.config.max_log_bytes
            ),
        ))
    }
}

/// Copies a request body to `out` (a staged file, or memory for the
/// results, which are parsed), charging it to the job's upload budget as it
/// comes, a megabyte at a time: a body past the budget is refused when it
/// gets there, not once it is all in memory. The charge is given back
/// unless the caller keeps the upload ([`Charge::keep`]).
async fn receive_charged(
    state: &AppState,
    job_id: &str,
    body: axum::body::Body,
    out: &mut (impl tokio::io::AsyncWrite + Unpin),
) -> Result<Charge, ApiError> {
    let mut charge = Charge { pool: state.pool.clone(), job_id: job_id.to_string(), bytes: 0, kept: false };
    let received = async {
        let mut chunks = body.into_data_stream();
        let mut uncharged = 0usize;
        while let Some(chunk) = chunks.next().await {
            let chunk =
                chunk.map_err(|e| ApiError::bad_request("upload_interrupted", format!("the upload broke off: {e}")))?;
            uncharged += chunk.len();
            if uncharged >= CHARGE_BLOCK {
                charge_upload(state, job_id, uncharged).await?;
                charge.bytes += std::mem::take(&mut uncharged);
            }
            out.write_all(&chunk).await.map_err(ApiError::internal)?;
        }
        charge_upload(state, job_id, uncharged).await?;
        charge.bytes += uncharged;
        Ok::<(), ApiError>(())
    }
    .await;
    match received {
        Ok(()) => Ok(charge),
        Err(e) => {
            charge.give_back().await;
            Err(e)
        }
    }
}

/// What one upload has charged to its job's budget. An upload that is not
/// kept (it broke off, was refused or could not be written) gives it back
/// ([`Charge::give_back`]; dropped without [`Charge::keep`], as when the
/// client hangs up, in the background): a runner that retries a broken
/// upload is not charged twice.
struct Charge {
    pool: sqlx::AnyPool,
    job_id: String,
    bytes: usize,
    kept: bool,
}

impl Charge {
    /// The upload is kept: its charge stands.
    fn keep(mut self) {
        self.kept = true;
    }

    /// The upload is not kept: its charge is given back now (before the
    /// answer, so that a retry finds the budget as it was).
    async fn give_back(mut self) {
        self.kept = true;
        if let Err(e) = crate::jobs::refund_upload(&self.pool, &self.job_id, self.bytes).await {
            tracing::warn!("giving back {} upload bytes to job {}: {e}", self.bytes, self.job_id);
        }
    }
}

impl Drop for Charge {
    fn drop(&mut self) {
        if self.kept || self.bytes == 0 {
            return;
        }
        let (pool, job_id, bytes) = (self.pool.clone(), std::mem::take(&mut self.job_id), self.bytes);
        tokio::spawn(async move {
            if let Err(e) = crate::jobs::refund_upload(&pool, &job_id, bytes).await {
                tracing::warn!("giving back {bytes} upload bytes to job {job_id}: {e}");
            }
        });
    }
}

/// How much of an upload is received before it is charged.
const CHARGE_BLOCK: usize = 1 << 20;

/// Counts `bytes` against the job's upload budget, or refuses them.
async fn charge_upload(state: &AppState, job_id: &str, bytes: usize) -> Result<(), ApiError> {
    if !crate::jobs::charge_upload(&state.pool, job_id, bytes, state.config.max_upload_bytes).await? {
        return Err(ApiError::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "upload_too_large",
            format!("the job's uploads would pass {} bytes", state.config.max_upload_bytes),
        ));
    }
    Ok(())
}

/// `PUT /api/v1/jobs/{id}/files/{*name}`: one file of the result set,
/// streamed to its staging folder and charged to the job's upload budget
/// as it comes (a megabyte at a time), so that no upload is ever held in
/// memory whole: a body past the budget is refused when it gets there, and
/// its part on disk removed.
pub async fn put_file(
    State(state): State<AppState>,
    job: JobCaller,
    Path((_, name)): Path<(String, String)>,
    body: axum::body::Body,
) -> Result<StatusCode, ApiError> {
    crate::results::check_file_name(&name)?;
    let path = crate::results::staging_dir(&state.config.data_dir, &job.job_id).join(&name);
    let parent = path.parent().ok_or_else(|| ApiError::internal("a staged file without a folder"))?;
    tokio::fs::create_dir_all(parent).await.map_err(ApiError::internal)?;
    let partial = tempfile::NamedTempFile::new_in(parent).map_err(ApiError::internal)?;
    let mut file = tokio::fs::File::from_std(partial.reopen().map_err(ApiError::internal)?);
    let charge = receive_charged(&state, &job.job_id, body, &mut file).await?;
    let written = match file.flush().await {
        Ok(()) => partial.persist(&path).map_err(|e| e.error),
        Err(e) => Err(e),
    };
    match written {
        Ok(_) => {
            charge.keep();
            Ok(StatusCode::NO_CONTENT)
        }
        Err(e) => {
            charge.give_back().await;
            Err(ApiError::internal(e))
        }
    }
}

/// `GET /api/v1/jobs/{id}/references/{hash}[?buffer=NAME]`: 204 when the
/// server already holds the pixel file of reference `hash`
/// (`sha256:<hex>`), or of the feature buffer `NAME` made with it; 404
/// when the runner should upload it with the job's files
/// (`references/<hex>.fbpx`, `references/<hex>.<NAME>.fbpx`).
pub async fn has_reference(
    State(state): State<AppState>,
    _job: JobCaller,
    Path((_, hash)): Path<(String, String)>,
    Query(query): Query<ReferenceQuery>,
) -> Result<StatusCode, ApiError> {
    let path = crate::results::reference_pixels(&state.config.data_dir, &hash, query.buffer.as_deref());
    let what = query.buffer.as_ref().map_or(String::new(), |b| format!("{b} buffer of "));
    match path {
        Some(path) if tokio::fs::try_exists(&path).await.unwrap_or(false) => Ok(StatusCode::NO_CONTENT),
        Some(_) => {
            Err(ApiError::new(StatusCode::NOT_FOUND, "not_found", format!("no {what}reference {hash} yet: upload it")))
        }
        None => Err(ApiError::bad_request(
            "invalid_reference",
            format!(
                "{hash:?} is not sha256:<64 hex digits>, or {:?} is not one of {:?}",
                query.buffer.unwrap_or_default(),
                fbksd_exchange::scenes::FEATURE_BUFFERS
            ),
        )),
    }
}

/// The query of [`has_reference`].
#[derive(Debug, serde::Deserialize)]
pub struct ReferenceQuery {
    /// A feature buffer's name, to ask for it instead of the reference.
    buffer: Option<String>,
}

/// `PUT /api/v1/jobs/{id}/results`: the results (checked now; stored
/// when the job reports success).
pub async fn put_results(
    State(state): State<AppState>,
    job: JobCaller,
    body_stream: axum::body::Body,
) -> Result<StatusCode, ApiError> {
    let mut body = Vec::new();
    let charge = receive_charged(&state, &job.job_id, body_stream, &mut body).await?;
    let staged = async {
        let upload: crate::results::Upload = serde_json::from_slice(&body)
            .map_err(|e| ApiError::bad_request("invalid_output", format!("results: {e}")))?;
        let staging = crate::results::staging_dir(&state.config.data_dir, &job.job_id);
        upload.check(&uploaded_files(&staging)).map_err(|e| ApiError::bad_request("invalid_output", e))?;
        crate::references::check_upload(&state.pool, &upload).await?;
        let held = crate::jobs::get(&state.pool, &job.job_id).await?;
        if let Some(seeds) = held.filter(|j| j.kind == crate::jobs::JobKind::Seeds) {
            crate::seeds::check_upload(&state, &seeds, &upload).await?;
        }
        crate::jobs::stage_results(&state.pool, &job.job_id, &String::from_utf8_lossy(&body)).await?;
        Ok::<(), ApiError>(())
    }
    .await;
    match staged {
        Ok(()) => {
            charge.keep();
            Ok(StatusCode::NO_CONTENT)
        }
        Err(e) => {
            charge.give_back().await;
            Err(e)
        }
    }
}

/// Relative paths of the files under `dir`.
fn uploaded_files(dir: &std::path::Path) -> std::collections::BTreeSet<String> {
    fn walk(root: &std::path::Path, dir: &std::path::Path, out: &mut std::collections::BTreeSet<String>) {
        for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
            let path = entry.path();
            if path.is_dir() {
                walk(root, &path, out);
            } else if let Ok(rel) = path.strip_prefix(root) {
                out.insert(rel.to_string_lossy().into_owned());
            }
        }
    }
    let mut out = std::collections::BTreeSet::new();
    walk(dir, dir, &mut out);
    out
}

/// `POST /api/v1/jobs/{id}/finish`: the job ended.
pub async fn finish(
    State(state): State<AppState>,
    job: JobCaller,
    Json(outcome): Json<Outcome>,
) -> Result<Json<Finished>, ApiError> {
    let result_id = crate::pipelines::finish(&state, &job.job_id, job.attempt, outcome).await?;
    let results_url = result_id.as_ref().map(|id| format!("{}/results/{id}", state.public_url));
    Ok(Json(Finished { result_id, results_url }))
}
