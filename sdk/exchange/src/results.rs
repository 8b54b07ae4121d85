//! The results directory: images, per-run logs and a machine-readable index.
//!
//! ```text
//! <results>/index.json                              every run, one entry each
//! <results>/<technique>/<scene>/<spp>_<k>.exr         result image of repeat k (32-bit float, scanline)
//! <results>/<technique>/<scene>/<spp>_0.fbpx        the same pixels for the viewer (`crate::pixels`)
//! <results>/<technique>/<scene>/<spp>_0_log.json    the run's RunRecord
//! <results>/<technique>/<scene>/<spp>_0_technique.log   the technique's stdout and stderr
//! <results>/<technique>/<scene>/<spp>_0_<METRIC>.json    a metric's value (`fbksd results compute`)
//! <results>/<technique>/<scene>/<spp>_0_<METRIC>_map.png its error map
//! <results>/renderer-logs/<scene>.log               the renderer's stdout and stderr
//! ```
//!
//! File names follow the original FBKSD (`<spp>_0.exr`, `<spp>_0_log.json`,
//! where 0 is the run number: here, the repeat) and are spelled only here
//! ([`RunFiles`]). Every file listed with `_0` exists for each repeat `k`
//! but the pixel file and the error maps, which only the first repeat has.
//!
//! A run may be repeated with other sample seeds (`fbksd run --repeats`):
//! its index entry then holds every repeat ([`Repeat`]) and sums them up:
//! each metric's mean with its confidence interval ([`Interval`]), each
//! time's median with its spread ([`Spread`]), and the status of the first
//! repeat that failed.
//! The index is rewritten atomically after every run, so an interrupted
//! benchmark keeps every finished run.

use crate::ranking::Ranking;
use crate::record::{RunRecord, RunStatus};
use crate::stats::{Interval, Samples, Spread};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::io;
use std::path::{Path, PathBuf};

/// Name of the index file.
pub const INDEX_FILE: &str = "index.json";
/// Format tag of the index.
pub const INDEX_FORMAT: &str = "fbksd-results";
/// Version of the index format.
pub const INDEX_VERSION: u32 = 1;

/// The file names of one repeat of a run in its `<technique>/<scene>/`
/// directory. The number after the budget is the original's run number,
/// here the repeat (0 for a run made once).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunFiles {
    /// The run's budget in samples per pixel.
    pub spp: u64,
    /// The repeat.
    pub repeat: u32,
}

impl RunFiles {
    /// The files of a run's first (or only) repeat.
    pub fn first(spp: u64) -> RunFiles {
        RunFiles { spp, repeat: 0 }
    }
    /// The result image.
    pub fn image(self) -> String {
        format!("{}_{}.exr", self.spp, self.repeat)
    }
    /// The run's [`RunRecord`].
    pub fn log(self) -> String {
        format!("{}_{}_log.json", self.spp, self.repeat)
    }
    /// The result's pixels for the viewer ([`crate::pixels`]).
    pub fn pixels(self) -> String {
        format!("{}_{}.{}", self.spp, self.repeat, crate::pixels::EXTENSION)
    }
    /// The technique's stdout and stderr.
    pub fn technique_log(self) -> String {
        format!("{}_{}_technique.log", self.spp, self.repeat)
    }
    /// A metric's value record.
    pub fn metric_value(self, metric: &str) -> String {
        format!("{}_{}_{metric}.json", self.spp, self.repeat)
    }
    /// A metric's error map.
    pub fn error_map(self, metric: &str) -> String {
        format!("{}_{}_{metric}_map.png", self.spp, self.repeat)
    }
}

/// What a metric is, in the original FBKSD's IQA `info.json` terms; result
/// uploads carry one per metric their values are in.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MetricInfo {
    /// Short name, e.g. `"MSE"`.
    pub acronym: String,
    /// Full name.
    pub name: String,
    /// Citation.
    pub reference: String,
    /// Whether smaller values are better.
    pub lower_is_better: bool,
    /// Whether the metric draws an error map.
    pub has_error_map: bool,
}

