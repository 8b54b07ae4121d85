//! More seeds where they decide, on the service.
//!
//! A benchmark job measures one technique, so a tie on the board is
//! between result sets of different jobs. When one of those ties is too
//! close to call (the rule `fbksd run --max-repeats` uses:
//! [`fbksd_exchange::ranking::too_close`]), the server queues a *seeds
//! job* for each published set the tie rests on: its runner builds the
//! set's commit again and makes only those runs, with the next seeds. The
//! repeats it uploads are added to the set ([`add_repeats`]), the board
//! changes, and the planner looks again.
//!
//! The rule, written for users in sdk/README ("More seeds on the service"):
//! - both sides of a tie get the same new seeds (the paired tests pair
//!   runs by seed), twice as many as the better-seeded side has, up to
//!   `max_seeds` per run, and so do their runs' peers (sets whose run at
//!   the scene and budget nothing tells apart from theirs, directly or
//!   through a chain of such runs: a third set is then judged against
//!   both on the same seeds);
//! - only sets ranked at equal time (published, visible, of the season's
//!   runner class and calibration) whose project still exists, and runs
//!   with two seeds or more (one seed has no spread to judge);
//! - a tie waits while a seeds job of either side is queued or running,
//!   and for good once one failed through the technique (its owner sees
//!   the failure) or was cancelled (an owner or administrator opted out);
//!   a job that ran out of attempts on the infrastructure is planned
//!   again at the next board change;
//! - repeats are added only when they are exactly the seeds asked for,
//!   scored against the set's own references, on the set's runner class.

use crate::error::ServiceError;
use crate::jobs::{Job, MoreSeeds};
use crate::results::{ResultSet, StoredRun, Upload};
use crate::AppState;
use fbksd_exchange::ranking::{too_close, RunKey};
use std::collections::{BTreeMap, BTreeSet};

/// The seeds jobs a season's board asks for: per result set, its runs
/// to make again. A tie waits while either side, or a peer, is in
/// `waiting` (a seeds job of its is queued or running, or one failed
/// through the technique, or was cancelled).
pub fn plan(
    sets: &[ResultSet],
    runs: &[StoredRun],
    class: Option<&str>,
    max_seeds: u32,
    waiting: &BTreeSet<String>,
) -> BTreeMap<String, Vec<MoreSeeds>> {
    let untimed = crate::leaderboard::untimed_sets(sets, class);
    let eligible: BTreeSet<&str> = sets
        .iter()
        .filter(|s| s.is_public() && s.project_id.is_some() && !untimed.contains_key(s.id.as_str()))
        .map(|s| s.id.as_str())
        .collect();
    // The runs the board ranks: scored against each scene's current reference.
    let (runs, _) = crate::leaderboard::one_reference_per_scene(sets, runs, None);
    let seeded: Vec<&StoredRun> =
        runs.into_iter().filter(|r| r.repeats.len() >= 2 && eligible.contains(r.result_id.as_str())).collect();
    let entries: Vec<_> = seeded.iter().map(|r| r.index_entry(&r.result_id)).collect();
    let seeds_by_run: BTreeMap<RunKey, u32> = seeded
        .iter()
        .map(|r| (RunKey { technique: r.result_id.clone(), scene: r.scene.clone(), spp: r.spp as u64 }, seeds_of(r)))
        .collect();
    let have = |key: &RunKey| seeds_by_run.get(key).copied().unwrap_or(0);
    let mut wanted: BTreeMap<RunKey, u32> = BTreeMap::new();
    for tie in too_close(&entries, max_seeds as usize) {
        let runs: Vec<RunKey> = tie.runs.into_iter().chain(tie.peers).collect();
        if runs.iter().any(|k| waiting.contains(&k.technique)) {
            continue;
        }
        let most = runs.iter().map(&have).max().unwrap_or(0);
        let target = (2 * most).min(max_seeds);
        for key in runs {
            let want = wanted.entry(key).or_default();
            *want = (*want).max(target);
        }
    }
    let mut plans: BTreeMap<String, Vec<MoreSeeds>> = BTreeMap::new();
    for (key, target) in wanted {
        let first = have(&key);
        if target > first {
            let run = MoreSeeds { scene: key.scene, spp: key.spp, first, end: target };
            plans.entry(key.technique).or_default().push(run);
        }
    }
    plans
}

