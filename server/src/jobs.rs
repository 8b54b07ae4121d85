//! The job queue: states, leases, logs and the per-job tokens runners
//! report with.
//!
//! A job is `queued` until a runner claims it ([`claim`]): the claim sets
//! it `running`, hands out a fresh job token and a lease. The runner
//! heartbeats to extend the lease; when a lease expires ([`expire_leases`])
//! the job is queued again, with a new token, until `max_attempts`, and
//! then fails as an `infrastructure_error`. Claims are safe with many
//! runners and several server instances: on PostgreSQL the claim locks the
//! row with `FOR UPDATE SKIP LOCKED`; on SQLite writers are serialised and
//! the update re-checks the state.

use crate::accounts::User;
use crate::error::ServiceError;
use crate::now_ms;
use crate::projects::Project;
use sqlx::{AnyPool, Row};

/// What a job does and where it is (shared with the runner).
pub use fbksd_exchange::runner_api::{JobKind, JobState};

/// Why a job failed (shared with the runner, which decides it).
pub use fbksd_exchange::FailureReason;

/// A job as pages and the API show it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Job {
    /// Random id.
    pub id: String,
    /// Its pipeline.
    pub pipeline_id: String,
    /// Its project's id.
    pub project_id: String,
    /// Its project's name.
    pub project: String,
    /// Who started the pipeline.
    pub user_id: String,
    /// Build, benchmark, publish, reference or seeds.
    pub kind: JobKind,
    /// Where it is in its life.
    pub state: JobState,
    /// Why it failed.
    pub failure_reason: Option<String>,
    /// What happened, for the user.
    pub message: String,
    /// Attempts so far.
    pub attempts: i64,
    /// Attempts allowed.
    pub max_attempts: i64,
    /// The runner holding or last holding it.
    pub runner_id: Option<String>,
    /// The commit it builds.
    pub commit_sha: String,
    /// The leaderboard season it runs for.
    pub season: i64,
    /// Times, Unix ms.
    pub created_at: i64,
    /// When a runner first claimed it.
    pub started_at: Option<i64>,
    /// When it ended.
    pub finished_at: Option<i64>,
    /// The result set it produced (benchmarks).
    pub result_id: Option<String>,
    /// The reference it makes (reference jobs).
    pub reference_key: Option<String>,
    /// The published result set it adds seeds to (seeds jobs).
    pub more_seeds_of: Option<String>,
    /// The runs it makes again, and their seeds (seeds jobs).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub more_seeds: Vec<MoreSeeds>,
    /// The published result set it measures again (benchmarks of a set
    /// measured off its class's calibration: [`crate::measure_again`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub measures_again: Option<String>,
}

/// A seeds job's run (shared with the runner).
pub use fbksd_exchange::runner_api::MoreSeeds;

impl Job {
    /// The job as a reader who may not see its result set reads it: the
    /// set's id leaves the JSON and the message (see
    /// [`crate::results::private_result_of`]).
    pub fn without_result(mut self) -> Job {
        if let Some(id) = self.result_id.take() {
            self.message = hide_result(&self.message, &id);
        }
        self
    }
}

/// `text` (a job's message or log) with the private result set `id` left out.
pub fn hide_result(text: &str, id: &str) -> String {
    text.replace(id, "<private>")
}

const JOB_COLUMNS: &str = "j.id, j.pipeline_id, j.project_id, p.name AS project_name, j.user_id, j.kind, j.state, \
     j.failure_reason, j.message, j.attempts, j.max_attempts, j.runner_id, pl.commit_sha, j.season, j.created_at, \
     j.started_at, j.finished_at, r.id AS result_id, j.reference_key, j.more_seeds_of, j.more_seeds, j.measures_again";
const JOB_FROM: &str = "jobs j JOIN projects p ON p.id = j.project_id JOIN pipelines pl ON pl.id = j.pipeline_id \
     LEFT JOIN result_sets r ON r.job_id = j.id";

