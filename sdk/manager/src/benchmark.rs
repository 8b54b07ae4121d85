//! A benchmark: every technique on every scene at each of its budgets.
//!
//! The renderer of a scene starts once and serves every run on that scene
//! (it is restarted only after a run left it broken or mid-request); the
//! technique starts once per (scene, budget, repeat), as in the original
//! FBKSD. Repeat `k` of a run has the renderer's sample seed `k`, so every
//! technique sees the same seeds and their values pair up in the ranking.
//!
//! Runs are made budget by budget and seed by seed, every technique's run
//! of one seed back to back, each seed in another order: a machine whose
//! speed drifts over minutes then moves every technique's cost alike
//! (costs pair by seed in the equal-time ranking), and no technique always
//! comes first after a change of budget.

use crate::process::Launcher;
use crate::scene::{Limits, SceneRunner, TechniqueLaunch};
use fbksd_exchange::ranking::RunKey;
use fbksd_exchange::record::{RunRecord, RunStatus};
use fbksd_exchange::results::{path_safe_name, write_json_atomically, ResultsDir, RunFiles};
use fbksd_iqa::image::write_exr;
use std::collections::BTreeMap;
use std::io;
use std::ops::Range;
use std::path::PathBuf;
use std::sync::Arc;

/// A technique to run: a name and a command.
#[derive(Debug, Clone)]
pub struct TechniqueSpec {
    /// Name used in results (a safe path component is derived from it).
    pub name: String,
    /// The command (program and arguments).
    pub argv: Vec<String>,
}

/// A scene to render: a name and the renderer command that loads it.
#[derive(Debug, Clone)]
pub struct SceneSpec {
    /// Name used in results.
    pub name: String,
    /// The renderer command, scene file included (normally last).
    pub renderer_argv: Vec<String>,
    /// Budgets in samples per pixel for this scene.
    pub spps: Vec<u64>,
}

/// What the benchmark reports while it works.
#[derive(Debug)]
pub enum Progress<'a> {
    /// A run starts.
    RunStarted {
        /// Scene name.
        scene: &'a str,
        /// Technique name.
        technique: &'a str,
        /// Budget.
        spp: u64,
        /// Repeat (also the sample seed).
        repeat: u32,
    },
    /// Samples flow (at most a few times per second).
    Samples {
        /// Delivered so far.
        delivered: u64,
        /// Budget.
        budget: u64,
    },
    /// A run ended.
    RunFinished(&'a RunRecord),
}

/// Every technique × scene × budget.
#[derive(Debug, Clone)]
pub struct Benchmark {
    /// Techniques.
    pub techniques: Vec<TechniqueSpec>,
    /// Scenes, each with its budgets.
    pub scenes: Vec<SceneSpec>,
    /// Where results go.
    pub results: PathBuf,
    /// Limits of every run.
    pub limits: Limits,
    /// Starts renderers and techniques ([`crate::LocalLauncher`] for local runs).
    pub launcher: Arc<dyn Launcher>,
    /// How many times each run is made, with sample seeds 0, 1, … (at least 1).
    pub repeats: u32,
}

/// The order of the techniques' runs of repeat `repeat`: rotated by one
/// each repeat.
fn run_order(techniques: usize, repeat: u32) -> impl Iterator<Item = usize> {
    let shift = repeat as usize % techniques.max(1);
    (0..techniques).map(move |i| (i + shift) % techniques)
}

