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
//! - **Equal time**: the time axis is each run's cost ([`crate::cost`]:
//!   the technique's CPU time, start-up excluded, and its samples at the
//!   scene's render rate). A scene's time points are, at each budget of its
//!   sweep, the cost of the cheapest technique at that budget, with its cost
//!   by seed. A technique whose cost at one of its budgets cannot be told
//!   apart from the point's ([`stats::same_cost`]: the noise of the
//!   techniques' own times at the scene, pooled ([`stats::CostNoise`]), at
//!   the point's share of the cost, and a job's noise on each side) is
//!   given that budget's result there: the same program under two names
//!   ties at equal time as it does at equal samples. Otherwise its error is
//!   read off its own error-against-cost curve (linear in log–log between
//!   the two budgets around the point), seed by seed, never extrapolated: a
//!   technique whose smallest budget costs more, beyond the noise, has no
//!   value there and ranks last, because it cannot give a result for that
//!   cost. Techniques whose costs cannot be told apart at the budgets
//!   they are read from or between (directly or through a chain of such
//!   techniques) are all read at one point of their budgets, not each at
//!   its own, for every comparison and for the value shown: none of them
//!   is the faster, so what is left between them is their values.
//!
//! [`stats::differ`]: crate::stats::differ
//! [`stats::same_cost`]: crate::stats::same_cost
//! [`stats::CostNoise`]: crate::stats::CostNoise

use crate::cost::Costs;
use crate::results::IndexEntry;
use crate::stats::{could_cost_differ, could_differ, differ, mean, median, same_cost, CostNoise, Samples};
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
    /// At equal time: the budget whose result the value is, when that
    /// budget's time is the time point's within the noise (absent when the
    /// value is read between two budgets).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spp: Option<u64>,
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
/// the module's documentation for the time points and how each
/// technique's value at one is found.
pub fn equal_time(runs: &[IndexEntry], lower_is_better: impl Fn(&str) -> bool) -> Ranking {
    let techniques: BTreeSet<&str> = runs.iter().map(|r| r.technique.as_str()).collect();
    let mut cells = Vec::new();
    for_each_time_point(runs, &timed_by_scene(runs), |scene, point, noise, metrics, sources| {
        for &metric in metrics {
            let readings = read_all(sources, metric, point.ms, noise);
            let at = At::Time { ms: point.ms, fastest: point.run.technique.clone(), spp: point.run.spp };
            let values = readings.iter().map(|(t, _, r)| (*t, r.samples.clone())).collect();
            let mut cell = place(scene, metric, at, values, &techniques, lower_is_better(metric));
            for p in &mut cell.places {
                p.spp = readings.iter().find(|(t, ..)| *t == p.technique).and_then(|(.., r)| r.spp);
            }
            cells.push(cell);
        }
    });
    standings(&techniques, cells)
}

/// Calls `visit` with every time point of every scene of `scenes` (the
/// runs' [`timed_by_scene`]): the scene, the point, the scene's cost noise
/// ([`CostNoise::pooled`]), its metrics, and where each technique's value
/// there comes from (techniques with no value there left out).
fn for_each_time_point<'a>(
    runs: &'a [IndexEntry],
    scenes: &BTreeMap<&'a str, Vec<Timed<'a>>>,
    mut visit: impl FnMut(&'a str, &Timed<'a>, CostNoise, &BTreeSet<&'a str>, &[(&'a str, Source<'a, '_>)]),
) {
    let techniques: BTreeSet<&str> = runs.iter().map(|r| r.technique.as_str()).collect();
    for (&scene, entries) in scenes {
        let metrics: BTreeSet<&str> = entries.iter().flat_map(|t| t.run.metrics.keys().map(String::as_str)).collect();
        let budgets: Vec<(&str, Vec<&Timed>)> =
            techniques.iter().map(|t| (*t, entries.iter().filter(|e| e.run.technique == *t).collect())).collect();
        let scene_noise = CostNoise::pooled(entries.iter().map(|t| &t.own));
        for point in time_points(entries) {
            let noise = scene_noise.at_share(point.share);
            let sources: Vec<(&str, Source)> =
                budgets.iter().filter_map(|(t, runs)| Some((*t, source(runs, point, noise)?))).collect();
            visit(scene, point, scene_noise, &metrics, &sources);
        }
    }
}

/// Each scene's runs that have a cost ([`Costs`]), with it, in budget order.
fn timed_by_scene(runs: &[IndexEntry]) -> BTreeMap<&str, Vec<Timed<'_>>> {
    let costs = Costs::of(runs);
    let mut by_scene: BTreeMap<&str, Vec<Timed>> = BTreeMap::new();
    for run in runs.iter().filter(|r| r.status == RunStatus::Ok) {
        let by_seed = costs.by_seed(run);
        let own = costs.own_by_seed(run);
        let shares: Samples = by_seed.iter().filter(|(_, c)| **c > 0.0).map(|(s, c)| (*s, own[s] / c)).collect();
        let timed = Timed { run, ms: median(&by_seed), by_seed, own, share: median(&shares) };
        if timed.ms > 0.0 && timed.ms.is_finite() {
            by_scene.entry(&run.scene).or_default().push(timed);
        }
    }
    for entries in by_scene.values_mut() {
        entries.sort_by_key(|t| t.run.spp);
    }
    by_scene
}

/// A run of a results index: technique, scene and budget.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct RunKey {
    /// Technique.
    pub technique: String,
    /// Scene.
    pub scene: String,
    /// Budget.
    pub spp: u64,
}