fn job_of(row: &sqlx::any::AnyRow) -> Result<Job, sqlx::Error> {
    Ok(Job {
        id: row.try_get("id")?,
        pipeline_id: row.try_get("pipeline_id")?,
        project_id: row.try_get("project_id")?,
        project: row.try_get("project_name")?,
        user_id: row.try_get("user_id")?,
        kind: kind_of(row)?,
        state: state_of(row)?,
        failure_reason: row.try_get("failure_reason")?,
        message: row.try_get("message")?,
        attempts: row.try_get("attempts")?,
        max_attempts: row.try_get("max_attempts")?,
        runner_id: row.try_get("runner_id")?,
        commit_sha: row.try_get("commit_sha")?,
        season: row.try_get("season")?,
        created_at: row.try_get("created_at")?,
        started_at: row.try_get("started_at")?,
        finished_at: row.try_get("finished_at")?,
        result_id: row.try_get("result_id")?,
        reference_key: row.try_get("reference_key")?,
        more_seeds_of: row.try_get("more_seeds_of")?,
        more_seeds: row
            .try_get::<Option<String>, _>("more_seeds")?
            .map(|json| serde_json::from_str(&json).map_err(|e| sqlx::Error::Decode(Box::new(e))))
            .transpose()?
            .unwrap_or_default(),
        measures_again: row.try_get("measures_again")?,
    })
}

fn kind_of(row: &sqlx::any::AnyRow) -> Result<JobKind, sqlx::Error> {
    let text: String = row.try_get("kind")?;
    JobKind::parse(&text).ok_or_else(|| sqlx::Error::Decode(format!("unknown job kind {text:?}").into()))
}

fn state_of(row: &sqlx::any::AnyRow) -> Result<JobState, sqlx::Error> {
    let text: String = row.try_get("state")?;
    JobState::parse(&text).ok_or_else(|| sqlx::Error::Decode(format!("unknown job state {text:?}").into()))
}

/// The job with id `id`, if any.
pub async fn get(pool: &AnyPool, id: &str) -> Result<Option<Job>, sqlx::Error> {
    let row = sqlx::query(&format!("SELECT {JOB_COLUMNS} FROM {JOB_FROM} WHERE j.id = $1"))
        .bind(id)
        .fetch_optional(pool)
        .await?;
    row.as_ref().map(job_of).transpose()
}

/// A project's jobs, newest first.
pub async fn of_project(pool: &AnyPool, project_id: &str, limit: i64) -> Result<Vec<Job>, sqlx::Error> {
    let rows = sqlx::query(&format!(
        "SELECT {JOB_COLUMNS} FROM {JOB_FROM} WHERE j.project_id = $1 ORDER BY j.created_at DESC, j.id LIMIT $2"
    ))
    .bind(project_id)
    .bind(limit)
    .fetch_all(pool)
    .await?;
    rows.iter().map(job_of).collect()
}

/// Every job, newest first (administration).
pub async fn all(pool: &AnyPool, limit: i64) -> Result<Vec<Job>, sqlx::Error> {
    let rows = sqlx::query(&format!("SELECT {JOB_COLUMNS} FROM {JOB_FROM} ORDER BY j.created_at DESC, j.id LIMIT $1"))
        .bind(limit)
        .fetch_all(pool)
        .await?;
    rows.iter().map(job_of).collect()
}

/// Prefix of job tokens (distinct from personal `fbksd_` and runner `fbksdr_` tokens).
pub const JOB_TOKEN_PREFIX: &str = "fbksdj_";

/// A claimed job: the job and the token its runner reports with.
pub struct Claimed {
    /// The job.
    pub job: Job,
    /// Valid for this attempt only.
    pub token: String,
}

/// The benchmarks a runner is held back from: its season's, but those
/// queued before a time (they have waited long enough).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Held {
    /// The season.
    pub season: i64,
    /// Jobs queued before this (ms since the epoch) are handed anyway.
    pub unless_queued_before_ms: i64,
}

