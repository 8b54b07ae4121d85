//! Pipelines: what a push, a form or an API call asks for at one commit,
//! and the jobs that do it.
//!
//! - no variable: a `build` job (every push);
//! - `FBKSD_RUN`: a `benchmark` job, which builds and then benchmarks;
//! - `FBKSD_PUBLISH=<uuid>`: publishes one of the owner's result sets, at
//!   once, as a `publish` job the server does itself.
//!
//! The same rules hold for push options (checked by the repositories'
//! `pre-receive` hook, whose script is written here: [`pre_receive_hook`])
//! and for the variables of the API and the pages ([`Request::parse`]).
//!
//! The sanity checks of the repository (info.json schema, build file,
//! environment) run here, at once, so a broken repository fails in a
//! second with the problem named, without waiting for a runner: as a
//! failed job, whichever way the pipeline was asked for, e-mailed to the
//! author.

use crate::accounts::User;
use crate::error::ServiceError;
use crate::jobs::{FailureReason, JobKind, JobState};
use crate::projects::Project;
use crate::{now_ms, AppState};
use fbksd_exchange::technique::TechniqueInfo;

/// What a pipeline's variables ask for.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// Build only.
    Build,
    /// Build and benchmark.
    Run,
    /// Publish this result set.
    Publish(uuid::Uuid),
}

/// The options the server knows, as the refusals name them.
const KNOWN: &str = "the server knows FBKSD_RUN (build and benchmark) and FBKSD_PUBLISH=<uuid> (publish a result)";

/// Why a pipeline cannot carry both requests.
const ONE_REQUEST: &str = "FBKSD_RUN and FBKSD_PUBLISH cannot be combined (nor given twice): \
                           run first, then publish the result's UUID with a later push or from its results page";

/// What FBKSD_PUBLISH needs, before the value that is not that.
const PUBLISH_NEEDS: &str = "FBKSD_PUBLISH needs the UUID of one of your results (the key in its /results/<uuid> URL)";

/// The `pre-receive` hook of every repository: the rules of
/// [`Request::parse`] for push options, and the account's repository
/// quota ([`crate::git::RepositoryQuota`]), refusing a push before anything
/// is written. Its lines reach the pusher as `remote:` lines.
pub fn pre_receive_hook() -> String {
    use crate::projects::DELETE_OR_ASK;
    format!(
        r#"#!/bin/sh
# FBKSD: check the push options before anything is written (the same rules
# as the server's pipeline variables; written by fbksd-server at start).
i=0
requests=0
# A value with a line break would add lines to the server's push record.
newline='
'
while [ "$i" -lt "${{GIT_PUSH_OPTION_COUNT:-0}}" ]; do
    eval "option=\$GIT_PUSH_OPTION_$i"
    case "$option" in
        *"$newline"*|*"$(printf '\r')"*)
            echo "FBKSD: a push option holds a line break: give each option on its own -o"
            exit 1 ;;
        FBKSD_RUN|FBKSD_RUN=*) requests=$((requests + 1)) ;;
        FBKSD_PUBLISH=*)
            requests=$((requests + 1))
            key="${{option#FBKSD_PUBLISH=}}"
            # grep matches line by line: the length check keeps a value with a newline out.
            if ! {{ [ "${{#key}}" -eq 36 ] || [ "${{#key}}" -eq 32 ]; }} ||
               ! printf '%s' "$key" | grep -Eqi '^([0-9a-f]{{32}}|[0-9a-f]{{8}}-[0-9a-f]{{4}}-[0-9a-f]{{4}}-[0-9a-f]{{4}}-[0-9a-f]{{12}})$'; then
                echo "FBKSD: {PUBLISH_NEEDS}, not '$key'"
                exit 1
            fi ;;
        *)
            echo "FBKSD: unknown push option '$option': {KNOWN}"
            exit 1 ;;
    esac
    i=$((i + 1))
done
if [ "$requests" -gt 1 ]; then
    echo "FBKSD: {ONE_REQUEST}"
    exit 1
