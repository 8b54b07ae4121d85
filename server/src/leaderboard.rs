//! The leaderboard of a season: every published result set, per scene and
//! spp, sorted by one metric, with each technique's mean rank across the
//! (scene, spp) groups shown. A private results page is the same board
//! with one unpublished set added and marked.
//!
//! The published part of a season is kept in memory ([`BoardCache`]) and
//! reloaded when the database's board version changes, so a page view
//! costs at most one small query however many techniques are published
//! (shared with the views waiting at the same time), and every server
//! instance sees every change.
//!
//! A board never mixes references: on each scene it ranks the runs scored
//! against the reference of the newest set that ran there
//! ([`one_reference_per_scene`]), and says how many it left out.
//!
//! Ranking is [`fbksd_exchange::ranking`]'s, twice: at equal samples per
//! (scene, spp) group and at equal time (each technique's error read off
//! its error-against-time curve at the fastest technique's time at each
//! budget). Differences within the noise of the repeats tie, and a
//! technique with no value in a group (its run failed, or it cannot give a
//! result in that time) ranks last there instead of being skipped, which
//! fixes the original's bias.

use crate::results::{ResultSet, StoredRun};
use crate::versioned::{Pick, Versioned};
use fbksd_exchange::ranking::{equal_spp, equal_time, At};
use fbksd_exchange::results::IndexEntry;
use fbksd_exchange::stats::Interval;
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
    /// Value of each board metric, in `Board::metrics` order (the mean over
    /// the repeats).
    pub values: Vec<Option<f64>>,
    /// Each value's 95 % confidence interval, when the run was repeated.
    pub intervals: Vec<Option<Interval>>,
    /// Place in the group by the sort metric (ties share).
    pub place: Option<f64>,
    /// The techniques it ties with by the sort metric.
    pub tied_with: Vec<String>,
    /// Technique time (median over the repeats).
    pub technique_ms: f64,
    /// The cost, the equal-time axis (`fbksd_exchange::cost`; median).
    pub cost_ms: f64,
    /// Coefficient of variation of the technique time over the repeats.
    pub time_cv: Option<f64>,
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
    /// Groups in which it ties with another technique.
    pub tied: usize,
    /// Mean rank at equal time (NaN when no time point was ranked).
    pub mean_rank_time: f64,
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
    /// Per scene whose runs were scored against different references: what
    /// was left out ([`one_reference_per_scene`]); and the sets measured on
    /// another runner class, left out of equal time ([`untimed_sets`]).
    pub left_out: Vec<String>,
    /// The runner class the season's times come from, once one is named.
    pub runner_class: Option<String>,
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
pub struct SeasonData {
    /// The runner class its times come from.
    pub runner_class: Option<String>,
    /// Its published result sets.
    pub sets: Vec<ResultSet>,
    /// Their runs.
    pub runs: Vec<StoredRun>,
    tags: BTreeMap<String, BTreeSet<String>>,
    /// Public boards already assembled, by (sort, tag).
    boards: Mutex<HashMap<BoardKey, Arc<Board>>>,
    /// Private pages' boards already assembled, by (set id, sort, tag): a
    /// set's runs change only with the board version (more seeds), so a
    /// page is assembled once per version of the season's data.
    pages: Mutex<HashMap<(String, BoardKey), Arc<Board>>>,
    /// Viewer documents (JSON) already made, by set id: made from this
    /// version's data and the set's own stored rows, which change only
    /// with the board version.
    documents: Mutex<HashMap<String, Arc<tokio::sync::OnceCell<axum::body::Bytes>>>>,
}

/// Viewer documents kept per season at most (each some hundreds of KB for
/// a season of 20 techniques); when full the map is emptied.
const MAX_CACHED_DOCUMENTS: usize = 64;

impl SeasonData {
    /// The viewer document of set `id` at this version: made by `make` if
    /// no one has made it yet (the others wait for it); a failure is not kept.
    pub async fn document<E, F, Fut>(&self, id: &str, make: F) -> Result<axum::body::Bytes, E>
    where
        F: FnOnce() -> Fut,
        Fut: std::future::Future<Output = Result<Vec<u8>, E>>,
    {
        let cell = {
            let mut documents = self.documents.lock().unwrap_or_else(|e| e.into_inner());
            if documents.len() >= MAX_CACHED_DOCUMENTS && !documents.contains_key(id) {
                documents.clear();
            }
            documents.entry(id.to_string()).or_default().clone()
        };
        Ok(cell.get_or_try_init(|| async { make().await.map(axum::body::Bytes::from) }).await?.clone())
    }
}

/// Private pages' boards kept per season at most; when full the map is
/// emptied (set ids come from requests, so it must not grow without bound).
const MAX_CACHED_PAGES: usize = 1024;