/// Hands a queued build or benchmark job to `runner_id`, if any, fairly
/// between users: a service account's jobs (the baselines) wait while a
/// user's job is queued; then the user with the fewest jobs running goes
/// first, and among those the one whose last job started longest ago
/// (round robin), so one user's hundred queued jobs do not hold back
/// another's one; a user's own jobs go oldest first. Seeds jobs go only
/// to runners that say they take them (`request.more_seeds`).
/// `held`: the benchmarks this runner is not handed now (its calibration
/// has drifted from its class's, [`crate::leaderboard::SeasonData::drift_of`]).
pub async fn claim(
    pool: &AnyPool,
    postgres: bool,
    runner_id: &str,
    lease_ms: i64,
    request: &fbksd_exchange::runner_api::ClaimRequest,
    held: Option<Held>,
) -> Result<Option<Claimed>, sqlx::Error> {
    let runner_class = request.runner_class.as_deref();
    // A season's benchmarks go to runners of the class its times come from
    // (a runner that names none gets them only while the season names none).
    // The held season and time are numbers, never text from a client.
    let pick = format!(
        "SELECT j.id FROM jobs j JOIN users u ON u.id = j.user_id \
         WHERE j.state = 'queued' AND j.kind IN ('build', 'benchmark'{}) \
         AND (j.kind = 'build' OR NOT EXISTS (SELECT 1 FROM seasons s WHERE s.number = j.season \
              AND s.runner_class IS NOT NULL AND s.runner_class <> $5)) \
         AND (j.kind = 'build' OR j.season <> {} OR j.created_at < {}) \
         ORDER BY u.is_service, \
         (SELECT COUNT(*) FROM jobs r WHERE r.user_id = j.user_id AND r.state = 'running'), \
         (SELECT COALESCE(MAX(r.started_at), 0) FROM jobs r WHERE r.user_id = j.user_id), \
         j.created_at, j.id LIMIT 1",
        if request.more_seeds { ", 'seeds'" } else { "" },
        held.map_or(-1, |h| h.season),
        held.map_or(0, |h| h.unless_queued_before_ms),
    );
    claim_picked(pool, postgres, runner_id, lease_ms, &pick, &[runner_class.unwrap_or_default().to_string()]).await
}

/// Hands the oldest queued reference job of one of `keys` (the scenes the
/// runner has) to `runner_id`, if any. Runners ask for these before any
/// other job: every benchmark waits for its references.
pub async fn claim_reference(
    pool: &AnyPool,
    postgres: bool,
    runner_id: &str,
    lease_ms: i64,
    keys: &[String],
) -> Result<Option<Claimed>, sqlx::Error> {
    if keys.is_empty() {
        return Ok(None);
    }
    // $1..$4 are the claim's own parameters.
    let list = (0..keys.len()).map(|i| format!("${}", i + 5)).collect::<Vec<_>>().join(", ");
    let pick = format!(
        "SELECT j.id FROM jobs j WHERE j.state = 'queued' AND j.kind = 'reference' \
         AND j.reference_key IN ({list}) ORDER BY j.created_at, j.id LIMIT 1"
    );
    claim_picked(pool, postgres, runner_id, lease_ms, &pick, keys).await
}

/// Sets the job `pick` selects (a query of one `j.id`, whose parameters
/// `extra` follow the claim's four) running for `runner_id`, with a new
/// token and lease.
async fn claim_picked(
    pool: &AnyPool,
    postgres: bool,
    runner_id: &str,
    lease_ms: i64,
    pick: &str,
    extra: &[String],
) -> Result<Option<Claimed>, sqlx::Error> {
    let token = format!("{JOB_TOKEN_PREFIX}{}", crate::accounts::random_token());
    let now = now_ms();
    let lock = if postgres { " FOR UPDATE OF j SKIP LOCKED" } else { "" };
    let sql = format!(
        "UPDATE jobs SET state = 'running', runner_id = $1, token_hash = $2, lease_expires_at = $3, \
         attempts = attempts + 1, started_at = COALESCE(started_at, $4), attempt_started_at = $4 \
         WHERE state = 'queued' AND id = ({pick}{lock}) RETURNING id"
    );
    let mut query =
        sqlx::query(&sql).bind(runner_id).bind(crate::accounts::digest(&token)).bind(now + lease_ms).bind(now);
    for value in extra {
        query = query.bind(value);
    }
    let row = query.fetch_optional(pool).await?;
    let Some(row) = row else { return Ok(None) };
    let id: String = row.try_get("id")?;
    let job = get(pool, &id).await?.ok_or(sqlx::Error::RowNotFound)?;
    append_log(
        pool,
        &id,
        job.attempts,
        &format!("[fbksd] attempt {} of {}: runner {runner_id}\n", job.attempts, job.max_attempts),
        i64::MAX,
    )
    .await?;
    Ok(Some(Claimed { job, token }))
}