fi
# What the account's repositories may hold together (set by the server for
# pushes): what this push brings waits in git's quarantine until now. Plain
# sh and coreutils only (the server's image is a minimal Debian: no find).
if [ -n "${{FBKSD_MAX_REPOSITORIES_BYTES:-}}" ] && [ -n "${{GIT_QUARANTINE_PATH:-}}" ]; then
    # Allocated blocks, as the server counts the repositories (fbksd_exchange::disk).
    incoming=$(du -sk "$GIT_QUARANTINE_PATH" | cut -f1)
    incoming=$((${{incoming:-0}} * 1024))
    if [ $((FBKSD_REPOSITORIES_BYTES + incoming)) -gt "$FBKSD_MAX_REPOSITORIES_BYTES" ]; then
        mib() {{ tenths=$((($1 * 10 + 524288) / 1048576)); echo "$((tenths / 10)).$((tenths % 10))"; }}
        echo "FBKSD: this push brings $(mib "$incoming") MiB, and the repositories of your projects hold \
$(mib "$FBKSD_REPOSITORIES_BYTES") of the $((FBKSD_MAX_REPOSITORIES_BYTES / 1048576)) MiB one account may keep: {DELETE_OR_ASK}"
        exit 1
    fi
fi
exit 0
"#
    )
}

impl Request {
    /// Parses variables given as `(name, value)`; unknown names and bad
    /// values are refused with the allowed ones named, and so is more than
    /// one request.
    pub fn parse<'a>(variables: impl IntoIterator<Item = (&'a str, &'a str)>) -> Result<Request, ServiceError> {
        let mut request = Request::Build;
        for (name, value) in variables {
            let next = match name {
                "FBKSD_RUN" => Request::Run,
                // The hook's forms only: 32 hex digits, or 8-4-4-4-12.
                "FBKSD_PUBLISH" => {
                    match uuid::Uuid::parse_str(value).ok().filter(|_| [32, 36].contains(&value.len())) {
                        Some(key) => Request::Publish(key),
                        None => {
                            return Err(ServiceError::invalid(
                                "invalid_variable",
                                format!("{PUBLISH_NEEDS}, not {value:?}"),
                            ))
                        }
                    }
                }
                other => {
                    return Err(ServiceError::invalid(
                        "unknown_variable",
                        format!("unknown variable {other:?}: {KNOWN}"),
                    ))
                }
            };
            if request != Request::Build {
                return Err(ServiceError::invalid("conflicting_variables", ONE_REQUEST));
            }
            request = next;
        }
        Ok(request)
    }

    /// Parses push options (`NAME` or `NAME=value`).
    pub fn from_push_options(options: &[String]) -> Result<Request, ServiceError> {
        Request::parse(options.iter().map(|o| o.split_once('=').unwrap_or((o.as_str(), ""))))
    }

    fn variables(&self) -> serde_json::Value {
        match self {
            Request::Build => serde_json::json!({}),
            Request::Run => serde_json::json!({ "FBKSD_RUN": "1" }),
            Request::Publish(key) => serde_json::json!({ "FBKSD_PUBLISH": key.to_string() }),
        }
    }
}

/// Where a pipeline came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Source {
    /// `git push` (the push has landed: problems become failed jobs).
    Push,
    /// The API or a form (bad variables and quotas are refused before
    /// anything is written; a broken repository is a failed job).
    Api,
    /// A new leaderboard season re-runs a published technique.
    Season,
}

impl Source {
    fn as_str(self) -> &'static str {
        match self {
            Source::Push => "push",
            Source::Api => "api",
            Source::Season => "season",
        }
    }
}

/// A created pipeline and its job.
#[derive(Debug, serde::Serialize)]
pub struct Started {
    /// Pipeline id.
    pub pipeline_id: String,
    /// Its job.
    pub job: crate::jobs::Job,
}

/// The most files a technique's commit may hold: `ls-tree` is read only
/// this far, so a "git bomb" (nested trees naming ~10¹⁰ paths in a few KB)
/// is refused in a second instead of filling the server's memory.
pub const MAX_FILES: usize = 20_000;

/// The most bytes a checkout of a technique's commit may hold (the sum of
/// its files' sizes): what a runner's clone writes to its disk.
pub const MAX_CHECKOUT_BYTES: u64 = 512 << 20;

/// The largest info.json read.
const MAX_INFO_BYTES: usize = 64 * 1024;