/// Seasons kept in memory at most: the season is a query parameter, so
/// without a bound any number of (even empty) seasons could be loaded.
pub const MAX_CACHED_SEASONS: usize = 8;

/// Seasons' published data kept in memory, by season; the least recently
/// read season leaves first.
#[derive(Clone, Default)]
pub struct BoardCache {
    seasons: Arc<Mutex<CachedSeasons>>,
    version: crate::results::SharedBoardVersion,
}

#[derive(Default)]
struct CachedSeasons {
    /// Season → (its data's slot, when it was last read, by `clock`).
    seasons: HashMap<i64, (Arc<Versioned<SeasonData>>, u64)>,
    clock: u64,
}

impl CachedSeasons {
    /// The slot of `season`'s data at `version` ([`Versioned::pick`]).
    fn slot(&mut self, season: i64, version: i64) -> Arc<Versioned<SeasonData>> {
        self.clock += 1;
        let slot = match Versioned::pick(self.seasons.get(&season).map(|(slot, _)| slot), version) {
            Pick::Share(slot) => slot,
            Pick::Alone(slot) => return slot,
            Pick::Keep(slot) => {
                if !self.seasons.contains_key(&season) && self.seasons.len() >= MAX_CACHED_SEASONS {
                    if let Some(oldest) = self.seasons.iter().min_by_key(|(_, (_, used))| *used).map(|(s, _)| *s) {
                        self.seasons.remove(&oldest);
                    }
                }
                slot
            }
        };
        self.seasons.insert(season, (slot.clone(), self.clock));
        slot
    }
}

impl BoardCache {
    /// The board version, from a read that began after this call (shared
    /// with the calls waiting at the same time).
    pub async fn version(&self, pool: &AnyPool) -> Result<i64, sqlx::Error> {
        self.version.read(pool).await
    }

    /// `season`'s published data at the current board version, read once
    /// per version and shared (by the boards and the viewer's documents).
    pub async fn season(&self, pool: &AnyPool, season: i64) -> Result<Arc<SeasonData>, sqlx::Error> {
        let version = self.version(pool).await?;
        let slot = match self.seasons.lock() {
            Ok(mut seasons) => seasons.slot(season, version),
            Err(_) => Versioned::new(version),
        };
        // Read after the version: the data is at least as new as the version it is kept under.
        slot.get_or_try_make(|| load_season(pool, season)).await
    }
}

impl SeasonData {
    /// How far a runner's latest calibration (in `machine`, its record)
    /// lies from its class's in this season, when beyond
    /// [`CALIBRATION_DRIFT_LIMIT`]: its times would not compare with the
    /// board's, so it is not handed the season's benchmarks meanwhile
    /// ([`crate::jobs::claim`]). `None` within it, for a runner of another
    /// class, and while no published set of the class has a calibration.
    pub fn drift_of(&self, machine: &serde_json::Value) -> Option<Drift> {
        let class = self.runner_class.as_deref()?;
        if crate::results::runner_class(machine) != Some(class) {
            return None;
        }
        let of_class: Vec<&ResultSet> = self
            .sets
            .iter()
            .filter(|s| crate::results::runner_class(&s.provenance["machine"]) == Some(class))
            .collect();
        drift_from(&class_calibrations(&of_class), machine)
    }
}

async fn load_season(pool: &AnyPool, season: i64) -> Result<SeasonData, sqlx::Error> {
    use crate::results::Selection;
    let mut tags = BTreeMap::new();
    crate::results::scene_tags(pool, Selection::Published(season), &mut tags).await?;
    Ok(SeasonData {
        runner_class: crate::results::season_class(pool, season).await?,
        sets: crate::results::published(pool, season).await?,
        runs: crate::results::runs(pool, Selection::Published(season)).await?,
        tags,
        boards: Mutex::new(HashMap::new()),
        pages: Mutex::new(HashMap::new()),
        documents: Mutex::new(HashMap::new()),
    })
}

