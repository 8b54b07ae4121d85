//! The leaderboard of a season: every published result set, per scene and
//! spp, sorted by one metric, with each technique's mean rank across the
//! (scene, spp) groups shown. A private results page is the same board
//! with one unpublished set added and marked.
//!
//! The published part of a season is kept in memory ([`BoardCache`]) and
//! reloaded when the database's board version changes, so a page view
//! costs one small query however many techniques are published, and every
//! server instance sees every change.
//!
//! Ranking fixes the original's bias: a technique with no value in a group
//! (its run failed) ranks last there instead of being skipped.

use crate::results::{ResultSet, StoredRun};
use fbksd_exchange::results::IndexEntry;
use fbksd_exchange::MetricInfo;
use serde::Serialize;
use sqlx::AnyPool;
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::{Arc, Mutex};

/// One technique in one (scene, spp) group.
#[derive(Debug, Clone, Serialize)]
pub struct Entry {
    /// Technique (its project's name).
    pub technique: String,
    /// Its full name, from its info.json.
    pub full_name: String,
    /// Its result set.
    pub result_id: String,
    /// Whether this is the set the private page is about.
    pub highlighted: bool,
    /// Run status (`ok`, `timeout`, …).
    pub status: String,
    /// Why, if not ok.
    pub message: String,
    /// Value of each board metric, in `Board::metrics` order.
    pub values: Vec<Option<f64>>,
    /// Technique time.
    pub technique_ms: f64,
    /// The result image, if uploaded.
    pub image: Option<String>,
}

/// One (scene, spp) group.
#[derive(Debug, Clone, Serialize)]
pub struct Group {
    /// Scene.
    pub scene: String,
    /// Its tags.
    pub tags: Vec<String>,
    /// Budget.
    pub spp: i64,
    /// Techniques, best first by the sort metric; missing values last.
    pub entries: Vec<Entry>,
}

/// A technique's mean rank.
#[derive(Debug, Clone, Serialize)]
pub struct Standing {
    /// Technique (its project's name).
    pub technique: String,
    /// Its full name, from its info.json.
    pub full_name: String,
    /// Its citation, from its info.json (may be empty).
    pub citation: String,
    /// Its result set.
    pub result_id: String,
    /// Whether this is the private page's set.
    pub highlighted: bool,
    /// Mean rank over the shown groups by the sort metric (1 is best).
    pub mean_rank: f64,
    /// Groups with no value (ranked last).
    pub missing: usize,
}

/// A whole board.
#[derive(Debug, Clone, Serialize)]
pub struct Board {
    /// Season shown.
    pub season: i64,
    /// The metrics, in column order.
    pub metrics: Vec<MetricInfo>,
    /// The metric rows are sorted by.
    pub sort: String,
    /// Every tag of the season's scenes.
    pub tags: Vec<String>,
    /// The tag filter in effect.
    pub tag: Option<String>,
    /// Standings, best first.
    pub standings: Vec<Standing>,
    /// Groups by scene, then spp.
    pub groups: Vec<Group>,
}

/// What to show.
#[derive(Debug, Clone, Default, serde::Deserialize)]
pub struct BoardQuery {
    /// Season (default: current).
    pub season: Option<i64>,
    /// Sort metric (default: the first metric, MSE for the built-in set).
    pub sort: Option<String>,
    /// Only scenes with this tag.
    pub tag: Option<String>,
}

/// A public board's (sort metric, tag filter).
type BoardKey = (Option<String>, Option<String>);

/// The published sets of one season with their runs and scene tags.
struct SeasonData {
    version: i64,
    sets: Vec<ResultSet>,
    runs: Vec<StoredRun>,
    tags: BTreeMap<String, BTreeSet<String>>,
    /// Public boards already assembled, by (sort, tag).
    boards: Mutex<HashMap<BoardKey, Arc<Board>>>,
}

/// Seasons' published data kept in memory, by season.
#[derive(Clone, Default)]
pub struct BoardCache(Arc<Mutex<HashMap<i64, Arc<SeasonData>>>>);

impl BoardCache {
    async fn season(&self, pool: &AnyPool, season: i64) -> Result<Arc<SeasonData>, sqlx::Error> {
        use crate::results::Selection;
        let version = crate::results::board_version(pool).await?;
        if let Some(data) = self.0.lock().ok().and_then(|m| m.get(&season).cloned()) {
            if data.version == version {
                return Ok(data);
            }
        }
        // Read after the version: the data is at least as new as the version it is kept under.
        let mut tags = BTreeMap::new();
        crate::results::scene_tags(pool, Selection::Published(season), &mut tags).await?;
        let data = Arc::new(SeasonData {
            version,
            sets: crate::results::published(pool, season).await?,
            runs: crate::results::runs(pool, Selection::Published(season)).await?,
            tags,
            boards: Mutex::new(HashMap::new()),
        });
        if let Ok(mut map) = self.0.lock() {
            map.insert(season, data.clone());
        }
        Ok(data)
    }
}