impl RunKey {
    fn of(run: &IndexEntry) -> RunKey {
        RunKey { technique: run.technique.clone(), scene: run.scene.clone(), spp: run.spp }
    }
}

/// Two techniques tied in a cell that more seeds could tell apart
/// ([`too_close`]), and the runs the tie rests on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TooClose {
    /// Scene.
    pub scene: String,
    /// The metric whose values tie; `None` when it is the cost (a
    /// technique's budget "at" a time point only within the noise), which
    /// decides every metric's cell at the point.
    pub metric: Option<String>,
    /// Budget or time point.
    pub at: At,
    /// The two techniques.
    pub techniques: [String; 2],
    /// The runs whose seeds decide it.
    pub runs: Vec<RunKey>,
    /// Runs of other techniques that nothing tells apart from one of
    /// `runs` (their peers, [`too_close`]): to be given the same seeds, so
    /// that a third technique is judged against both on the same seeds.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub peers: Vec<RunKey>,
}

/// The ties that `seeds` seeds per run could break, at equal samples and at
/// equal time: two techniques' values tie ([`differ`]) but would differ at
/// `seeds` shared seeds if their difference and its spread held
/// ([`could_differ`]), or a technique's budget is at a time point only
/// because the noise cannot yet rule it out ([`could_cost_differ`]). The
/// same program twice has equal values and never appears; nor does a tie
/// already at `seeds` seeds. Each tie names its runs' peers too
/// ([`TooClose::peers`]).
///
/// [`could_differ`]: crate::stats::could_differ
/// [`could_cost_differ`]: crate::stats::could_cost_differ
pub fn too_close(runs: &[IndexEntry], seeds: usize) -> Vec<TooClose> {
    let mut found = Vec::new();
    let mut cells: BTreeMap<SppCell, Vec<(&IndexEntry, Samples)>> = BTreeMap::new();
    for r in runs {
        for metric in r.metrics.keys() {
            cells.entry((&r.scene, r.spp, metric)).or_default().push((r, r.samples(metric)));
        }
    }
    for ((scene, spp, metric), values) in cells {
        let values: Vec<_> = values.into_iter().filter(|(_, s)| comparable(s)).collect();
        for (i, (a, sa)) in values.iter().enumerate() {
            for (b, sb) in &values[i + 1..] {
                if could_differ(sa, sb, seeds) {
                    found.push(TooClose {
                        scene: scene.to_string(),
                        metric: Some(metric.to_string()),
                        at: At::Spp { spp },
                        techniques: [a.technique.clone(), b.technique.clone()],
                        runs: vec![RunKey::of(a), RunKey::of(b)],
                        peers: Vec::new(),
                    });
                }
            }
        }
    }
    let scenes = timed_by_scene(runs);
    for_each_time_point(runs, &scenes, |scene, point, noise, metrics, sources| {
        let at = At::Time { ms: point.ms, fastest: point.run.technique.clone(), spp: point.run.spp };
        for (t, source) in sources {
            if let Some(r) = source.budget {
                if could_cost_differ(&r.by_seed, &point.by_seed, noise.at_share(point.share), seeds) {
                    found.push(TooClose {
                        scene: scene.to_string(),
                        metric: None,
                        at: at.clone(),
                        techniques: [t.to_string(), point.run.technique.clone()],
                        runs: vec![RunKey::of(r.run), RunKey::of(point.run)],
                        peers: Vec::new(),
                    });
                }
            }
        }
        for &metric in metrics {
            let mut readings = read_all(sources, metric, point.ms, noise);
            readings.retain(|(.., r)| comparable(&r.samples));
            for (i, (ta, a, ra)) in readings.iter().enumerate() {
                for (tb, b, rb) in &readings[i + 1..] {
                    if could_differ(&ra.samples, &rb.samples, seeds) {
                        found.push(TooClose {
                            scene: scene.to_string(),
                            metric: Some(metric.to_string()),
                            at: at.clone(),
                            techniques: [ta.to_string(), tb.to_string()],
                            runs: a.runs(point.ms).chain(b.runs(point.ms)).map(RunKey::of).collect(),
                            peers: Vec::new(),
                        });
                    }
                }
            }
        }
    });
    let peers = peers(&scenes);
    for tie in &mut found {
        let mut theirs: Vec<RunKey> =
            tie.runs.iter().filter_map(|k| peers.get(k)).flatten().filter(|p| !tie.runs.contains(p)).cloned().collect();
        theirs.sort();
        theirs.dedup();
        tie.peers = theirs;
    }
    found
}