/// Builds the board of `query.season` (or `extra`'s season), adding
/// `extra` (a private set) if given. Boards are assembled once per version
/// of the season's published data: public ones per (sort, tag), private
/// pages' per set too.
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
    let key = (query.sort.clone(), query.tag.clone());
    let class = data.runner_class.as_deref();
    let Some(extra) = extra else {
        if let Some(board) = data.boards.lock().ok().and_then(|b| b.get(&key).cloned()) {
            return Ok(board);
        }
        let board = Arc::new(assemble(season, class, &data.sets, &data.runs, &data.tags, query, None));
        if let Ok(mut boards) = data.boards.lock() {
            // Bounded: only metric and tag names that exist are worth keeping.
            if boards.len() < 256 {
                boards.insert(key, board.clone());
            }
        }
        return Ok(board);
    };
    let page_key = (extra.id.clone(), key);
    if let Some(board) = data.pages.lock().ok().and_then(|p| p.get(&page_key).cloned()) {
        return Ok(board);
    }
    let highlighted = Some(extra.id.as_str());
    let board = if data.sets.iter().any(|s| s.id == extra.id) {
        Arc::new(assemble(season, class, &data.sets, &data.runs, &data.tags, query, highlighted))
    } else {
        let mut sets = data.sets.clone();
        sets.push(extra.clone());
        let mut runs = data.runs.clone();
        runs.extend(crate::results::runs(pool, Selection::One(&extra.id)).await?);
        let mut tags = data.tags.clone();
        crate::results::scene_tags(pool, Selection::One(&extra.id), &mut tags).await?;
        Arc::new(assemble(season, class, &sets, &runs, &tags, query, highlighted))
    };
    if let Ok(mut pages) = data.pages.lock() {
        if pages.len() >= MAX_CACHED_PAGES {
            pages.clear();
        }
        pages.insert(page_key, board.clone());
    }
    Ok(board)
}

/// The runs of `runs` scored against each scene's current reference: the
/// one the newest set (of `sets`) that ran the scene was scored against, or
/// on a private page (`page`) the page's own set's. Sets scored against
/// another (an older renderer, other scene files) cannot be compared with
/// it. Also returns a line per scene that lost runs.
pub fn one_reference_per_scene<'a>(
    sets: &[ResultSet],
    runs: &'a [StoredRun],
    page: Option<&str>,
) -> (Vec<&'a StoredRun>, Vec<String>) {
    let created: HashMap<&str, (bool, i64, &str)> =
        sets.iter().map(|s| (s.id.as_str(), (page == Some(s.id.as_str()), s.created_at, s.id.as_str()))).collect();
    let mut current: BTreeMap<&str, ((bool, i64, &str), &str)> = BTreeMap::new();
    for run in runs {
        let Some(&when) = created.get(run.result_id.as_str()) else { continue };
        let newest = current.entry(&run.scene).or_insert((when, &run.reference_hash));
        if when > newest.0 {
            *newest = (when, &run.reference_hash);
        }
    }
    let mut left: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
    let kept = runs
        .iter()
        .filter(|r| {
            let same = current.get(r.scene.as_str()).is_none_or(|(_, hash)| *hash == r.reference_hash);
            if !same {
                left.entry(&r.scene).or_default().insert(&r.result_id);
            }
            same
        })
        .collect();
    let notes = left
        .into_iter()
        .map(|(scene, sets)| {
            let hash = current[scene].1;
            format!(
                "{scene}: {} result set(s) scored against an earlier reference are left out; \
                 this board ranks the runs scored against {}",
                sets.len(),
                &hash[..hash.len().min(19)]
            )
        })
        .collect();
    (kept, notes)
}

/// How far a result set's calibration (its runner's CPU time for the
/// calibration workload, measured before the job) may lie from its class's
/// before its times are left out of equal time: 10 %. One runner's
/// calibrations lay within 2.3 % of their median idle and within 5 % with
/// both cores' memory bandwidth taken by other processes (ci-runner/README.md,
/// "Calibration drift"), so a set beyond this was measured on a machine
/// that had become another one (a capped clock, a busy sibling
/// hyper-thread), and its costs would move its ranks by the machine, not
/// by its work. A tighter limit would hold runners back on noise.
pub const CALIBRATION_DRIFT_LIMIT: f64 = 0.10;

/// Why equal time leaves a result set out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Untimed {
    /// Measured on another runner class than the season's.
    OtherClass,
    /// Measured while its runner's calibration was off its class's.
    Drifted(Drift),
}

impl Untimed {
    /// In a few words, for the viewer's labels.
    pub fn reason(&self) -> String {
        match self {
            Untimed::OtherClass => "another runner class".to_string(),
            Untimed::Drifted(d) => format!("its runner's calibration {:+.0} % from its class's", 100.0 * d.ratio()),
        }
    }
}

/// The sets of `sets` that equal time leaves out when the season's times
/// come from `class` (none while it names none), by set id.
pub fn untimed_sets<'a>(sets: &'a [ResultSet], class: Option<&str>) -> BTreeMap<&'a str, Untimed> {
    let Some(class) = class else { return BTreeMap::new() };
    let (of_class, other): (Vec<&ResultSet>, Vec<&ResultSet>) =
        sets.iter().partition(|s| crate::results::runner_class(&s.provenance["machine"]) == Some(class));
    let mut untimed: BTreeMap<&str, Untimed> = other.iter().map(|s| (s.id.as_str(), Untimed::OtherClass)).collect();
    untimed.extend(drifted_calibrations(&of_class).into_iter().map(|(id, drift)| (id, Untimed::Drifted(drift))));
    untimed
}

