//! Measuring a published result set again when its runner had drifted.
//!
//! Equal time compares only the sets whose runner's calibration lay within
//! [`CALIBRATION_DRIFT_LIMIT`] of its class's; a set beyond it was measured
//! on a machine that had become another one, and is ranked at equal spp
//! only ([`crate::leaderboard::untimed_sets`]). Holding drifted runners
//! back from benchmarks ([`crate::jobs::claim`]) does not prevent every
//! such set: the class's calibration is the median over the season's sets,
//! so it moves as sets arrive, and a runner within the limit when it
//! claimed a job can lie beyond it once the season has more sets. Left
//! there, the set's technique would be off the time axis for the machine's
//! sake, while the same code measured on a steadier runner is on it.
//!
//! So each time the board changes, a published set left out for its
//! calibration gets a benchmark of its commit, for its season, queued by
//! the service: held-back runners are not handed it, and when it succeeds
//! its set is published in the old one's place (if the old one is still
//! the project's published set: its owner may have published another
//! meanwhile). At most [`MAX_TRIES`] per project, commit and season: a
//! set whose new measurement drifted too stays off the time axis, and the
//! board still says why.

use crate::error::ServiceError;
use crate::leaderboard::{Drift, Untimed, CALIBRATION_DRIFT_LIMIT};
use crate::results::ResultSet;
use crate::AppState;
use std::collections::{BTreeMap, BTreeSet};

/// How many benchmarks the service queues per (project, commit, season)
/// to measure a drifted set again: one more than the first measurement is
/// usually enough (a runner whose calibration is off is held back), and a
/// second covers a runner that drifted during the job.
pub const MAX_TRIES: usize = 2;

/// The season's benchmarks that measure sets again, so far.
#[derive(Debug, Default)]
pub struct Tried {
    /// Per (project id, commit): how many were queued.
    pub tries: BTreeMap<(String, String), usize>,
    /// The projects with one queued or running.
    pub pending: BTreeSet<String>,
}

/// The sets of `sets` (a season's published ones, whose times come from
/// `class`) to measure again, with their drift and the try it would be:
/// published, visible, their project still there, left out of equal time
/// for their calibration, none of their project's waiting, and fewer than
/// [`MAX_TRIES`] of their commit's tried.
pub fn plan<'a>(sets: &'a [ResultSet], class: Option<&str>, tried: &Tried) -> Vec<(&'a ResultSet, Drift, usize)> {
    let untimed = crate::leaderboard::untimed_sets(sets, class);
    sets.iter()
        .filter_map(|set| {
            let Some(Untimed::Drifted(drift)) = untimed.get(set.id.as_str()) else { return None };
            let project = set.project_id.as_deref().filter(|_| set.is_public())?;
            let tries = tried.tries.get(&(project.to_string(), set.commit_sha.clone())).copied().unwrap_or(0);
            (!tried.pending.contains(project) && tries < MAX_TRIES).then_some((set, *drift, tries + 1))
        })
        .collect()
}

/// Queues the benchmarks that measure `season`'s drifted sets again
/// ([`plan`]); `sets` are its published ones, its times from `class`.
pub async fn queue_for(
    state: &AppState,
    season: i64,
    sets: &[ResultSet],
    class: Option<&str>,
) -> Result<(), ServiceError> {
    let rows: Vec<(String, String, String)> = sqlx::query_as(
        "SELECT j.project_id, pl.commit_sha, j.state FROM jobs j JOIN pipelines pl ON pl.id = j.pipeline_id \
         WHERE j.measures_again IS NOT NULL AND j.season = $1",
    )
    .bind(season)
    .fetch_all(&state.pool)
    .await?;
    let mut tried = Tried::default();
    for (project, commit, job_state) in rows {
        if job_state == "queued" || job_state == "running" {
            tried.pending.insert(project.clone());
        }
        *tried.tries.entry((project, commit)).or_default() += 1;
    }
    for (set, drift, try_number) in plan(sets, class, &tried) {
        queue(state, set, drift, try_number).await?;
    }
    Ok(())
}