/// The job a job token belongs to: (job id, its state, attempt).
pub async fn token_job(pool: &AnyPool, token: &str) -> Result<Option<(String, JobState, i64)>, sqlx::Error> {
    if !token.starts_with(JOB_TOKEN_PREFIX) {
        return Ok(None);
    }
    let row = sqlx::query("SELECT id, state, attempts FROM jobs WHERE token_hash = $1")
        .bind(crate::accounts::digest(token))
        .fetch_optional(pool)
        .await?;
    row.map(|r| Ok((r.try_get("id")?, state_of(&r)?, r.try_get("attempts")?))).transpose()
}

/// Extends a running job's lease, and records that its runner reported.
pub async fn heartbeat(pool: &AnyPool, job_id: &str, lease_ms: i64) -> Result<(), sqlx::Error> {
    let now = now_ms();
    sqlx::query("UPDATE jobs SET lease_expires_at = $1 WHERE id = $2 AND state = 'running'")
        .bind(now + lease_ms)
        .bind(job_id)
        .execute(pool)
        .await?;
    // A runner busy with a long job asks for no other: its job's heartbeats
    // are what say it is connected (else the home page would say no runner
    // is, minutes into every benchmark).
    sqlx::query(
        "UPDATE runners SET last_seen_at = $1 \
         WHERE id = (SELECT runner_id FROM jobs WHERE id = $2 AND state = 'running')",
    )
    .bind(now)
    .bind(job_id)
    .execute(pool)
    .await?;
    Ok(())
}

/// Appends to a job's log, keeping it within `max_bytes`: text that would
/// pass the limit is cut there and ends with a line saying so, and once the
/// log is full nothing more of the runner's is kept. Returns whether all of
/// `text` was kept (the runner stops sending when not).
pub async fn append_log(
    pool: &AnyPool,
    job_id: &str,
    attempt: i64,
    text: &str,
    max_bytes: i64,
) -> Result<bool, sqlx::Error> {
    let mut tx = pool.begin().await?;
    let Some(row) =
        sqlx::query("SELECT log_bytes FROM jobs WHERE id = $1").bind(job_id).fetch_optional(&mut *tx).await?
    else {
        return Ok(false);
    };
    let used: i64 = row.try_get("log_bytes")?;
    let room = max_bytes.saturating_sub(used);
    let marker = format!("\n[fbksd] the log reached its limit of {max_bytes} bytes: later output is left out\n");
    let (kept, all) = if text.len() as i64 <= room {
        (std::borrow::Cow::Borrowed(text), true)
    } else if room <= marker.len() as i64 {
        return Ok(false);
    } else {
        let mut end = (room as usize - marker.len()).min(text.len());
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        (std::borrow::Cow::Owned(format!("{}{marker}", &text[..end])), false)
    };
    // A cut log is full: the next batch of the runner's is refused at once.
    let grown = if all { used + kept.len() as i64 } else { max_bytes };
    sqlx::query("UPDATE jobs SET log_bytes = $1 WHERE id = $2").bind(grown).bind(job_id).execute(&mut *tx).await?;
    let next = sqlx::query("SELECT COALESCE(MAX(seq), 0) + 1 AS next FROM job_logs WHERE job_id = $1")
        .bind(job_id)
        .fetch_one(&mut *tx)
        .await?;
    sqlx::query("INSERT INTO job_logs (job_id, seq, attempt, content, created_at) VALUES ($1, $2, $3, $4, $5)")
        .bind(job_id)
        .bind(next.try_get::<i64, _>("next")?)
        .bind(attempt)
        .bind(kept.as_ref())
        .bind(now_ms())
        .execute(&mut *tx)
        .await?;
    tx.commit().await?;
    Ok(all)
}

/// A job's log chunks after `after` (a sequence number): (seq, text).
pub async fn log_since(pool: &AnyPool, job_id: &str, after: i64) -> Result<Vec<(i64, String)>, sqlx::Error> {
    let rows = sqlx::query("SELECT seq, content FROM job_logs WHERE job_id = $1 AND seq > $2 ORDER BY seq")
        .bind(job_id)
        .bind(after)
        .fetch_all(pool)
        .await?;
    rows.iter().map(|r| Ok((r.try_get("seq")?, r.try_get("content")?))).collect()
}

