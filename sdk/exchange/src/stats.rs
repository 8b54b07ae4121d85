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
    match df {
        0 => f64::INFINITY,
        1..=30 => TABLE[df - 1],
        31..=40 => 2.021,
        41..=60 => 2.000,
        61..=120 => 1.980,
        _ => 1.960,
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
    fn noisy_differences_tie() {
        let a = samples(&[1.0, 1.2, 0.9, 1.1]);
        let b = samples(&[1.05, 1.1, 1.0, 1.02]);
        assert!(!differ(&a, &b));
        // A single seed cannot measure noise: any real difference counts.
        assert!(differ(&samples(&[1.0]), &samples(&[1.01])));
    }
}
