//! The renderer's speed as a control inside every job: which scenes of a
//! job were measured while the machine was slow.
//!
//! A shared machine slows down for minutes at a time, and everything on it
//! slows with it. In the service's equal-time check (ci-runner/README, "The
//! same program twice, through the service") a technique's CPU time rose by
//! 20–30 % on every seed of a job that ran during such a spell, the
//! calibrations before and after the job saw nothing, and two copies of
//! one program stopped tying at equal time. The renderer does the same work
//! for every technique on a scene (the same samples), so its CPU time per
//! sample is the machine's speed during those very runs.
//!
//! The runner keeps, for its renderer image, the renderer's CPU time per
//! sample at each scene, budget and sample size (floats per sample: more
//! features cost more) over its last [`KEPT`] jobs, in
//! `<work dir>/renderer-rates.json`. A scene at which a job's renderer ran
//! more than `remeasure_above` times slower than its usual (the median of
//! those jobs, once there are [`MIN_JOBS`]) is measured again, up to
//! `max_remeasures` times, and the calmest measurement is kept. Every job
//! adds the rates it kept, so a lasting change of speed (a new host)
//! becomes the usual after a few jobs instead of being measured again for
//! ever.

use fbksd_exchange::record::{RunRecord, RunStatus};
use fbksd_exchange::stats::Spread;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// The history's file in the runner's work directory.
pub const FILE: &str = "renderer-rates.json";
/// How many jobs' rates the history keeps per scene, budget and sample size.
pub const KEPT: usize = 9;
/// How many jobs a usual rate needs: before that, nothing is measured again.
pub const MIN_JOBS: usize = 3;

/// What a renderer's rate is kept by: scene (its name in the results),
/// budget, floats per sample.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct RateKey {
    /// The scene, as the results name it.
    pub scene: String,
    /// The budget in samples per pixel.
    pub spp: u64,
    /// Floats per sample of the technique's layout.
    pub floats: u32,
}

/// The renderer's CPU time per sample (ms) of each scene, budget and sample
/// size: the median over the `ok` runs that measured it.
pub fn rates_of<'a>(records: impl IntoIterator<Item = &'a RunRecord>) -> BTreeMap<RateKey, f64> {
    let mut rates: BTreeMap<RateKey, Vec<f64>> = BTreeMap::new();
    for r in records {
        if r.status == RunStatus::Ok && r.times.render_cpu_ms > 0.0 && r.used_samples > 0 {
            let key = RateKey { scene: r.scene.clone(), spp: r.spp_budget, floats: r.sample_floats };
            rates.entry(key).or_default().push(r.times.render_cpu_ms / r.used_samples as f64);
        }
    }
    rates.into_iter().filter_map(|(k, v)| Some((k, Spread::of(&v)?.median))).collect()
}

/// How much slower than its usual the renderer ran at one scene, budget
/// and sample size.
#[derive(Debug, Clone, PartialEq)]
pub struct Slowdown {
    /// Where.
    pub key: RateKey,
    /// ms per sample in this measurement.
    pub rate: f64,
    /// ms per sample, the median of the runner's last jobs.
    pub usual: f64,
}

impl Slowdown {
    /// `rate / usual`: 1 is the usual speed, 2 half of it.
    pub fn ratio(&self) -> f64 {
        self.rate / self.usual
    }
}

impl std::fmt::Display for Slowdown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:.2}× its usual at {} spp ({:.3} against {:.3} µs of CPU per sample)",
            self.ratio(),
            self.key.spp,
            1e3 * self.rate,
            1e3 * self.usual
        )
    }
}

/// One scene, budget and sample size's rates, oldest first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Rates {
    scene: String,
    spp: u64,
    floats: u32,
    ms_per_sample: Vec<f64>,
}

/// The renderer's rates over this runner's last jobs.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RateHistory {
    /// The renderer image they were measured with (its tag names its
    /// content): another image starts a history of its own.
    renderer_image: String,
    rates: Vec<Rates>,
}