/// One run in the index.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IndexEntry {
    /// Technique name.
    pub technique: String,
    /// Scene name.
    pub scene: String,
    /// Budget in samples per pixel.
    pub spp: u64,
    /// Typed status.
    pub status: RunStatus,
    /// Why (empty for ok).
    pub message: String,
    /// The run's log, relative to the results directory.
    pub log: String,
    /// The result image, relative to the results directory.
    pub image: Option<String>,
    /// Technique time in ms.
    pub technique_ms: f64,
    /// Render time in ms.
    pub render_ms: f64,
    /// Wall time in ms, from starting the technique to its result (0 in
    /// indexes written before it was recorded).
    #[serde(default)]
    pub wall_ms: f64,
    /// CPU time of the technique process in ms.
    #[serde(default)]
    pub cpu_ms: f64,
    /// Peak resident memory of the technique process in bytes.
    #[serde(default)]
    pub peak_memory_bytes: u64,
    /// Samples used.
    pub used_samples: u64,
    /// Metric values by acronym (filled by `fbksd results compute`): the
    /// mean over the repeats.
    #[serde(default)]
    pub metrics: BTreeMap<String, f64>,
    /// Time the technique waited for the renderer, in ms.
    #[serde(default)]
    pub waiting_ms: f64,
    /// Time to the result in ms: the technique's time plus the time it
    /// waited for the renderer to render the samples it asked for (wall
    /// time); 0 in older indexes, where [`IndexEntry::time`] falls back to
    /// the wall time.
    #[serde(default)]
    pub time_ms: f64,
    /// The technique's CPU time in ms, every thread and process, from its
    /// hello to its result (see [`crate::record::Times`]); 0 where it was
    /// not measured.
    #[serde(default)]
    pub technique_cpu_ms: f64,
    /// Start-up in ms (technique start → its hello), shown, not charged.
    #[serde(default)]
    pub startup_ms: f64,
    /// Each metric's 95 % confidence interval over the repeats.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub intervals: BTreeMap<String, Interval>,
    /// The times' spread over the repeats.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timing: Option<Timing>,
    /// Every repeat, by repeat number (empty in indexes written before
    /// repeats: the entry is then its only run, with seed 0).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub repeats: Vec<Repeat>,
}

/// One repeat of a run: the same technique, scene and budget with another
/// sample seed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Repeat {
    /// The renderer's sample seed.
    pub seed: u64,
    /// Typed status.
    pub status: RunStatus,
    /// Why (empty for ok).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub message: String,
    /// The repeat's log, relative to the results directory.
    pub log: String,
    /// Its result image, relative to the results directory.
    pub image: Option<String>,
    /// Technique time in ms.
    pub technique_ms: f64,
    /// Render time in ms.
    pub render_ms: f64,
    /// Wall time in ms.
    pub wall_ms: f64,
    /// CPU time of the technique in ms.
    pub cpu_ms: f64,
    /// Time the technique waited for the renderer, in ms.
    pub waiting_ms: f64,
    /// The technique's CPU time in ms, every thread and process, from its
    /// hello to its result; 0 where not measured.
    #[serde(default)]
    pub technique_cpu_ms: f64,
    /// The renderer's CPU time over the same span; 0 where not measured.
    #[serde(default)]
    pub render_cpu_ms: f64,
    /// Floats per sample of the technique's layout (0 where not recorded).
    #[serde(default)]
    pub sample_floats: u32,
    /// Start-up in ms (technique start → its hello).
    #[serde(default)]
    pub startup_ms: f64,
    /// Peak resident memory of the technique in bytes.
    pub peak_memory_bytes: u64,
    /// Samples used.
    pub used_samples: u64,
    /// Metric values by acronym.
    #[serde(default)]
    pub metrics: BTreeMap<String, f64>,
}

