//! Ranking techniques over a results index, at equal samples and at equal
//! time. The CLI ranks a local results directory, the viewer shows its
//! cells, and the server ranks its leaderboard, all with these rules:
//!
//! - A **cell** is one scene and one metric at one budget (equal samples)
//!   or at one time point (equal time). In a cell, two techniques **tie**
//!   unless their values differ beyond the noise ([`stats::differ`]: the
//!   paired t-test over the seeds they share, and a rounding floor), and a
//!   technique's place is `1 + (techniques better than it) + ½ (techniques
//!   tied with it)`: tied techniques share the mean of their places, and
//!   the places of a cell always sum to `n(n+1)/2`.
//! - A technique's **mean rank** is the mean of its places over every cell,
//!   a missing value counting as last. That fixes the original, where a
//!   missing result was simply not ranked, which favoured incomplete
//!   techniques.
//! - **Equal time**: a scene's time points are, at each budget of its
//!   sweep, the time to the result of the fastest technique at that budget.
//!   Each technique's error at a time point is read off its own
//!   error-against-time curve (its budgets, linear in log–log between the
//!   two budgets around the time point), seed by seed, never extrapolated:
//!   a technique whose smallest budget already takes longer has no value
//!   there, and ranks last, because it cannot give a result in that time.
//!
//! [`stats::differ`]: crate::stats::differ

use crate::results::IndexEntry;
use crate::stats::{differ, mean, Samples};
use crate::RunStatus;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};

/// A technique's place in the ranking.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Standing {
    /// Technique.
    pub technique: String,
    /// Mean place over every cell; lower is better.
    pub mean_rank: f64,
    /// Cells in which it had a value.
    pub ranked: usize,
    /// Cells in which it had none (counted as last).
    pub missing: usize,
    /// Cells in which it tied with at least one other technique.
    #[serde(default)]
    pub tied: usize,
}

/// Where a cell compares the techniques.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum At {
    /// At this budget.
    Spp {
        /// Samples per pixel.
        spp: u64,
    },
    /// At this time to the result.
    Time {
        /// The time point in ms.
        ms: f64,
        /// The fastest technique at `spp`, whose time it is.
        fastest: String,
        /// The budget.
        spp: u64,
    },
}

/// One technique in a cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Place {
    /// Technique.
    pub technique: String,
    /// Mean value over its seeds.
    pub mean: f64,
    /// Seeds the value is the mean of.
    pub seeds: usize,
    /// Its place (1 is best; ties share).
    pub place: f64,
    /// The techniques it ties with.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tied_with: Vec<String>,
}

/// One scene and metric at one budget or time point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Cell {
    /// Scene.
    pub scene: String,
    /// Metric acronym.
    pub metric: String,
    /// Budget or time point.
    pub at: At,
    /// Techniques with a value, best first.
    pub places: Vec<Place>,
    /// Techniques without one (they count as last).
    pub missing: Vec<String>,
}

/// Standings and the cells they come from.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Ranking {
    /// Best first.
    pub standings: Vec<Standing>,
    /// Every cell.
    pub cells: Vec<Cell>,
}

/// A technique's values in a cell, by seed.
type CellValues<'a> = (&'a str, Samples);

/// Ranks techniques by mean place over (scene, spp, metric) cells.
pub fn rank(runs: &[IndexEntry], lower_is_better: impl Fn(&str) -> bool) -> Vec<Standing> {
    equal_spp(runs, lower_is_better).standings
}

/// The ranking at equal samples: a cell per (scene, spp, metric).
pub fn equal_spp(runs: &[IndexEntry], lower_is_better: impl Fn(&str) -> bool) -> Ranking {
    let techniques: BTreeSet<&str> = runs.iter().map(|r| r.technique.as_str()).collect();
    let mut cells: BTreeMap<(&str, u64, &str), Vec<CellValues>> = BTreeMap::new();
    for r in runs {
        for metric in r.metrics.keys() {
            cells.entry((&r.scene, r.spp, metric)).or_default().push((&r.technique, r.samples(metric)));
        }
    }
    let cells = cells
        .into_iter()
        .map(|((scene, spp, metric), values)| {
            place(scene, metric, At::Spp { spp }, values, &techniques, lower_is_better(metric))
        })
        .collect();
    standings(&techniques, cells)
}

