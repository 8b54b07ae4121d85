//! Statistics over a run's repeats: a metric's mean with its 95 %
//! confidence interval, a time's median and spread, and the paired test
//! that decides whether two techniques differ in a ranking cell.
//!
//! Repeats of a run differ only in the renderer's sample seed, and every
//! technique is run with the same seeds, so two techniques' values pair up
//! seed by seed: the paired test sees the difference the techniques make,
//! not the noise the seeds share.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

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

/// Whether two runs' costs (by sample seed) cannot be told apart: their
/// medians differ by at most [`COST_FLOOR`] (relative), or the paired
/// t-test over the log-ratios of the seeds they share does not reject "the
/// same cost" at the 1 % level. Costs pair by seed because the manager runs
/// one seed of every technique back to back: a machine whose speed drifts
/// moves both alike. 1 % rather than the values' 5 %, because a false
/// "faster" decides every equal-time cell of the point, where a false
/// "better" decides one; with one shared seed only the floor ties.
pub fn same_cost(a: &Samples, b: &Samples) -> bool {
    let (ma, mb) = (median(a), median(b));
    if !(ma > 0.0 && mb > 0.0) {
        return ma == mb;
    }
    if (ma / mb).ln().abs() <= COST_FLOOR.ln_1p() {
        return true;
    }
    let ratios: Vec<f64> = a
        .iter()
        .filter_map(|(seed, va)| b.get(seed).filter(|vb| *va > 0.0 && **vb > 0.0).map(|vb| (va / vb).ln()))
        .collect();
    if ratios.len() < 2 {
        return false;
    }
    let (d, sd) = mean_sd(&ratios);
    if sd == 0.0 {
        return false;
    }
    d.abs() / (sd / (ratios.len() as f64).sqrt()) <= t_quantile_995(ratios.len() - 1)
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
        // The same program twice: 1 % apart on the median, noisy seeds.
        assert!(same_cost(&samples(&[100.0, 103.0, 98.0]), &samples(&[101.0, 99.0, 100.5])));
        // 5 % apart, but the seeds' noise is larger than that.
        assert!(same_cost(&samples(&[100.0, 130.0, 80.0]), &samples(&[105.0, 90.0, 120.0])));
        // Twice the work, whatever the noise pattern.
        assert!(!same_cost(&samples(&[100.0, 103.0, 98.0]), &samples(&[200.0, 199.0, 204.0])));
        // 10 % apart with 1 % noise: different.
        assert!(!same_cost(&samples(&[100.0, 101.0, 99.0, 100.5]), &samples(&[110.0, 111.0, 109.5, 110.0])));
        // One shared seed: only the floor ties.
        assert!(same_cost(&samples(&[100.0]), &samples(&[101.0])));
        assert!(!same_cost(&samples(&[100.0]), &samples(&[110.0])));
        // Nothing measured on both sides is the same; on one side only, not.
        assert!(same_cost(&Samples::new(), &Samples::new()));
        assert!(!same_cost(&samples(&[0.0]), &samples(&[10.0])));
    }

    #[test]
    fn noisy_differences_tie() {
        let a = samples(&[1.0, 1.2, 0.9, 1.1]);
        let b = samples(&[1.05, 1.1, 1.0, 1.02]);
        assert!(!differ(&a, &b));
        // A single seed cannot measure noise: any real difference counts.
        assert!(differ(&samples(&[1.0]), &samples(&[1.01])));
    }
}
