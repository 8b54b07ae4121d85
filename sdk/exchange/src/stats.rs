//! Statistics over a run's repeats: a metric's mean with its 95 %
//! confidence interval, a time's median and spread, and the paired test
//! that decides whether two techniques differ in a ranking cell.
//!
//! Repeats of a run differ only in the renderer's sample seed, and every
//! technique is run with the same seeds, so two techniques' values pair up
//! seed by seed: the paired test sees the difference the techniques make,
//! not the noise the seeds share.

use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};

/// Below this relative difference two values are equal whatever their
/// noise: float rounding (a C++ and a Python box filter agree to 8 digits
/// and must not rank 1st and 2nd).
pub const ROUNDING_FLOOR: f64 = 1e-6;

/// Below this relative difference two costs are the same whatever their
/// noise (see [`same_cost`]).
pub const COST_FLOOR: f64 = 0.02;

/// A metric's mean over the repeats and its 95 % confidence interval
/// (Student's t); `low == high == mean` for a single repeat.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Interval {
    /// Mean over the repeats.
    pub mean: f64,
    /// Lower end of the 95 % confidence interval of the mean.
    pub low: f64,
    /// Upper end.
    pub high: f64,
    /// Number of repeats.
    pub n: usize,
}

impl Interval {
    /// The interval of finite `values`; `None` for none.
    pub fn of(values: &[f64]) -> Option<Interval> {
        let n = values.len();
        if n == 0 {
            return None;
        }
        let (mean, sd) = mean_sd(values);
        let half = if n > 1 { t_quantile_975(n - 1) * sd / (n as f64).sqrt() } else { 0.0 };
        Some(Interval { mean, low: mean - half, high: mean + half, n })
    }

    /// Half the interval's width.
    pub fn half_width(&self) -> f64 {
        (self.high - self.low) / 2.0
    }
}

/// A time's median over the repeats, its range and its coefficient of
/// variation (standard deviation over mean; 0 for one repeat).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Spread {
    /// Median.
    pub median: f64,
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
    /// Coefficient of variation.
    pub cv: f64,
}

impl Spread {
    /// The spread of `values`; `None` for none.
    pub fn of(values: &[f64]) -> Option<Spread> {
        if values.is_empty() {
            return None;
        }
        let mut sorted = values.to_vec();
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len();
        let median = if n % 2 == 1 { sorted[n / 2] } else { (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0 };
        let (mean, sd) = mean_sd(values);
        let cv = if mean > 0.0 { sd / mean } else { 0.0 };
        Some(Spread { median, min: sorted[0], max: sorted[n - 1], cv })
    }
}

/// Mean and sample standard deviation (0 for one value).
fn mean_sd(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    if values.len() < 2 {
        return (mean, 0.0);
    }
    let var = values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0);
    (mean, var.sqrt())
}

/// The 97.5 % quantile of Student's t with `df` degrees of freedom (two-sided 95 %).
pub fn t_quantile_975(df: usize) -> f64 {
    const TABLE: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131,
        2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
    ];
    t_quantile(df, &TABLE, [2.021, 2.000, 1.980, 1.960])
}

/// The 99.5 % quantile of Student's t with `df` degrees of freedom (two-sided 99 %).
pub fn t_quantile_995(df: usize) -> f64 {
    const TABLE: [f64; 30] = [
        63.657, 9.925, 5.841, 4.604, 4.032, 3.707, 3.499, 3.355, 3.250, 3.169, 3.106, 3.055, 3.012, 2.977, 2.947,
        2.921, 2.898, 2.878, 2.861, 2.845, 2.831, 2.819, 2.807, 2.797, 2.787, 2.779, 2.771, 2.763, 2.756, 2.750,
    ];
    t_quantile(df, &TABLE, [2.704, 2.660, 2.617, 2.576])
}

