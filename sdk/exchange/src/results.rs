//! The results directory: images, per-run logs and a machine-readable index.
//!
//! ```text
//! <results>/index.json                              every run, one entry each
//! <results>/<technique>/<scene>/<spp>_0.exr         result image (32-bit float, scanline)
//! <results>/<technique>/<scene>/<spp>_0.fbpx        the same pixels for the viewer (`crate::pixels`)
//! <results>/<technique>/<scene>/<spp>_0_log.json    the run's RunRecord
//! <results>/<technique>/<scene>/<spp>_0_technique.log   the technique's stdout and stderr
//! <results>/<technique>/<scene>/<spp>_0_<METRIC>.json    a metric's value (`fbksd results compute`)
//! <results>/<technique>/<scene>/<spp>_0_<METRIC>_map.png its error map
//! <results>/renderer-logs/<scene>.log               the renderer's stdout and stderr
//! ```
//!
//! File names follow the original FBKSD (`<spp>_0.exr`, `<spp>_0_log.json`)
//! and are spelled only here ([`RunFiles`]).
//! The index is rewritten atomically after every run, so an interrupted
//! benchmark keeps every finished run.

use crate::record::{RunRecord, RunStatus};
use serde::{Deserialize, Serialize};
use std::io;
use std::path::{Path, PathBuf};

/// Name of the index file.
pub const INDEX_FILE: &str = "index.json";
/// Format tag of the index.
pub const INDEX_FORMAT: &str = "fbksd-results";
/// Version of the index format.
pub const INDEX_VERSION: u32 = 1;

/// The file names of one run in its `<technique>/<scene>/` directory. The
/// `_0` is the original's run number: one run per budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunFiles {
    /// The run's budget in samples per pixel.
    pub spp: u64,
}

impl RunFiles {
    /// The result image.
    pub fn image(self) -> String {
        format!("{}_0.exr", self.spp)
    }
    /// The run's [`RunRecord`].
    pub fn log(self) -> String {
        format!("{}_0_log.json", self.spp)
    }
    /// The result's pixels for the viewer ([`crate::pixels`]).
    pub fn pixels(self) -> String {
        format!("{}_0.{}", self.spp, crate::pixels::EXTENSION)
    }
    /// The technique's stdout and stderr.
    pub fn technique_log(self) -> String {
        format!("{}_0_technique.log", self.spp)
    }
    /// A metric's value record.
    pub fn metric_value(self, metric: &str) -> String {
        format!("{}_0_{metric}.json", self.spp)
    }
    /// A metric's error map.
    pub fn error_map(self, metric: &str) -> String {
        format!("{}_0_{metric}_map.png", self.spp)
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
    /// Metric values by acronym (filled by `fbksd results compute`).
    #[serde(default)]
    pub metrics: std::collections::BTreeMap<String, f64>,
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
}

impl Default for ResultsIndex {
    fn default() -> Self {
        ResultsIndex { format: INDEX_FORMAT.into(), version: INDEX_VERSION, runs: Vec::new() }
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
            Ok(bytes) => serde_json::from_slice(&bytes)
                .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, format!("{}: {e}", path.display()))),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(ResultsIndex::default()),
            Err(e) => Err(e),
        }
    }

    /// Adds (or replaces) a run in the index.
    pub fn record(&self, record: &RunRecord, log_path: &Path, image_path: Option<&Path>) -> io::Result<()> {
        let rel = |p: &Path| p.strip_prefix(&self.root).unwrap_or(p).to_string_lossy().into_owned();
        let entry = IndexEntry {
            technique: record.technique.clone(),
            scene: record.scene.clone(),
            spp: record.spp_budget,
            status: record.status,
            message: record.message.clone(),
            log: rel(log_path),
            image: image_path.map(rel),
            technique_ms: record.times.technique_ms,
            render_ms: record.times.render_ms,
            wall_ms: record.times.wall_ms,
            cpu_ms: record.times.cpu_ms,
            peak_memory_bytes: record.peak_memory_bytes,
            used_samples: record.used_samples,
            metrics: Default::default(),
        };
        let mut index = self.read_index()?;
        // A run replaced by a new one loses its old metric values and files.
        if let Some(old) =
            index.runs.iter().find(|r| (&r.technique, &r.scene, r.spp) == (&entry.technique, &entry.scene, entry.spp))
        {
            let dir = self.root.join(&old.technique).join(&old.scene);
            let files = RunFiles { spp: old.spp };
            let _ = std::fs::remove_file(dir.join(files.pixels()));
            for metric in old.metrics.keys() {
                let _ = std::fs::remove_file(dir.join(files.metric_value(metric)));
                let _ = std::fs::remove_file(dir.join(files.error_map(metric)));
            }
        }
        index.runs.retain(|r| (&r.technique, &r.scene, r.spp) != (&entry.technique, &entry.scene, entry.spp));
        index.runs.push(entry);
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
}