/// Builds the board of `query.season` (or `extra`'s season), adding
/// `extra` (a private set) if given.
pub async fn build(
    pool: &AnyPool,
    cache: &BoardCache,
    query: &BoardQuery,
    extra: Option<&ResultSet>,
) -> Result<Arc<Board>, sqlx::Error> {
    use crate::results::Selection;
    let season = match (query.season, extra) {
        (_, Some(set)) => set.season,
        (Some(s), None) => s,
        (None, None) => crate::results::current_season(pool).await?,
    };
    let data = cache.season(pool, season).await?;
    let highlighted = extra.map(|s| s.id.as_str());
    match extra.filter(|e| !data.sets.iter().any(|s| s.id == e.id)) {
        None if highlighted.is_none() => {
            let key = (query.sort.clone(), query.tag.clone());
            if let Some(board) = data.boards.lock().ok().and_then(|b| b.get(&key).cloned()) {
                return Ok(board);
            }
            let board = Arc::new(assemble(season, &data.sets, &data.runs, &data.tags, query, None));
            if let Ok(mut boards) = data.boards.lock() {
                // Bounded: only metric and tag names that exist are worth keeping.
                if boards.len() < 256 {
                    boards.insert(key, board.clone());
                }
            }
            Ok(board)
        }
        None => Ok(Arc::new(assemble(season, &data.sets, &data.runs, &data.tags, query, highlighted))),
        Some(extra) => {
            let mut sets = data.sets.clone();
            sets.push(extra.clone());
            let mut runs = data.runs.clone();
            runs.extend(crate::results::runs(pool, Selection::One(&extra.id)).await?);
            let mut tags = data.tags.clone();
            crate::results::scene_tags(pool, Selection::One(&extra.id), &mut tags).await?;
            Ok(Arc::new(assemble(season, &sets, &runs, &tags, query, highlighted)))
        }
    }
}