/// A quantile of Student's t from its table for 1–30 degrees of freedom
/// and its values at 40, 60, 120 and infinity (each used up to the next).
fn t_quantile(df: usize, table: &[f64; 30], beyond: [f64; 4]) -> f64 {
    match df {
        0 => f64::INFINITY,
        1..=30 => table[df - 1],
        31..=40 => beyond[0],
        41..=60 => beyond[1],
        61..=120 => beyond[2],
        _ => beyond[3],
    }
}

/// One technique's values in a ranking cell, by sample seed.
pub type Samples = BTreeMap<u64, f64>;

/// The mean of a cell entry's values.
pub fn mean(samples: &Samples) -> f64 {
    samples.values().sum::<f64>() / samples.len().max(1) as f64
}

/// Whether two techniques' values in one cell differ beyond the noise:
/// their means differ by more than [`ROUNDING_FLOOR`] (relative), and,
/// when they share two or more seeds, the paired t-test over the shared
/// seeds rejects "no difference" at the 5 % level. With a single shared
/// seed there is no noise estimate, and only the rounding floor ties.
pub fn differ(a: &Samples, b: &Samples) -> bool {
    let (ma, mb) = (mean(a), mean(b));
    let scale = ma.abs().max(mb.abs());
    if (ma - mb).abs() <= ROUNDING_FLOOR * scale || ma == mb {
        return false;
    }
    let diffs: Vec<f64> = a.iter().filter_map(|(seed, va)| b.get(seed).map(|vb| va - vb)).collect();
    if diffs.len() < 2 {
        return true;
    }
    let (d, sd) = mean_sd(&diffs);
    if d.abs() <= ROUNDING_FLOOR * scale {
        return false;
    }
    if sd == 0.0 {
        return true;
    }
    let t = d.abs() / (sd / (diffs.len() as f64).sqrt());
    t > t_quantile_975(diffs.len() - 1)
}

/// How much a technique's own CPU time moves from seed to seed at one
/// scene, the machine's noise: the standard deviation of its log once each
/// run's own level and each seed's shared drift are taken out (the residual
/// of the additive model log time = run + seed), pooled over every run
/// there with two seeds or more, and its degrees of freedom (0: no
/// estimate). [`CostNoise::at_share`] turns it into the noise of a log cost.
///
/// Pooled, because the noise is the machine's (the scheduler, other work,
/// frequency), not the technique's, and three seeds of one pair are too few
/// to measure it: judged pair by pair on its own two degrees of freedom, a
/// technique whose cost happened to scatter more was "at the time point"
/// more readily than a steadier and cheaper one, which then had no result
/// there, and ranked below it (an AMD EPYC board, 2026-12: the box filter
/// with twice the extra work above the one with the extra work once).
///
/// Pooled over the technique's own time, not the cost, because that is
/// what scatters alike at every budget: the renderer's share of a cost is
/// charged at the pooled render rate ([`crate::cost`]) and does not
/// scatter at all. The C++ box filter on seven procedural scenes through
/// the service (2026-12-07, AMD EPYC): its CPU time scattered by 3–14 %
/// from seed to seed at every budget from 1 to 64 spp, while its cost
/// scattered by 0.2–1.6 % at 1 spp and under 0.1 % at 64; pooled over the
/// budgets, a cost's noise was half what it was at 1 spp, where equal time
/// is decided.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CostNoise {
    /// Standard deviation of a log time (about its CV).
    pub sd: f64,
    /// Degrees of freedom of `sd`.
    pub df: usize,
}

/// How far a job moves a run's cost, in units of the seed-to-seed noise:
/// a job runs on the machine as it is in those minutes (other tenants'
/// memory traffic, frequency, what the kernel has in its caches), so two
/// jobs of the same program differ by more than their seeds explain, and
/// in the service every technique is measured in a job of its own. The C++
/// box filter, benchmarked in 20 jobs on seven procedural scenes at 1–64
/// spp (AMD EPYC, 2026-12-07): a job moved the mean of its own CPU time by
/// 0–11 % (median 6 %) beyond what its seeds explain, against 2–15 %
/// (median 5.5 %) from seed to seed; of 4 230 pairs of its jobs at one
/// scene and budget, the farthest apart differed by 5.6 times the pooled
/// seed noise, where a job's noise of 1 puts the 1 % threshold at 4.2 (50
/// pairs beyond it) and 1.5 at 5.9 (none). Twice the work (a log-ratio of
/// 0.69) stays beyond it while the seeds scatter by less than 11 %. Inside
/// one job (`fbksd run`) the term is not needed, and it is kept there too:
/// one rule, which only adds ties of costs within a job's noise.
pub const JOB_NOISE: f64 = 1.5;