/// Queues again, or fails, every running job whose lease has expired;
/// returns how many were touched.
pub async fn expire_leases(pool: &AnyPool) -> Result<usize, sqlx::Error> {
    let now = now_ms();
    let rows = sqlx::query(
        "SELECT id, attempts, max_attempts, runner_id FROM jobs WHERE state = 'running' AND lease_expires_at < $1",
    )
    .bind(now)
    .fetch_all(pool)
    .await?;
    let mut touched = 0;
    for row in rows {
        let id: String = row.try_get("id")?;
        let attempts: i64 = row.try_get("attempts")?;
        let max: i64 = row.try_get("max_attempts")?;
        let runner: Option<String> = row.try_get("runner_id")?;
        let runner = runner.unwrap_or_default();
        // Conditional on the lease still being expired: another server instance may have done it.
        let (sql, note) = if attempts < max {
            (
                "UPDATE jobs SET state = 'queued', token_hash = NULL, lease_expires_at = NULL \
                 WHERE id = $1 AND state = 'running' AND lease_expires_at < $2",
                format!("[fbksd] runner {runner} stopped reporting (lease expired): the job is queued again\n"),
            )
        } else {
            (
                "UPDATE jobs SET state = 'failed', failure_reason = 'infrastructure_error', token_hash = NULL, \
                 lease_expires_at = NULL, counts_for_quota = 0, finished_at = $2, \
                 message = 'runners stopped reporting on this job too many times; it does not count against your quota: run it again' \
                 WHERE id = $1 AND state = 'running' AND lease_expires_at < $2",
                format!("[fbksd] runner {runner} stopped reporting (lease expired) on the last attempt: the job failed\n"),
            )
        };
        let done = sqlx::query(sql).bind(&id).bind(now).execute(pool).await?;
        if done.rows_affected() > 0 {
            append_log(pool, &id, attempts, &note, i64::MAX).await?;
            touched += 1;
        }
    }
    Ok(touched)
}

/// Fails every running job whose attempt started more than `max_ms` ago,
/// as a timeout, however its runner heart-beats: its token stops working,
/// so the runner is told to stop at its next report. The runner bounds
/// every build and run itself, so an attempt this long is the runner's
/// doing more likely than the technique's: it does not count against the
/// owner's quota. Returns how many.
pub async fn stop_overdue(pool: &AnyPool, max_ms: i64) -> Result<usize, sqlx::Error> {
    let now = now_ms();
    let rows = sqlx::query("SELECT id, attempts FROM jobs WHERE state = 'running' AND attempt_started_at < $1")
        .bind(now - max_ms)
        .fetch_all(pool)
        .await?;
    let limit = match max_ms / 1000 {
        s if s >= 3600 && s % 3600 == 0 => format!("{} h", s / 3600),
        s => format!("{s} s"),
    };
    let message = format!(
        "the job ran past the service's limit of {limit} per attempt (max_job_seconds); \
         it does not count against your quota"
    );
    let mut stopped = 0;
    for row in rows {
        let (id, attempts): (String, i64) = (row.try_get("id")?, row.try_get("attempts")?);
        let done = sqlx::query(
            "UPDATE jobs SET state = 'failed', failure_reason = 'timeout', token_hash = NULL, \
             lease_expires_at = NULL, counts_for_quota = 0, finished_at = $1, message = $2 \
             WHERE id = $3 AND state = 'running' AND attempt_started_at < $4",
        )
        .bind(now)
        .bind(&message)
        .bind(&id)
        .bind(now - max_ms)
        .execute(pool)
        .await?;
        if done.rows_affected() > 0 {
            append_log(pool, &id, attempts, &format!("[fbksd] {message}: stopped\n"), i64::MAX).await?;
            stopped += 1;
        }
    }
    Ok(stopped)
}

/// Cancels a queued or running job; a job cancelled before it started does
/// not count against the quota.
pub async fn cancel(pool: &AnyPool, job_id: &str, by: &str) -> Result<(), ServiceError> {
    let done = sqlx::query(
        "UPDATE jobs SET state = 'cancelled', token_hash = NULL, lease_expires_at = NULL, finished_at = $1, \
         message = $2, counts_for_quota = CASE WHEN started_at IS NULL THEN 0 ELSE counts_for_quota END \
         WHERE id = $3 AND state IN ('queued', 'running')",
    )
    .bind(now_ms())
    .bind(format!("cancelled by {by}"))
    .bind(job_id)
    .execute(pool)
    .await?;
    if done.rows_affected() == 0 {
        return Err(ServiceError::conflict("job_finished", "the job has already ended"));
    }
    append_log(pool, job_id, 0, &format!("[fbksd] cancelled by {by}\n"), i64::MAX).await?;
    Ok(())
}