/// Descriptions of commits that passed [`sanity_check`], by project and
/// commit: a commit never changes, so a project page viewed again reads
/// only which commit `main` is (one `rev-parse`, not `ls-tree` and
/// `cat-file` per view). At most [`CheckedCommits::KEPT`], forgotten all
/// at once when full; problems are not kept (a busy server's failed read
/// must not stick).
#[derive(Clone, Default)]
pub struct CheckedCommits(std::sync::Arc<std::sync::Mutex<std::collections::HashMap<(String, String), TechniqueInfo>>>);

impl CheckedCommits {
    /// Descriptions kept at most: each is an info.json of at most 64 KiB
    /// (usually a few hundred bytes), so at most 16 MiB.
    pub const KEPT: usize = 256;

    fn get(&self, project_id: &str, commit: &str) -> Option<TechniqueInfo> {
        let kept = self.0.lock().unwrap_or_else(|e| e.into_inner());
        kept.get(&(project_id.to_string(), commit.to_string())).cloned()
    }

    fn keep(&self, project_id: &str, commit: &str, info: &TechniqueInfo) {
        let mut kept = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if kept.len() >= Self::KEPT {
            kept.clear();
        }
        kept.insert((project_id.to_string(), commit.to_string()), info.clone());
    }
}

/// Checks the repository at `commit`: its parsed info.json, or what is wrong.
/// Sizes are checked before anything is read, so a repository built to be
/// big costs the server no more than a small one.
pub async fn sanity_check(state: &AppState, project: &Project, commit: &str) -> Result<TechniqueInfo, String> {
    if let Some(info) = state.checked.get(&project.id, commit) {
        return Ok(info);
    }
    let info = read_info(state, project, commit).await?;
    state.checked.keep(&project.id, commit, &info);
    Ok(info)
}

async fn read_info(state: &AppState, project: &Project, commit: &str) -> Result<TechniqueInfo, String> {
    let files = state.git.files(&project.id, commit, MAX_FILES).await.map_err(|e| match e.kind {
        crate::git::GitErrorKind::TooLarge => format!(
            "the commit holds more than {MAX_FILES} files: a technique's repository must stay below that \
             (keep data sets and build outputs out of it)"
        ),
        _ => e.to_string(),
    })?;
    let total: u64 = files.iter().map(|f| f.size).sum();
    if total > MAX_CHECKOUT_BYTES {
        return Err(format!(
            "the commit's files add up to {} MiB, more than the {} MiB a checkout may hold",
            total >> 20,
            MAX_CHECKOUT_BYTES >> 20
        ));
    }
    let info = files
        .iter()
        .find(|f| f.path == "info.json")
        .ok_or("the repository has no info.json at its root: see the SDK's example techniques")?;
    let text = state.git.read(&project.id, info, MAX_INFO_BYTES).await?;
    let paths: Vec<String> = files.into_iter().map(|f| f.path).collect();
    TechniqueInfo::parse(&text, &paths)
}