impl CostNoise {
    /// The noise of the log costs at a point where the technique's own
    /// time is `share` of the cost (the renderer's part, at the pooled
    /// render rate, does not scatter).
    pub fn at_share(self, share: f64) -> CostNoise {
        CostNoise { sd: self.sd * share.clamp(0.0, 1.0), df: self.df }
    }

    /// The noise of these runs' times (by seed) at one scene.
    pub fn pooled<'a>(runs: impl IntoIterator<Item = &'a Samples>) -> CostNoise {
        let logs: Vec<BTreeMap<u64, f64>> = runs
            .into_iter()
            .map(|r| r.iter().filter(|(_, v)| **v > 0.0 && v.is_finite()).map(|(s, v)| (*s, v.ln())).collect())
            .filter(|r: &BTreeMap<u64, f64>| r.len() >= 2)
            .collect();
        let seeds: BTreeSet<u64> = logs.iter().flat_map(|r| r.keys().copied()).collect();
        let n: usize = logs.iter().map(BTreeMap::len).sum();
        let Some(df) = (n + 1).checked_sub(logs.len() + seeds.len()).filter(|df| *df > 0 && !logs.is_empty()) else {
            return CostNoise::default();
        };
        // Least squares of the additive model by alternating means (backfitting),
        // which also fits runs that lack some seeds.
        let mut level: Vec<f64> = logs.iter().map(|r| r.values().sum::<f64>() / r.len() as f64).collect();
        let mut drift: BTreeMap<u64, f64> = BTreeMap::new();
        for _ in 0..100 {
            drift = seeds
                .iter()
                .map(|s| {
                    let d: Vec<f64> = logs.iter().zip(&level).filter_map(|(r, l)| Some(r.get(s)? - l)).collect();
                    (*s, d.iter().sum::<f64>() / d.len() as f64)
                })
                .collect();
            level = logs.iter().map(|r| r.iter().map(|(s, x)| x - drift[s]).sum::<f64>() / r.len() as f64).collect();
        }
        let drift = &drift;
        let squares: f64 =
            logs.iter().zip(&level).flat_map(|(r, l)| r.iter().map(move |(s, x)| (x - l - drift[s]).powi(2))).sum();
        CostNoise { sd: (squares / df as f64).sqrt(), df }
    }
}

/// Whether two runs' costs (by sample seed) cannot be told apart where
/// log costs scatter as `noise` (a scene's [`CostNoise`] at the point's
/// share): the mean log-ratio of the seeds they share (of their medians,
/// when they share none) is within [`COST_FLOOR`], or within what the noise
/// explains at the 1 % level (Student's t on the pooled degrees of
/// freedom): the seeds' noise of the mean over the shared seeds, and
/// [`JOB_NOISE`] for each of the two jobs. Costs pair by seed because the
/// manager runs one seed of every technique back to back: a machine whose
/// speed drifts moves both alike. 1 % rather than the values' 5 %, because
/// a false "faster" decides every equal-time cell of the point, where a
/// false "better" decides one. With one noise for the point, the answer
/// depends only on the cost ratio and the seeds shared: of two techniques
/// at one point, the cheaper is at it whenever the costlier is.
pub fn same_cost(a: &Samples, b: &Samples, noise: CostNoise) -> bool {
    let (ma, mb) = (median(a), median(b));
    if !(ma > 0.0 && mb > 0.0) {
        return ma == mb;
    }
    let ratios = log_ratios(a, b);
    let d = if ratios.is_empty() { (ma / mb).ln() } else { ratios.iter().sum::<f64>() / ratios.len() as f64 };
    if d.abs() <= COST_FLOOR.ln_1p() {
        return true;
    }
    if ratios.is_empty() || noise.df == 0 {
        return false;
    }
    d.abs() <= cost_threshold(noise, ratios.len())
}