/// The ranking at equal time: a cell per (scene, time point, metric); see
/// the module's documentation for the time points and the interpolation.
pub fn equal_time(runs: &[IndexEntry], lower_is_better: impl Fn(&str) -> bool) -> Ranking {
    let techniques: BTreeSet<&str> = runs.iter().map(|r| r.technique.as_str()).collect();
    let mut by_scene: BTreeMap<&str, Vec<&IndexEntry>> = BTreeMap::new();
    for r in runs.iter().filter(|r| r.status == RunStatus::Ok && r.time() > 0.0 && r.time().is_finite()) {
        by_scene.entry(&r.scene).or_default().push(r);
    }
    let mut cells = Vec::new();
    for (scene, mut entries) in by_scene {
        entries.sort_by_key(|r| r.spp);
        let points = time_points(&entries);
        let metrics: BTreeSet<&str> = entries.iter().flat_map(|r| r.metrics.keys().map(String::as_str)).collect();
        // Each technique's curve per metric, in budget order, made once for every time point.
        let curves: BTreeMap<&str, Vec<(&str, Curve)>> = metrics
            .iter()
            .map(|&metric| {
                let curve = |t: &str| -> Curve {
                    entries.iter().filter(|r| r.technique == t).map(|r| (r.time(), r.samples(metric))).collect()
                };
                (metric, techniques.iter().map(|t| (*t, curve(t))).collect())
            })
            .collect();
        for &(ms, fastest, spp) in &points {
            for (&metric, curves) in &curves {
                let values = curves.iter().filter_map(|(t, curve)| Some((*t, interpolate(curve, ms)?))).collect();
                let at = At::Time { ms, fastest: fastest.to_string(), spp };
                cells.push(place(scene, metric, at, values, &techniques, lower_is_better(metric)));
            }
        }
    }
    standings(&techniques, cells)
}

/// A technique's error-against-time curve: (time to result, values by seed), in budget order.
type Curve = Vec<(f64, Samples)>;

/// A scene's time points: at each budget, the fastest technique's time.
fn time_points<'a>(entries: &[&'a IndexEntry]) -> Vec<(f64, &'a str, u64)> {
    let mut fastest: BTreeMap<u64, &IndexEntry> = BTreeMap::new();
    for r in entries {
        let best = fastest.entry(r.spp).or_insert(r);
        if r.time() < best.time() {
            *best = r;
        }
    }
    fastest.into_values().map(|r| (r.time(), r.technique.as_str(), r.spp)).collect()
}

/// The value of a technique's curve (time, values by seed; in budget
/// order) at time `t`, seed by seed: linear in log–log between the two
/// budgets around `t` (linear where a value is not positive); `None`
/// outside the curve.
pub fn interpolate(points: &[(f64, Samples)], t: f64) -> Option<Samples> {
    if let Some((_, s)) = points.iter().find(|(time, s)| *time == t && !s.is_empty()) {
        return Some(s.clone());
    }
    for pair in points.windows(2) {
        let ((t0, s0), (t1, s1)) = (&pair[0], &pair[1]);
        if !(t0.min(*t1) < t && t < t0.max(*t1)) {
            continue;
        }
        let w = (t / t0).ln() / (t1 / t0).ln();
        let samples: Samples = s0
            .iter()
            .filter_map(|(seed, v0)| {
                let v1 = s1.get(seed)?;
                Some((
                    *seed,
                    if *v0 > 0.0 && *v1 > 0.0 { (v0.ln() + w * (v1.ln() - v0.ln())).exp() } else { v0 + w * (v1 - v0) },
                ))
            })
            .collect();
        if !samples.is_empty() {
            return Some(samples);
        }
    }
    None
}