/// One past a run's highest seed (the seeds it has are 0, 1, …).
fn seeds_of(run: &StoredRun) -> u32 {
    run.repeats.iter().map(|r| r.seed as u32 + 1).max().unwrap_or(1)
}

/// Queues the seeds jobs the board of a season (`data`) asks for.
pub async fn queue_for(state: &AppState, data: &crate::leaderboard::SeasonData) -> Result<(), ServiceError> {
    let waiting: BTreeSet<String> = sqlx::query_scalar::<_, Option<String>>(
        "SELECT DISTINCT more_seeds_of FROM jobs WHERE kind = 'seeds' \
         AND (state IN ('queued', 'running', 'cancelled') OR (state = 'failed' AND failure_reason <> 'infrastructure_error'))",
    )
    .fetch_all(&state.pool)
    .await?
    .into_iter()
    .flatten()
    .collect();
    let plans = plan(&data.sets, &data.runs, data.runner_class.as_deref(), state.config.max_seeds, &waiting);
    for (set_id, runs) in plans {
        let Some(set) = data.sets.iter().find(|s| s.id == set_id) else { continue };
        queue(state, set, &runs).await?;
    }
    Ok(())
}

/// Queues a seeds job for `set`'s `runs`.
async fn queue(state: &AppState, set: &ResultSet, runs: &[MoreSeeds]) -> Result<(), ServiceError> {
    let described: Vec<String> =
        runs.iter().map(|r| format!("{} at {} spp, seeds {}–{}", r.scene, r.spp, r.first, r.end - 1)).collect();
    let message = format!(
        "more seeds for result set {}: a tie on the board rests on {} of its runs, or on runs nothing tells apart from them ({})",
        set.id,
        runs.len(),
        described.join("; ")
    );
    crate::planner::queue_for_set(state, set, crate::planner::ForSet::Seeds(runs), &message).await
}

/// Whether `upload` is what seeds job `job` asked for: exactly its runs
/// and seeds, scored against its set's references, on its set's runner
/// class. Checked when the runner uploads (only a checked upload is
/// staged, as a benchmark's).
pub async fn check_upload(state: &AppState, job: &Job, upload: &Upload) -> Result<ResultSet, ServiceError> {
    let invalid = |message: String| ServiceError::invalid("invalid_output", message);
    let set_id = job.more_seeds_of.as_deref().ok_or_else(|| ServiceError::internal("a seeds job without its set"))?;
    let set = crate::results::get(&state.pool, set_id)
        .await?
        .ok_or_else(|| ServiceError::conflict("result_gone", format!("result set {set_id} was deleted")))?;
    let asked: BTreeMap<(&str, u64), &MoreSeeds> =
        job.more_seeds.iter().map(|r| ((r.scene.as_str(), r.spp), r)).collect();
    let metrics: BTreeSet<&str> = set.metrics.iter().map(|m| m.acronym.as_str()).collect();
    for run in &upload.runs {
        let at = format!("results: {} at {} spp", run.scene, run.spp);
        let Some(wanted) = asked.get(&(run.scene.as_str(), run.spp)) else {
            return Err(invalid(format!("{at}: not one of the runs this seeds job makes")));
        };
        let mut seeds: Vec<u64> = run.repeats.iter().map(|r| r.seed).collect();
        seeds.sort_unstable();
        let want: Vec<u64> = wanted.seeds().map(u64::from).collect();
        if seeds != want {
            return Err(invalid(format!("{at}: seeds {seeds:?}, where the job asked for {want:?}")));
        }
        if run.repeats.iter().any(|r| r.image.is_some() || !r.log.is_empty()) {
            return Err(invalid(format!("{at}: a seeds job uploads values, not images or logs")));
        }
        for repeat in run.repeats.iter().filter(|r| r.status == fbksd_exchange::RunStatus::Ok) {
            let got: BTreeSet<&str> = repeat.metrics.keys().map(String::as_str).collect();
            if got != metrics {
                return Err(invalid(format!(
                    "{at}: seed {} has the metrics {got:?}, the result set {metrics:?}",
                    repeat.seed
                )));
            }
        }
    }
    if upload.runs.len() != asked.len() {
        return Err(invalid(format!("results: {} runs, where the job asked for {}", upload.runs.len(), asked.len())));
    }
    for scene in &upload.scenes {
        if let Some(theirs) = crate::results::reference_hash(&state.pool, &set.id, &scene.name).await? {
            if theirs != scene.reference_hash {
                return Err(invalid(format!(
                    "results: scene {} was scored against reference {}, the result set against {theirs}",
                    scene.name, scene.reference_hash
                )));
            }
        }
    }
    let (mine, theirs) = (
        crate::results::runner_class(&upload.provenance.machine),
        crate::results::runner_class(&set.provenance["machine"]),
    );
    if theirs.is_some() && mine != theirs {
        return Err(invalid(format!(
            "results: measured on runner class {}, the result set on {}",
            mine.unwrap_or("(none)"),
            theirs.unwrap_or("(none)")
        )));
    }
    Ok(set)
}

