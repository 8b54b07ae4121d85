//! The results viewer's document: everything `frontend/static/viewer/`
//! shows, as one JSON value. The server builds it from its database
//! (`GET /api/v1/results/<id>/viewer`) and `fbksd results page` from a
//! results directory, so the one viewer reads both.
//!
//! Addresses (`pixels`, `log`, `error_maps`, a scene's `reference`) are
//! relative to the page. How the viewer loads pixels depends on
//! [`Delivery`]: a page from a server fetches them; a folder opened from
//! `file://`, where browsers refuse `fetch`, loads them as scripts.

use crate::cost::Costs;
use crate::ranking::Cell;
use crate::results::{IndexEntry, MetricInfo, Timing};
use crate::stats::Interval;
use crate::RunStatus;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Format tag of the document.
pub const FORMAT: &str = "fbksd-viewer";
/// Version of the document's format.
pub const VERSION: u32 = 1;

/// How the viewer loads pixel files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Delivery {
    /// `fetch(address)` returns the `.fbpx` bytes.
    Fetch,
    /// `<script src=address>` calls `fbksdPixels(address, base64)`.
    Script,
}

/// The viewer's document.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewerData {
    /// Always [`FORMAT`].
    pub format: String,
    /// Always [`VERSION`].
    pub version: u32,
    /// The page's heading.
    pub title: String,
    /// How pixels load.
    pub delivery: Delivery,
    /// The technique (its [`ViewerTechnique::key`]) whose row stands out.
    pub highlight: Option<String>,
    /// The metrics the values are in.
    pub metrics: Vec<MetricInfo>,
    /// The scenes, by name.
    pub scenes: Vec<ViewerScene>,
    /// The techniques compared.
    pub techniques: Vec<ViewerTechnique>,
    /// Every ranking cell, at equal samples and at equal time (techniques
    /// by key): the viewer averages their places over the scenes shown, so
    /// its ranking has the ties and the rule of [`crate::ranking`].
    #[serde(default)]
    pub rankings: Rankings,
    /// The runner class the document's times come from, when the runs were
    /// measured on more than one machine: the time charts leave out the
    /// techniques measured on another ([`ViewerTechnique::runner_class`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub runner_class: Option<String>,
}

/// The ranking cells of a document.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Rankings {
    /// A cell per (scene, spp, metric).
    pub equal_spp: Vec<Cell>,
    /// A cell per (scene, time point, metric).
    pub equal_time: Vec<Cell>,
}

impl Rankings {
    /// The cells of `runs`, whose `technique` is the document's technique
    /// key: equal spp over all of them, equal time over those `timed` keeps
    /// (the runs measured on one runner class).
    pub fn of(
        runs: &[IndexEntry],
        timed: impl Fn(&IndexEntry) -> bool,
        lower_is_better: impl Fn(&str) -> bool + Copy,
    ) -> Rankings {
        let timed: Vec<IndexEntry> = runs.iter().filter(|r| timed(r)).cloned().collect();
        Rankings {
            equal_spp: crate::ranking::equal_spp(runs, lower_is_better).cells,
            equal_time: crate::ranking::equal_time(&timed, lower_is_better).cells,
        }
    }
}

impl ViewerData {
    /// Sets each run's cost from the index entries of the document's runs
    /// (their `technique` the technique's key), pooled over all of them as
    /// the equal-time ranking pools it.
    pub fn set_costs(&mut self, runs: &[IndexEntry]) {
        let costs = Costs::of(runs);
        let by_key: BTreeMap<(&str, &str, u64), &IndexEntry> =
            runs.iter().map(|e| ((e.technique.as_str(), e.scene.as_str(), e.spp), e)).collect();
        for technique in &mut self.techniques {
            for run in &mut technique.runs {
                if let Some(entry) = by_key.get(&(technique.key.as_str(), run.scene.as_str(), run.spp)) {
                    run.cost_ms = costs.of_run(entry);
                }
            }
        }
    }

    /// An empty document.
    pub fn new(title: impl Into<String>, delivery: Delivery) -> ViewerData {
        ViewerData {
            format: FORMAT.into(),
            version: VERSION,
            title: title.into(),
            delivery,
            highlight: None,
            metrics: Vec::new(),
            scenes: Vec::new(),
            techniques: Vec::new(),
            rankings: Rankings::default(),
            runner_class: None,
        }
    }
}

/// A scene of the document.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewerScene {
    /// Scene name.
    pub name: String,
    /// Its pool tags.
    pub tags: Vec<String>,
    /// The reference's pixel file, when known.
    pub reference: Option<String>,
    /// The pixel files of the feature buffers made with the reference, by
    /// name ([`crate::scenes::FEATURE_BUFFERS`]), those that exist.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub buffers: BTreeMap<String, String>,
}