impl Benchmark {
    /// Runs everything, writing results as each run ends.
    pub fn run(&self, progress: impl FnMut(Progress<'_>) + Send) -> io::Result<Vec<RunRecord>> {
        let repeats = self.repeats.max(1);
        self.run_seeds(|_, _, _| 0..repeats, progress)
    }

    /// Makes runs again with more seeds: each (technique, scene, budget) of
    /// `runs`, by its names in the results, gets the seeds of its range,
    /// which pair with the other techniques' runs of the same seeds. Runs
    /// and scenes not named are not touched (a scene's renderer starts only
    /// if one of its runs is).
    pub fn run_more_seeds(
        &self,
        runs: &BTreeMap<RunKey, Range<u32>>,
        progress: impl FnMut(Progress<'_>) + Send,
    ) -> io::Result<Vec<RunRecord>> {
        self.run_seeds(
            |technique, scene, spp| {
                let key = RunKey { technique: path_safe_name(technique), scene: path_safe_name(scene), spp };
                runs.get(&key).cloned().unwrap_or(0..0)
            },
            progress,
        )
    }

    /// Runs each (technique, scene, budget) with the seeds `seeds` gives it
    /// (by the names given to the benchmark): budget by budget, seed by
    /// seed, the techniques of one seed back to back.
    fn run_seeds(
        &self,
        seeds: impl Fn(&str, &str, u64) -> Range<u32>,
        mut progress: impl FnMut(Progress<'_>) + Send,
    ) -> io::Result<Vec<RunRecord>> {
        let results = ResultsDir::create(&self.results)?;
        let mut records = Vec::new();
        for scene in &self.scenes {
            let wanted = |spp: u64| -> Vec<Range<u32>> {
                self.techniques.iter().map(|t| seeds(&t.name, &scene.name, spp)).collect()
            };
            if scene.spps.iter().all(|&spp| wanted(spp).iter().all(Range::is_empty)) {
                continue;
            }
            let scene_name = path_safe_name(&scene.name);
            let renderer_log = results.renderer_log(&scene_name)?;
            let mut runner = SceneRunner::new(scene.renderer_argv.clone(), Some(renderer_log), self.limits.clone())?
                .with_launcher(self.launcher.clone())?;
            let dirs = self
                .techniques
                .iter()
                .map(|t| results.run_dir(&path_safe_name(&t.name), &scene_name))
                .collect::<io::Result<Vec<_>>>()?;
            for &spp in &scene.spps {
                let wanted = wanted(spp);
                let (Some(first), Some(end)) =
                    (wanted.iter().map(|r| r.start).min(), wanted.iter().map(|r| r.end).max())
                else {
                    continue;
                };
                for repeat in first..end {
                    runner.set_seed(repeat as u64);
                    for i in run_order(self.techniques.len(), repeat).filter(|&i| wanted[i].contains(&repeat)) {
                        let record = self.run_once(
                            &mut runner,
                            &results,
                            &dirs[i],
                            &self.techniques[i],
                            &scene_name,
                            spp,
                            repeat,
                            &mut progress,
                        )?;
                        progress(Progress::RunFinished(&record));
                        records.push(record);
                    }
                }
            }
            let _ = runner.finish();
        }
        Ok(records)
    }

    /// One repeat of one run, its files written and indexed.
    #[allow(clippy::too_many_arguments)]
    fn run_once(
        &self,
        runner: &mut SceneRunner,
        results: &ResultsDir,
        dir: &std::path::Path,
        technique: &TechniqueSpec,
        scene_name: &str,
        spp: u64,
        repeat: u32,
        progress: &mut (impl FnMut(Progress<'_>) + Send),
    ) -> io::Result<RunRecord> {
        let technique_name = path_safe_name(&technique.name);
        progress(Progress::RunStarted { scene: scene_name, technique: &technique_name, spp, repeat });
        let files = RunFiles { spp, repeat };
        let technique_log = dir.join(files.technique_log());
        let _ = std::fs::remove_file(&technique_log);
        let date = humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string();
        let outcome = runner.run_with_progress(
            spp,
            &TechniqueLaunch::Command(technique.argv.clone()),
            &technique_log,
            &mut |delivered, budget| progress(Progress::Samples { delivered, budget }),
        );
        let image_path = dir.join(files.image());
        let _ = std::fs::remove_file(&image_path);
        let mut status = outcome.status;
        let mut message = outcome.message;
        let image = match &outcome.image {
            Some(rgb) => match write_exr(&image_path, outcome.width, outcome.height, rgb) {
                Ok(()) => Some(image_path),
                Err(e) => {
                    status = RunStatus::InvalidOutput;
                    message = format!("cannot write the result image: {e}");
                    None
                }
            },
            None => None,
        };
        let record = RunRecord {
            date,
            spp_budget: spp,
            samples_budget: outcome.samples_budget,
            used_samples: outcome.used_samples,
            sample_floats: outcome.sample_floats,
            aborted: status != RunStatus::Ok,
            exec_time: outcome.times.technique_ms,
            status,
            message,
            scene: scene_name.to_string(),
            technique: technique_name,
            width: outcome.width,
            height: outcome.height,
            times: outcome.times,
            peak_memory_bytes: outcome.peak_memory_bytes,
            requests: outcome.requests,
            image: image.as_ref().map(|_| files.image()),
            technique_log: files.technique_log(),
            seed: repeat as u64,
            repeat,
        };
        let log_path = dir.join(files.log());
        write_json_atomically(&log_path, &record)?;
        results.record(&record, &log_path, image.as_deref())?;
        Ok(record)
    }
}