impl Repeat {
    /// Time to the result in ms (see [`IndexEntry::time_ms`]).
    pub fn time_ms(&self) -> f64 {
        self.technique_ms + self.waiting_ms
    }
}

/// How the times of a run's repeats spread.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Technique time.
    pub technique: Spread,
    /// Time to the result (technique + waiting for the renderer).
    pub time: Spread,
    /// Render time.
    pub render: Spread,
    /// CPU time of the technique.
    pub cpu: Spread,
    /// The technique's CPU time, hello → result (absent in older results).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub technique_cpu: Option<Spread>,
}

impl IndexEntry {
    /// An entry with nothing measured yet (and no repeat).
    pub fn new(technique: &str, scene: &str, spp: u64) -> IndexEntry {
        IndexEntry {
            technique: technique.to_string(),
            scene: scene.to_string(),
            spp,
            status: RunStatus::Ok,
            message: String::new(),
            log: String::new(),
            image: None,
            technique_ms: 0.0,
            render_ms: 0.0,
            wall_ms: 0.0,
            cpu_ms: 0.0,
            peak_memory_bytes: 0,
            used_samples: 0,
            metrics: BTreeMap::new(),
            waiting_ms: 0.0,
            time_ms: 0.0,
            technique_cpu_ms: 0.0,
            startup_ms: 0.0,
            intervals: BTreeMap::new(),
            timing: None,
            repeats: Vec::new(),
        }
    }

    /// Wall time to the result in ms: [`IndexEntry::time_ms`], or in older
    /// indexes the wall time (or technique + render time before that). The
    /// equal-time axis is the cost ([`crate::cost`]), which falls back to
    /// this where CPU times were not recorded.
    pub fn time(&self) -> f64 {
        if self.time_ms > 0.0 {
            self.time_ms
        } else if self.wall_ms > 0.0 {
            self.wall_ms
        } else {
            self.technique_ms + self.render_ms
        }
    }

    /// Turns an entry written before repeats into one with its single
    /// repeat (seed 0).
    pub fn upgrade(&mut self) {
        if !self.repeats.is_empty() {
            return;
        }
        self.repeats.push(Repeat {
            seed: 0,
            status: self.status,
            message: self.message.clone(),
            log: self.log.clone(),
            image: self.image.clone(),
            technique_ms: self.technique_ms,
            render_ms: self.render_ms,
            wall_ms: self.wall_ms,
            cpu_ms: self.cpu_ms,
            waiting_ms: (self.wall_ms - self.technique_ms).max(0.0),
            technique_cpu_ms: self.technique_cpu_ms,
            render_cpu_ms: 0.0,
            sample_floats: 0,
            startup_ms: self.startup_ms,
            peak_memory_bytes: self.peak_memory_bytes,
            used_samples: self.used_samples,
            metrics: self.metrics.clone(),
        });
        self.summarize();
    }

    /// The value of `metric` for each sample seed: one per `ok` repeat (the
    /// entry's own value, seed 0, in indexes without repeats); none at all
    /// when the run has no value for it ([`IndexEntry::summarize`]: some
    /// repeat failed, or lacks the metric), so that a run ranks the same way
    /// at equal samples and at equal time.
    pub fn samples(&self, metric: &str) -> Samples {
        if !self.metrics.contains_key(metric) {
            return Samples::new();
        }
        if self.repeats.is_empty() {
            return self.metrics.get(metric).map(|v| (0, *v)).into_iter().collect();
        }
        self.repeats
            .iter()
            .filter(|r| r.status == RunStatus::Ok)
            .filter_map(|r| r.metrics.get(metric).map(|v| (r.seed, *v)))
            .collect()
    }

