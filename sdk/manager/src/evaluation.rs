//! Metric values and error maps for every run of a results directory.
//!
//! `compute` is incremental: a repeat's metric is computed only when its
//! value file ([`RunFiles::metric_value`]) is missing; a run's first repeat
//! also gets error maps ([`RunFiles::error_map`]) and the viewer's pixel
//! file of its image ([`RunFiles::pixels`]). Values are gathered into
//! `index.json`, where each run sums its repeats up
//! ([`IndexEntry::summarize`]).
//!
//! [`IndexEntry::summarize`]: fbksd_exchange::results::IndexEntry::summarize
//! Ranking the techniques is [`fbksd_exchange::ranking`]'s.

use fbksd_exchange::results::{path_safe_name, ResultsDir, RunFiles};
use fbksd_exchange::scenes::{SceneMeta, META_FILE};
use fbksd_iqa::external::ExternalMetric;
use fbksd_iqa::image::Image;
use fbksd_iqa::{evaluate, Metric, MetricInfo, ValueRecord};
use std::collections::BTreeMap;
use std::io;
use std::path::{Path, PathBuf};

/// A metric to compute: built in or external.
#[derive(Debug, Clone)]
pub enum AnyMetric {
    /// A built-in metric.
    Builtin(Metric),
    /// An external program.
    External(ExternalMetric),
}

impl AnyMetric {
    /// What it is.
    pub fn info(&self) -> MetricInfo {
        match self {
            AnyMetric::Builtin(m) => m.info(),
            AnyMetric::External(e) => e.info.clone(),
        }
    }
}

/// What `compute` did.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct ComputeSummary {
    /// Metric values computed now.
    pub computed: usize,
    /// Values already there.
    pub kept: usize,
    /// Runs not evaluated: not `ok`, or no reference (with why).
    pub skipped: Vec<String>,
}

/// Finds every scene's metadata under `roots`, by scene name.
pub fn find_scenes(roots: &[PathBuf]) -> io::Result<BTreeMap<String, SceneMeta>> {
    fn walk(dir: &Path, depth: usize, out: &mut BTreeMap<String, SceneMeta>) -> io::Result<()> {
        if dir.join(META_FILE).is_file() {
            let meta = SceneMeta::load(dir).map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e.to_string()))?;
            if let Some(other) = out.get(&path_safe_name(&meta.name)) {
                // Results are filed by scene name: two scenes of one name would share a reference.
                return Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    format!("two scenes are named {:?}: {} and {}", meta.name, other.dir.display(), meta.dir.display()),
                ));
            }
            out.insert(path_safe_name(&meta.name), meta);
            return Ok(());
        }
        if depth == 0 {
            return Ok(());
        }
        for entry in std::fs::read_dir(dir)? {
            let path = entry?.path();
            if path.is_dir() {
                walk(&path, depth - 1, out)?;
            }
        }
        Ok(())
    }
    let mut out = BTreeMap::new();
    for root in roots {
        walk(root, 4, &mut out)?;
    }
    Ok(out)
}