/// The pure part of [`build`].
fn assemble(
    season: i64,
    sets: &[ResultSet],
    runs: &[StoredRun],
    scene_tags: &BTreeMap<String, BTreeSet<String>>,
    query: &BoardQuery,
    highlighted: Option<&str>,
) -> Board {
    // Metric columns: the union over sets, in first-seen order.
    let mut metrics: Vec<MetricInfo> = Vec::new();
    for set in sets {
        for m in &set.metrics {
            if !metrics.iter().any(|k| k.acronym == m.acronym) {
                metrics.push(m.clone());
            }
        }
    }
    let sort = query
        .sort
        .clone()
        .filter(|s| metrics.iter().any(|m| &m.acronym == s))
        .or_else(|| metrics.first().map(|m| m.acronym.clone()))
        .unwrap_or_default();
    let lower_is_better =
        |acronym: &str| metrics.iter().find(|m| m.acronym == acronym).is_none_or(|m| m.lower_is_better);
    let sort_lower = lower_is_better(&sort);
    let technique_of: BTreeMap<&str, &ResultSet> = sets.iter().map(|s| (s.id.as_str(), s)).collect();
    let shown = |scene: &str| match &query.tag {
        Some(tag) => scene_tags.get(scene).is_some_and(|t| t.contains(tag)),
        None => true,
    };

    let mut by_group: BTreeMap<(String, i64), Vec<Entry>> = BTreeMap::new();
    for run in runs.iter().filter(|r| shown(&r.scene)) {
        let Some(set) = technique_of.get(run.result_id.as_str()) else { continue };
        by_group.entry((run.scene.clone(), run.spp)).or_default().push(Entry {
            technique: set.technique.clone(),
            full_name: set.full_name().to_string(),
            result_id: set.id.clone(),
            highlighted: highlighted == Some(set.id.as_str()),
            status: run.status.clone(),
            message: run.message.clone(),
            values: metrics.iter().map(|m| run.metrics.get(&m.acronym).copied()).collect(),
            technique_ms: run.technique_ms,
            image: run.image.clone(),
        });
    }
    let sort_index = metrics.iter().position(|m| m.acronym == sort);
    let groups: Vec<Group> = by_group
        .into_iter()
        .map(|((scene, spp), mut entries)| {
            entries.sort_by(|a, b| {
                let key = |e: &Entry| sort_index.and_then(|i| e.values[i]);
                match (key(a), key(b)) {
                    (Some(x), Some(y)) if sort_lower => x.total_cmp(&y),
                    (Some(x), Some(y)) => y.total_cmp(&x),
                    (Some(_), None) => std::cmp::Ordering::Less,
                    (None, Some(_)) => std::cmp::Ordering::Greater,
                    (None, None) => a.technique.cmp(&b.technique),
                }
            });
            let tags = scene_tags.get(&scene).map(|t| t.iter().cloned().collect()).unwrap_or_default();
            Group { scene, tags, spp, entries }
        })
        .collect();

    // Mean rank by the sort metric over the shown groups; a set missing from
    // a group (or without a value there) counts as last.
    let index: Vec<IndexEntry> = runs
        .iter()
        .filter(|r| shown(&r.scene))
        .filter_map(|r| {
            let set = technique_of.get(r.result_id.as_str())?;
            Some(IndexEntry {
                technique: set.id.clone(),
                scene: r.scene.clone(),
                spp: r.spp as u64,
                status: fbksd_exchange::RunStatus::Ok,
                message: String::new(),
                log: String::new(),
                image: None,
                technique_ms: r.technique_ms,
                render_ms: r.render_ms,
                wall_ms: r.wall_ms,
                cpu_ms: r.cpu_ms,
                peak_memory_bytes: r.peak_memory_bytes as u64,
                used_samples: r.used_samples as u64,
                metrics: r.metrics.get(&sort).map(|v| (sort.clone(), *v)).into_iter().collect(),
            })
        })
        .collect();
    let standings = fbksd_exchange::ranking::rank(&index, lower_is_better)
        .into_iter()
        .filter_map(|s| {
            let set = technique_of.get(s.technique.as_str())?;
            Some(Standing {
                technique: set.technique.clone(),
                full_name: set.full_name().to_string(),
                citation: set.info["citation"].as_str().unwrap_or("").trim().to_string(),
                result_id: set.id.clone(),
                highlighted: highlighted == Some(set.id.as_str()),
                mean_rank: s.mean_rank,
                missing: s.missing,
            })
        })
        .filter(|s| s.mean_rank.is_finite())
        .collect();
    let tags: BTreeSet<String> = scene_tags.values().flatten().cloned().collect();
    Board { season, metrics, sort, tags: tags.into_iter().collect(), tag: query.tag.clone(), standings, groups }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(id: &str, technique: &str) -> ResultSet {
        ResultSet {
            id: id.into(),
            technique: technique.into(),
            project: Some(technique.into()),
            user_id: None,
            info: serde_json::json!({}),
            commit_sha: String::new(),
            season: 1,
            provenance: serde_json::json!({}),
            metrics: vec![
                MetricInfo {
                    acronym: "MSE".into(),
                    name: String::new(),
                    reference: String::new(),
                    lower_is_better: true,
                    has_error_map: false,
                },
                MetricInfo {
                    acronym: "SSIM".into(),
                    name: String::new(),
                    reference: String::new(),
                    lower_is_better: false,
                    has_error_map: false,
                },
            ],
            created_at: 0,
            published_at: Some(0),
            hidden_reason: None,
        }
    }

    fn run(id: &str, scene: &str, mse: Option<f64>, ssim: f64) -> StoredRun {
        let mut metrics = BTreeMap::from([("SSIM".to_string(), ssim)]);
        if let Some(m) = mse {
            metrics.insert("MSE".into(), m);
        }
        StoredRun {
            result_id: id.into(),
            scene: scene.into(),
            spp: 4,
            status: if mse.is_some() { "ok".into() } else { "timeout".into() },
            message: String::new(),
            technique_ms: 1.0,
            render_ms: 1.0,
            wall_ms: 2.0,
            cpu_ms: 1.0,
            peak_memory_bytes: 1 << 20,
            used_samples: 1,
            metrics,
            image: None,
            log: None,
        }
    }

    #[test]
    fn sorts_by_the_chosen_metric_and_ranks_missing_values_last() {
        let sets = [set("a", "alpha"), set("b", "beta")];
        // beta is better on MSE where it has a value, but timed out on "s2".
        let runs = [
            run("a", "s1", Some(2.0), 0.5),
            run("b", "s1", Some(1.0), 0.6),
            run("a", "s2", Some(2.0), 0.5),
            run("b", "s2", None, 0.9),
        ];
        let tags = BTreeMap::from([
            ("s1".to_string(), BTreeSet::from(["dof".to_string()])),
            ("s2".to_string(), BTreeSet::new()),
        ]);
        let board = assemble(1, &sets, &runs, &tags, &BoardQuery::default(), Some("b"));
        assert_eq!(board.sort, "MSE");
        assert_eq!(board.groups[0].entries[0].technique, "beta");
        assert_eq!(board.groups[1].entries[0].technique, "alpha", "a missing value sorts last");
        // Mean ranks: alpha (2 + 1) / 2 = 1.5, beta (1 + 2) / 2 = 1.5 → tie broken by id.
        assert_eq!(board.standings.iter().map(|s| s.mean_rank).collect::<Vec<_>>(), [1.5, 1.5]);
        assert!(board.standings.iter().any(|s| s.highlighted && s.technique == "beta" && s.missing == 1));

        let by_ssim =
            assemble(1, &sets, &runs, &tags, &BoardQuery { sort: Some("SSIM".into()), ..Default::default() }, None);
        assert_eq!(by_ssim.groups[1].entries[0].technique, "beta", "higher SSIM is better");
        assert_eq!(by_ssim.standings[0].technique, "beta");

        let dof = assemble(1, &sets, &runs, &tags, &BoardQuery { tag: Some("dof".into()), ..Default::default() }, None);
        assert_eq!(dof.groups.len(), 1);
        assert_eq!(dof.standings[0].technique, "beta");
        assert_eq!(dof.tags, ["dof"]);
    }
}