/// Each run's peers: the runs of other techniques at its scene and budget
/// that nothing tells apart from it, neither their costs ([`same_cost`], at
/// the scene's noise and the larger of the two runs' own-time shares) nor
/// their values on any metric ([`differ`]), directly or through a chain of
/// such runs. Where a tie is given more seeds, its runs' peers are given
/// the same: a third technique is then judged against each of two such
/// runs on the same seeds. Given to one copy of NL-means and not the other
/// (12 seeds and 6, through the service, Intel Xeon, 2026-12-07), the box
/// filters tied with one copy and ranked ahead of the other at the same
/// point, and the copies were placed apart. The chains matter because a
/// cost at the edge of the noise is "the same" as one of two copies and
/// not the other: there, NL-means's pass-through 1 spp pulled one copy of
/// the C++ box filter into its seeds job and not the other (6 seeds and 12).
fn peers(scenes: &BTreeMap<&str, Vec<Timed>>) -> BTreeMap<RunKey, Vec<RunKey>> {
    let alike = |a: &Timed, b: &Timed, noise: CostNoise| {
        let metrics: BTreeSet<&String> = a.run.metrics.keys().chain(b.run.metrics.keys()).collect();
        same_cost(&a.by_seed, &b.by_seed, noise.at_share(a.share.max(b.share)))
            && metrics.iter().all(|m| {
                let (sa, sb) = (a.run.samples(m), b.run.samples(m));
                comparable(&sa) && comparable(&sb) && !differ(&sa, &sb)
            })
    };
    let mut peers: BTreeMap<RunKey, Vec<RunKey>> = BTreeMap::new();
    for entries in scenes.values() {
        let noise = CostNoise::pooled(entries.iter().map(|t| &t.own));
        let mut budgets: BTreeMap<u64, Vec<&Timed>> = BTreeMap::new();
        for t in entries {
            budgets.entry(t.run.spp).or_default().push(t);
        }
        for at_budget in budgets.values() {
            let group = groups(at_budget.len(), |i, j| alike(at_budget[i], at_budget[j], noise));
            for (i, a) in at_budget.iter().enumerate() {
                let theirs: Vec<RunKey> = (0..at_budget.len())
                    .filter(|&j| j != i && group[j] == group[i])
                    .map(|j| RunKey::of(at_budget[j].run))
                    .collect();
                if !theirs.is_empty() {
                    peers.insert(RunKey::of(a.run), theirs);
                }
            }
        }
    }
    peers
}

/// Each of `n` items' group, where `joined` items are in one group, and so
/// are chains of them: the label of the group's first item.
fn groups(n: usize, joined: impl Fn(usize, usize) -> bool) -> Vec<usize> {
    let mut group: Vec<usize> = (0..n).collect();
    for i in 0..n {
        for j in i + 1..n {
            if group[i] != group[j] && joined(i, j) {
                let (keep, merged) = (group[i].min(group[j]), group[i].max(group[j]));
                group.iter_mut().filter(|g| **g == merged).for_each(|g| *g = keep);
            }
        }
    }
    group
}

/// An equal-samples cell: scene, budget, metric.
type SppCell<'a> = (&'a str, u64, &'a str);

/// Whether a cell entry's values can be ranked (as [`place`] keeps them).
fn comparable(s: &Samples) -> bool {
    !s.is_empty() && s.values().all(|v| v.is_finite())
}

/// A technique's error-against-cost curve: (cost, values by seed), in budget order.
type Curve = Vec<(f64, Samples)>;

/// A run with its cost ([`Costs`]): the median, and by seed (its noise).
struct Timed<'a> {
    run: &'a IndexEntry,
    ms: f64,
    by_seed: Samples,
    /// The technique's own part of the cost by seed, which is what scatters.
    own: Samples,
    /// The median share of the cost that is the technique's own.
    share: f64,
}

/// A scene's time points: at each budget, the cheapest technique's run.
fn time_points<'a, 'b>(entries: &'b [Timed<'a>]) -> Vec<&'b Timed<'a>> {
    let mut cheapest: BTreeMap<u64, &Timed> = BTreeMap::new();
    for t in entries {
        let best = cheapest.entry(t.run.spp).or_insert(t);
        if t.ms < best.ms {
            *best = t;
        }
    }
    cheapest.into_values().collect()
}

/// A technique's value at a time point.
struct Reading {
    /// By seed.
    samples: Samples,
    /// The budget it is the result of (`None` when read between budgets).
    spp: Option<u64>,
    /// Where on its budgets it was read, in log spp.
    position: f64,
}

/// Where a technique's value at a time point comes from: its runs (in
/// budget order), and the budget whose cost is the point's within the
/// noise, if one is; else its curve between the two budgets around the
/// point.
struct Source<'a, 'b> {
    runs: &'b [&'b Timed<'a>],
    budget: Option<&'b Timed<'a>>,
}

impl<'a, 'b> Source<'a, 'b> {
    /// The technique's value of `metric` at time `ms`: its budget's, or
    /// read off its curve between the two budgets around `ms` (as
    /// [`interpolate`] reads it).
    fn read(&self, metric: &str, ms: f64) -> Option<Reading> {
        let log_spp = |r: &Timed| (r.run.spp as f64).ln();
        if let Some(r) = self.budget {
            return Some(Reading { samples: r.run.samples(metric), spp: Some(r.run.spp), position: log_spp(r) });
        }
        let curve = self.curve(metric, |r| r.ms);
        let (i, w) = bracket(&curve, ms)?;
        let position = if w == 0.0 {
            log_spp(self.runs[i])
        } else {
            log_spp(self.runs[i]) + w * (log_spp(self.runs[i + 1]) - log_spp(self.runs[i]))
        };
        Some(Reading { samples: blend(&curve, i, w), spp: None, position })
    }

    /// The technique's curve of `metric` against `x` (its cost, or its budget).
    fn curve(&self, metric: &str, x: impl Fn(&Timed) -> f64) -> Curve {
        self.runs.iter().map(|r| (x(r), r.run.samples(metric))).collect()
    }

    /// The technique's value of `metric` at `position` (log spp) on its
    /// budgets, seed by seed, in log–log between the two budgets around it.
    fn read_at_position(&self, metric: &str, position: f64) -> Option<Reading> {
        let spp = position.exp();
        // A budget's own position, not a hair beside it.
        let budget = self.runs.iter().map(|r| r.run.spp).find(|s| (*s as f64 - spp).abs() <= 1e-9 * *s as f64);
        let samples = interpolate(&self.curve(metric, |r| r.run.spp as f64), budget.map_or(spp, |s| s as f64))?;
        Some(Reading { samples, spp: budget, position })
    }