/// Queues a job again (administration): a new attempt budget, a new token.
pub async fn requeue(pool: &AnyPool, job_id: &str, by: &str) -> Result<(), ServiceError> {
    let done = sqlx::query(
        "UPDATE jobs SET state = 'queued', token_hash = NULL, lease_expires_at = NULL, finished_at = NULL, \
         failure_reason = NULL, message = '', attempts = 0, staged_results = NULL, upload_bytes = 0 \
         WHERE id = $1 AND kind <> 'publish' AND NOT EXISTS (SELECT 1 FROM result_sets r WHERE r.job_id = $1)",
    )
    .bind(job_id)
    .execute(pool)
    .await?;
    if done.rows_affected() == 0 {
        return Err(ServiceError::conflict(
            "not_requeueable",
            "this job cannot be queued again (it published or produced a result set)",
        ));
    }
    append_log(pool, job_id, 0, &format!("[fbksd] queued again by {by}\n"), i64::MAX).await?;
    Ok(())
}

/// A job to create, in the state its pipeline decided.
pub struct NewJob<'a> {
    /// Random id.
    pub id: &'a str,
    /// Its pipeline.
    pub pipeline_id: &'a str,
    /// Its project.
    pub project_id: &'a str,
    /// Who started it.
    pub user_id: &'a str,
    /// What it does.
    pub kind: JobKind,
    /// Queued, or already ended (failed checks, over quota, a publish).
    pub state: JobState,
    /// Why it failed, if it did.
    pub failure_reason: Option<FailureReason>,
    /// What happened, for the user.
    pub message: &'a str,
    /// Attempts allowed.
    pub max_attempts: i64,
    /// The season it runs for.
    pub season: i64,
    /// Publish the result set when it succeeds (season re-runs, and sets
    /// measured again).
    pub publish_on_success: bool,
    /// Whether it uses up one of the day's runs.
    pub counts_for_quota: bool,
    /// When it ended, if it already has.
    pub finished_at: Option<i64>,
    /// The reference it makes (reference jobs).
    pub reference_key: Option<&'a str>,
    /// The published set it adds seeds to, and the runs (seeds jobs).
    pub more_seeds: Option<(&'a str, &'a [MoreSeeds])>,
    /// The published set it measures again (benchmarks).
    pub measures_again: Option<&'a str>,
}

/// Creates a job in its pipeline's transaction.
pub async fn insert(tx: &mut sqlx::Transaction<'_, sqlx::Any>, new: &NewJob<'_>) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO jobs (id, pipeline_id, project_id, user_id, kind, state, failure_reason, message, attempts, \
         max_attempts, season, publish_on_success, counts_for_quota, log_bytes, upload_bytes, created_at, finished_at, \
         reference_key, more_seeds_of, more_seeds, measures_again) \
         VALUES ($1, $2, $3, $4, $5, $6, $7, $8, 0, $9, $10, $11, $12, 0, 0, $13, $14, $15, $16, $17, $18)",
    )
    .bind(new.id)
    .bind(new.pipeline_id)
    .bind(new.project_id)
    .bind(new.user_id)
    .bind(new.kind.as_str())
    .bind(new.state.as_str())
    .bind(new.failure_reason.map(FailureReason::as_str))
    .bind(new.message)
    .bind(new.max_attempts)
    .bind(new.season)
    .bind(new.publish_on_success as i64)
    .bind(new.counts_for_quota as i64)
    .bind(now_ms())
    .bind(new.finished_at)
    .bind(new.reference_key)
    .bind(new.more_seeds.map(|(set, _)| set))
    .bind(new.more_seeds.map(|(_, runs)| serde_json::to_string(runs).unwrap_or_default()))
    .bind(new.measures_again)
    .execute(&mut **tx)
    .await?;
    Ok(())
}

/// Puts a running job back in the queue (an infrastructure error: not the
/// author's fault), dropping its token and anything it staged.
pub async fn queue_again(pool: &AnyPool, job_id: &str) -> Result<(), sqlx::Error> {
    sqlx::query(
        "UPDATE jobs SET state = 'queued', token_hash = NULL, lease_expires_at = NULL, staged_results = NULL, \
         upload_bytes = 0 WHERE id = $1 AND state = 'running'",
    )
    .bind(job_id)
    .execute(pool)
    .await?;
    Ok(())
}

