//! Administration that spans the service: a new leaderboard season.
//!
//! Jobs (requeue, cancel), runners and hidden result sets are administered
//! through their own modules; starting a season touches seasons, boards and
//! pipelines at once, so it lives here.

use crate::error::ServiceError;
use crate::pipelines::{Request, Source};
use crate::AppState;
use serde::Serialize;

/// What starting a season did.
#[derive(Debug, Serialize)]
pub struct SeasonStarted {
    /// The new season's number.
    pub season: i64,
    /// The re-runs queued.
    pub queued: Vec<Rerun>,
    /// The techniques not re-run, and why.
    pub skipped: Vec<Skipped>,
}

/// A re-run queued for the new season.
#[derive(Debug, Serialize)]
pub struct Rerun {
    /// The technique.
    pub technique: String,
    /// Its benchmark job.
    pub job: String,
}

/// A published technique that was not re-run.
#[derive(Debug, Serialize)]
pub struct Skipped {
    /// The technique.
    pub technique: String,
    /// Why not.
    pub why: String,
}

/// Starts a season (the scene pool changed; the old boards stay readable)
/// and queues a benchmark of every technique published in the previous
/// one, at the same commit, published on success.
/// `runner_class` names the runner class its times come from (the new
/// hardware of the fleet, say); by default its first result's names it.
pub async fn start_season(
    state: &AppState,
    note: &str,
    runner_class: Option<&str>,
) -> Result<SeasonStarted, ServiceError> {
    let note = note.trim();
    if note.is_empty() {
        return Err(ServiceError::invalid("missing_note", "say what changed in the scene pool"));
    }
    let previous = crate::results::current_season(&state.pool).await?;
    let published = crate::results::published(&state.pool, previous).await?;
    let runner_class = runner_class.map(str::trim).filter(|c| !c.is_empty());
    sqlx::query("INSERT INTO seasons (number, note, started_at, runner_class) VALUES ($1, $2, $3, $4)")
        .bind(previous + 1)
        .bind(note)
        .bind(crate::now_ms())
        .bind(runner_class)
        .execute(&state.pool)
        .await?;
    crate::results::boards_changed(&state.pool).await?;
    let mut started = SeasonStarted { season: previous + 1, queued: Vec::new(), skipped: Vec::new() };
    for set in published {
        // By id: a deleted project's name may since belong to someone else.
        let project = match &set.project_id {
            Some(id) => crate::projects::by_id(&state.pool, id).await?,
            None => None,
        };
        let owner = match &project {
            Some(p) => crate::accounts::user_by_id(&state.pool, &p.owner_id).await?,
            None => None,
        };
        match (project, owner) {
            (Some(project), Some(owner)) => {
                let run = crate::pipelines::start(
                    state,
                    &project,
                    &owner,
                    &set.commit_sha,
                    "season",
                    Request::Run,
                    Source::Season,
                )
                .await?;
                started.queued.push(Rerun { technique: set.technique, job: run.job.id });
            }
            _ => started
                .skipped
                .push(Skipped { technique: set.technique, why: "its project or owner was deleted".into() }),
        }
    }
    Ok(started)
}