/// Places the techniques of one cell.
fn place(scene: &str, metric: &str, at: At, values: Vec<CellValues>, techniques: &BTreeSet<&str>, lower: bool) -> Cell {
    let (values, _): (Vec<_>, Vec<_>) =
        values.into_iter().partition(|(_, s)| !s.is_empty() && s.values().all(|v| v.is_finite()));
    let means: Vec<f64> = values.iter().map(|(_, s)| mean(s)).collect();
    let better = |i: usize, j: usize| if lower { means[i] < means[j] } else { means[i] > means[j] };
    let mut places: Vec<Place> = (0..values.len())
        .map(|i| {
            let mut ahead = 0;
            let mut tied_with = Vec::new();
            for j in (0..values.len()).filter(|&j| j != i) {
                if !differ(&values[i].1, &values[j].1) {
                    tied_with.push(values[j].0.to_string());
                } else if better(j, i) {
                    ahead += 1;
                }
            }
            Place {
                technique: values[i].0.to_string(),
                mean: means[i],
                seeds: values[i].1.len(),
                place: 1.0 + ahead as f64 + tied_with.len() as f64 / 2.0,
                tied_with,
            }
        })
        .collect();
    places.sort_by(|a, b| {
        a.place.total_cmp(&b.place).then_with(
            || {
                if lower {
                    a.mean.total_cmp(&b.mean)
                } else {
                    b.mean.total_cmp(&a.mean)
                }
            },
        )
    });
    let present: BTreeSet<&str> = places.iter().map(|p| p.technique.as_str()).collect();
    let missing = techniques.iter().filter(|t| !present.contains(*t)).map(|t| t.to_string()).collect();
    Cell { scene: scene.to_string(), metric: metric.to_string(), at, places, missing }
}