/// Computes every missing metric value of every `ok` run.
pub fn compute(
    results: &ResultsDir,
    scenes: &BTreeMap<String, SceneMeta>,
    metrics: &[AnyMetric],
    mut progress: impl FnMut(&str, &str),
) -> io::Result<ComputeSummary> {
    let mut index = results.read_index()?;
    let mut summary = ComputeSummary::default();
    let mut references: BTreeMap<String, Image> = BTreeMap::new();
    for entry in index.runs.iter_mut() {
        let spp = entry.spp;
        let (technique, scene) = (entry.technique.clone(), entry.scene.clone());
        for (k, repeat) in entry.repeats.iter_mut().enumerate() {
            let what = format!("{technique} / {scene} / {spp} spp / seed {}", repeat.seed);
            let Some(image) = repeat.image.clone().filter(|_| repeat.status == fbksd_exchange::RunStatus::Ok) else {
                summary.skipped.push(format!("{what}: status {}", repeat.status));
                continue;
            };
            let files = RunFiles { spp, repeat: k as u32 };
            // The viewer shows a run's first repeat; error maps too.
            let first = k == 0;
            let test_path = results.root().join(&image);
            let mut test: Option<Image> = None;
            let pixels_file = test_path.with_file_name(files.pixels());
            if first && !pixels_file.is_file() {
                let image = test.insert(Image::read(&test_path)?);
                std::fs::write(&pixels_file, image.pixels_file())?;
            }
            let Some(meta) = scenes.get(&scene) else {
                summary.skipped.push(format!("{what}: no scene named {scene:?} in the scene directories"));
                continue;
            };
            let reference_path = meta.reference_file();
            if !reference_path.is_file() {
                summary.skipped.push(format!(
                    "{what}: no reference at {} (build it: fbksd-{} reference {})",
                    reference_path.display(),
                    meta.renderer,
                    meta.dir.display()
                ));
                continue;
            }
            let dir = test_path.parent().unwrap_or(results.root()).to_path_buf();
            for metric in metrics {
                let acronym = metric.info().acronym;
                let value_file = dir.join(files.metric_value(&acronym));
                let map_file = dir.join(files.error_map(&acronym));
                if let Ok(bytes) = std::fs::read(&value_file) {
                    if let Ok(v) = serde_json::from_slice::<ValueRecord>(&bytes) {
                        repeat.metrics.insert(acronym, v.value);
                        summary.kept += 1;
                        continue;
                    }
                }
                progress(&what, &acronym);
                let record = match metric {
                    AnyMetric::Builtin(m) => {
                        if !references.contains_key(&scene) {
                            references.insert(scene.clone(), Image::read(&reference_path)?);
                        }
                        let reference = &references[&scene];
                        let test = match &test {
                            Some(t) => t,
                            None => test.insert(Image::read(&test_path)?),
                        };
                        // A value that cannot be computed (nothing finite to compare) is
                        // reported for this run and the others go on.
                        let e = match evaluate(*m, reference, test) {
                            Ok(e) => e,
                            Err(e) => {
                                summary.skipped.push(format!("{what}: {acronym}: {e}"));
                                continue;
                            }
                        };
                        if let (Some(map), true) = (&e.map, first) {
                            map.write_png(&map_file)?;
                        }
                        ValueRecord {
                            metric: acronym.clone(),
                            value: e.value,
                            nonfinite_reference: e.nonfinite_reference,
                            nonfinite_test: e.nonfinite_test,
                        }
                    }
                    AnyMetric::External(x) => {
                        let map = first.then_some(map_file.as_path());
                        let value = x
                            .run(&reference_path, &test_path, map)
                            .map_err(|e| io::Error::other(format!("{what}: {e}")))?;
                        ValueRecord { metric: acronym.clone(), value, nonfinite_reference: 0, nonfinite_test: 0 }
                    }
                };
                summary.computed += 1;
                if !record.value.is_finite() {
                    // Reported here and left out of the run's values (it then ranks last), never averaged.
                    summary.skipped.push(format!(
                        "{what}: {acronym} is {} ({} non-finite pixels in the reference, {} in the result)",
                        record.value, record.nonfinite_reference, record.nonfinite_test
                    ));
                    continue;
                }
                std::fs::write(&value_file, serde_json::to_vec_pretty(&record)?)?;
                repeat.metrics.insert(acronym, record.value);
            }
        }
        entry.summarize();
    }
    let infos: Vec<MetricInfo> = metrics.iter().map(AnyMetric::info).collect();
    index.rank(|acronym| match infos.iter().find(|m| m.acronym == acronym) {
        Some(m) => m.lower_is_better,
        None => Metric::from_acronym(acronym).is_none_or(|m| m.info().lower_is_better),
    });
    results.write_index(index)?;
    Ok(summary)
}