    /// Its runs from the budget at or below `low` to the one at or above
    /// `high` (log spp); none where either is beyond its budgets.
    fn span(&self, low: f64, high: f64) -> &'b [&'b Timed<'a>] {
        let logs: Vec<f64> = self.runs.iter().map(|r| (r.run.spp as f64).ln()).collect();
        let from = logs.iter().rposition(|l| *l <= low + 1e-12);
        let to = logs.iter().position(|l| *l >= high - 1e-12);
        match (from, to) {
            (Some(from), Some(to)) if from <= to => &self.runs[from..=to],
            _ => &[],
        }
    }

    /// The runs the value at time `ms` may be read from: the budget, or
    /// every pair of budgets around `ms` (or at it).
    fn runs(&self, ms: f64) -> impl Iterator<Item = &'a IndexEntry> + '_ {
        let around: Vec<&IndexEntry> = match self.budget {
            Some(r) => vec![r.run],
            None => self
                .runs
                .windows(2)
                .filter(|w| w[0].ms.min(w[1].ms) <= ms && ms <= w[0].ms.max(w[1].ms))
                .flat_map(|w| [w[0].run, w[1].run])
                .collect(),
        };
        around.into_iter()
    }
}

/// Where the value of a technique with these runs (in budget order) at
/// `point` comes from: a budget whose cost cannot be told apart from the
/// point's at the scene's `noise` ([`same_cost`]; the nearest, if
/// several), else its curve, when the point lies within it; `None` when it
/// lies beyond the noise outside the curve (never extrapolated).
fn source<'a, 'b>(runs: &'b [&'b Timed<'a>], point: &Timed, noise: CostNoise) -> Option<Source<'a, 'b>> {
    let distance = |t: &Timed| (t.ms / point.ms).ln().abs();
    let nearest = runs
        .iter()
        .filter(|t| same_cost(&t.by_seed, &point.by_seed, noise))
        .min_by(|a, b| distance(a).total_cmp(&distance(b)));
    if let Some(t) = nearest {
        return Some(Source { runs, budget: Some(t) });
    }
    let (first, last) = (runs.first()?.ms, runs.last()?.ms);
    (first.min(last) < point.ms && point.ms < first.max(last)).then_some(Source { runs, budget: None })
}

/// Every technique's value of `metric` at time `ms` ([`Source::read`]),
/// techniques of one cost read at one point of their budgets. Techniques
/// whose costs cannot be told apart at each budget they are read from or
/// between ([`same_cost`] at the scene's `noise`, budget by budget),
/// directly or through a chain of such techniques, are one group: none of
/// them is the faster, so each is read at the mean of their positions (in
/// log spp), and what is left between them, and between each of them and
/// any other technique, is their values. Read each at its own position, two
/// such techniques would differ by how far each one's cost offset moved it
/// between its budgets, alike on every seed, which the paired test takes
/// for a difference: the same NL-means twice, through the service, read
/// between its pass-through 1 spp and its costly 2 spp at a cheap
/// technique's time points, was 0.3–2 % apart and placed apart in 12 of 14
/// such cells (AMD EPYC, 2026-12-07). Compared at one point with each
/// other but each at its own with the box filters, one copy tied with them
/// and the other ranked behind, in 3 of 3 seasons (Intel Xeon,
/// 2026-12-07): ties do not chain, so a group is read at one point for
/// every comparison.
fn read_all<'s, 'a, 'b>(
    sources: &'s [(&'a str, Source<'a, 'b>)],
    metric: &str,
    ms: f64,
    noise: CostNoise,
) -> Vec<(&'a str, &'s Source<'a, 'b>, Reading)> {
    let mut readings: Vec<(&str, &Source, Reading)> =
        sources.iter().filter_map(|(t, source)| Some((*t, source, source.read(metric, ms)?))).collect();
    let group = groups(readings.len(), |i, j| {
        let ((_, a, ra), (_, b, rb)) = (&readings[i], &readings[j]);
        same_costs_around(a, b, ra.position.min(rb.position), ra.position.max(rb.position), noise)
    });
    for label in group.iter().copied().collect::<BTreeSet<usize>>() {
        let members: Vec<usize> = (0..readings.len()).filter(|&i| group[i] == label).collect();
        if members.len() < 2 {
            continue;
        }
        let common = members.iter().map(|&i| readings[i].2.position).sum::<f64>() / members.len() as f64;
        let read: Option<Vec<Reading>> =
            members.iter().map(|&i| readings[i].1.read_at_position(metric, common)).collect();
        // Seeds that do not pair between budgets leave each at its own reading.
        for (i, reading) in members.into_iter().zip(read.into_iter().flatten()) {
            readings[i].2 = reading;
        }
    }
    readings
}

/// Whether two techniques have the same budgets from the one at or below
/// `low` to the one at or above `high` (log spp), at costs that cannot be
/// told apart budget by budget at the scene's `noise` (at the larger of
/// the two runs' shares of the cost that is their own).
fn same_costs_around(a: &Source, b: &Source, low: f64, high: f64, noise: CostNoise) -> bool {
    let (runs_a, runs_b) = (a.span(low, high), b.span(low, high));
    !runs_a.is_empty()
        && runs_a.len() == runs_b.len()
        && runs_a.iter().zip(runs_b).all(|(ra, rb)| {
            ra.run.spp == rb.run.spp && same_cost(&ra.by_seed, &rb.by_seed, noise.at_share(ra.share.max(rb.share)))
        })
}