/// Starts a pipeline at `commit` for `user` (the project's owner).
pub async fn start(
    state: &AppState,
    project: &Project,
    user: &User,
    commit: &str,
    git_ref: &str,
    request: Request,
    source: Source,
) -> Result<Started, ServiceError> {
    // Decide everything before writing, so a refusal writes nothing.
    let season = crate::results::current_season(&state.pool).await?;
    let (kind, mut failure, mut cancelled) = (
        match request {
            Request::Build => JobKind::Build,
            Request::Run => JobKind::Benchmark,
            Request::Publish(_) => JobKind::Publish,
        },
        None::<(FailureReason, String)>,
        None::<String>,
    );
    let mut message = String::new();
    match &request {
        Request::Build | Request::Run => {
            // A broken repository is a failed job whoever asked: its author
            // finds the problem in the project's history and in the mail.
            if let Err(problem) = sanity_check(state, project, commit).await {
                failure = Some((FailureReason::BuildFailed, problem));
            }
        }
        Request::Publish(key) => {
            let published = async {
                let set = crate::results::owned(&state.pool, &key.to_string(), &user.id).await?;
                if set.project.as_deref() != Some(project.name.as_str()) {
                    return Err(ServiceError::invalid(
                        "wrong_project",
                        format!("result {key} belongs to another project"),
                    ));
                }
                crate::results::publish(&state.pool, &set).await
            }
            .await;
            match published {
                Ok(()) => message = format!("published {}/results/{key}", state.public_url),
                Err(e) if source == Source::Api => return Err(e),
                Err(e) => failure = Some((FailureReason::BuildFailed, e.message)),
            }
        }
    }
    if kind != JobKind::Publish && failure.is_none() && source != Source::Season {
        if let Err(e) = check_quota(state, &user.id, kind).await {
            if source == Source::Api {
                return Err(e);
            }
            let not = if kind == JobKind::Build { "not built" } else { "not run" };
            cancelled = Some(format!("{not}: {}", e.message));
        }
    }
    // Each push refused (over a quota, or a broken commit) makes a row and
    // a mail, and pushes of empty commits are cheap: past a day's most,
    // the refusal is told to the pusher and nothing is written or sent.
    if source == Source::Push
        && (failure.is_some() || cancelled.is_some())
        && refusals_today(state, &user.id).await? >= REFUSALS_KEPT_PER_DAY
    {
        let why = failure.as_ref().map(|(_, problem)| problem).or(cancelled.as_ref()).cloned().unwrap_or_default();
        return Err(ServiceError::too_many(
            "refusal_not_kept",
            format!(
                "{why} (not kept in the project's history, and not mailed: \
                 {REFUSALS_KEPT_PER_DAY} refused pipelines a day are)"
            ),
        ));
    }

    let (job_state, finished) = match (&failure, &cancelled, kind) {
        (Some((_, problem)), _, _) => {
            message = problem.clone();
            (JobState::Failed, Some(now_ms()))
        }
        (None, Some(why), _) => {
            message = why.clone();
            (JobState::Cancelled, Some(now_ms()))
        }
        (None, None, JobKind::Publish) => (JobState::Succeeded, Some(now_ms())),
        (None, None, _) => (JobState::Queued, None),
    };
    let (pipeline_id, job_id) = (uuid::Uuid::new_v4().to_string(), uuid::Uuid::new_v4().to_string());
    let mut tx = state.pool.begin().await?;
    let variables = request.variables().to_string();
    insert_pipeline(&mut tx, &pipeline_id, (&project.id, &user.id), (commit, git_ref), &variables, source.as_str())
        .await?;
    let new_job = crate::jobs::NewJob {
        id: &job_id,
        pipeline_id: &pipeline_id,
        project_id: &project.id,
        user_id: &user.id,
        kind,
        state: job_state,
        failure_reason: failure.as_ref().map(|(reason, _)| *reason),
        message: &message,
        max_attempts: state.config.max_attempts as i64,
        season,
        publish_on_success: source == Source::Season,
        // Only jobs that were queued use up the day's runs or builds.
        counts_for_quota: kind != JobKind::Publish && job_state == JobState::Queued && source != Source::Season,
        finished_at: finished,
        reference_key: None,
        more_seeds: None,
        measures_again: None,
    };
    crate::jobs::insert(&mut tx, &new_job).await?;
    tx.commit().await?;

    let first_line = match job_state {
        JobState::Queued => format!("[fbksd] {} of {commit} queued ({})\n", kind.as_str(), source.as_str()),
        _ => format!("[fbksd] {job_state}: {message}\n"),
    };
    crate::jobs::append_log(&state.pool, &job_id, 0, &first_line, i64::MAX).await?;
    state.job_queued.notify_waiters();
    let job = crate::jobs::get(&state.pool, &job_id).await?.ok_or_else(|| ServiceError::internal("job vanished"))?;
    if job_state == JobState::Failed {
        mail_failure(state, user, &job).await;
    }
    Ok(Started { pipeline_id, job })
}

/// Creates the pipeline `id` of (project, user) at (commit, git ref), in
/// its job's transaction. Reference jobs' pipelines name the reference's
/// key and scene instead of a commit and a ref.
pub(crate) async fn insert_pipeline(
    tx: &mut sqlx::Transaction<'_, sqlx::Any>,
    id: &str,
    (project_id, user_id): (&str, &str),
    (commit, git_ref): (&str, &str),
    variables: &str,
    source: &str,
) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO pipelines (id, project_id, user_id, commit_sha, git_ref, variables, source, created_at) \
         VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
    )
    .bind(id)
    .bind(project_id)
    .bind(user_id)
    .bind(commit)
    .bind(git_ref)
    .bind(variables)
    .bind(source)
    .bind(now_ms())
    .execute(&mut **tx)
    .await?;
    Ok(())
}