impl RateHistory {
    /// The history in `path` for `renderer_image`: empty when there is none
    /// yet, when it was kept for another image, or when it cannot be read
    /// (said in the runner's log; the next job writes a good one).
    pub fn load(path: &Path, renderer_image: &str) -> RateHistory {
        let fresh = RateHistory { renderer_image: renderer_image.to_string(), rates: Vec::new() };
        let bytes = match std::fs::read(path) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return fresh,
            Err(e) => {
                tracing::warn!("{}: {e}; the renderer's rates start afresh", path.display());
                return fresh;
            }
        };
        match serde_json::from_slice::<RateHistory>(&bytes) {
            Ok(history) if history.renderer_image == renderer_image => history,
            Ok(_) => fresh,
            Err(e) => {
                tracing::warn!("{}: {e}; the renderer's rates start afresh", path.display());
                fresh
            }
        }
    }

    /// Writes the history to `path` (atomically).
    pub fn save(&self, path: &Path) -> std::io::Result<()> {
        fbksd_exchange::results::write_json_atomically(path, self)
    }

    fn position(&self, key: &RateKey) -> Option<usize> {
        self.rates.iter().position(|r| r.scene == key.scene && r.spp == key.spp && r.floats == key.floats)
    }

    fn entry(&self, key: &RateKey) -> Option<&Rates> {
        self.position(key).map(|i| &self.rates[i])
    }

    /// The usual rate: the median of the last jobs', once there are [`MIN_JOBS`].
    pub fn usual(&self, key: &RateKey) -> Option<f64> {
        let rates = &self.entry(key)?.ms_per_sample;
        (rates.len() >= MIN_JOBS).then(|| Spread::of(rates).map(|s| s.median)).flatten()
    }

    /// Adds one job's rates, keeping the last [`KEPT`] of each.
    pub fn add(&mut self, rates: &BTreeMap<RateKey, f64>) {
        for (key, &rate) in rates {
            let i = match self.position(key) {
                Some(i) => i,
                None => {
                    self.rates.push(Rates {
                        scene: key.scene.clone(),
                        spp: key.spp,
                        floats: key.floats,
                        ms_per_sample: Vec::new(),
                    });
                    self.rates.len() - 1
                }
            };
            let kept = &mut self.rates[i].ms_per_sample;
            kept.push(rate);
            let over = kept.len().saturating_sub(KEPT);
            kept.drain(..over);
        }
    }

    /// Where `rates` (one scene's) ran slowest against their usual; `None`
    /// when none has a usual to compare with.
    pub fn slowest(&self, rates: &BTreeMap<RateKey, f64>) -> Option<Slowdown> {
        rates
            .iter()
            .filter_map(|(key, &rate)| Some(Slowdown { key: key.clone(), rate, usual: self.usual(key)? }))
            .max_by(|a, b| a.ratio().total_cmp(&b.ratio()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fbksd_exchange::record::Times;

    fn run(scene: &str, spp: u64, floats: u32, render_cpu_ms: f64, status: RunStatus) -> RunRecord {
        RunRecord {
            date: String::new(),
            spp_budget: spp,
            samples_budget: spp * 100,
            used_samples: spp * 100,
            sample_floats: floats,
            aborted: status != RunStatus::Ok,
            exec_time: 1.0,
            status,
            message: String::new(),
            scene: scene.into(),
            technique: "box".into(),
            width: 10,
            height: 10,
            times: Times { render_cpu_ms, ..Default::default() },
            peak_memory_bytes: 1,
            requests: 1,
            image: None,
            technique_log: String::new(),
            seed: 0,
            repeat: 0,
        }
    }

    fn key(scene: &str, spp: u64, floats: u32) -> RateKey {
        RateKey { scene: scene.into(), spp, floats }
    }

    #[test]
    fn a_rate_is_the_median_per_sample_of_the_runs_that_measured_it() {
        let runs = [
            run("sphere", 4, 3, 40.0, RunStatus::Ok),
            run("sphere", 4, 3, 48.0, RunStatus::Ok),
            run("sphere", 4, 3, 44.0, RunStatus::Ok),
            run("sphere", 4, 3, 900.0, RunStatus::Timeout),
            run("sphere", 4, 5, 0.0, RunStatus::Ok),
            run("sphere", 16, 3, 160.0, RunStatus::Ok),
        ];
        let rates = rates_of(&runs);
        assert_eq!(rates.len(), 2, "{rates:?}");
        assert!((rates[&key("sphere", 4, 3)] - 0.11).abs() < 1e-12);
        assert!((rates[&key("sphere", 16, 3)] - 0.1).abs() < 1e-12);
    }

    #[test]
    fn a_slow_job_is_seen_once_the_usual_is_known_and_a_lasting_change_becomes_the_usual() {
        let k = key("sphere", 4, 3);
        let job = |rate: f64| BTreeMap::from([(k.clone(), rate)]);
        let mut history = RateHistory::default();
        for _ in 0..MIN_JOBS - 1 {
            history.add(&job(0.1));
            assert_eq!(history.slowest(&job(0.2)), None, "too few jobs to judge");
        }
        history.add(&job(0.1));
        let slow = history.slowest(&job(0.15)).unwrap();
        assert!((slow.ratio() - 1.5).abs() < 1e-12, "{slow:?}");
        // Another sample size or budget has a usual of its own.
        assert_eq!(history.slowest(&BTreeMap::from([(key("sphere", 4, 5), 0.3)])), None);
        // A machine that stays slower becomes the usual after a few jobs.
        for _ in 0..KEPT {
            history.add(&job(0.15));
        }
        assert!((history.slowest(&job(0.15)).unwrap().ratio() - 1.0).abs() < 1e-12);
        assert_eq!(history.entry(&k).unwrap().ms_per_sample.len(), KEPT);
    }

    #[test]
    fn the_slowest_key_of_a_scene_decides() {
        let mut history = RateHistory::default();
        let usual = BTreeMap::from([(key("sphere", 4, 3), 0.1), (key("sphere", 16, 3), 0.08)]);
        for _ in 0..MIN_JOBS {
            history.add(&usual);
        }
        let measured = BTreeMap::from([(key("sphere", 4, 3), 0.11), (key("sphere", 16, 3), 0.12)]);
        let slow = history.slowest(&measured).unwrap();
        assert_eq!(slow.key, key("sphere", 16, 3));
        assert!((slow.ratio() - 1.5).abs() < 1e-12);
        assert_eq!(slow.to_string(), "1.50× its usual at 16 spp (120.000 against 80.000 µs of CPU per sample)");
    }

    #[test]
    fn a_history_is_kept_per_renderer_image_and_survives_a_bad_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE);
        let mut history = RateHistory::load(&path, "fbksd-renderer:aaa");
        for _ in 0..MIN_JOBS {
            history.add(&BTreeMap::from([(key("sphere", 4, 3), 0.1)]));
        }
        history.save(&path).unwrap();
        assert_eq!(RateHistory::load(&path, "fbksd-renderer:aaa"), history);
        assert_eq!(RateHistory::load(&path, "fbksd-renderer:bbb").usual(&key("sphere", 4, 3)), None);
        std::fs::write(&path, "{not json").unwrap();
        assert_eq!(RateHistory::load(&path, "fbksd-renderer:aaa").usual(&key("sphere", 4, 3)), None);
    }
}