/// The log-ratios of two runs' costs, seed by seed, over the seeds they share.
fn log_ratios(a: &Samples, b: &Samples) -> Vec<f64> {
    a.iter()
        .filter_map(|(seed, va)| b.get(seed).filter(|vb| *va > 0.0 && **vb > 0.0).map(|vb| (va / vb).ln()))
        .collect()
}

/// The largest mean log-ratio of two costs over `seeds` shared seeds that
/// `noise` explains at the 1 % level, with a job's noise on each side.
fn cost_threshold(noise: CostNoise, seeds: usize) -> f64 {
    t_quantile_995(noise.df) * noise.sd * (2.0 / seeds as f64 + 2.0 * JOB_NOISE * JOB_NOISE).sqrt()
}

/// Whether more seeds could make two values that [`differ`] calls tied
/// differ: their means are apart by more than [`ROUNDING_FLOOR`], they
/// share fewer than `seeds` seeds, and the paired test would reject "no
/// difference" at `seeds` shared seeds if the difference and its spread
/// held. A tie that `seeds` seeds could not break is not worth them;
/// values equal to the rounding floor (the same program twice) never are.
pub fn could_differ(a: &Samples, b: &Samples, seeds: usize) -> bool {
    if differ(a, b) {
        return false;
    }
    let diffs: Vec<f64> = a.iter().filter_map(|(seed, va)| b.get(seed).map(|vb| va - vb)).collect();
    if diffs.len() < 2 || diffs.len() >= seeds {
        return false;
    }
    let (d, sd) = mean_sd(&diffs);
    let scale = mean(a).abs().max(mean(b).abs());
    if d.abs() <= ROUNDING_FLOOR * scale || sd == 0.0 {
        return false;
    }
    d.abs() / (sd / (seeds as f64).sqrt()) > t_quantile_975(seeds - 1)
}

/// Whether more seeds could show that two costs [`same_cost`] cannot tell
/// apart do differ: their shared seeds' mean log-ratio is beyond
/// [`COST_FLOOR`], they share fewer than `seeds` seeds, and at `seeds`
/// shared seeds the same ratio would be beyond what `noise` explains. The
/// jobs' part of the noise does not shrink with seeds, so a ratio within
/// it is never worth more.
pub fn could_cost_differ(a: &Samples, b: &Samples, noise: CostNoise, seeds: usize) -> bool {
    if !same_cost(a, b, noise) || noise.df == 0 {
        return false;
    }
    let ratios = log_ratios(a, b);
    if ratios.is_empty() || ratios.len() >= seeds {
        return false;
    }
    let d = ratios.iter().sum::<f64>() / ratios.len() as f64;
    d.abs() > COST_FLOOR.ln_1p() && d.abs() > cost_threshold(noise, seeds)
}