    /// Recomputes what the entry says about all its repeats: status and
    /// message (the first failed repeat's, naming its seed), median times,
    /// peak memory, mean metric values with their intervals, spreads.
    /// A metric that is missing or not finite on some `ok` repeat has no
    /// value for the run (it ranks last), and the message says where.
    pub fn summarize(&mut self) {
        let Some(first) = self.repeats.first() else { return };
        self.log = first.log.clone();
        self.image = first.image.clone();
        let many = self.repeats.len() > 1;
        match self.repeats.iter().find(|r| r.status != RunStatus::Ok) {
            Some(bad) => {
                self.status = bad.status;
                self.message =
                    if many { format!("repeat with seed {}: {}", bad.seed, bad.message) } else { bad.message.clone() };
            }
            None => {
                self.status = RunStatus::Ok;
                self.message.clear();
            }
        }
        let column = |f: &dyn Fn(&Repeat) -> f64| -> Vec<f64> { self.repeats.iter().map(f).collect() };
        let spread = |f: &dyn Fn(&Repeat) -> f64| Spread::of(&column(f)).expect("at least one repeat");
        let timing = Timing {
            technique: spread(&|r| r.technique_ms),
            time: spread(&|r| r.time_ms()),
            render: spread(&|r| r.render_ms),
            cpu: spread(&|r| r.cpu_ms),
            technique_cpu: self.repeats.iter().all(|r| r.render_cpu_ms > 0.0).then(|| spread(&|r| r.technique_cpu_ms)),
        };
        self.technique_ms = timing.technique.median;
        self.time_ms = timing.time.median;
        self.render_ms = timing.render.median;
        self.cpu_ms = timing.cpu.median;
        self.wall_ms = Spread::of(&column(&|r| r.wall_ms)).map_or(0.0, |s| s.median);
        self.waiting_ms = Spread::of(&column(&|r| r.waiting_ms)).map_or(0.0, |s| s.median);
        self.technique_cpu_ms = timing.technique_cpu.map_or(0.0, |s| s.median);
        self.startup_ms = Spread::of(&column(&|r| r.startup_ms)).map_or(0.0, |s| s.median);
        self.peak_memory_bytes = self.repeats.iter().map(|r| r.peak_memory_bytes).max().unwrap_or(0);
        self.used_samples = self.repeats.iter().map(|r| r.used_samples).max().unwrap_or(0);
        self.timing = Some(timing);
        self.metrics.clear();
        self.intervals.clear();
        if self.status != RunStatus::Ok {
            return;
        }
        let names: BTreeSet<&String> = self.repeats.iter().flat_map(|r| r.metrics.keys()).collect();
        let mut problems = Vec::new();
        for name in names {
            let values: Vec<(u64, Option<f64>)> =
                self.repeats.iter().map(|r| (r.seed, r.metrics.get(name).copied())).collect();
            if let Some((seed, v)) = values.iter().find(|(_, v)| !v.is_some_and(f64::is_finite)) {
                problems.push(match v {
                    Some(v) => format!("{name} is {v} with seed {seed}"),
                    None => format!("{name} is missing with seed {seed}"),
                });
                continue;
            }
            let values: Vec<f64> = values.iter().filter_map(|(_, v)| *v).collect();
            let interval = Interval::of(&values).expect("at least one repeat");
            self.metrics.insert(name.clone(), interval.mean);
            if many {
                self.intervals.insert(name.clone(), interval);
            }
        }
        if !problems.is_empty() {
            self.message = format!("no value (ranks last): {}", problems.join("; "));
        }
    }
}

/// The index file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResultsIndex {
    /// Always [`INDEX_FORMAT`].
    pub format: String,
    /// Always [`INDEX_VERSION`].
    pub version: u32,
    /// Runs, sorted by technique, scene and spp.
    pub runs: Vec<IndexEntry>,
    /// The techniques ranked at equal samples and at equal time, as of the
    /// last `fbksd results compute` (dropped when a run is recorded after it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rankings: Option<IndexRankings>,
}

/// The rankings of an index.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IndexRankings {
    /// At equal samples per pixel.
    pub equal_spp: Ranking,
    /// At equal time to the result.
    pub equal_time: Ranking,
    /// Each run's cost by seed, as the equal-time ranking charged it
    /// ([`crate::cost`]; absent in indexes ranked before costs).
    #[serde(default)]
    pub costs: Vec<RunCost>,
}