/// The most branches one push starts pipelines for: a push of 10 000
/// branches queues a handful of builds, and the pusher is told why.
pub const MAX_BRANCHES_PER_PUSH: usize = 5;

/// Starts the pipelines of a push that landed, one per branch moved (at
/// most [`MAX_BRANCHES_PER_PUSH`]); what each started, for the pusher.
pub async fn start_push(
    state: &AppState,
    project: &Project,
    user: &User,
    record: &crate::git::PushRecord,
) -> Vec<String> {
    // The pre-receive hook has checked the options with the same rules;
    // should the two ever disagree, the push is told, not silently built.
    let request = match Request::from_push_options(&record.options) {
        Ok(request) => request,
        Err(e) => return vec![format!("FBKSD: nothing started: {}", e.message)],
    };
    let branches: Vec<_> = record
        .updates
        .iter()
        .filter(|u| u.name.starts_with("refs/heads/") && !u.new.bytes().all(|b| b == b'0'))
        .collect();
    let mut messages = Vec::new();
    for update in branches.iter().take(MAX_BRANCHES_PER_PUSH) {
        let branch = update.name.trim_start_matches("refs/heads/");
        match start(state, project, user, &update.new, branch, request.clone(), Source::Push).await {
            Ok(started) => messages.push(describe(state, &started.job, branch)),
            Err(e) if e.code == "refusal_not_kept" => messages.push(format!("FBKSD: {branch}: {}", e.message)),
            Err(e) => {
                tracing::error!("pipeline for push to {}: {}", project.name, e.message);
                messages.push(format!("FBKSD: no pipeline started for {branch}: {}", e.message));
            }
        }
    }
    if branches.len() > MAX_BRANCHES_PER_PUSH {
        messages.push(format!(
            "FBKSD: {} more branches moved, but a push starts at most {MAX_BRANCHES_PER_PUSH} pipelines: \
             push them separately, or start them from the project's page",
            branches.len() - MAX_BRANCHES_PER_PUSH
        ));
    }
    if messages.is_empty() {
        messages.push("FBKSD: no branch moved, so nothing was started (tags and deletions start no pipeline)".into());
    }
    messages
}

/// What a push started, in a line or two for its `remote:` output.
pub fn describe(state: &AppState, job: &crate::jobs::Job, branch: &str) -> String {
    let url = format!("{}/jobs/{}", state.public_url, job.id);
    let what = format!("{} of {branch} at {}", job.kind.as_str(), &job.commit_sha[..job.commit_sha.len().min(10)]);
    let first_line = job.message.lines().next().unwrap_or("");
    match (job.state, job.kind) {
        (JobState::Queued, JobKind::Benchmark) => format!(
            "FBKSD: {what} queued: {url}\nFBKSD: when it ends, its log and a mail give your private results link"
        ),
        (JobState::Queued, _) => format!("FBKSD: {what} queued: {url}"),
        (JobState::Failed, _) => format!("FBKSD: {what} failed: {first_line}\nFBKSD: details: {url}"),
        (JobState::Cancelled, _) => format!("FBKSD: {what}: {first_line}\nFBKSD: details: {url}"),
        (_, _) => format!("FBKSD: {first_line}"),
    }
}

/// Pushed pipelines refused at once (over a quota, or a broken commit)
/// that are kept as jobs (and mailed), per user and 24 hours; the pusher
/// is told of every refusal.
pub const REFUSALS_KEPT_PER_DAY: i64 = 20;

/// The user's jobs of the last 24 hours that ended before they started:
/// refused, or cancelled while queued.
async fn refusals_today(state: &AppState, user_id: &str) -> Result<i64, sqlx::Error> {
    sqlx::query_scalar(
        "SELECT COUNT(*) FROM jobs WHERE user_id = $1 AND state IN ('cancelled', 'failed') \
         AND started_at IS NULL AND created_at > $2",
    )
    .bind(user_id)
    .bind(now_ms() - 24 * 3600 * 1000)
    .fetch_one(&state.pool)
    .await
}

/// Builds allowed per user and day: a build is much cheaper than a run, so
/// a multiple of the run quota (a setting would be one more knob to get
/// wrong; this keeps the two in proportion).
pub fn builds_per_day(config: &crate::config::Config) -> u64 {
    config.max_runs_per_day.saturating_mul(5)
}

