//! What a run costs: the time axis of the equal-time comparison.
//!
//! A run's cost is the technique's CPU time (every thread of every process
//! it started, from its hello to its result; see [`crate::record::Times`])
//! plus the renderer's cost of the samples it was delivered: that many
//! samples at the scene's **render rate**, the renderer's CPU time per
//! sample pooled over every run being compared (the median of the runs'
//! own rates), one rate per scene and sample size (floats per sample:
//! features cost the renderer more to compute and to hand over).
//!
//! Why pooled: the renderer renders the same samples for every technique,
//! yet its CPU time for them varies from run to run as much as wall time
//! does on a shared machine (the procedural sphere at 16 spp, ten seeds of
//! one box filter on a 2-core VM: 283–358 ms, CV 6.3 %, against the box
//! filter's own 14–20 ms). Charged run by run, that noise would decide the
//! equal-time cells of every fast technique; pooled, two techniques given
//! the same samples pay the same for them, and what separates their costs
//! is what they do with them.
//!
//! What a pooled rate does not see: an adaptive sampler that puts its
//! samples where the renderer is slower than average pays the average. Each
//! run's own renderer CPU time is kept (`render_cpu_ms`) and shown beside.
//! Runs recorded before CPU times were measured cost their wall time to
//! the result ([`IndexEntry::time`]).

use crate::record::RunStatus;
use crate::results::{IndexEntry, Repeat};
use crate::stats::{median, Samples, Spread};
use std::collections::BTreeMap;

/// The render rates of a set of runs, and so each run's cost.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Costs {
    /// ms of renderer CPU per sample, by (scene, floats per sample).
    rates: BTreeMap<(String, u32), f64>,
}

impl Costs {
    /// The render rates pooled over `runs` (every `ok` repeat that measured
    /// its CPU times).
    pub fn of(runs: &[IndexEntry]) -> Costs {
        let mut rates: BTreeMap<(String, u32), Vec<f64>> = BTreeMap::new();
        for run in runs {
            for r in run.repeats.iter().filter(|r| measured(r)) {
                rates
                    .entry((run.scene.clone(), r.sample_floats))
                    .or_default()
                    .push(r.render_cpu_ms / r.used_samples as f64);
            }
        }
        let median_of = |v: Vec<f64>| Spread::of(&v).map_or(0.0, |s| s.median);
        Costs { rates: rates.into_iter().map(|(k, v)| (k, median_of(v))).collect() }
    }

    /// The renderer's CPU time per sample in ms on `scene` for samples of
    /// `floats` floats, when some run measured it.
    pub fn rate(&self, scene: &str, floats: u32) -> Option<f64> {
        self.rates.get(&(scene.to_string(), floats)).copied()
    }

    /// The run's cost in ms for each sample seed, one per `ok` repeat.
    pub fn by_seed(&self, run: &IndexEntry) -> Samples {
        self.parts_by_seed(run).into_iter().map(|(seed, own, samples)| (seed, own + samples)).collect()
    }

    /// The technique's own part of the run's cost in ms for each sample
    /// seed: its CPU time, or the whole cost where CPU times were not
    /// measured (what [`Costs::by_seed`] charges beside the samples).
    pub fn own_by_seed(&self, run: &IndexEntry) -> Samples {
        self.parts_by_seed(run).into_iter().map(|(seed, own, _)| (seed, own)).collect()
    }

    /// Each seed's cost in two parts: the technique's own, and its samples
    /// at the pooled rate (0 where CPU times were not measured and the
    /// whole cost is the wall time).
    fn parts_by_seed(&self, run: &IndexEntry) -> Vec<(u64, f64, f64)> {
        if run.repeats.is_empty() {
            return vec![(0, run.time(), 0.0)];
        }
        let parts = |r: &Repeat| match self.rate(&run.scene, r.sample_floats) {
            Some(rate) if measured(r) => (r.seed, r.technique_cpu_ms, rate * r.used_samples as f64),
            _ => (r.seed, r.time_ms(), 0.0),
        };
        run.repeats.iter().filter(|r| r.status == RunStatus::Ok).map(parts).collect()
    }

    /// The run's cost in ms: the median over its seeds (0 for none).
    pub fn of_run(&self, run: &IndexEntry) -> f64 {
        median(&self.by_seed(run))
    }
}

/// Whether a repeat measured the CPU times a cost is made of.
fn measured(r: &Repeat) -> bool {
    r.status == RunStatus::Ok && r.render_cpu_ms > 0.0 && r.used_samples > 0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(technique: &str, floats: u32, repeats: &[(f64, f64, u64)]) -> IndexEntry {
        let mut e = IndexEntry::new(technique, "s", 4);
        e.repeats = repeats
            .iter()
            .enumerate()
            .map(|(seed, &(technique_cpu_ms, render_cpu_ms, used_samples))| Repeat {
                seed: seed as u64,
                status: RunStatus::Ok,
                message: String::new(),
                log: String::new(),
                image: None,
                technique_ms: 1.0,
                render_ms: 1.0,
                wall_ms: 500.0,
                cpu_ms: 1.0,
                waiting_ms: 1.0,
                technique_cpu_ms,
                render_cpu_ms,
                sample_floats: floats,
                startup_ms: 0.0,
                peak_memory_bytes: 0,
                used_samples,
                metrics: BTreeMap::new(),
            })
            .collect();
        e.summarize();
        e
    }

    #[test]
    fn the_same_samples_cost_every_technique_the_same() {
        // Two techniques, 1000 samples each seed, the renderer noisy around 1 µs/sample.
        let a = run("a", 3, &[(10.0, 0.9, 1000), (11.0, 1.3, 1000), (10.5, 1.0, 1000)]);
        let b = run("b", 3, &[(20.0, 1.1, 1000), (21.0, 0.8, 1000), (20.5, 1.2, 1000)]);
        // Features cost the renderer three times as much per sample.
        let c = run("c", 14, &[(5.0, 3.0, 1000), (5.0, 3.0, 1000), (5.0, 3.0, 1000)]);
        let costs = Costs::of(&[a.clone(), b.clone(), c.clone()]);
        let close = |x: f64, y: f64| (x - y).abs() < 1e-9;
        assert!(close(costs.rate("s", 3).unwrap(), 1.05e-3));
        assert!(close(costs.rate("s", 14).unwrap(), 3e-3));
        let by_seed: Vec<f64> = costs.by_seed(&a).into_values().collect();
        assert!(by_seed.iter().zip([11.05, 12.05, 11.55]).all(|(x, y)| close(*x, y)), "{by_seed:?}");
        assert!(close(costs.of_run(&b), 20.5 + 1.05));
        assert!(close(costs.of_run(&c), 5.0 + 3.0));
        // Without CPU times (older results), the wall time.
        let old = run("old", 3, &[(0.0, 0.0, 1000)]);
        assert_eq!(Costs::of(std::slice::from_ref(&old)).of_run(&old), old.repeats[0].time_ms());
    }
}