/// A technique of the document.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewerTechnique {
    /// Unique within the document (a result set's UUID, or a name).
    pub key: String,
    /// Short name.
    pub name: String,
    /// Full name.
    pub full_name: String,
    /// Citation, if any.
    pub citation: String,
    /// The runner class its runs were measured on, when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub runner_class: Option<String>,
    /// Why equal time leaves its runs out, when it does: measured on
    /// another runner class than the document's, or while its runner's
    /// calibration was off its class's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub untimed: Option<String>,
    /// Its runs.
    pub runs: Vec<ViewerRun>,
}

/// One run of a technique.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewerRun {
    /// Scene name.
    pub scene: String,
    /// Budget in samples per pixel.
    pub spp: u64,
    /// Typed status.
    pub status: RunStatus,
    /// Why (empty for ok).
    pub message: String,
    /// Technique time in ms.
    pub technique_ms: f64,
    /// Render time in ms.
    pub render_ms: f64,
    /// Wall time in ms (0 when not recorded).
    pub wall_ms: f64,
    /// CPU time in ms (0 when not recorded).
    pub cpu_ms: f64,
    /// Peak resident memory in bytes (0 when not recorded).
    pub peak_memory_bytes: u64,
    /// Samples used.
    pub used_samples: u64,
    /// Metric values by acronym.
    pub metrics: BTreeMap<String, f64>,
    /// The result's pixel file.
    pub pixels: Option<String>,
    /// The technique's output.
    pub log: Option<String>,
    /// Error maps (PNG) by metric acronym.
    pub error_maps: BTreeMap<String, String>,
    /// Time to the result in ms: technique time + waiting for the renderer.
    #[serde(default)]
    pub time_ms: f64,
    /// Repeats (sample seeds) the values and times are over.
    #[serde(default)]
    pub seeds: usize,
    /// Each metric's 95 % confidence interval over the repeats.
    #[serde(default)]
    pub intervals: BTreeMap<String, Interval>,
    /// The times' spread over the repeats.
    #[serde(default)]
    pub timing: Option<Timing>,
    /// The run's cost in ms, the equal-time axis ([`crate::cost`]: pooled
    /// over the document's runs, so set by [`ViewerData::set_costs`], not
    /// by [`ViewerRun::measured`]).
    #[serde(default)]
    pub cost_ms: f64,
    /// The technique's CPU time in ms, hello → result (median).
    #[serde(default)]
    pub technique_cpu_ms: f64,
    /// Start-up in ms, before the technique's hello (median): not charged.
    #[serde(default)]
    pub startup_ms: f64,
}

impl ViewerRun {
    /// A run's measurements from its index entry; the caller adds the
    /// addresses of its files.
    pub fn measured(entry: &IndexEntry) -> ViewerRun {
        ViewerRun {
            scene: entry.scene.clone(),
            spp: entry.spp,
            status: entry.status,
            message: entry.message.clone(),
            technique_ms: entry.technique_ms,
            render_ms: entry.render_ms,
            wall_ms: entry.wall_ms,
            cpu_ms: entry.cpu_ms,
            peak_memory_bytes: entry.peak_memory_bytes,
            used_samples: entry.used_samples,
            metrics: entry.metrics.clone(),
            pixels: None,
            log: None,
            error_maps: BTreeMap::new(),
            time_ms: entry.time(),
            seeds: entry.repeats.len().max(1),
            intervals: entry.intervals.clone(),
            timing: entry.timing,
            cost_ms: 0.0,
            technique_cpu_ms: entry.technique_cpu_ms,
            startup_ms: entry.startup_ms,
        }
    }
}

/// The viewer's code (`frontend/static/viewer/`), compiled in so that the
/// server and `fbksd results page` ship the same files: (name, text), in
/// the order the page loads them.
pub const ASSETS: &[(&str, &str)] = &[
    ("viewer.css", include_str!("../../../frontend/static/viewer/viewer.css")),
    ("pixels.js", include_str!("../../../frontend/static/viewer/pixels.js")),
    ("images.js", include_str!("../../../frontend/static/viewer/images.js")),
    ("charts.js", include_str!("../../../frontend/static/viewer/charts.js")),
    ("tables.js", include_str!("../../../frontend/static/viewer/tables.js")),
    ("viewer.js", include_str!("../../../frontend/static/viewer/viewer.js")),
];

/// The `<link>` and `<script>` tags that load [`ASSETS`] from `base`
/// (`"/static/viewer/"`, or `"viewer/"` in a static folder).
pub fn asset_tags(base: &str) -> String {
    ASSETS
        .iter()
        .map(|(name, _)| {
            if name.ends_with(".css") {
                format!("<link rel=\"stylesheet\" href=\"{base}{name}\">\n")
            } else {
                format!("<script src=\"{base}{name}\"></script>\n")
            }
        })
        .collect()
}