/// Ends a running job in `state` (and logs it); `counts_for_quota` false
/// gives the author's run back.
pub async fn end(
    pool: &AnyPool,
    job_id: &str,
    state: JobState,
    reason: Option<FailureReason>,
    message: &str,
    counts_for_quota: bool,
) -> Result<(), sqlx::Error> {
    sqlx::query(
        "UPDATE jobs SET state = $1, failure_reason = $2, message = $3, finished_at = $4, token_hash = NULL, \
         lease_expires_at = NULL, counts_for_quota = CASE WHEN $5 = 1 THEN counts_for_quota ELSE 0 END \
         WHERE id = $6 AND state = 'running'",
    )
    .bind(state.as_str())
    .bind(reason.map(FailureReason::as_str))
    .bind(message)
    .bind(now_ms())
    .bind(counts_for_quota as i64)
    .bind(job_id)
    .execute(pool)
    .await?;
    let line = match reason {
        Some(r) => format!("[fbksd] failed ({}): {message}\n", r.as_str()),
        None => format!("[fbksd] {state}\n"),
    };
    append_log(pool, job_id, 0, &line, i64::MAX).await?;
    Ok(())
}

/// Counts `bytes` against a job's upload budget of `max` bytes; false (and
/// nothing counted) when they would pass it.
pub async fn charge_upload(pool: &AnyPool, job_id: &str, bytes: usize, max: u64) -> Result<bool, sqlx::Error> {
    let done =
        sqlx::query("UPDATE jobs SET upload_bytes = upload_bytes + $1 WHERE id = $2 AND upload_bytes + $1 <= $3")
            .bind(bytes as i64)
            .bind(job_id)
            .bind(max as i64)
            .execute(pool)
            .await?;
    Ok(done.rows_affected() > 0)
}

/// Gives back `bytes` charged to a job's upload budget by an upload that
/// was not kept (it broke off, or was refused).
pub async fn refund_upload(pool: &AnyPool, job_id: &str, bytes: usize) -> Result<(), sqlx::Error> {
    sqlx::query("UPDATE jobs SET upload_bytes = upload_bytes - $1 WHERE id = $2 AND upload_bytes >= $1")
        .bind(bytes as i64)
        .bind(job_id)
        .execute(pool)
        .await?;
    Ok(())
}

/// Keeps a job's checked results upload until the job reports success.
pub async fn stage_results(pool: &AnyPool, job_id: &str, upload: &str) -> Result<(), sqlx::Error> {
    sqlx::query("UPDATE jobs SET staged_results = $1 WHERE id = $2").bind(upload).bind(job_id).execute(pool).await?;
    Ok(())
}

/// A job's staged results upload, and whether it publishes on success.
pub async fn staged_results(pool: &AnyPool, job_id: &str) -> Result<(Option<String>, bool), sqlx::Error> {
    let row = sqlx::query("SELECT staged_results, publish_on_success FROM jobs WHERE id = $1")
        .bind(job_id)
        .fetch_one(pool)
        .await?;
    Ok((row.try_get("staged_results")?, row.try_get::<i64, _>("publish_on_success")? != 0))
}

/// Ends a running benchmark with its result set, in the transaction that
/// stores the set; false when the job is no longer running.
pub async fn succeed_with_results(
    tx: &mut sqlx::Transaction<'_, sqlx::Any>,
    job_id: &str,
    result_id: &str,
) -> Result<bool, sqlx::Error> {
    succeed_in(tx, job_id, &format!("results: /results/{result_id}")).await
}

/// Ends running job `job_id` as succeeded with `message` inside `tx`, with
/// what it stored; false if it was no longer running.
pub async fn succeed_in(
    tx: &mut sqlx::Transaction<'_, sqlx::Any>,
    job_id: &str,
    message: &str,
) -> Result<bool, sqlx::Error> {
    let ended = sqlx::query(
        "UPDATE jobs SET state = 'succeeded', finished_at = $1, token_hash = NULL, lease_expires_at = NULL, \
         staged_results = NULL, message = $2 WHERE id = $3 AND state = 'running'",
    )
    .bind(now_ms())
    .bind(message)
    .bind(job_id)
    .execute(&mut **tx)
    .await?;
    Ok(ended.rows_affected() > 0)
}