/// One run's cost, by sample seed, in ms.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunCost {
    /// Technique.
    pub technique: String,
    /// Scene.
    pub scene: String,
    /// Budget in samples per pixel.
    pub spp: u64,
    /// The cost of each `ok` repeat, by seed.
    pub by_seed: Samples,
}

impl Default for ResultsIndex {
    fn default() -> Self {
        ResultsIndex { format: INDEX_FORMAT.into(), version: INDEX_VERSION, runs: Vec::new(), rankings: None }
    }
}

impl ResultsIndex {
    /// Ranks the runs at equal samples and at equal time, and records the
    /// costs the equal-time ranking charged.
    pub fn rank(&mut self, lower_is_better: impl Fn(&str) -> bool + Copy) {
        let costs = crate::cost::Costs::of(&self.runs);
        self.rankings = Some(IndexRankings {
            equal_spp: crate::ranking::equal_spp(&self.runs, lower_is_better),
            equal_time: crate::ranking::equal_time(&self.runs, lower_is_better),
            costs: self
                .runs
                .iter()
                .map(|r| RunCost {
                    technique: r.technique.clone(),
                    scene: r.scene.clone(),
                    spp: r.spp,
                    by_seed: costs.by_seed(r),
                })
                .collect(),
        });
    }
}

/// A results directory.
#[derive(Debug, Clone)]
pub struct ResultsDir {
    root: PathBuf,
}

impl ResultsDir {
    /// Opens (creating if needed) a results directory.
    pub fn create(root: &Path) -> io::Result<Self> {
        std::fs::create_dir_all(root)?;
        Ok(ResultsDir { root: root.to_path_buf() })
    }

    /// The directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The directory of one technique on one scene (created).
    pub fn run_dir(&self, technique: &str, scene: &str) -> io::Result<PathBuf> {
        let dir = self.root.join(technique).join(scene);
        std::fs::create_dir_all(&dir)?;
        Ok(dir)
    }

    /// Path of a renderer's log for a scene.
    pub fn renderer_log(&self, scene: &str) -> io::Result<PathBuf> {
        let dir = self.root.join("renderer-logs");
        std::fs::create_dir_all(&dir)?;
        Ok(dir.join(format!("{scene}.log")))
    }