/// Adds the repeats seeds job `job` staged to its result set, and ends
/// the job. Idempotent: a seed the set already has is not added twice (a
/// server stopped between the two steps is told the end again).
pub async fn add_repeats(state: &AppState, job: &Job) -> Result<(), ServiceError> {
    let (staged, _) = crate::jobs::staged_results(&state.pool, &job.id).await?;
    let staged = staged.ok_or_else(|| {
        ServiceError::conflict("no_results", "upload the results (PUT …/results) before reporting success")
    })?;
    let upload: Upload = serde_json::from_str(&staged).map_err(ServiceError::internal)?;
    let set_id = job.more_seeds_of.as_deref().ok_or_else(|| ServiceError::internal("a seeds job without its set"))?;
    let set = crate::results::get(&state.pool, set_id)
        .await?
        .ok_or_else(|| ServiceError::conflict("result_gone", format!("result set {set_id} was deleted")))?;
    let stored = crate::results::runs(&state.pool, crate::results::Selection::One(&set.id)).await?;
    let mut tx = state.pool.begin().await?;
    let mut added = 0;
    for run in &upload.runs {
        let Some(old) = stored.iter().find(|r| r.scene == run.scene && r.spp as u64 == run.spp) else {
            continue;
        };
        let mut merged = old.clone();
        for repeat in &run.repeats {
            if !merged.repeats.iter().any(|r| r.seed == repeat.seed) {
                merged.repeats.push(repeat.clone());
                added += 1;
            }
        }
        merged.repeats.sort_by_key(|r| r.seed);
        crate::results::replace_repeats(&mut tx, &merged).await?;
    }
    crate::results::boards_changed(&mut *tx).await?;
    // With the repeats, so that the planner never sees the new board with
    // the job still running (it would let the tie wait for no one).
    let message = format!("{added} repeats added to result set {}", set.id);
    if !crate::jobs::succeed_in(&mut tx, &job.id, &message).await? {
        return Err(ServiceError::gone("job_not_running", "the job is no longer running"));
    }
    tx.commit().await?;
    crate::jobs::append_log(&state.pool, &job.id, 0, "[fbksd] succeeded\n", i64::MAX).await?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::leaderboard::tests::{repeated, set};

    #[test]
    fn a_tie_gets_more_seeds_and_so_does_a_set_nothing_tells_apart_from_one_side() {
        let sets = [set("a", "alpha"), set("twin", "alpha-again"), set("close", "gamma"), set("far", "delta")];
        // "close" ties with "a" by less than three seeds can show, and is decided behind
        // "twin", which ties with "a": given to "a" alone, seeds 3-5 would judge "close"
        // against "a" on six seeds and against "twin" on three.
        let runs = [
            repeated("a", "s", 4, [1.0, 1.2, 0.9], 10.0),
            repeated("twin", "s", 4, [1.05, 1.4, 0.89], 10.0),
            repeated("close", "s", 4, [1.1, 1.45, 0.95], 10.0),
            repeated("far", "s", 4, [3.0, 3.3, 2.9], 10.0),
        ];
        let plans = plan(&sets, &runs, None, 12, &BTreeSet::new());
        let seeds_3_to_5 = [MoreSeeds { scene: "s".into(), spp: 4, first: 3, end: 6 }];
        for id in ["a", "close", "twin"] {
            assert_eq!(plans.get(id).map(Vec::as_slice), Some(&seeds_3_to_5[..]), "{id}: {plans:?}");
        }
        assert!(!plans.contains_key("far"), "{plans:?}");
        // While the twin's seeds job runs, the tie waits for it.
        assert!(plan(&sets, &runs, None, 12, &BTreeSet::from(["twin".to_string()])).is_empty());
    }
}