/// The runs of `runs` that equal time may compare: those of the sets
/// measured on `class`, the runner class the season's times come from (all
/// of them while it names none), whose runner's calibration was within
/// [`CALIBRATION_DRIFT_LIMIT`] of the class's. A cost is CPU time, and CPU
/// time depends on the CPU: a technique measured on a faster class, or on
/// a runner that had slowed down, would win or lose on the machine, not on
/// its work. Also returns lines saying what was left out and why.
fn one_runner_class<'a>(
    sets: &[ResultSet],
    runs: &[&'a StoredRun],
    class: Option<&str>,
) -> (Vec<&'a StoredRun>, Vec<String>) {
    let untimed = untimed_sets(sets, class);
    let (kept, left): (Vec<&StoredRun>, Vec<&StoredRun>) =
        runs.iter().partition(|r| !untimed.contains_key(r.result_id.as_str()));
    let left: BTreeSet<&str> = left.iter().map(|r| r.result_id.as_str()).collect();
    let mut notes = Vec::new();
    let left_other = left.iter().filter(|id| untimed[*id] == Untimed::OtherClass).count();
    // Sets are untimed only under a named class.
    if let Some(class) = class.filter(|_| left_other > 0) {
        notes.push(format!(
            "{left_other} result set(s) measured on another runner class are ranked at equal spp only: \
             equal time compares the runs of this season's class, {class}"
        ));
    }
    let left_drifted: Vec<String> = left
        .iter()
        .filter_map(|id| match untimed[*id] {
            Untimed::Drifted(drift) => {
                let technique = sets.iter().find(|s| s.id == *id).map_or("?", |s| s.technique.as_str());
                Some(format!("{technique} ({})", drift.figures()))
            }
            Untimed::OtherClass => None,
        })
        .collect();
    if !left_drifted.is_empty() {
        notes.push(format!(
            "{} result set(s) measured while their runner's calibration was more than {:.0} % from its class's \
             are ranked at equal spp only (their costs would rank the machine): {}",
            left_drifted.len(),
            100.0 * CALIBRATION_DRIFT_LIMIT,
            left_drifted.join(", ")
        ));
    }
    (kept, notes)
}

/// A result set's calibration against its class's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drift {
    /// The set's runner's CPU time for the calibration workload, in ms.
    pub cpu_ms: f64,
    /// The class's: the median over the sets compared.
    pub class_ms: f64,
}

impl Drift {
    /// How far the set's calibration lies from the class's, as a fraction.
    pub fn ratio(&self) -> f64 {
        self.cpu_ms / self.class_ms - 1.0
    }

    /// `44.1 ms against 39.4 ms, +12 %`.
    pub fn figures(&self) -> String {
        format!("{:.1} ms against {:.1} ms, {:+.0} %", self.cpu_ms, self.class_ms, 100.0 * self.ratio())
    }
}

/// A result set's or a runner's calibration: (workload, CPU ms), from its
/// machine record; `None` without one (from before calibrations).
fn calibration_of(machine: &serde_json::Value) -> Option<(&str, f64)> {
    let c = &machine["calibration"];
    Some((c["workload"].as_str()?, c["cpu_ms"].as_f64().filter(|ms| *ms > 0.0)?))
}

/// A runner class's calibration by workload: the median over the sets of
/// `of_class` (calibrations compare only under one workload).
fn class_calibrations<'a>(of_class: &[&'a ResultSet]) -> BTreeMap<&'a str, f64> {
    let mut by_workload: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
    for (workload, ms) in of_class.iter().filter_map(|s| calibration_of(&s.provenance["machine"])) {
        by_workload.entry(workload).or_default().push(ms);
    }
    by_workload
        .into_iter()
        .filter_map(|(workload, ms)| Some((workload, fbksd_exchange::stats::Spread::of(&ms)?.median)))
        .collect()
}

/// How far `machine`'s calibration lies from `class_ms`'s, when beyond
/// [`CALIBRATION_DRIFT_LIMIT`].
fn drift_from(class_ms: &BTreeMap<&str, f64>, machine: &serde_json::Value) -> Option<Drift> {
    let (workload, cpu_ms) = calibration_of(machine)?;
    let drift = Drift { cpu_ms, class_ms: *class_ms.get(workload)? };
    (drift.ratio().abs() > CALIBRATION_DRIFT_LIMIT).then_some(drift)
}

/// The sets among `of_class` (one runner class) whose calibration lies
/// beyond [`CALIBRATION_DRIFT_LIMIT`] from the median of theirs, by set id.
/// A set without one (from before calibrations) is kept, as before.
fn drifted_calibrations<'a>(of_class: &[&'a ResultSet]) -> BTreeMap<&'a str, Drift> {
    let class_ms = class_calibrations(of_class);
    of_class.iter().filter_map(|s| Some((s.id.as_str(), drift_from(&class_ms, &s.provenance["machine"])?))).collect()
}