/// Refuses a job of `kind` (a run, or a build: both take a runner) over the
/// user's quotas: the queued jobs, then that kind's daily number.
async fn check_quota(state: &AppState, user_id: &str, kind: JobKind) -> Result<(), ServiceError> {
    if crate::accounts::is_service(&state.pool, user_id).await? {
        return Ok(());
    }
    let queued = crate::jobs::queued_count(&state.pool, user_id).await?;
    if queued >= state.config.max_queued_jobs_per_user as i64 {
        let jobs = if queued == 1 { "job" } else { "jobs" };
        return Err(ServiceError::too_many(
            "quota_queued",
            format!(
                "you have {queued} {jobs} queued (the limit is {}): wait for them to run",
                state.config.max_queued_jobs_per_user
            ),
        ));
    }
    let (limit, code, what) = match kind {
        JobKind::Build => (builds_per_day(&state.config), "quota_builds", "builds"),
        _ => (state.config.max_runs_per_day, "quota_runs", "benchmark runs"),
    };
    if crate::jobs::counted_today(&state.pool, user_id, kind).await? >= limit as i64 {
        return Err(ServiceError::too_many(
            code,
            format!(
                "you have used your {limit} {what} of the last 24 hours; {what} that failed for infrastructure \
                 reasons or were cancelled before starting do not count"
            ),
        ));
    }
    Ok(())
}

/// Mails the author that a job failed (failures to send are logged, not fatal).
pub async fn mail_failure(state: &AppState, user: &User, job: &crate::jobs::Job) {
    let body = format!(
        "Your {} job of {} at commit {} failed ({}):\n\n{}\n\nLog: {}/jobs/{}\n",
        job.kind.as_str(),
        job.project,
        &job.commit_sha[..job.commit_sha.len().min(12)],
        job.failure_reason.as_deref().unwrap_or("failed"),
        job.message,
        state.public_url,
        job.id
    );
    let subject = format!("[FBKSD] {} {} failed", job.project, job.kind.as_str());
    if let Err(e) = state.mailer.send(&state.config.mail_from, &user.email, &subject, body).await {
        tracing::warn!("mail to {}: {e}", user.email);
    }
}

/// How a runner says a job ended (shared with the runner).
pub use fbksd_exchange::runner_api::Outcome;

/// Ends a running job as its runner reports; a successful benchmark stores
/// its result set. Returns the result set's UUID, if one was stored.
pub async fn finish(
    state: &AppState,
    job_id: &str,
    attempt: i64,
    outcome: Outcome,
) -> Result<Option<String>, ServiceError> {
    let job = crate::jobs::get(&state.pool, job_id).await?.ok_or_else(|| ServiceError::internal("job vanished"))?;
    let (kind, reason) = (job.kind, outcome.reason);
    let worked = (now_ms() - job.started_at.unwrap_or_else(now_ms)) as f64 / 1e3;
    let requeued = outcome.state == JobState::Failed
        && reason == Some(FailureReason::InfrastructureError)
        && job.attempts < job.max_attempts;
    let end = if requeued { "requeued" } else { outcome.state.as_str() };
    let ended = end_job(state, job, attempt, outcome).await;
    if ended.is_ok() {
        state.telemetry.job_ended(kind.as_str(), end, worked, reason.map(FailureReason::as_str));
    }
    ended
}