/// The median of a cell entry's values (0 for none).
pub fn median(samples: &Samples) -> f64 {
    Spread::of(&samples.values().copied().collect::<Vec<_>>()).map_or(0.0, |s| s.median)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn samples(values: &[f64]) -> Samples {
        values.iter().enumerate().map(|(i, v)| (i as u64, *v)).collect()
    }

    #[test]
    fn intervals_follow_student() {
        let i = Interval::of(&[1.0, 2.0, 3.0]).unwrap();
        // mean 2, sd 1, t(2) = 4.303 → ± 4.303 / √3.
        assert_eq!(i.mean, 2.0);
        assert!((i.half_width() - 4.303 / 3f64.sqrt()).abs() < 1e-12);
        let one = Interval::of(&[5.0]).unwrap();
        assert_eq!((one.low, one.high, one.n), (5.0, 5.0, 1));
        assert!(Interval::of(&[]).is_none());
    }

    #[test]
    fn spreads_report_median_and_cv() {
        let s = Spread::of(&[10.0, 12.0, 11.0, 50.0]).unwrap();
        assert_eq!((s.median, s.min, s.max), (11.5, 10.0, 50.0));
        assert!(s.cv > 0.5);
        assert_eq!(Spread::of(&[3.0]).unwrap().cv, 0.0);
    }

    #[test]
    fn rounding_differences_tie_even_when_consistent() {
        // A C++ and a Python box filter: the same to 8 digits on every seed.
        let cpp = samples(&[0.0123456789, 0.0131111111, 0.0119999999]);
        let py = samples(&[0.0123456790, 0.0131111112, 0.0120000000]);
        assert!(!differ(&cpp, &py));
        assert!(!differ(&samples(&[1.0]), &samples(&[1.0 + 1e-9])));
    }

    #[test]
    fn the_paired_test_sees_through_shared_noise() {
        // Seeds move both techniques a lot; one is always 1 % better.
        let a = samples(&[1.0, 2.0, 0.5, 1.5, 3.0]);
        let b: Samples = a.iter().map(|(k, v)| (*k, v * 1.01)).collect();
        assert!(differ(&a, &b));
        // Unpaired, the intervals would overlap completely.
        let (ia, ib) = (Interval::of(&[1.0, 2.0, 0.5, 1.5, 3.0]).unwrap(), Interval::of(&[1.01, 2.02]).unwrap());
        assert!(ia.high > ib.low);
    }

    #[test]
    fn costs_tie_within_the_floor_or_the_noise() {
        let noise = |sd: f64| CostNoise { sd, df: 10 };
        // The same program twice: 1 % apart, whatever the noise.
        assert!(same_cost(&samples(&[100.0, 103.0, 98.0]), &samples(&[101.0, 99.0, 100.5]), noise(0.0)));
        // 5 % apart, on a scene where costs scatter by 20 %.
        assert!(same_cost(&samples(&[100.0, 130.0, 80.0]), &samples(&[105.0, 90.0, 120.0]), noise(0.2)));
        // Twice the work, or 10 % more with 1 % noise: different.
        assert!(!same_cost(&samples(&[100.0, 103.0, 98.0]), &samples(&[200.0, 199.0, 204.0]), noise(0.02)));
        assert!(!same_cost(
            &samples(&[100.0, 101.0, 99.0, 100.5]),
            &samples(&[110.0, 111.0, 109.5, 110.0]),
            noise(0.01)
        ));
        // One shared seed is judged on the scene's noise too.
        assert!(same_cost(&samples(&[100.0]), &samples(&[110.0]), noise(0.05)));
        assert!(!same_cost(&samples(&[100.0]), &samples(&[110.0]), noise(0.01)));
        // Without an estimate of the noise, only the floor ties.
        assert!(same_cost(&samples(&[100.0]), &samples(&[101.0]), CostNoise::default()));
        assert!(!same_cost(&samples(&[100.0, 130.0]), &samples(&[115.0, 140.0]), CostNoise::default()));
        // Two jobs of the same program, 5 % apart on every seed where a seed scatters by 2 %:
        // a job's noise on each side ties them (up to 12.9 %); twice the work does not.
        let steady = samples(&[100.0, 101.0, 99.0]);
        let job = |r: f64| samples(&[100.0 * r, 101.0 * r, 99.0 * r]);
        let machine = CostNoise { sd: 0.02, df: 20 };
        assert!(same_cost(&steady, &job(1.05), machine));
        assert!(!same_cost(&steady, &job(1.2), machine));
        assert!(!same_cost(&steady, &job(2.0), machine));
        // Nothing measured on both sides is the same; on one side only, not.
        assert!(same_cost(&Samples::new(), &Samples::new(), noise(0.1)));
        assert!(!same_cost(&samples(&[0.0]), &samples(&[10.0]), noise(0.1)));
    }

    #[test]
    fn the_pooled_noise_leaves_out_what_runs_and_seeds_share() {
        // Two runs, three seeds, the second seed 20 % slower for both: no noise left.
        let a = samples(&[100.0, 120.0, 110.0]);
        let b = samples(&[200.0, 240.0, 220.0]);
        let exact = CostNoise::pooled([&a, &b]);
        assert_eq!(exact.df, 2);
        assert!(exact.sd < 1e-12, "{exact:?}");
        // For one pair, a log-ratio scatters as twice the pooled variance: sd(log a/b) = √2 sd.
        let c = samples(&[205.0, 230.0, 224.0]);
        let pair = CostNoise::pooled([&a, &c]);
        let ratios: Vec<f64> = a.values().zip(c.values()).map(|(x, y)| (x / y).ln()).collect();
        assert!((pair.sd * 2f64.sqrt() - mean_sd(&ratios).1).abs() < 1e-9, "{pair:?}");
        // A run with one seed says nothing about the noise; one missing a seed still does.
        let holey: Samples = [(0, 50.0), (2, 51.0)].into();
        let more = CostNoise::pooled([&a, &c, &samples(&[70.0]), &holey]);
        assert_eq!(more.df, 3);
        assert!(more.sd > 0.0 && more.sd < 0.1, "{more:?}");
        // Nothing to pool from.
        assert_eq!(CostNoise::pooled([&samples(&[1.0]), &samples(&[2.0])]), CostNoise::default());
    }

    #[test]
    fn noisy_differences_tie() {
        let a = samples(&[1.0, 1.2, 0.9, 1.1]);
        let b = samples(&[1.05, 1.1, 1.0, 1.02]);
        assert!(!differ(&a, &b));
        // A single seed cannot measure noise: any real difference counts.
        assert!(differ(&samples(&[1.0]), &samples(&[1.01])));
    }

    #[test]
    fn more_seeds_are_asked_for_only_where_they_could_decide() {
        let base = samples(&[1.0, 1.2, 0.9]);
        let shifted = |d: [f64; 3]| samples(&[1.0 + d[0], 1.2 + d[1], 0.9 + d[2]]);
        // A steady difference that 3 seeds cannot show (t = 2.2 < 4.30) and 6 would (3.1 > 2.57).
        let close = shifted([0.1, 0.25, 0.05]);
        assert!(!differ(&base, &close));
        assert!(could_differ(&base, &close, 6));
        // The same difference already at the cap: nothing more to ask.
        assert!(!could_differ(&base, &close, 3));
        // A difference the noise swamps even at 6 seeds (t would be 1.6).
        assert!(!could_differ(&base, &shifted([0.1, 0.3, -0.05]), 6));
        // The same program twice: equal values never ask for more.
        assert!(!could_differ(&base, &base.clone(), 100));
        // Values that already differ are decided.
        assert!(!could_differ(&base, &shifted([1.0, 1.1, 1.05]), 6));

        // Costs at a point whose log costs scatter by 5 % (10 degrees of freedom), with a
        // job's noise on each side: 3 shared seeds tie up to a ratio of e^0.360, 6 would
        // only up to e^0.348; the jobs' part does not shrink with seeds.
        let machine = CostNoise { sd: 0.05, df: 10 };
        let cost = samples(&[100.0, 104.0, 98.0]);
        let times = |r: f64| samples(&[100.0 * r, 104.0 * r, 98.0 * r]);
        assert!(same_cost(&cost, &times(1.42), machine));
        assert!(could_cost_differ(&cost, &times(1.42), machine, 6));
        assert!(!could_cost_differ(&cost, &times(1.3), machine, 100), "within the jobs' noise, whatever the seeds");
        assert!(!could_cost_differ(&cost, &times(1.015), machine, 100), "within the floor");
        assert!(!could_cost_differ(&cost, &times(1.5), machine, 6), "already apart");
        assert!(!could_cost_differ(&cost, &times(1.42), CostNoise::default(), 6), "no noise estimate");
    }
}