/// The pure part of [`build`].
fn assemble(
    season: i64,
    runner_class: Option<&str>,
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

    let (runs, mut left_out) = one_reference_per_scene(sets, runs, highlighted);
    let runs: Vec<&StoredRun> =
        runs.into_iter().filter(|r| shown(&r.scene) && technique_of.contains_key(r.result_id.as_str())).collect();
    let (timed, other_class) = one_runner_class(sets, &runs, runner_class);
    left_out.extend(other_class);
    let timed: BTreeSet<(&str, &str, i64)> =
        timed.iter().map(|r| (r.result_id.as_str(), r.scene.as_str(), r.spp)).collect();
    // Every shown run as an index entry of its result set (techniques are
    // told apart by set id), its repeats summed up; and whether equal time
    // may compare it.
    let index: Vec<(IndexEntry, bool)> = runs
        .iter()
        .map(|r| (r.index_entry(&r.result_id), timed.contains(&(r.result_id.as_str(), r.scene.as_str(), r.spp))))
        .collect();
    // Rank by the sort metric only.
    let by_sort: Vec<(IndexEntry, bool)> = index
        .iter()
        .cloned()
        .map(|(mut e, timed)| {
            e.metrics.retain(|m, _| *m == sort);
            e.repeats.iter_mut().for_each(|r| r.metrics.retain(|m, _| *m == sort));
            (e, timed)
        })
        .collect();
    let timed_only = |entries: &[(IndexEntry, bool)]| -> Vec<IndexEntry> {
        entries.iter().filter(|(_, timed)| *timed).map(|(e, _)| e.clone()).collect()
    };
    let at_time = equal_time(&timed_only(&by_sort), lower_is_better);
    let costs = fbksd_exchange::cost::Costs::of(&timed_only(&index));
    let at_spp = equal_spp(&by_sort.into_iter().map(|(e, _)| e).collect::<Vec<_>>(), lower_is_better);
    let places: BTreeMap<(&str, u64, &str), &fbksd_exchange::ranking::Place> = at_spp
        .cells
        .iter()
        .filter_map(|c| match c.at {
            At::Spp { spp } => Some(c.places.iter().map(move |p| ((c.scene.as_str(), spp, p.technique.as_str()), p))),
            At::Time { .. } => None,
        })
        .flatten()
        .collect();

    let mut by_group: BTreeMap<(String, i64), Vec<Entry>> = BTreeMap::new();
    for (run, timed) in &index {
        let set = technique_of[run.technique.as_str()];
        let place = places.get(&(run.scene.as_str(), run.spp, run.technique.as_str()));
        by_group.entry((run.scene.clone(), run.spp as i64)).or_default().push(Entry {
            technique: set.technique.clone(),
            full_name: set.full_name().to_string(),
            result_id: set.id.clone(),
            highlighted: highlighted == Some(set.id.as_str()),
            status: run.status.as_str().to_string(),
            message: run.message.clone(),
            values: metrics.iter().map(|m| run.metrics.get(&m.acronym).copied()).collect(),
            intervals: metrics.iter().map(|m| run.intervals.get(&m.acronym).copied()).collect(),
            place: place.map(|p| p.place),
            tied_with: place
                .map(|p| p.tied_with.iter().filter_map(|id| technique_of.get(id.as_str())).map(|s| s.technique.clone()))
                .into_iter()
                .flatten()
                .collect(),
            technique_ms: run.technique_ms,
            cost_ms: if *timed { costs.of_run(run) } else { f64::NAN },
            time_cv: run.timing.filter(|_| run.repeats.len() > 1).map(|t| t.technique.cv),
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

    let time_rank: BTreeMap<&str, f64> =
        at_time.standings.iter().map(|s| (s.technique.as_str(), s.mean_rank)).collect();
    let standings = at_spp
        .standings
        .iter()
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
                tied: s.tied,
                mean_rank_time: time_rank.get(s.technique.as_str()).copied().unwrap_or(f64::NAN),
            })
        })
        .filter(|s| s.mean_rank.is_finite())
        .collect();
    let tags: BTreeSet<String> = scene_tags.values().flatten().cloned().collect();
    Board {
        season,
        metrics,
        sort,
        tags: tags.into_iter().collect(),
        tag: query.tag.clone(),
        standings,
        groups,
        left_out,
        runner_class: runner_class.map(str::to_string),
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) fn set(id: &str, technique: &str) -> ResultSet {
        ResultSet {
            id: id.into(),
            technique: technique.into(),
            project: Some(technique.into()),
            project_id: Some(format!("project-{technique}")),
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
            repeats: Vec::new(),
            reference_hash: "sha256:current".into(),
        }
    }

    /// A run repeated with seeds 0, 1, 2: MSE per seed, time to result per seed.
    pub(crate) fn repeated(id: &str, scene: &str, spp: i64, mse: [f64; 3], time_ms: f64) -> StoredRun {
        let mut r = run(id, scene, Some(mse[0]), 0.5);
        r.spp = spp;
        r.repeats = mse
            .iter()
            .enumerate()
            .map(|(seed, v)| fbksd_exchange::results::Repeat {
                seed: seed as u64,
                status: fbksd_exchange::RunStatus::Ok,
                message: String::new(),
                log: String::new(),
                image: None,
                technique_ms: time_ms * (1.0 + seed as f64 / 100.0),
                render_ms: 0.0,
                wall_ms: time_ms,
                cpu_ms: time_ms,
                waiting_ms: 0.0,
                technique_cpu_ms: 0.0,
                render_cpu_ms: 0.0,
                sample_floats: 0,
                startup_ms: 0.0,
                peak_memory_bytes: 0,
                used_samples: 0,
                metrics: [("MSE".to_string(), *v)].into(),
            })
            .collect();
        r
    }

    #[test]
    fn the_season_cache_keeps_a_bounded_number_of_seasons_the_least_recently_read_leaving_first() {
        let mut cache = CachedSeasons::default();
        let first = cache.slot(1, 0);
        // Asking for season after season (a query parameter) never grows it past the bound.
        for season in 2..1000 {
            assert!(Arc::ptr_eq(&cache.slot(1, 0), &first), "the season read all along stays");
            cache.slot(season, 0);
            assert!(cache.seasons.len() <= MAX_CACHED_SEASONS);
        }
        assert_eq!(cache.seasons.len(), MAX_CACHED_SEASONS);
        assert!(cache.seasons.contains_key(&999) && !cache.seasons.contains_key(&2));
        // A publish replaces the season's data; a reader of the version before it does not put it back.
        let newer = cache.slot(1, 1);
        assert!(!Arc::ptr_eq(&newer, &first));
        assert!(!Arc::ptr_eq(&cache.slot(1, 0), &newer));
        assert!(Arc::ptr_eq(&cache.slot(1, 1), &newer));
    }

    #[test]
    fn noise_ties_and_the_equal_time_rank_reach_the_board() {
        let sets = [set("a", "alpha"), set("b", "beta"), set("c", "gamma")];
        // alpha and beta differ by float rounding; gamma is 10x better but 4x slower.
        let mut runs = Vec::new();
        for (spp, t) in [(4, 10.0), (16, 40.0)] {
            let e = 1.0 / spp as f64;
            runs.push(repeated("a", "s", spp, [e, 1.1 * e, 0.9 * e], t));
            runs.push(repeated("b", "s", spp, [e * (1.0 + 1e-9), 1.1 * e, 0.9 * e], t));
            runs.push(repeated("c", "s", spp, [0.1 * e, 0.11 * e, 0.09 * e], 4.0 * t));
        }
        let board = assemble(1, None, &sets, &runs, &BTreeMap::new(), &BoardQuery::default(), None);
        let group = &board.groups[0];
        let entry = |t: &str| group.entries.iter().find(|e| e.technique == t).unwrap();
        assert_eq!(entry("alpha").tied_with, ["beta"]);
        assert_eq!((entry("alpha").place, entry("gamma").place), (Some(2.5), Some(1.0)));
        let interval = entry("gamma").intervals[0].expect("repeated runs carry an interval");
        assert!(interval.low < interval.mean && interval.mean < interval.high);
        assert!(entry("alpha").time_cv.unwrap() > 0.0);
        let standing = |t: &str| board.standings.iter().find(|s| s.technique == t).unwrap();
        assert_eq!(standing("gamma").mean_rank, 1.0);
        assert_eq!((standing("alpha").mean_rank, standing("alpha").tied), (2.5, 2));
        // At equal time gamma has no result at alpha's 10 ms (its 4 spp takes 40 ms): last there;
        // at 40 ms its 4 spp (0.025) beats alpha's 16 spp (0.0625).
        assert_eq!(standing("gamma").mean_rank_time, (3.0 + 1.0) / 2.0);
        assert_eq!(standing("alpha").mean_rank_time, (1.5 + 2.5) / 2.0);
    }

    #[test]
    fn equal_time_compares_only_the_seasons_runner_class_and_says_what_it_left_out() {
        let on = |id: &str, technique: &str, class: Option<&str>| {
            let mut s = set(id, technique);
            if let Some(class) = class {
                s.provenance = serde_json::json!({ "machine": { "class": class } });
            }
            s
        };
        let slow = "Slow CPU · x86-64-v2 · 2 cores · 8 GiB";
        // gamma, the same work as alpha, measured on a machine twice as fast
        // (and another set from before classes): on one axis gamma would win
        // every equal-time point on the machine alone.
        let sets = [
            on("a", "alpha", Some(slow)),
            on("b", "beta", Some(slow)),
            on("c", "gamma", Some("Fast CPU")),
            on("d", "delta", None),
        ];
        let mut runs = Vec::new();
        for (spp, t) in [(4, 10.0), (16, 40.0)] {
            let e = 1.0 / spp as f64;
            runs.push(repeated("a", "s", spp, [e, 1.1 * e, 0.9 * e], t));
            runs.push(repeated("b", "s", spp, [2.0 * e, 2.2 * e, 1.8 * e], t));
            runs.push(repeated("c", "s", spp, [e, 1.1 * e, 0.9 * e], t / 2.0));
            runs.push(repeated("d", "s", spp, [e, 1.1 * e, 0.9 * e], t / 2.0));
        }
        let board = assemble(1, Some(slow), &sets, &runs, &BTreeMap::new(), &BoardQuery::default(), None);
        let standing = |t: &str| board.standings.iter().find(|s| s.technique == t).unwrap();
        assert_eq!(standing("alpha").mean_rank_time, 1.0, "alpha is compared with beta only");
        assert_eq!(standing("beta").mean_rank_time, 2.0);
        for other in ["gamma", "delta"] {
            assert!(standing(other).mean_rank_time.is_nan(), "{other} has no equal-time rank");
            // At equal spp every set counts: gamma and delta tie with alpha.
            assert_eq!(standing(other).mean_rank, standing("alpha").mean_rank);
        }
        let entry = |t: &str| board.groups[0].entries.iter().find(|e| e.technique == t).unwrap();
        assert!(entry("gamma").cost_ms.is_nan() && entry("alpha").cost_ms > 0.0);
        assert_eq!(board.runner_class.as_deref(), Some(slow));
        assert_eq!(board.left_out.len(), 1, "{:?}", board.left_out);
        assert!(
            board.left_out[0].starts_with("2 result set(s) measured on another runner class"),
            "{:?}",
            board.left_out
        );
        assert!(board.left_out[0].ends_with(slow), "{:?}", board.left_out);

        // A season that names no class yet compares everything.
        let unnamed = assemble(1, None, &sets, &runs, &BTreeMap::new(), &BoardQuery::default(), None);
        assert!(unnamed.left_out.is_empty() && unnamed.standings.iter().all(|s| s.mean_rank_time.is_finite()));
    }

    #[test]
    fn a_set_measured_off_its_classs_calibration_is_left_out_of_equal_time_and_named() {
        const CLASS: &str = "Some CPU · x86-64-v3 · 2 cores · 8 GiB";
        let calibrated = |id: &str, technique: &str, calibration: serde_json::Value| {
            let mut s = set(id, technique);
            s.provenance = serde_json::json!({ "machine": { "class": CLASS, "calibration": calibration } });
            s
        };
        let ms = |cpu_ms: f64| serde_json::json!({ "workload": "fbksd-calibration-1", "cpu_ms": cpu_ms });
        // The same work everywhere; "hasty" ran on a runner 12 % faster than
        // its class, so its costs look 12 % cheaper.
        let sets = [
            calibrated("a", "alpha", ms(40.0)),
            calibrated("b", "beta", ms(41.0)),
            calibrated("g", "gamma", ms(40.0)),
            calibrated("c", "hasty", ms(35.2)),
            // Within 10 % of the median (40.0), and one from before calibrations: kept.
            calibrated("d", "delta", ms(38.5)),
            calibrated("e", "epsilon", serde_json::Value::Null),
            // Another workload is never compared with this one.
            calibrated("f", "phi", serde_json::json!({ "workload": "fbksd-calibration-2", "cpu_ms": 10.0 })),
        ];
        let mut runs = Vec::new();
        for (spp, t) in [(4, 10.0), (16, 40.0)] {
            let e = 1.0 / spp as f64;
            for id in ["a", "b", "d", "e", "f", "g"] {
                runs.push(repeated(id, "s", spp, [e, 1.1 * e, 0.9 * e], t));
            }
            runs.push(repeated("c", "s", spp, [e, 1.1 * e, 0.9 * e], 0.88 * t));
        }
        let board = assemble(1, Some(CLASS), &sets, &runs, &BTreeMap::new(), &BoardQuery::default(), None);
        let standing = |t: &str| board.standings.iter().find(|s| s.technique == t).unwrap();
        assert!(standing("hasty").mean_rank_time.is_nan(), "hasty has no equal-time rank");
        assert_eq!(standing("hasty").mean_rank, standing("alpha").mean_rank, "equal spp keeps it");
        for kept in ["alpha", "beta", "gamma", "delta", "epsilon", "phi"] {
            assert!(standing(kept).mean_rank_time.is_finite(), "{kept} is compared at equal time");
        }
        assert_eq!(
            board.left_out,
            ["1 result set(s) measured while their runner's calibration was more than 10 % from its class's are \
              ranked at equal spp only (their costs would rank the machine): hasty (35.2 ms against 40.0 ms, -12 %)"]
        );
        // A runner is held back by the same measure against the published sets.
        let season = SeasonData {
            runner_class: Some(CLASS.into()),
            sets: sets.to_vec(),
            runs: Vec::new(),
            tags: BTreeMap::new(),
            boards: Mutex::default(),
            pages: Mutex::default(),
            documents: Mutex::default(),
        };
        let runner = |cpu_ms: f64| serde_json::json!({ "class": CLASS, "calibration": ms(cpu_ms) });
        assert_eq!(
            season.drift_of(&runner(44.4)).map(|d| d.figures()).as_deref(),
            Some("44.4 ms against 40.0 ms, +11 %")
        );
        assert_eq!(season.drift_of(&runner(41.9)), None, "within 10 %");
        let other_class = serde_json::json!({ "class": "Other", "calibration": ms(80.0) });
        assert_eq!(season.drift_of(&other_class), None, "another class is kept out by its class, not its calibration");
    }

    #[test]
    fn a_board_ranks_each_scene_against_one_reference_and_says_what_it_left_out() {
        let (mut old, mut new, other) = (set("old", "old-filter"), set("new", "new-filter"), set("other", "other"));
        old.created_at = 1;
        new.created_at = 2;
        let against = |mut r: StoredRun, hash: &str| {
            r.reference_hash = hash.into();
            r
        };
        let runs = vec![
            against(run("old", "sphere", Some(0.1), 0.5), "sha256:aaaa"),
            against(run("new", "sphere", Some(0.2), 0.5), "sha256:bbbb"),
            against(run("other", "sphere", Some(0.3), 0.5), "sha256:bbbb"),
            // Another scene with one reference loses nothing.
            against(run("old", "bands", Some(0.1), 0.5), "sha256:cccc"),
            against(run("new", "bands", Some(0.2), 0.5), "sha256:cccc"),
        ];
        let sets = [old, new, other];
        let board = assemble(1, None, &sets, &runs, &BTreeMap::new(), &BoardQuery::default(), None);
        let on = |board: &Board, scene: &str| -> Vec<String> {
            let group = board.groups.iter().find(|g| g.scene == scene).unwrap();
            group.entries.iter().map(|e| e.technique.clone()).collect()
        };
        assert_eq!(on(&board, "sphere"), ["new-filter", "other"], "the newest set's reference");
        assert_eq!(on(&board, "bands"), ["old-filter", "new-filter"]);
        assert_eq!(board.left_out.len(), 1, "{:?}", board.left_out);
        assert!(board.left_out[0].starts_with("sphere: 1 result set(s)"), "{:?}", board.left_out);

        // A private page ranks against its own set's references.
        let page = assemble(1, None, &sets, &runs, &BTreeMap::new(), &BoardQuery::default(), Some("old"));
        assert_eq!(on(&page, "sphere"), ["old-filter"]);
        assert!(page.left_out[0].starts_with("sphere: 2 result set(s)"), "{:?}", page.left_out);
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
        let board = assemble(1, None, &sets, &runs, &tags, &BoardQuery::default(), Some("b"));
        assert_eq!(board.sort, "MSE");
        assert_eq!(board.groups[0].entries[0].technique, "beta");
        assert_eq!(board.groups[1].entries[0].technique, "alpha", "a missing value sorts last");
        // Mean ranks: alpha (2 + 1) / 2 = 1.5, beta (1 + 2) / 2 = 1.5 → tie broken by id.
        assert_eq!(board.standings.iter().map(|s| s.mean_rank).collect::<Vec<_>>(), [1.5, 1.5]);
        assert!(board.standings.iter().any(|s| s.highlighted && s.technique == "beta" && s.missing == 1));

        let by_ssim = assemble(
            1,
            None,
            &sets,
            &runs,
            &tags,
            &BoardQuery { sort: Some("SSIM".into()), ..Default::default() },
            None,
        );
        assert_eq!(by_ssim.groups[0].entries[0].technique, "beta", "higher SSIM is better");
        // A failed run has no value by any metric, whatever it recorded.
        assert_eq!(by_ssim.groups[1].entries[0].technique, "alpha");
        assert_eq!(by_ssim.groups[1].entries[1].values, [None, None]);

        let dof =
            assemble(1, None, &sets, &runs, &tags, &BoardQuery { tag: Some("dof".into()), ..Default::default() }, None);
        assert_eq!(dof.groups.len(), 1);
        assert_eq!(dof.standings[0].technique, "beta");
        assert_eq!(dof.tags, ["dof"]);
    }
}