async fn end_job(
    state: &AppState,
    job: crate::jobs::Job,
    attempt: i64,
    outcome: Outcome,
) -> Result<Option<String>, ServiceError> {
    let job_id = job.id.as_str();
    let owner = crate::accounts::user_by_id(&state.pool, &job.user_id).await?;
    match (outcome.state, outcome.reason) {
        (JobState::Succeeded, _) if job.kind == JobKind::Benchmark => {
            let (result_id, published) = store_results(state, &job).await?;
            let url = format!("{}/results/{result_id}", state.public_url);
            crate::jobs::append_log(&state.pool, job_id, attempt, &format!("[fbksd] private results: {url}\n"), i64::MAX)
                .await?;
            if let Some(old) = &job.measures_again {
                // The service asked for it, not the owner: no mail.
                let note = if published {
                    format!("[fbksd] published in the place of result set {old}\n")
                } else {
                    format!("[fbksd] kept private: result set {old} is no longer published\n")
                };
                crate::jobs::append_log(&state.pool, job_id, attempt, &note, i64::MAX).await?;
            } else if let Some(owner) = owner {
                let body = format!(
                    "The benchmark of {} at commit {} is done.\n\nYour private results: {url}\n\n\
                     Publish them from that page, or with FBKSD_PUBLISH={result_id}.\n",
                    job.project, job.commit_sha
                );
                let subject = format!("[FBKSD] {} results", job.project);
                if let Err(e) = state.mailer.send(&state.config.mail_from, &owner.email, &subject, body).await {
                    tracing::warn!("mail: {e}");
                }
            }
            Ok(Some(result_id))
        }
        (JobState::Succeeded, _) if job.kind == JobKind::Reference => {
            crate::references::store(state, &job).await?;
            Ok(None)
        }
        (JobState::Succeeded, _) if job.kind == JobKind::Seeds => {
            crate::seeds::add_repeats(state, &job).await?;
            Ok(None)
        }
        (JobState::Succeeded, _) => {
            crate::jobs::end(&state.pool, job_id, JobState::Succeeded, None, &outcome.message, true).await?;
            Ok(None)
        }
        (JobState::Failed, Some(FailureReason::InfrastructureError)) if job.attempts < job.max_attempts => {
            // Not the user's fault: another runner tries again.
            crate::jobs::queue_again(&state.pool, job_id).await?;
            discard_attempt(state, job_id).await?;
            let note = format!("[fbksd] infrastructure error: {}; the job is queued again\n", outcome.message);
            crate::jobs::append_log(&state.pool, job_id, attempt, &note, i64::MAX).await?;
            state.job_queued.notify_waiters();
            Ok(None)
        }
        (JobState::Failed, Some(reason)) => {
            let counts = reason != FailureReason::InfrastructureError;
            crate::jobs::end(&state.pool, job_id, JobState::Failed, Some(reason), &outcome.message, counts).await?;
            discard_attempt(state, job_id).await?;
            if let (Some(owner), Some(job)) = (owner, crate::jobs::get(&state.pool, job_id).await?) {
                mail_failure(state, &owner, &job).await;
            }
            Ok(None)
        }
        (JobState::Failed, None) => Err(ServiceError::invalid(
            "missing_reason",
            "a failed job needs a reason: build_failed, timeout, out_of_memory, crashed, invalid_output, over_limit or infrastructure_error",
        )),
        (other, _) => Err(ServiceError::invalid("invalid_state", format!("state {other}: use succeeded or failed"))),
    }
}

/// Turns a benchmark job's staged upload into a result set, in one
/// transaction with the job's end.
///
/// Idempotent, so a server killed at any step loses nothing when the
/// runner reports the end again: the set's id is chosen once and kept on
/// the job; the files move under it (a retry finds them there); the shared
/// references are kept; then the set and the job's end commit together.
async fn store_results(state: &AppState, job: &crate::jobs::Job) -> Result<(String, bool), ServiceError> {
    let (staged, mut publish) = crate::jobs::staged_results(&state.pool, &job.id).await?;
    let staged = staged.ok_or_else(|| {
        ServiceError::conflict("no_results", "upload the results (PUT …/results) before reporting success")
    })?;
    if let Some(old) = &job.measures_again {
        publish &= crate::measure_again::still_published(state, old).await?;
    }
    let upload: crate::results::Upload = serde_json::from_str(&staged).map_err(ServiceError::internal)?;
    let info = match sanity_check(
        state,
        &crate::projects::by_id(&state.pool, &job.project_id)
            .await?
            .ok_or_else(|| ServiceError::internal("project vanished"))?,
        &job.commit_sha,
    )
    .await
    {
        Ok(info) => serde_json::to_value(&info).map_err(ServiceError::internal)?,
        Err(problem) => return Err(ServiceError::conflict("invalid_repository", problem)),
    };
    let data = &state.config.data_dir;
    let id = crate::jobs::pending_result_id(&state.pool, &job.id).await?;
    let (staging, target) = (crate::results::staging_dir(data, &job.id), crate::results::files_dir(data, &id));
    if tokio::fs::try_exists(&staging).await.unwrap_or(false) {
        if let Some(parent) = target.parent() {
            tokio::fs::create_dir_all(parent).await.map_err(ServiceError::internal)?;
        }
        // Files of an earlier try of this same attempt: the staged ones are newer.
        let _ = tokio::fs::remove_dir_all(&target).await;
        tokio::fs::rename(&staging, &target).await.map_err(ServiceError::internal)?;
    }
    crash_point("moved");
    crate::results::keep_references(data, &target, &upload).await;
    crash_point("references-kept");
    let mut tx = state.pool.begin().await?;
    crate::results::insert(
        &mut tx,
        &crate::results::NewResultSet {
            id: &id,
            job_id: &job.id,
            project_id: &job.project_id,
            user_id: &job.user_id,
            technique: &job.project,
            info: &info,
            commit_sha: &job.commit_sha,
            season: job.season,
            publish,
            upload: &upload,
        },
    )
    .await?;
    if !crate::jobs::succeed_with_results(&mut tx, &job.id, &id).await? {
        return Err(ServiceError::gone("job_not_running", "the job is no longer running"));
    }
    tx.commit().await?;
    crash_point("committed");
    Ok((id, publish))
}

