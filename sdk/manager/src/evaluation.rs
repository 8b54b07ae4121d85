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
use fbksd_iqa::{evaluate_against, Metric, MetricInfo, Reference, ValueRecord};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

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

/// One repeat to score: where it is in the index and what to compute.
struct Task {
    run: usize,
    repeat: usize,
    what: String,
    scene: String,
    test_path: PathBuf,
    reference_path: PathBuf,
    files: RunFiles,
    /// Whether the viewer's pixel file of the image is still to be written.
    write_pixels: bool,
}

/// What scoring one repeat gave, applied to the index afterwards in order.
#[derive(Default)]
struct Scored {
    values: Vec<(String, f64)>,
    computed: usize,
    kept: usize,
    skipped: Vec<String>,
}

/// Computes every missing metric value of every `ok` run.
///
/// Each scene's reference is read and prepared once ([`Reference`]: ꟻLIP's
/// filtered reference at each exposure) for all the runs on it that lack a
/// value, then the repeats are scored in parallel. `progress` is called from the worker
/// threads as each value starts.
pub fn compute(
    results: &ResultsDir,
    scenes: &BTreeMap<String, SceneMeta>,
    metrics: &[AnyMetric],
    progress: impl Fn(&str, &str) + Sync,
) -> io::Result<ComputeSummary> {
    let mut index = results.read_index()?;
    let mut summary = ComputeSummary::default();
    let mut tasks = Vec::new();
    for (run, entry) in index.runs.iter().enumerate() {
        for (k, repeat) in entry.repeats.iter().enumerate() {
            let what = format!("{} / {} / {} spp / seed {}", entry.technique, entry.scene, entry.spp, repeat.seed);
            let Some(image) = repeat.image.clone().filter(|_| repeat.status == fbksd_exchange::RunStatus::Ok) else {
                summary.skipped.push(format!("{what}: status {}", repeat.status));
                continue;
            };
            let files = RunFiles { spp: entry.spp, repeat: k as u32 };
            let test_path = results.root().join(&image);
            // The viewer shows a run's first repeat, even when it cannot be scored.
            let pixels_file = test_path.with_file_name(files.pixels());
            let write_pixels = k == 0 && !pixels_file.is_file();
            let unscored = match scenes.get(&entry.scene) {
                None => Err(format!("{what}: no scene named {:?} in the scene directories", entry.scene)),
                Some(meta) if !meta.reference_file().is_file() => Err(format!(
                    "{what}: no reference at {} (build it: fbksd-{} reference {})",
                    meta.reference_file().display(),
                    meta.renderer,
                    meta.dir.display()
                )),
                Some(meta) => Ok(meta.reference_file()),
            };
            match unscored {
                Ok(reference_path) => tasks.push(Task {
                    run,
                    repeat: k,
                    what,
                    scene: entry.scene.clone(),
                    test_path,
                    reference_path,
                    files,
                    write_pixels,
                }),
                Err(why) => {
                    if write_pixels {
                        std::fs::write(&pixels_file, Image::read(&test_path)?.pixels_file())?;
                    }
                    summary.skipped.push(why);
                }
            }
        }
    }

    // Each scene's reference, read once. The scenes where some run still
    // lacks a built-in value are read and prepared up front, in parallel; a
    // re-run that finds every value in place reads no reference (a value
    // file that turns out unreadable reads its scene's on demand).
    let builtins: Vec<Metric> =
        metrics.iter().filter_map(|m| if let AnyMetric::Builtin(b) = m { Some(*b) } else { None }).collect();
    let mut lacking: BTreeMap<&str, (&Path, Vec<Metric>)> = BTreeMap::new();
    for task in &tasks {
        let dir = task.test_path.parent().unwrap_or(Path::new("."));
        for m in &builtins {
            if !dir.join(task.files.metric_value(m.acronym())).is_file() {
                let (_, wanted) =
                    lacking.entry(task.scene.as_str()).or_insert((task.reference_path.as_path(), Vec::new()));
                if !wanted.contains(m) {
                    wanted.push(*m);
                }
            }
        }
    }
    let references: BTreeMap<&str, OnceLock<io::Result<Reference<'static>>>> =
        tasks.iter().map(|t| (t.scene.as_str(), OnceLock::new())).collect();
    let load = |path: &Path| {
        Image::read(path).map(Reference::new).map_err(|e| io::Error::new(e.kind(), format!("{}: {e}", path.display())))
    };
    lacking.into_par_iter().for_each(|(scene, (path, wanted))| {
        if let Ok(reference) = references[scene].get_or_init(|| load(path)) {
            wanted.par_iter().for_each(|m| reference.prepare(*m));
        }
    });
    let reference_of = |task: &Task| -> io::Result<&Reference<'static>> {
        references[task.scene.as_str()]
            .get_or_init(|| load(&task.reference_path))
            .as_ref()
            .map_err(|e| io::Error::new(e.kind(), e.to_string()))
    };
    let scored: Vec<Scored> =
        tasks.par_iter().map(|task| score(task, metrics, &reference_of, &progress)).collect::<io::Result<_>>()?;

    for (task, scored) in tasks.iter().zip(scored) {
        let repeat = &mut index.runs[task.run].repeats[task.repeat];
        repeat.metrics.extend(scored.values);
        summary.computed += scored.computed;
        summary.kept += scored.kept;
        summary.skipped.extend(scored.skipped);
    }
    for entry in &mut index.runs {
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

/// Scores one repeat with every metric whose value file is missing.
fn score<'r>(
    task: &Task,
    metrics: &[AnyMetric],
    reference_of: &(impl Fn(&Task) -> io::Result<&'r Reference<'static>> + Sync),
    progress: &(impl Fn(&str, &str) + Sync),
) -> io::Result<Scored> {
    let mut scored = Scored::default();
    let what = &task.what;
    // Error maps are drawn for the first repeat only: the viewer shows it.
    let first = task.repeat == 0;
    let dir = task.test_path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let mut test: Option<Image> = None;
    if task.write_pixels {
        let image = test.insert(Image::read(&task.test_path)?);
        std::fs::write(task.test_path.with_file_name(task.files.pixels()), image.pixels_file())?;
    }
    for metric in metrics {
        let acronym = metric.info().acronym;
        let value_file = dir.join(task.files.metric_value(&acronym));
        let map_file = dir.join(task.files.error_map(&acronym));
        if let Ok(bytes) = std::fs::read(&value_file) {
            if let Ok(v) = serde_json::from_slice::<ValueRecord>(&bytes) {
                scored.values.push((acronym, v.value));
                scored.kept += 1;
                continue;
            }
        }
        progress(what, &acronym);
        let record = match metric {
            AnyMetric::Builtin(m) => {
                let reference = reference_of(task)?;
                let test = match &test {
                    Some(t) => t,
                    None => test.insert(Image::read(&task.test_path)?),
                };
                // A value that cannot be computed (nothing finite to compare) is
                // reported for this run and the others go on.
                let e = match evaluate_against(*m, reference, test) {
                    Ok(e) => e,
                    Err(e) => {
                        scored.skipped.push(format!("{what}: {acronym}: {e}"));
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
                    .run(&task.reference_path, &task.test_path, map)
                    .map_err(|e| io::Error::other(format!("{what}: {e}")))?;
                ValueRecord { metric: acronym.clone(), value, nonfinite_reference: 0, nonfinite_test: 0 }
            }
        };
        scored.computed += 1;
        if !record.value.is_finite() {
            // Reported here and left out of the run's values (it then ranks last), never averaged.
            scored.skipped.push(format!(
                "{what}: {acronym} is {} ({} non-finite pixels in the reference, {} in the result)",
                record.value, record.nonfinite_reference, record.nonfinite_test
            ));
            continue;
        }
        std::fs::write(&value_file, serde_json::to_vec_pretty(&record)?)?;
        scored.values.push((acronym, record.value));
    }
    Ok(scored)
}
