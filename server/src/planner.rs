//! What the board asks of the service each time it changes (a publish
//! here or on another instance, a set's seeds added, a season started):
//! seeds jobs for ties too close to call ([`crate::seeds`]), and
//! benchmarks that measure again the sets measured while their runner's
//! calibration was off its class's ([`crate::measure_again`]).

use crate::error::ServiceError;
use crate::AppState;

/// Plans the current season's board if it changed since `planned` (the
/// board version last planned), queueing the jobs it asks for.
pub async fn plan_if_changed(state: &AppState, planned: &mut Option<i64>) -> Result<(), ServiceError> {
    let version = state.boards.version(&state.pool).await?;
    if *planned == Some(version) {
        return Ok(());
    }
    let season = crate::results::current_season(&state.pool).await?;
    let data = state.boards.season(&state.pool, season).await?;
    if state.config.max_seeds > 0 {
        crate::seeds::queue_for(state, &data).await?;
    }
    crate::measure_again::queue_for(state, season, &data.sets, data.runner_class.as_deref()).await?;
    *planned = Some(version);
    Ok(())
}

/// A job the service queues for a published result set.
pub(crate) enum ForSet<'a> {
    /// A seeds job: the set's runs made again with these seeds.
    Seeds(&'a [crate::jobs::MoreSeeds]),
    /// A benchmark of the set's commit, published in its place.
    MeasureAgain,
}

/// Queues `job` for `set`, saying `message` in its log, unless one of its
/// kind is already queued or running for the set (planned by another
/// instance for the same board version) or the set's project is gone.
pub(crate) async fn queue_for_set(
    state: &AppState,
    set: &crate::results::ResultSet,
    job: ForSet<'_>,
    message: &str,
) -> Result<(), ServiceError> {
    let (Some(project_id), Some(user_id)) = (set.project_id.as_deref(), set.user_id.as_deref()) else {
        return Ok(());
    };
    let (kind, source, pending) = match job {
        ForSet::Seeds(_) => (crate::jobs::JobKind::Seeds, "seeds", "more_seeds_of"),
        ForSet::MeasureAgain => (crate::jobs::JobKind::Benchmark, "measure-again", "measures_again"),
    };
    let (pipeline_id, job_id) = (uuid::Uuid::new_v4().to_string(), uuid::Uuid::new_v4().to_string());
    let mut tx = state.pool.begin().await?;
    let pending: i64 = sqlx::query_scalar(&format!(
        "SELECT COUNT(*) FROM jobs WHERE {pending} = $1 AND state IN ('queued', 'running')"
    ))
    .bind(&set.id)
    .fetch_one(&mut *tx)
    .await?;
    if pending > 0 {
        return Ok(());
    }
    crate::pipelines::insert_pipeline(
        &mut tx,
        &pipeline_id,
        (project_id, user_id),
        (&set.commit_sha, source),
        "{}",
        source,
    )
    .await?;
    let new = crate::jobs::NewJob {
        id: &job_id,
        pipeline_id: &pipeline_id,
        project_id,
        user_id,
        kind,
        state: crate::jobs::JobState::Queued,
        failure_reason: None,
        message,
        max_attempts: state.config.max_attempts as i64,
        season: set.season,
        publish_on_success: matches!(job, ForSet::MeasureAgain),
        counts_for_quota: false,
        finished_at: None,
        reference_key: None,
        more_seeds: match job {
            ForSet::Seeds(runs) => Some((&set.id, runs)),
            ForSet::MeasureAgain => None,
        },
        measures_again: matches!(job, ForSet::MeasureAgain).then_some(set.id.as_str()),
    };
    crate::jobs::insert(&mut tx, &new).await?;
    tx.commit().await?;
    crate::jobs::append_log(&state.pool, &job_id, 0, &format!("[fbksd] queued: {message}\n"), i64::MAX).await?;
    tracing::info!("{message}");
    state.job_queued.notify_waiters();
    Ok(())
}