/// Mean places over `cells`, a missing value counting as last.
fn standings(techniques: &BTreeSet<&str>, cells: Vec<Cell>) -> Ranking {
    let n = techniques.len() as f64;
    let mut totals: BTreeMap<&str, Standing> = techniques
        .iter()
        .map(|t| (*t, Standing { technique: t.to_string(), mean_rank: 0.0, ranked: 0, missing: 0, tied: 0 }))
        .collect();
    for cell in &cells {
        for p in &cell.places {
            let s = totals.get_mut(p.technique.as_str()).expect("a ranked technique");
            s.mean_rank += p.place;
            s.ranked += 1;
            s.tied += usize::from(!p.tied_with.is_empty());
        }
        for t in &cell.missing {
            let s = totals.get_mut(t.as_str()).expect("a ranked technique");
            s.mean_rank += n;
            s.missing += 1;
        }
    }
    let mut standings: Vec<Standing> = totals
        .into_values()
        .map(|mut s| {
            let cells = s.ranked + s.missing;
            s.mean_rank = if cells == 0 { f64::NAN } else { s.mean_rank / cells as f64 };
            s
        })
        .collect();
    standings.sort_by(|a, b| a.mean_rank.total_cmp(&b.mean_rank).then(a.technique.cmp(&b.technique)));
    Ranking { standings, cells }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::results::Repeat;

    fn run(t: &str, scene: &str, spp: u64, metrics: &[(&str, f64)]) -> IndexEntry {
        IndexEntry {
            metrics: metrics.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            ..IndexEntry::new(t, scene, spp)
        }
    }

    /// A run repeated with seeds 0.., its MSE per seed and its time per seed.
    fn repeated(t: &str, scene: &str, spp: u64, mse: &[f64], time_ms: f64) -> IndexEntry {
        let mut e = run(t, scene, spp, &[]);
        e.repeats = mse
            .iter()
            .enumerate()
            .map(|(seed, v)| Repeat {
                seed: seed as u64,
                status: RunStatus::Ok,
                message: String::new(),
                log: String::new(),
                image: None,
                technique_ms: time_ms / 2.0,
                render_ms: time_ms / 2.0,
                wall_ms: time_ms,
                cpu_ms: 0.0,
                waiting_ms: time_ms / 2.0,
                peak_memory_bytes: 0,
                used_samples: 0,
                metrics: [("MSE".to_string(), *v)].into(),
            })
            .collect();
        e.summarize();
        e
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

    #[test]
    fn differences_within_the_noise_tie() {
        // b's errors are within a's seed-to-seed noise; c is clearly worse on every seed.
        let runs = vec![
            repeated("a", "s", 4, &[1.0, 1.2, 0.9, 1.1], 10.0),
            repeated("b", "s", 4, &[1.05, 1.1, 1.0, 1.02], 10.0),
            repeated("c", "s", 4, &[2.0, 2.3, 1.9, 2.2], 10.0),
        ];
        let ranking = equal_spp(&runs, |_| true);
        let cell = &ranking.cells[0];
        let places: Vec<(&str, f64)> = cell.places.iter().map(|p| (p.technique.as_str(), p.place)).collect();
        assert_eq!(places[2], ("c", 3.0));
        assert!(places[..2].iter().all(|(_, p)| *p == 1.5), "{places:?}");
        assert_eq!(cell.places[0].tied_with.len(), 1);
        assert_eq!(ranking.standings[2].technique, "c");
        assert_eq!(ranking.standings[0].tied, 1);
    }

    #[test]
    fn ties_that_do_not_chain_still_sum_to_the_places() {
        // a ~ b and b ~ c, but a beats c: places 1.5, 2, 2.5.
        let runs = vec![
            repeated("a", "s", 4, &[1.0, 1.0, 1.0, 1.0], 1.0),
            repeated("b", "s", 4, &[1.0, 1.5, 1.0, 1.5], 1.0),
            repeated("c", "s", 4, &[1.5, 1.5, 1.5, 1.5], 1.0),
        ];
        let cell = &equal_spp(&runs, |_| true).cells[0];
        let places: Vec<f64> = cell.places.iter().map(|p| p.place).collect();
        assert_eq!(places, [1.5, 2.0, 2.5]);
    }

    /// Known curves: "fast" has MSE = 1/t (t = 1, 4, 16 ms at 1, 4, 16 spp),
    /// "slow" takes 4× as long per budget but is 8× more accurate: MSE = 1/(8·t/4).
    #[test]
    fn equal_time_reads_each_curve_at_the_fastest_times() {
        let mut runs = Vec::new();
        for spp in [1u64, 4, 16] {
            let t = spp as f64;
            runs.push(repeated("fast", "s", spp, &[1.0 / t; 3], t));
            runs.push(repeated("slow", "s", spp, &[1.0 / (2.0 * t); 3], 4.0 * t));
        }
        let ranking = equal_time(&runs, |_| true);
        // Time points: 1, 4 and 16 ms (fast is the fastest at every budget).
        let at: Vec<f64> = ranking
            .cells
            .iter()
            .map(|c| match c.at {
                At::Time { ms, .. } => ms,
                _ => unreachable!(),
            })
            .collect();
        assert_eq!(at, [1.0, 4.0, 16.0]);
        // At 1 ms, slow has no result (its 1 spp takes 4 ms): fast wins, slow is missing.
        assert_eq!(ranking.cells[0].missing, ["slow"]);
        // At 4 ms, slow (1 spp) has MSE 0.5 against fast's 0.25 (4 spp).
        let c4 = &ranking.cells[1];
        assert_eq!(c4.places[0].technique, "fast");
        assert!((c4.places[1].mean - 0.5).abs() < 1e-12);
        // At 16 ms: slow's 4 spp (MSE 0.125) beats fast's 16 spp (0.0625)? No: fast still wins.
        // Between its budgets, slow's value is read in log–log: at 8 ms, 1/(2·2) = 0.25.
        let curve: Vec<(f64, Samples)> =
            [(4.0, [(0u64, 0.5)].into()), (16.0, [(0u64, 0.125)].into())].into_iter().collect();
        let mid = interpolate(&curve, 8.0).unwrap()[&0];
        assert!((mid - 0.25).abs() < 1e-12, "{mid}");
        // Never extrapolated.
        assert!(interpolate(&curve, 2.0).is_none());
        assert!(interpolate(&curve, 32.0).is_none());
        assert_eq!(ranking.standings[0].technique, "fast");
    }

    #[test]
    fn a_slower_but_better_technique_wins_at_equal_time_when_it_pays() {
        // "denoiser" takes twice the time of "box" per budget but is 10× more accurate.
        let mut runs = Vec::new();
        for spp in [1u64, 4, 16, 64] {
            let t = spp as f64;
            runs.push(repeated("box", "s", spp, &[1.0 / t, 1.1 / t], t));
            runs.push(repeated("denoiser", "s", spp, &[0.1 / t, 0.11 / t], 2.0 * t));
        }
        let spp = equal_spp(&runs, |_| true);
        let time = equal_time(&runs, |_| true);
        assert_eq!(spp.standings[0].technique, "denoiser");
        // At equal time: at 1 ms the denoiser has nothing (last); at 4, 16, 64 ms it wins.
        assert_eq!(time.standings[0].technique, "denoiser");
        let first = time.cells.iter().find(|c| matches!(c.at, At::Time { ms, .. } if ms == 1.0)).unwrap();
        assert_eq!(first.missing, ["denoiser"]);
        assert!((time.standings[0].mean_rank - (2.0 + 1.0 + 1.0 + 1.0) / 4.0).abs() < 1e-12);
    }
}
