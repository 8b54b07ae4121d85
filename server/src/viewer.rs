//! The results viewer's document for a result set: the set beside every
//! published technique of its season, on the set's scenes, with the
//! addresses of every file the viewer may show (pixels, error maps, logs,
//! references and the feature buffers made with them).
//! `frontend/static/viewer/` draws it; `fbksd results page`
//! writes the same document for a local results directory.
//!
//! Only files that exist are named, so the viewer never offers an image it
//! cannot load (sets stored before the viewer have no pixel files).

use crate::error::ServiceError;
use crate::results::{self, ResultSet, Selection, StoredRun};
use fbksd_exchange::results::RunFiles;
use fbksd_exchange::scenes::FEATURE_BUFFERS;
use fbksd_exchange::viewer::{Delivery, Rankings, ViewerData, ViewerRun, ViewerScene, ViewerTechnique};
use sqlx::AnyPool;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The viewer's document for `set` (which the caller may see), as JSON:
/// made once per board version. The season's published sets and runs come
/// from `boards`; `set`'s own rows change only with the board version
/// (a seeds job's repeats), and its files and
/// references are in place once it is stored (a shared reference file that
/// appears only later, for a set stored before references were kept,
/// shows from the next board version).
pub async fn document_json(
    pool: &AnyPool,
    boards: &crate::leaderboard::BoardCache,
    data_dir: &Path,
    set: &ResultSet,
) -> Result<axum::body::Bytes, ServiceError> {
    let season = boards.season(pool, set.season).await?;
    season
        .document(&set.id, || async {
            let doc = document(pool, &season, data_dir, set).await?;
            serde_json::to_vec(&doc).map_err(ServiceError::internal)
        })
        .await
}

/// The viewer's document for `set` beside `season`'s published sets.
async fn document(
    pool: &AnyPool,
    season: &crate::leaderboard::SeasonData,
    data_dir: &Path,
    set: &ResultSet,
) -> Result<ViewerData, ServiceError> {
    let mut sets = vec![set.clone()];
    sets.extend(season.sets.iter().filter(|s| s.id != set.id).cloned());
    let mut runs = results::runs(pool, Selection::One(&set.id)).await?;
    runs.extend(season.runs.iter().filter(|r| r.result_id != set.id).cloned());
    // Only runs scored against the references this set was scored against.
    let runs: Vec<StoredRun> =
        crate::leaderboard::one_reference_per_scene(&sets, &runs, Some(&set.id)).0.into_iter().cloned().collect();
    let mut tags = BTreeMap::new();
    results::scene_tags(pool, Selection::One(&set.id), &mut tags).await?;

    let mut doc = ViewerData::new(format!("Results of {}", set.full_name()), Delivery::Fetch);
    doc.highlight = Some(set.id.clone());
    doc.metrics = set.metrics.clone();
    for (name, tags) in &tags {
        let hash = results::reference_hash(pool, &set.id, name).await?;
        let stored = |path: Option<std::path::PathBuf>| path.is_some_and(|p| p.is_file());
        let reference = match &hash {
            Some(hash) if stored(results::reference_pixels(data_dir, hash, None)) => {
                Some(format!("/results/{}/references/{name}", set.id))
            }
            _ => None,
        };
        let buffers = FEATURE_BUFFERS
            .iter()
            .filter(|b| hash.as_ref().is_some_and(|h| stored(results::reference_pixels(data_dir, h, Some(b)))))
            .map(|b| (b.to_string(), format!("/results/{}/references/{name}/{b}", set.id)))
            .collect();
        doc.scenes.push(ViewerScene { name: name.clone(), tags: tags.iter().cloned().collect(), reference, buffers });
    }
    let metrics_with_maps: Vec<String> =
        set.metrics.iter().filter(|m| m.has_error_map).map(|m| m.acronym.clone()).collect();
    let data_dir = data_dir.to_path_buf();
    let scenes: BTreeSet<String> = tags.into_keys().collect();
    let entries: Vec<_> = runs
        .iter()
        .filter(|r| scenes.contains(&r.scene) && sets.iter().any(|s| s.id == r.result_id))
        .map(|r| r.index_entry(&r.result_id))
        .collect();
    let lower_is_better =
        |acronym: &str| doc.metrics.iter().find(|m| m.acronym == acronym).is_none_or(|m| m.lower_is_better);
    // Equal time and the costs compare only the runs of the season's runner class.
    // (the entries' technique is their set's id).
    let class = season.runner_class.clone();
    let untimed: BTreeMap<String, String> = crate::leaderboard::untimed_sets(&sets, class.as_deref())
        .into_iter()
        .map(|(id, why)| (id.to_string(), why.reason()))
        .collect();
    let is_timed = |e: &fbksd_exchange::results::IndexEntry| !untimed.contains_key(&e.technique);
    doc.rankings = Rankings::of(&entries, is_timed, lower_is_better);
    let timed_entries: Vec<_> = entries.iter().filter(|e| is_timed(e)).cloned().collect();
    doc.runner_class = class;
    // Existence checks touch the disk once per file: off the async threads.
    let techniques = tokio::task::spawn_blocking(move || {
        sets.iter()
            .map(|s| ViewerTechnique {
                key: s.id.clone(),
                name: s.technique.clone(),
                full_name: s.full_name().to_string(),
                citation: s.info["citation"].as_str().unwrap_or("").trim().to_string(),
                runner_class: results::runner_class(&s.provenance["machine"]).map(str::to_string),
                untimed: untimed.get(&s.id).cloned(),
                runs: runs
                    .iter()
                    .filter(|r| r.result_id == s.id && scenes.contains(&r.scene))
                    .map(|r| viewer_run(&data_dir, r, &metrics_with_maps))
                    .collect(),
            })
            .collect::<Vec<_>>()
    })
    .await
    .map_err(ServiceError::internal)?;
    doc.techniques = techniques;
    doc.set_costs(&timed_entries);
    Ok(doc)
}

fn viewer_run(data_dir: &Path, run: &StoredRun, metrics_with_maps: &[String]) -> ViewerRun {
    let files = results::files_dir(data_dir, &run.result_id);
    let files_of_run = RunFiles::first(run.spp as u64);
    // The run's directory among the set's files: beside its record or image.
    let dir = run.log.as_deref().or(run.image.as_deref()).and_then(|f| Path::new(f).parent()).map(Path::to_path_buf);
    let existing = |name: String| -> Option<String> {
        let rel = dir.as_ref()?.join(name);
        files.join(&rel).is_file().then(|| format!("/results/{}/files/{}", run.result_id, rel.to_string_lossy()))
    };
    ViewerRun {
        pixels: existing(files_of_run.pixels()),
        log: existing(files_of_run.technique_log()),
        error_maps: metrics_with_maps
            .iter()
            .filter_map(|m| Some((m.clone(), existing(files_of_run.error_map(m))?)))
            .collect(),
        ..ViewerRun::measured(&run.index_entry(&run.result_id))
    }
}