/// The id a running job's result set will have: chosen on the first call
/// and kept, so every retry of storing it agrees on where its files go.
pub async fn pending_result_id(pool: &AnyPool, job_id: &str) -> Result<String, sqlx::Error> {
    sqlx::query("UPDATE jobs SET result_pending = $1 WHERE id = $2 AND result_pending IS NULL")
        .bind(uuid::Uuid::new_v4().to_string())
        .bind(job_id)
        .execute(pool)
        .await?;
    sqlx::query("SELECT result_pending FROM jobs WHERE id = $1").bind(job_id).fetch_one(pool).await?.try_get(0)
}

/// Forgets a job's pending result id (its attempt ended without a set);
/// returns it, if there was one.
pub async fn take_pending_result_id(pool: &AnyPool, job_id: &str) -> Result<Option<String>, sqlx::Error> {
    let row = sqlx::query("SELECT result_pending FROM jobs WHERE id = $1 AND state <> 'succeeded'")
        .bind(job_id)
        .fetch_optional(pool)
        .await?;
    let pending: Option<String> = row.map(|r| r.try_get(0)).transpose()?.flatten();
    if pending.is_some() {
        sqlx::query("UPDATE jobs SET result_pending = NULL WHERE id = $1").bind(job_id).execute(pool).await?;
    }
    Ok(pending)
}

/// The ids of the jobs a runner holds now.
pub async fn running_ids(pool: &AnyPool) -> Result<std::collections::HashSet<String>, sqlx::Error> {
    let rows = sqlx::query("SELECT id FROM jobs WHERE state = 'running'").fetch_all(pool).await?;
    rows.iter().map(|r| r.try_get(0)).collect()
}

/// Ends the leases of a removed runner's running jobs, so the sweeper
/// queues them again at once.
pub async fn drop_leases_of(pool: &AnyPool, runner_id: &str) -> Result<(), sqlx::Error> {
    sqlx::query("UPDATE jobs SET lease_expires_at = 0 WHERE runner_id = $1 AND state = 'running'")
        .bind(runner_id)
        .execute(pool)
        .await?;
    Ok(())
}

/// The job `id` and its project if `user` can read the project; not found
/// otherwise (and for an invalid id), so private jobs stay invisible.
pub async fn readable(pool: &AnyPool, id: &str, user: Option<&User>) -> Result<(Job, Project), ServiceError> {
    let not_found = || ServiceError::not_found(format!("no job {id:?} that you can see"));
    let job = get(pool, id).await?.ok_or_else(not_found)?;
    let project = crate::projects::by_id(pool, &job.project_id).await?.ok_or_else(not_found)?;
    if !project.readable_by(user) {
        return Err(not_found());
    }
    Ok((job, project))
}

/// Cancels job `id` if `user` owns its project or is an administrator.
pub async fn cancel_as(pool: &AnyPool, id: &str, user: &User) -> Result<(), ServiceError> {
    let (job, project) = readable(pool, id, Some(user)).await?;
    if !(project.writable_by(user) || user.is_admin) {
        return Err(ServiceError::forbidden(
            "not_owner",
            "only the project's owner or an administrator can cancel its jobs",
        ));
    }
    cancel(pool, &job.id, &user.email).await
}

/// Queued jobs of a user.
pub async fn queued_count(pool: &AnyPool, user_id: &str) -> Result<i64, sqlx::Error> {
    // Seeds jobs are the server's asking, not the user's: they hold no place.
    let row = sqlx::query("SELECT COUNT(*) AS n FROM jobs WHERE user_id = $1 AND state = 'queued' AND kind <> 'seeds'")
        .bind(user_id)
        .fetch_one(pool)
        .await?;
    row.try_get("n")
}

/// Jobs of `kind` (benchmark runs, or builds) of a user in the last 24
/// hours that count for the quota.
pub async fn counted_today(pool: &AnyPool, user_id: &str, kind: JobKind) -> Result<i64, sqlx::Error> {
    let row = sqlx::query(
        "SELECT COUNT(*) AS n FROM jobs WHERE user_id = $1 AND kind = $2 AND counts_for_quota = 1 \
         AND created_at > $3",
    )
    .bind(user_id)
    .bind(kind.as_str())
    .bind(now_ms() - 24 * 3600 * 1000)
    .fetch_one(pool)
    .await?;
    row.try_get("n")
}