    /// Reads the index (an empty one when there is none yet).
    pub fn read_index(&self) -> io::Result<ResultsIndex> {
        let path = self.root.join(INDEX_FILE);
        match std::fs::read(&path) {
            Ok(bytes) => {
                let mut index: ResultsIndex = serde_json::from_slice(&bytes)
                    .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, format!("{}: {e}", path.display())))?;
                index.runs.iter_mut().for_each(IndexEntry::upgrade);
                Ok(index)
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(ResultsIndex::default()),
            Err(e) => Err(e),
        }
    }

    /// Adds (or replaces) a repeat of a run in the index. A run's first
    /// repeat starts it afresh: the run's other repeats, metric values and
    /// files are dropped; a later repeat replaces the one of its number.
    pub fn record(&self, record: &RunRecord, log_path: &Path, image_path: Option<&Path>) -> io::Result<()> {
        let rel = |p: &Path| p.strip_prefix(&self.root).unwrap_or(p).to_string_lossy().into_owned();
        let repeat = Repeat {
            seed: record.seed,
            status: record.status,
            message: record.message.clone(),
            log: rel(log_path),
            image: image_path.map(rel),
            technique_ms: record.times.technique_ms,
            render_ms: record.times.render_ms,
            wall_ms: record.times.wall_ms,
            cpu_ms: record.times.cpu_ms,
            waiting_ms: record.times.waiting_ms,
            technique_cpu_ms: record.times.technique_cpu_ms,
            render_cpu_ms: record.times.render_cpu_ms,
            sample_floats: record.sample_floats,
            startup_ms: record.times.startup_ms,
            peak_memory_bytes: record.peak_memory_bytes,
            used_samples: record.used_samples,
            metrics: BTreeMap::new(),
        };
        let key = (record.technique.as_str(), record.scene.as_str(), record.spp_budget);
        let mut index = self.read_index()?;
        let position = index.runs.iter().position(|r| (r.technique.as_str(), r.scene.as_str(), r.spp) == key);
        let mut entry = match position {
            Some(i) if record.repeat > 0 => index.runs.remove(i),
            Some(i) => {
                let old = index.runs.remove(i);
                self.remove_files(&old);
                IndexEntry::new(&record.technique, &record.scene, record.spp_budget)
            }
            None => IndexEntry::new(&record.technique, &record.scene, record.spp_budget),
        };
        let k = record.repeat as usize;
        if k < entry.repeats.len() {
            self.remove_repeat_files(&entry, k);
            entry.repeats[k] = repeat;
        } else {
            entry.repeats.push(repeat);
        }
        entry.summarize();
        index.runs.push(entry);
        index.rankings = None;
        self.write_index(index)
    }

    /// Removes what `compute` derived from a run (and the files of its
    /// repeats beyond the first, which the next benchmark may not make).
    fn remove_files(&self, old: &IndexEntry) {
        for k in 0..old.repeats.len().max(1) {
            self.remove_repeat_files(old, k);
            if k > 0 {
                let dir = self.root.join(&old.technique).join(&old.scene);
                let files = RunFiles { spp: old.spp, repeat: k as u32 };
                for name in [files.image(), files.log(), files.technique_log()] {
                    let _ = std::fs::remove_file(dir.join(name));
                }
            }
        }
    }

    /// Removes the pixel file, metric values and error maps of repeat `k`.
    fn remove_repeat_files(&self, entry: &IndexEntry, k: usize) {
        let dir = self.root.join(&entry.technique).join(&entry.scene);
        let files = RunFiles { spp: entry.spp, repeat: k as u32 };
        let _ = std::fs::remove_file(dir.join(files.pixels()));
        let metrics: BTreeSet<&String> =
            entry.metrics.keys().chain(entry.repeats.iter().flat_map(|r| r.metrics.keys())).collect();
        for metric in metrics {
            let _ = std::fs::remove_file(dir.join(files.metric_value(metric)));
            let _ = std::fs::remove_file(dir.join(files.error_map(metric)));
        }
    }

    /// Replaces every run of `scene` here, with its files and its
    /// renderer's log, by the runs of `scene` in `other` (a second
    /// measurement of the same runs, made in a directory of its own): the
    /// runs of other scenes are not touched. `other` loses what moved.
    pub fn take_scene(&self, other: &ResultsDir, scene: &str) -> io::Result<()> {
        let mut index = self.read_index()?;
        let theirs = other.read_index()?;
        let techniques: BTreeSet<String> =
            index.runs.iter().chain(&theirs.runs).filter(|r| r.scene == scene).map(|r| r.technique.clone()).collect();
        for technique in &techniques {
            let ours = self.root.join(technique).join(scene);
            if ours.exists() {
                std::fs::remove_dir_all(&ours)?;
            }
            let moved = other.root.join(technique).join(scene);
            if moved.exists() {
                std::fs::create_dir_all(self.root.join(technique))?;
                std::fs::rename(moved, ours)?;
            }
        }
        let log = other.root.join("renderer-logs").join(format!("{scene}.log"));
        if log.exists() {
            std::fs::rename(log, self.renderer_log(scene)?)?;
        }
        index.runs.retain(|r| r.scene != scene);
        index.runs.extend(theirs.runs.into_iter().filter(|r| r.scene == scene));
        index.rankings = None;
        self.write_index(index)
    }

    /// Writes the index (sorted by technique, scene and spp).
    pub fn write_index(&self, mut index: ResultsIndex) -> io::Result<()> {
        index.runs.sort_by(|a, b| (&a.technique, &a.scene, a.spp).cmp(&(&b.technique, &b.scene, b.spp)));
        write_json_atomically(&self.root.join(INDEX_FILE), &index)
    }
}