/// The value of a technique's curve (time, values by seed; in budget
/// order) at time `t`, seed by seed: linear in log–log between the two
/// budgets around `t` (linear where a value is not positive); `None`
/// outside the curve.
pub fn interpolate(points: &[(f64, Samples)], t: f64) -> Option<Samples> {
    let (i, w) = bracket(points, t)?;
    Some(blend(points, i, w))
}

/// The values of a curve `w` of the way from point `i` to the next, seed by
/// seed (see [`interpolate`]); point `i`'s own when `w` is 0.
fn blend(points: &[(f64, Samples)], i: usize, w: f64) -> Samples {
    if w == 0.0 {
        return points[i].1.clone();
    }
    let (s0, s1) = (&points[i].1, &points[i + 1].1);
    s0.iter()
        .filter_map(|(seed, v0)| {
            let v1 = s1.get(seed)?;
            Some((
                *seed,
                if *v0 > 0.0 && *v1 > 0.0 { (v0.ln() + w * (v1.ln() - v0.ln())).exp() } else { v0 + w * (v1 - v0) },
            ))
        })
        .collect()
}

/// Where `t` lies on a curve: the point at it (weight 0), else the first
/// pair of points around it that share a seed, and how far between them
/// `t` is in log time; `None` outside the curve.
fn bracket(points: &[(f64, Samples)], t: f64) -> Option<(usize, f64)> {
    if let Some(i) = points.iter().position(|(time, s)| *time == t && !s.is_empty()) {
        return Some((i, 0.0));
    }
    points
        .windows(2)
        .position(|pair| {
            let ((t0, s0), (t1, s1)) = (&pair[0], &pair[1]);
            t0.min(*t1) < t && t < t0.max(*t1) && s0.keys().any(|seed| s1.contains_key(seed))
        })
        .map(|i| {
            let (t0, t1) = (points[i].0, points[i + 1].0);
            (i, (t / t0).ln() / (t1 / t0).ln())
        })
}

