//! Results computation and ranking: metric values and error maps for every
//! run of a results directory, and the ranking of techniques.
//!
//! `compute` is incremental: a run's metric is computed only when its value
//! file (`<spp>_0_<METRIC>.json`) is missing; error maps go beside it as
//! `<spp>_0_<METRIC>_map.png`. Values are also gathered into `index.json`.
//!
//! **Ranking** (fixing the original, where a missing result was simply not
//! ranked, which favoured incomplete techniques): for every (scene, spp,
//! metric), techniques are ranked 1 (best) to n, ties sharing the mean of
//! their ranks; a technique with no value there (failed or missing run)
//! takes rank n, the worst. A technique's score is its mean rank.

use crate::results::{path_safe_name, IndexEntry, ResultsDir};
use crate::scenes::{SceneMeta, META_FILE};
use fbksd_iqa::external::ExternalMetric;
use fbksd_iqa::image::Image;
use fbksd_iqa::{evaluate, Metric, MetricInfo, ValueRecord};
use std::collections::{BTreeMap, BTreeSet};
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
    mut progress: impl FnMut(&IndexEntry, &str),
) -> io::Result<ComputeSummary> {
    let mut index = results.read_index()?;
    let mut summary = ComputeSummary::default();
    let mut references: BTreeMap<String, Image> = BTreeMap::new();
    for entry in index.runs.iter_mut() {
        let what = format!("{} / {} / {} spp", entry.technique, entry.scene, entry.spp);
        let Some(image) = entry.image.clone().filter(|_| entry.status == crate::RunStatus::Ok) else {
            summary.skipped.push(format!("{what}: status {}", entry.status));
            continue;
        };
        let Some(meta) = scenes.get(&entry.scene) else {
            summary.skipped.push(format!("{what}: no scene named {:?} in the scene directories", entry.scene));
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
        let test_path = results.root().join(&image);
        let dir = test_path.parent().unwrap_or(results.root()).to_path_buf();
        let mut test: Option<Image> = None;
        for metric in metrics {
            let acronym = metric.info().acronym;
            let value_file = dir.join(format!("{}_0_{acronym}.json", entry.spp));
            let map_file = dir.join(format!("{}_0_{acronym}_map.png", entry.spp));
            if let Ok(bytes) = std::fs::read(&value_file) {
                if let Ok(v) = serde_json::from_slice::<ValueRecord>(&bytes) {
                    entry.metrics.insert(acronym, v.value);
                    summary.kept += 1;
                    continue;
                }
            }
            progress(entry, &acronym);
            let record = match metric {
                AnyMetric::Builtin(m) => {
                    if !references.contains_key(&entry.scene) {
                        references.insert(entry.scene.clone(), Image::read(&reference_path)?);
                    }
                    let reference = &references[&entry.scene];
                    let test = match &test {
                        Some(t) => t,
                        None => test.insert(Image::read(&test_path)?),
                    };
                    let e = evaluate(*m, reference, test)
                        .map_err(|e| io::Error::other(format!("{what}: {acronym}: {e}")))?;
                    if let Some(map) = &e.map {
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
                    let value = x
                        .run(&reference_path, &test_path, Some(&map_file))
                        .map_err(|e| io::Error::other(format!("{what}: {e}")))?;
                    ValueRecord { metric: acronym.clone(), value, nonfinite_reference: 0, nonfinite_test: 0 }
                }
            };
            std::fs::write(&value_file, serde_json::to_vec_pretty(&record)?)?;
            entry.metrics.insert(acronym, record.value);
            summary.computed += 1;
        }
    }
    results.write_index(index)?;
    Ok(summary)
}

/// A technique's place in the ranking.
#[derive(Debug, Clone, PartialEq)]
pub struct Standing {
    /// Technique.
    pub technique: String,
    /// Mean rank over every (scene, spp, metric); lower is better.
    pub mean_rank: f64,
    /// Groups in which it had a value.
    pub ranked: usize,
    /// Groups in which it had none (counted as last).
    pub missing: usize,
}

/// Values of one (scene, spp, metric) group, by technique.
type Group<'a> = Vec<(&'a str, f64)>;

/// Ranks techniques by mean rank over (scene, spp, metric) groups.
pub fn rank(runs: &[IndexEntry], lower_is_better: impl Fn(&str) -> bool) -> Vec<Standing> {
    let techniques: BTreeSet<&str> = runs.iter().map(|r| r.technique.as_str()).collect();
    let n = techniques.len();
    // (scene, spp, metric) → (technique, value).
    let mut groups: BTreeMap<(&str, u64, &str), Group> = BTreeMap::new();
    for r in runs {
        for (metric, value) in &r.metrics {
            groups.entry((&r.scene, r.spp, metric)).or_default().push((&r.technique, *value));
        }
    }
    let mut totals: BTreeMap<&str, (f64, usize, usize)> = techniques.iter().map(|t| (*t, (0.0, 0, 0))).collect();
    for ((_, _, metric), mut values) in groups {
        let lower = lower_is_better(metric);
        values.retain(|(_, v)| !v.is_nan());
        values.sort_by(|a, b| if lower { a.1.total_cmp(&b.1) } else { b.1.total_cmp(&a.1) });
        let mut i = 0;
        while i < values.len() {
            let mut j = i;
            while j + 1 < values.len() && values[j + 1].1 == values[i].1 {
                j += 1;
            }
            let shared = (i + j) as f64 / 2.0 + 1.0;
            for (t, _) in &values[i..=j] {
                let e = totals.get_mut(t).unwrap();
                e.0 += shared;
                e.1 += 1;
            }
            i = j + 1;
        }
        let present: BTreeSet<&str> = values.iter().map(|(t, _)| *t).collect();
        for t in &techniques {
            if !present.contains(t) {
                let e = totals.get_mut(t).unwrap();
                e.0 += n as f64;
                e.2 += 1;
            }
        }
    }
    let mut out: Vec<Standing> = totals
        .into_iter()
        .map(|(t, (sum, ranked, missing))| Standing {
            technique: t.to_string(),
            mean_rank: if ranked + missing == 0 { f64::NAN } else { sum / (ranked + missing) as f64 },
            ranked,
            missing,
        })
        .collect();
    out.sort_by(|a, b| a.mean_rank.total_cmp(&b.mean_rank).then(a.technique.cmp(&b.technique)));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(t: &str, scene: &str, spp: u64, metrics: &[(&str, f64)]) -> IndexEntry {
        IndexEntry {
            technique: t.into(),
            scene: scene.into(),
            spp,
            status: crate::RunStatus::Ok,
            message: String::new(),
            log: String::new(),
            image: None,
            technique_ms: 0.0,
            render_ms: 0.0,
            used_samples: 0,
            metrics: metrics.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
        }
    }

    #[test]
    fn ranks_by_direction_with_shared_ties() {
        let runs = vec![
            run("a", "s", 4, &[("MSE", 1.0), ("SSIM", 0.9)]),
            run("b", "s", 4, &[("MSE", 2.0), ("SSIM", 0.9)]),
            run("c", "s", 4, &[("MSE", 3.0), ("SSIM", 0.5)]),
        ];
        let r = rank(&runs, |m| m != "SSIM");
        let get = |t: &str| r.iter().find(|s| s.technique == t).unwrap().mean_rank;
        // a: MSE 1, SSIM 1.5 → 1.25; b: 2, 1.5 → 1.75; c: 3, 3 → 3.
        assert_eq!((get("a"), get("b"), get("c")), (1.25, 1.75, 3.0));
        assert_eq!(r[0].technique, "a");
    }

    /// Regression of the original: a technique with missing results was not
    /// ranked there, so failing on the hard scenes improved its mean rank.
    #[test]
    fn a_missing_result_counts_as_last() {
        let runs = vec![
            run("good", "easy", 4, &[("MSE", 1.0)]),
            run("good", "hard", 4, &[("MSE", 5.0)]),
            run("good", "harder", 4, &[("MSE", 9.0)]),
            run("quitter", "easy", 4, &[("MSE", 0.9)]),
        ];
        // Ignoring missing results, the quitter would rank 1.0 and the good one 1.33.
        let r = rank(&runs, |_| true);
        assert_eq!(r[0].technique, "good", "{r:?}");
        assert!((r[0].mean_rank - 4.0 / 3.0).abs() < 1e-12);
        let q = r.iter().find(|s| s.technique == "quitter").unwrap();
        assert_eq!((q.ranked, q.missing), (1, 2));
        assert!((q.mean_rank - 5.0 / 3.0).abs() < 1e-12);
    }
}