/// Ends the process at once when `FBKSD_CRASH_AT` names `step`: the
/// crash tests kill the server between the steps of storing a result set
/// (as a power cut would) and check that the retry loses nothing.
fn crash_point(step: &str) {
    if std::env::var("FBKSD_CRASH_AT").is_ok_and(|s| s == step) {
        eprintln!("FBKSD_CRASH_AT={step}: ending the server here");
        std::process::abort();
    }
}

/// Drops what an attempt of a job staged or moved (its uploads, and the
/// files of a set it did not commit): called when an attempt starts, so
/// stale files never satisfy a later check, and when a job ends without a
/// set.
pub async fn discard_attempt(state: &AppState, job_id: &str) -> Result<(), ServiceError> {
    let data = &state.config.data_dir;
    let _ = tokio::fs::remove_dir_all(crate::results::staging_dir(data, job_id)).await;
    if let Some(pending) = crate::jobs::take_pending_result_id(&state.pool, job_id).await? {
        let _ = tokio::fs::remove_dir_all(crate::results::files_dir(data, &pending)).await;
    }
    Ok(())
}

/// Removes the uploads of every job that is not running (failed,
/// cancelled, requeued, deleted), and the files of sets they did not
/// commit: what a crash or an ended job left. Run at start and now and then.
pub async fn sweep_uploads(state: &AppState) -> Result<usize, ServiceError> {
    let uploads = state.config.data_dir.join("uploads");
    let Ok(mut entries) = tokio::fs::read_dir(&uploads).await else { return Ok(0) };
    let running = crate::jobs::running_ids(&state.pool).await?;
    let mut stale = 0;
    while let Ok(Some(entry)) = entries.next_entry().await {
        // A job's uploads are a directory named by its id (readiness probes are files).
        let id = entry.file_name().to_string_lossy().into_owned();
        if entry.file_type().await.is_ok_and(|t| t.is_dir()) && !running.contains(&id) {
            discard_attempt(state, &id).await?;
            stale += 1;
        }
    }
    Ok(stale)
}

#[cfg(test)]
mod tests {
    /// Runs the `pre-receive` hook with `options` as git passes push options.
    fn hook_accepts(options: &[&str]) -> (bool, String) {
        let mut command = std::process::Command::new("sh");
        command.arg("-c").arg(super::pre_receive_hook()).env("GIT_PUSH_OPTION_COUNT", options.len().to_string());
        for (i, option) in options.iter().enumerate() {
            command.env(format!("GIT_PUSH_OPTION_{i}"), option);
        }
        let out = command.output().unwrap();
        (out.status.success(), String::from_utf8_lossy(&out.stdout).into_owned())
    }

    #[test]
    fn a_push_option_with_a_line_break_is_refused_before_it_reaches_the_push_record() {
        // Git's own client refuses such options; a hand-made request can send them, and the
        // post-receive hook writes one line per option.
        assert!(hook_accepts(&["FBKSD_RUN"]).0);
        let injected = "FBKSD_RUN=x\nref 0000000000000000000000000000000000000000 abcd refs/heads/other";
        let (accepted, said) = hook_accepts(&[injected]);
        assert!(!accepted && said.contains("holds a line break"), "{said}");
        assert!(!hook_accepts(&["FBKSD_RUN\r"]).0);
    }
}