/// Places the techniques of one cell by their values.
fn place(scene: &str, metric: &str, at: At, values: Vec<CellValues>, techniques: &BTreeSet<&str>, lower: bool) -> Cell {
    let (values, _): (Vec<_>, Vec<_>) = values.into_iter().partition(|(_, s)| comparable(s));
    let means: Vec<f64> = values.iter().map(|(_, s)| mean(s)).collect();
    let better = |a: f64, b: f64| if lower { a < b } else { a > b };
    let mut places: Vec<Place> = (0..values.len())
        .map(|i| {
            let mut ahead = 0;
            let mut tied_with = Vec::new();
            for j in (0..values.len()).filter(|&j| j != i) {
                if !differ(&values[i].1, &values[j].1) {
                    tied_with.push(values[j].0.to_string());
                } else if better(means[j], means[i]) {
                    ahead += 1;
                }
            }
            Place {
                technique: values[i].0.to_string(),
                mean: means[i],
                seeds: values[i].1.len(),
                place: 1.0 + ahead as f64 + tied_with.len() as f64 / 2.0,
                tied_with,
                spp: None,
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
                technique_cpu_ms: 0.0,
                render_cpu_ms: 0.0,
                sample_floats: 0,
                startup_ms: 0.0,
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

    /// A run whose seeds cost `costs` (ms, measured CPU times) with these MSEs.
    fn costly(t: &str, scene: &str, spp: u64, mse: &[f64], costs: &[f64]) -> IndexEntry {
        let mut e = repeated(t, scene, spp, mse, 1.0);
        for (r, cost) in e.repeats.iter_mut().zip(costs) {
            // The render rate is pooled (1 µs per sample here), so the technique's CPU carries the differences.
            r.used_samples = spp * 1000;
            r.render_cpu_ms = spp as f64;
            r.technique_cpu_ms = cost - spp as f64;
        }
        e.summarize();
        e
    }

    /// A run whose technique used `cpu` ms per seed beside a renderer that
    /// spent 1.6 µs on each of the budget's samples (64 × 64 pixels).
    fn cpu_run(t: &str, spp: u64, mse: &[f64], cpu: &[f64]) -> IndexEntry {
        let mut e = repeated(t, "s", spp, mse, 1.0);
        for (r, cpu) in e.repeats.iter_mut().zip(cpu) {
            r.used_samples = spp * 4096;
            r.render_cpu_ms = r.used_samples as f64 * 1.6e-3;
            r.technique_cpu_ms = *cpu;
        }
        e.summarize();
        e
    }

    #[test]
    fn the_same_program_in_jobs_of_its_own_ties_at_equal_time() {
        // The C++ box filter in three jobs through the service (AMD EPYC, 2026-12): at 1 spp
        // its own CPU time scattered by about 7 % from seed to seed, and each job moved its
        // mean by about as much again (here b runs 12 % below a, c 5 % above a): a quarter
        // of the cost, so c costs 4 % more than b, beyond the 2 % floor and beyond what
        // three seeds explain.
        let mut runs = Vec::new();
        for (name, one, four) in [
            ("a", [2.27, 2.10, 2.40], [2.60, 2.75, 2.45]),
            ("b", [2.00, 2.12, 1.86], [2.20, 2.35, 2.50]),
            ("c", [2.38, 2.52, 2.20], [2.90, 2.60, 2.75]),
            // The same with a busy loop doubling its work.
            ("doubled", [4.20, 4.54, 4.80], [5.50, 4.90, 5.20]),
        ] {
            runs.push(cpu_run(name, 1, &[0.4, 0.5, 0.45], &one));
            runs.push(cpu_run(name, 4, &[0.1, 0.12, 0.11], &four));
        }
        let time = equal_time(&runs, |_| true);
        assert_eq!(time.cells.len(), 2);
        // At b's 1 spp point, the doubled copy has no result; at its 4 spp point, it has
        // one read off its curve, and worse.
        assert_eq!(time.cells[0].missing, ["doubled"], "{:?}", time.cells[0]);
        for cell in &time.cells {
            let copies: Vec<&Place> = cell.places.iter().filter(|p| p.technique != "doubled").collect();
            assert!(copies.len() == 3 && copies.iter().all(|p| p.place == 2.0 && p.spp.is_some()), "{cell:?}");
        }
        let rank = |t: &str| time.standings.iter().find(|s| s.technique == t).unwrap().mean_rank;
        assert_eq!((rank("a"), rank("b"), rank("c")), (2.0, 2.0, 2.0), "{:?}", time.standings);
        assert_eq!(rank("doubled"), 4.0);
        // Not the floor's doing: at b's 1 spp point, c costs more than 2 % above it.
        let costs = Costs::of(&runs);
        let cost = |t: &str| costs.of_run(runs.iter().find(|r| r.technique == t && r.spp == 1).unwrap());
        assert!(cost("c") / cost("b") > 1.0 + crate::stats::COST_FLOOR, "{} / {}", cost("c"), cost("b"));
    }

    #[test]
    fn the_same_program_twice_ties_at_equal_time_whatever_its_times() {
        // Bit-equal values; costs that differ by noise (b is "faster" at 4 spp, a at 16).
        let mut runs = Vec::new();
        for (name, c4, c16) in [("a", [9.0, 9.6, 9.3], [33.0, 33.4, 32.8]), ("b", [8.8, 9.2, 9.5], [33.6, 33.1, 33.5])]
        {
            runs.push(costly(name, "s", 4, &[0.4, 0.5, 0.45], &c4));
            runs.push(costly(name, "s", 16, &[0.1, 0.12, 0.11], &c16));
        }
        let time = equal_time(&runs, |_| true);
        assert_eq!(time.cells.len(), 2);
        for cell in &time.cells {
            assert!(cell.places.iter().all(|p| p.place == 1.5), "{cell:?}");
            // Each read at its own budget, never between budgets.
            assert!(cell.places.iter().all(|p| Some(p.spp) == Some(cell.places[0].spp) && p.spp.is_some()), "{cell:?}");
        }
        assert_eq!(time.standings[0].mean_rank, time.standings[1].mean_rank);
    }

    #[test]
    fn the_same_program_twice_ties_where_it_is_read_between_budgets() {
        // NL-means through the service (AMD EPYC, 2026-12-07): a pass-through at 1 spp,
        // seconds of work at 2, so at the box filter's 2 and 4 spp time points each copy is
        // read between its budgets, and each job's cost offset (within the noise) moved it
        // to another point of its curve, alike on every seed: the copies were placed apart.
        let mse1 = [1.0, 1.2, 0.9];
        let mse2 = [0.05, 0.06, 0.045];
        let mut runs = vec![
            costly("box", "s", 1, &[0.8, 0.95, 0.75], &[10.0, 10.4, 9.7]),
            costly("box", "s", 2, &[0.4, 0.5, 0.38], &[20.0, 20.6, 19.5]),
            costly("box", "s", 4, &[0.2, 0.24, 0.19], &[40.0, 41.0, 39.2]),
        ];
        for (name, c1, c2, better) in [
            ("nlm-a", [9.8, 10.1, 9.6], [1000.0, 1030.0, 985.0], 1.0),
            ("nlm-b", [10.0, 9.9, 10.2], [1015.0, 1040.0, 1000.0], 1.0),
            // The same costs as nlm-b, and 10 % better on every seed at 2 spp.
            ("nlm-better", [10.0, 9.9, 10.2], [1015.0, 1040.0, 1000.0], 0.9),
        ] {
            runs.push(costly(name, "s", 1, &mse1, &c1));
            runs.push(costly(name, "s", 2, &mse2.map(|v| v * better), &c2));
        }
        let time = equal_time(&runs, |_| true);
        assert_eq!(time.cells.len(), 3);
        let place = |cell: &Cell, t: &str| cell.places.iter().find(|p| p.technique == t).unwrap().clone();
        for cell in &time.cells[1..] {
            let (a, b) = (place(cell, "nlm-a"), place(cell, "nlm-b"));
            assert_eq!((a.spp, b.spp), (None, None), "read between budgets: {cell:?}");
            // Read at one point of their budgets, for every comparison: the same values,
            // so every other technique meets both alike.
            assert_eq!(a.mean, b.mean, "{cell:?}");
            let others = |p: &Place| p.tied_with.iter().filter(|t| !t.starts_with("nlm-")).cloned().collect::<Vec<_>>();
            assert_eq!(others(&a), others(&b), "{cell:?}");
            assert_eq!(a.place, b.place, "{cell:?}");
            assert!(a.tied_with.contains(&"nlm-b".to_string()), "{cell:?}");
            // What is left between techniques of one cost is their values.
            assert!(place(cell, "nlm-better").place < a.place, "{cell:?}");
        }
        let rank = |t: &str| time.standings.iter().find(|s| s.technique == t).unwrap().mean_rank;
        assert_eq!(rank("nlm-a"), rank("nlm-b"), "{:?}", time.standings);
    }

    #[test]
    fn doubled_work_ranks_below_at_equal_time() {
        let mut runs = Vec::new();
        for (name, extra) in [("plain", 0.0), ("doubled", 6.0)] {
            runs.push(costly(name, "s", 4, &[0.4, 0.5, 0.45], &[10.0 + extra, 10.2 + extra, 9.9 + extra]));
            runs.push(costly(
                name,
                "s",
                16,
                &[0.1, 0.12, 0.11],
                &[40.0 + 4.0 * extra, 40.5 + 4.0 * extra, 39.8 + 4.0 * extra],
            ));
        }
        let time = equal_time(&runs, |_| true);
        // At plain's 4 spp cost, doubled has no result; at its 16 spp cost, doubled's is read between its budgets.
        assert_eq!(time.cells[0].missing, ["doubled"]);
        let second = &time.cells[1];
        assert_eq!((second.places[0].technique.as_str(), second.places[0].place), ("plain", 1.0));
        assert_eq!(second.places[1].spp, None);
        assert_eq!(time.standings[0].technique, "plain");
        // At equal samples they are the same program.
        assert!(equal_spp(&runs, |_| true).cells.iter().all(|c| c.places.iter().all(|p| p.place == 1.5)));
    }

    #[test]
    fn a_costlier_technique_never_gets_a_point_a_cheaper_one_misses() {
        // An AMD EPYC board: the box filter twice, with extra work once (steady) and
        // twice (noisy); the same images. Judged pair by pair, the noisy double was
        // "at" the copies' 4 spp point and the steadier single was not: it ranked below.
        let mse4 = [0.4, 0.5, 0.45];
        let mse16 = [0.1, 0.12, 0.11];
        let mut runs = Vec::new();
        for (name, c4, c16) in [
            ("copy-a", [205.0, 212.0, 210.0], [830.0, 835.0, 828.0]),
            ("copy-b", [209.0, 211.0, 208.0], [832.0, 829.0, 836.0]),
            ("heavy", [236.0, 238.0, 240.0], [950.0, 945.0, 952.0]),
            ("doubled", [330.0, 420.0, 510.0], [1060.0, 1075.0, 1065.0]),
        ] {
            runs.push(costly(name, "s", 4, &mse4, &c4));
            runs.push(costly(name, "s", 16, &mse16, &c16));
        }
        let time = equal_time(&runs, |_| true);
        let cost4 = |t: &str| match t {
            "copy-a" | "copy-b" => 209.0,
            "heavy" => 238.0,
            _ => 420.0,
        };
        assert_eq!(time.cells[0].missing, ["doubled"], "{:?}", time.cells[0]);
        // At every point, whoever is placed, every technique cheaper at that budget is placed too.
        for cell in &time.cells {
            let placed: Vec<&str> = cell.places.iter().map(|p| p.technique.as_str()).collect();
            for p in cell.places.iter().filter(|p| p.spp == Some(4)) {
                for missing in &cell.missing {
                    assert!(
                        cost4(missing) > cost4(&p.technique),
                        "{missing} missing where {} placed: {cell:?}",
                        p.technique
                    );
                }
            }
            assert!(placed.contains(&"copy-a") && placed.contains(&"copy-b"), "{cell:?}");
        }
        let rank = |t: &str| time.standings.iter().find(|s| s.technique == t).unwrap().mean_rank;
        assert!(rank("heavy") <= rank("doubled"), "{:?}", time.standings);
        assert_eq!(rank("copy-a"), rank("copy-b"));
    }

    #[test]
    fn messy_results_rank_alike_at_equal_samples_and_at_equal_time() {
        let mut runs = vec![
            // Non-positive values (a metric that can go negative): read linearly, never dropped.
            costly("signed", "s", 4, &[-0.2, 0.0, -0.1], &[10.0, 10.1, 9.9]),
            costly("signed", "s", 16, &[-0.4, -0.3, -0.35], &[40.0, 40.2, 39.9]),
            costly("steady", "s", 4, &[0.5, 0.6, 0.55], &[10.0, 10.2, 9.8]),
            costly("steady", "s", 16, &[0.2, 0.25, 0.22], &[40.1, 40.0, 40.3]),
            // Seeds that differ between budgets: nothing to pair, so nothing read between them.
            costly("reseeded", "s", 4, &[0.5, 0.6, 0.55], &[20.0, 20.1, 20.2]),
        ];
        let mut reseeded16 = costly("reseeded", "s", 16, &[0.2, 0.25, 0.22], &[80.0, 80.2, 80.1]);
        reseeded16.repeats.iter_mut().for_each(|r| r.seed += 10);
        reseeded16.summarize();
        runs.push(reseeded16);
        // A metric missing on one repeat: no value for the run, at equal samples and at equal time.
        let mut holey = costly("holey", "s", 4, &[0.01, 0.01, 0.01], &[10.0, 10.1, 10.0]);
        holey.repeats[1].metrics.clear();
        holey.summarize();
        runs.push(holey);
        runs.push(costly("holey", "s", 16, &[0.001, 0.001, 0.001], &[40.0, 40.1, 40.2]));

        let spp = equal_spp(&runs, |_| true);
        let time = equal_time(&runs, |_| true);
        let at = |r: &Ranking, spp4: bool| {
            r.cells
                .iter()
                .find(|c| matches!(c.at, At::Spp { spp: 4 } | At::Time { spp: 4, .. }) == spp4)
                .unwrap()
                .clone()
        };
        for ranking in [&spp, &time] {
            let first = at(ranking, true);
            assert!(first.missing.contains(&"holey".to_string()), "{first:?}");
            assert_eq!(first.places[0].technique, "signed", "negative values still rank: {first:?}");
        }
        // At the 16 spp point (40 ms), reseeded's 4 spp (20 ms) and 16 spp (80 ms) share no seed.
        let last = at(&time, false);
        assert!(last.missing.contains(&"reseeded".to_string()), "{last:?}");
        // Holey's 16 spp run lacks nothing: it ranks there, behind the negative values.
        let order: Vec<&str> = last.places.iter().map(|p| p.technique.as_str()).collect();
        assert_eq!(order, ["signed", "holey", "steady"]);
    }

    #[test]
    fn a_ties_peers_are_named_so_that_a_third_technique_meets_both_on_the_same_seeds() {
        // "twin" ties with "a" and is decided ahead of "close"; "a" only ties with
        // "close", by less than three seeds can show. Given six seeds, "a" alone
        // would meet "close" on six seeds and "twin" on three.
        let costs = [10.0, 10.2, 9.9];
        let runs = vec![
            costly("a", "s", 4, &[1.0, 1.2, 0.9], &costs),
            costly("twin", "s", 4, &[1.05, 1.4, 0.89], &costs),
            costly("close", "s", 4, &[1.1, 1.45, 0.95], &costs),
            // A chain of costs: "slower" is the cost of "a" within the 2 % floor, and
            // "slowest" the cost of "slower", not of "a"; the same values as "a".
            costly("slower", "s", 4, &[1.0, 1.2, 0.9], &costs.map(|c| 1.015 * c)),
            costly("slowest", "s", 4, &[1.0, 1.2, 0.9], &costs.map(|c| 1.03 * c)),
            // Tied with "a" in values, at twice the cost: no peer.
            costly("pricey", "s", 4, &[1.02, 1.25, 0.88], &costs.map(|c| 2.0 * c)),
            // The cost of "a", decided worse: no peer.
            costly("far", "s", 4, &[3.0, 3.3, 2.9], &costs),
        ];
        let close = too_close(&runs, 6);
        let key = |t: &str| RunKey { technique: t.into(), scene: "s".into(), spp: 4 };
        let tie = close
            .iter()
            .find(|c| matches!(c.at, At::Spp { .. }) && c.techniques == ["a".to_string(), "close".to_string()])
            .unwrap_or_else(|| panic!("{close:?}"));
        assert_eq!(tie.runs, [key("a"), key("close")]);
        assert_eq!(tie.peers, [key("slower"), key("slowest"), key("twin")], "{tie:?}");
        assert!(!close.iter().any(|c| c.techniques.contains(&"twin".to_string())), "{close:?}");
    }

    #[test]
    fn ties_too_close_to_call_name_the_runs_more_seeds_could_settle() {
        let costs = [10.0, 10.2, 9.9];
        let runs = vec![
            costly("a", "s", 4, &[1.0, 1.2, 0.9], &costs),
            costly("copy", "s", 4, &[1.0, 1.2, 0.9], &costs),
            // Worse on every seed, by less than three seeds can show (t = 2.2); six would (3.1).
            costly("close", "s", 4, &[1.1, 1.45, 0.95], &costs),
            // Worse beyond doubt.
            costly("far", "s", 4, &[3.0, 3.3, 2.9], &costs),
        ];
        let close = too_close(&runs, 6);
        let pairs: BTreeSet<(&str, &str, bool)> = close
            .iter()
            .map(|c| {
                let (a, b) = (c.techniques[0].as_str(), c.techniques[1].as_str());
                (a.min(b), a.max(b), matches!(c.at, At::Spp { .. }))
            })
            .collect();
        // At equal samples and at the time point alike (the same budget), close against a and its copy only.
        let expected: BTreeSet<(&str, &str, bool)> =
            [("a", "close", true), ("close", "copy", true), ("a", "close", false), ("close", "copy", false)].into();
        assert_eq!(pairs, expected, "{close:?}");
        let spp = close.iter().find(|c| matches!(c.at, At::Spp { spp: 4 }) && c.techniques[0] == "a").unwrap();
        assert_eq!(spp.metric.as_deref(), Some("MSE"));
        let key = |t: &str| RunKey { technique: t.into(), scene: "s".into(), spp: 4 };
        assert_eq!(spp.runs, [key("a"), key("close")]);
        // At the cap, nothing is too close any more.
        assert!(too_close(&runs, 3).is_empty());

        // Costs: "pricier" is at the cheap one's time point only within the noise of three seeds.
        let mse = [0.5, 0.6, 0.55];
        let timed = vec![
            costly("cheap", "t", 4, &mse, &[100.0, 104.0, 98.0]),
            costly("pricier", "t", 4, &mse, &[139.1, 144.7, 136.3]),
            costly("cheap", "t", 16, &[0.1, 0.12, 0.11], &[400.0, 412.0, 396.0]),
            costly("pricier", "t", 16, &[0.1, 0.12, 0.11], &[440.0, 452.0, 436.0]),
            // A noisy technique that makes the scene's noise (4.4 % at the point): 39 % above
            // (a log-ratio of 0.33) ties at 3 seeds with a job's noise on each side (up to
            // 0.337), not at 12 (0.320).
            costly("noisy", "t", 4, &mse, &[200.0, 185.0, 215.0]),
        ];
        let close = too_close(&timed, 12);
        let cost: Vec<&TooClose> = close.iter().filter(|c| c.metric.is_none()).collect();
        assert!(!cost.is_empty(), "{close:?}");
        for c in &cost {
            assert_eq!(c.techniques, ["pricier".to_string(), "cheap".to_string()]);
            assert!(c.runs.iter().all(|r| r.scene == "t" && r.spp == c.runs[0].spp), "{c:?}");
        }
        // Equal values never ask for more.
        assert!(close.iter().all(|c| c.metric.is_none()), "{close:?}");
    }
}