/// Writes JSON to a temporary file and renames it into place.
pub fn write_json_atomically<T: Serialize>(path: &Path, value: &T) -> io::Result<()> {
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, serde_json::to_vec_pretty(value).map_err(io::Error::other)?)?;
    std::fs::rename(tmp, path)
}

/// Turns a name into a safe single path component (letters, digits, `-_.`).
pub fn path_safe_name(name: &str) -> String {
    let s: String =
        name.chars().map(|c| if c.is_ascii_alphanumeric() || "-_.".contains(c) { c } else { '_' }).collect();
    match s.trim_start_matches('.') {
        "" => "unnamed".into(),
        t => t.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_become_path_components() {
        assert_eq!(path_safe_name("box filter/v2"), "box_filter_v2");
        assert_eq!(path_safe_name(".."), "unnamed");
        assert_eq!(path_safe_name("ok-1.2_x"), "ok-1.2_x");
    }

    /// Records repeat `repeat` of a run with its log file, as a benchmark does.
    fn record(results: &ResultsDir, scene: &str, spp: u64, repeat: u32, technique_ms: f64) {
        let record = RunRecord {
            date: String::new(),
            spp_budget: spp,
            samples_budget: spp * 4,
            used_samples: spp * 4,
            sample_floats: 3,
            aborted: false,
            exec_time: technique_ms,
            status: RunStatus::Ok,
            message: String::new(),
            scene: scene.into(),
            technique: "box".into(),
            width: 2,
            height: 2,
            times: crate::record::Times { technique_ms, ..Default::default() },
            peak_memory_bytes: 1,
            requests: 1,
            image: None,
            technique_log: RunFiles { spp, repeat }.technique_log(),
            seed: repeat as u64,
            repeat,
        };
        let log = results.run_dir("box", scene).unwrap().join(RunFiles { spp, repeat }.log());
        write_json_atomically(&log, &record).unwrap();
        std::fs::write(results.renderer_log(scene).unwrap(), format!("{scene} rendered {technique_ms}")).unwrap();
        results.record(&record, &log, None).unwrap();
    }

    #[test]
    fn a_scene_measured_again_replaces_that_scene_alone() {
        let dir = tempfile::tempdir().unwrap();
        let first = ResultsDir::create(&dir.path().join("results")).unwrap();
        let again = ResultsDir::create(&dir.path().join("again")).unwrap();
        for repeat in 0..2 {
            record(&first, "sphere", 4, repeat, 30.0);
            record(&first, "sin-bands", 4, repeat, 10.0);
            record(&again, "sphere", 4, repeat, 20.0);
        }
        first.take_scene(&again, "sphere").unwrap();

        let index = first.read_index().unwrap();
        let times = |scene: &str| -> Vec<f64> {
            let run = index.runs.iter().find(|r| r.scene == scene).unwrap();
            run.repeats.iter().map(|r| r.technique_ms).collect()
        };
        assert_eq!(times("sphere"), [20.0, 20.0]);
        assert_eq!(times("sin-bands"), [10.0, 10.0]);
        assert_eq!(index.runs.len(), 2);
        // The files moved with the entries: each repeat's log is the second measurement's.
        for repeat in &index.runs.iter().find(|r| r.scene == "sphere").unwrap().repeats {
            let log: RunRecord =
                serde_json::from_slice(&std::fs::read(first.root().join(&repeat.log)).unwrap()).unwrap();
            assert_eq!(log.times.technique_ms, 20.0);
        }
        let renderer_log = std::fs::read_to_string(first.renderer_log("sphere").unwrap()).unwrap();
        assert_eq!(renderer_log, "sphere rendered 20");
        assert!(!again.root().join("box").join("sphere").exists());
    }
}