/// Queues the `try_number`th benchmark that measures `set` again.
async fn queue(state: &AppState, set: &ResultSet, drift: Drift, try_number: usize) -> Result<(), ServiceError> {
    let message = format!(
        "measured again: result set {} was measured while its runner's calibration lay more than {:.0} % from its \
         class's ({}), so equal time leaves it out; this benchmark of the same commit is published in its place \
         when it succeeds (try {try_number} of {MAX_TRIES})",
        set.id,
        100.0 * CALIBRATION_DRIFT_LIMIT,
        drift.figures()
    );
    crate::planner::queue_for_set(state, set, crate::planner::ForSet::MeasureAgain, &message).await
}

/// Whether a benchmark that measures `old` again (its id) publishes its
/// set: only while `old` is still published and visible, so a set its
/// owner has since replaced, unpublished or an administrator hid is not
/// brought back by the service.
pub async fn still_published(state: &AppState, old: &str) -> Result<bool, ServiceError> {
    Ok(crate::results::get(&state.pool, old).await?.is_some_and(|set| set.is_public()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::leaderboard::tests::set;

    const CLASS: &str = "Some CPU · x86-64-v3 · 2 cores · 8 GiB";

    /// A published set of `technique` (its own project) measured at
    /// `cpu_ms` of calibration on `class`.
    fn measured(id: &str, technique: &str, class: &str, cpu_ms: f64) -> ResultSet {
        let mut s = set(id, technique);
        s.project_id = Some(format!("project-{technique}"));
        s.commit_sha = format!("commit-{technique}");
        s.provenance = serde_json::json!({ "machine": { "class": class,
            "calibration": { "workload": "fbksd-calibration-1", "cpu_ms": cpu_ms } } });
        s
    }

    #[test]
    fn a_published_set_left_out_for_its_calibration_is_measured_again_a_bounded_number_of_times() {
        let sets = [
            measured("a", "alpha", CLASS, 40.0),
            measured("b", "beta", CLASS, 40.4),
            measured("c", "gamma", CLASS, 46.0),
            measured("d", "delta", "Other CPU", 80.0),
        ];
        let planned = |tried: &Tried| -> Vec<String> {
            plan(&sets, Some(CLASS), tried).into_iter().map(|(s, _, _)| s.id.clone()).collect()
        };
        // Only the drifted set of the season's class: another class's is
        // left out for its class, which measuring it again would not change.
        assert_eq!(planned(&Tried::default()), ["c"]);
        let (drifted, drift, _) = plan(&sets, Some(CLASS), &Tried::default())[0];
        assert_eq!((drifted.id.as_str(), drift.cpu_ms, drift.class_ms), ("c", 46.0, 40.4));

        let key = ("project-gamma".to_string(), "commit-gamma".to_string());
        let once = Tried { tries: [(key.clone(), 1)].into(), pending: BTreeSet::new() };
        assert_eq!(planned(&once), ["c"], "a second try after a first that drifted too");
        let waiting = Tried { tries: [(key.clone(), 1)].into(), pending: ["project-gamma".to_string()].into() };
        assert!(planned(&waiting).is_empty(), "not while one is queued or running");
        let twice = Tried { tries: [(key, MAX_TRIES)].into(), pending: BTreeSet::new() };
        assert!(planned(&twice).is_empty(), "at most {MAX_TRIES} tries");

        // Nor a set whose project was deleted, nor one an administrator hid.
        let mut orphan = sets.clone();
        orphan[2].project_id = None;
        assert!(plan(&orphan, Some(CLASS), &Tried::default()).is_empty());
        let mut hidden = sets.clone();
        hidden[2].hidden_reason = Some("spam".into());
        assert!(plan(&hidden, Some(CLASS), &Tried::default()).is_empty());
        // While the season names no class, nothing is left out for it.
        assert!(plan(&sets, None, &Tried::default()).is_empty());
    }
}
