//! More seeds where they decide: after a benchmark's planned repeats, the
//! runs behind a tie that more seeds could break are made again with the
//! next seeds, round by round, up to a cap of seeds per run.
//!
//! A round computes the metrics, asks the ranking which ties are too close
//! to call ([`fbksd_exchange::ranking::too_close`]: a difference in values,
//! or a budget's cost against a time point, that the paired tests would
//! decide at the cap's seeds if it held), and gives each run behind one,
//! and each of their peers (runs of other techniques that nothing tells
//! apart from them), twice its seeds, at most the cap. It stops when
//! nothing is too close, or every run behind what is has the cap's seeds.
//! Extra seeds are runs like the others: one that fails fails its run, as
//! with `--repeats`. What it costs is the extra runs only: at most (cap /
//! repeats − 1) times the runs behind the close ties and their peers.

use crate::benchmark::{Benchmark, Progress};
use crate::evaluation::{compute, AnyMetric};
use fbksd_exchange::ranking::{too_close, RunKey, TooClose};
use fbksd_exchange::results::{path_safe_name, ResultsDir};
use fbksd_exchange::scenes::SceneMeta;
use fbksd_exchange::RunStatus;
use std::collections::BTreeMap;
use std::io;
use std::ops::Range;
use std::time::{Duration, Instant};

/// One round of more seeds.
#[derive(Debug, Clone)]
pub struct Round {
    /// The ties too close to call that asked for it.
    pub close: Vec<TooClose>,
    /// The runs made again, each with its new seeds.
    pub runs: BTreeMap<RunKey, Range<u32>>,
    /// Wall time of the round's runs.
    pub wall: Duration,
}

/// Gives the runs behind ties too close to call more seeds, up to `cap`
/// seeds per run, round by round, with metric values computed by `metrics`
/// against the references of `scenes`; `round` hears of each round before
/// its runs are made. Returns every round made. A tie may still be a tie
/// after them (its runs at the cap, or its difference gone with more
/// seeds): the ranking then ties it, as it ties any cell within the noise.
pub fn settle(
    bench: &Benchmark,
    scenes: &BTreeMap<String, SceneMeta>,
    metrics: &[AnyMetric],
    cap: u32,
    mut round: impl FnMut(&Round),
    mut progress: impl FnMut(Progress<'_>) + Send,
) -> io::Result<Vec<Round>> {
    let results = ResultsDir::create(&bench.results)?;
    let mut rounds = Vec::new();
    // Ties with a technique of an earlier benchmark in the same results are not ours to settle.
    let ours = |k: &RunKey| {
        bench.techniques.iter().any(|t| path_safe_name(&t.name) == k.technique)
            && bench.scenes.iter().any(|s| path_safe_name(&s.name) == k.scene && s.spps.contains(&k.spp))
    };
    loop {
        compute(&results, scenes, metrics, |_, _| {})?;
        let index = results.read_index()?;
        let close: Vec<TooClose> =
            too_close(&index.runs, cap as usize).into_iter().filter(|c| c.runs.iter().all(ours)).collect();
        let seeds: BTreeMap<&RunKey, u32> = index
            .runs
            .iter()
            .filter(|r| r.status == RunStatus::Ok)
            .filter_map(|r| {
                let key =
                    close.iter().flat_map(|c| c.runs.iter().chain(c.peers.iter().filter(|k| ours(k)))).find(|k| {
                        (k.technique.as_str(), k.scene.as_str(), k.spp)
                            == (r.technique.as_str(), r.scene.as_str(), r.spp)
                    })?;
                Some((key, r.repeats.len().max(1) as u32))
            })
            .collect();
        let Some(most) = seeds.values().max() else { return Ok(rounds) };
        let target = (2 * most).min(cap);
        let runs: BTreeMap<RunKey, Range<u32>> =
            seeds.iter().filter(|(_, n)| **n < target).map(|(k, n)| ((*k).clone(), *n..target)).collect();
        if runs.is_empty() {
            return Ok(rounds);
        }
        let mut this = Round { close, runs, wall: Duration::ZERO };
        round(&this);
        let started = Instant::now();
        let records = bench.run_more_seeds(&this.runs, &mut progress)?;
        this.wall = started.elapsed();
        rounds.push(this);
        if records.is_empty() {
            return Ok(rounds);
        }
    }
}
