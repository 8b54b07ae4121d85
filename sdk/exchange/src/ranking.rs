//! Ranking techniques over a results index: the mean of each technique's
//! rank in every (scene, spp, metric) group, ties sharing the mean of their
//! places and a missing value counting as last. The CLI ranks a local
//! results directory and the server its leaderboard with this one rule.
//!
//! A missing value counting as last fixes the original, where a missing
//! result was simply not ranked, which favoured incomplete techniques.

use crate::results::IndexEntry;
use std::collections::{BTreeMap, BTreeSet};

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
            wall_ms: 0.0,
            cpu_ms: 0.0,
            peak_memory_bytes: 0,
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
