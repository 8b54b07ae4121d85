//! `fbksd results compute | show | page`: metric values for a results
//! directory, tables and ranking, and the results viewer as a static folder.

use anyhow::Context;
use clap::Subcommand;
use fbksd_exchange::ranking::{equal_spp, equal_time, At, Cell};
use fbksd_exchange::results::ResultsDir;
use fbksd_iqa::external::ExternalMetric;
use fbksd_iqa::Metric;
use fbksd_manager::evaluation::{compute, find_scenes, AnyMetric};
use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum ResultsCommand {
    /// Compute the missing metric values and error maps of every run.
    Compute {
        /// The results directory.
        #[arg(long, default_value = "fbksd-results")]
        results: PathBuf,
        /// Where to look for scenes (their fbksd-scene.json and references). Repeatable.
        #[arg(long = "scenes", default_value = "scenes")]
        scenes: Vec<PathBuf>,
        /// Built-in metrics to compute, comma-separated [default: all].
        #[arg(long, value_delimiter = ',')]
        metrics: Vec<String>,
        /// A directory holding an external metric (info.json and its program). Repeatable.
        #[arg(long = "metric-dir")]
        metric_dirs: Vec<PathBuf>,
    },
    /// Print a table per scene and the ranking of techniques.
    Show {
        /// The results directory.
        #[arg(long, default_value = "fbksd-results")]
        results: PathBuf,
    },
    /// Write the results viewer (images, charts, ranking, costs) as a
    /// static folder that opens from file:// or any static server.
    Page {
        /// The results directory.
        #[arg(long, default_value = "fbksd-results")]
        results: PathBuf,
        /// Where to look for scenes (their references). Repeatable.
        #[arg(long = "scenes", default_value = "scenes")]
        scenes: Vec<PathBuf>,
        /// The folder to write [default: <results>/page].
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

pub fn results(command: ResultsCommand) -> anyhow::Result<()> {
    match command {
        ResultsCommand::Compute { results, scenes, metrics, metric_dirs } => {
            let dir = ResultsDir::create(&results)?;
            let scenes = find_scenes(&scenes).context("reading the scene directories")?;
            let mut chosen = builtin_metrics(&metrics)?;
            for d in &metric_dirs {
                chosen.push(AnyMetric::External(ExternalMetric::load(d)?));
            }
            let summary = compute(&dir, &scenes, &chosen, |run, metric| eprintln!("  {run}: {metric}"))?;
            for s in &summary.skipped {
                eprintln!("skipped {s}");
            }
            eprintln!(
                "{} values computed, {} already there, {} runs skipped",
                summary.computed,
                summary.kept,
                summary.skipped.len()
            );
            Ok(())
        }
        ResultsCommand::Show { results } => show(&results),
        ResultsCommand::Page { results, scenes, out } => {
            let out = out.unwrap_or_else(|| results.join("page"));
            let scenes = find_scenes(&scenes).context("reading the scene directories")?;
            let written = crate::page::write(&ResultsDir::create(&results)?, &scenes, &out)?;
            for note in &written.notes {
                eprintln!("note: {note}");
            }
            let index = out.join("index.html");
            let index = std::fs::canonicalize(&index).unwrap_or(index);
            eprintln!(
                "wrote {} pixel files ({:.1} MB); open file://{}",
                written.pixel_files,
                written.pixel_bytes as f64 / 1e6,
                index.display()
            );
            Ok(())
        }
    }
}

/// The built-in metrics named by their acronyms; all of them for none.
pub fn builtin_metrics(names: &[String]) -> anyhow::Result<Vec<AnyMetric>> {
    if names.is_empty() {
        return Ok(Metric::ALL.iter().map(|m| AnyMetric::Builtin(*m)).collect());
    }
    names
        .iter()
        .map(|name| {
            let m =
                Metric::from_acronym(name).with_context(|| format!("unknown metric {name:?} (see fbksd iqa list)"))?;
            Ok(AnyMetric::Builtin(m))
        })
        .collect()
}

fn lower_is_better(acronym: &str) -> bool {
    Metric::from_acronym(acronym).is_none_or(|m| m.info().lower_is_better)
}

fn show(results: &std::path::Path) -> anyhow::Result<()> {
    let index = ResultsDir::create(results)?.read_index()?;
    if index.runs.is_empty() {
        anyhow::bail!("{} holds no runs (run `fbksd run` first)", results.display());
    }
    let mut metrics: Vec<String> = index.runs.iter().flat_map(|r| r.metrics.keys().cloned()).collect();
    metrics.sort();
    metrics.dedup();
    let at_spp = equal_spp(&index.runs, lower_is_better);
    let at_time = equal_time(&index.runs, lower_is_better);
    let costs = fbksd_exchange::cost::Costs::of(&index.runs);
    let tied = |cells: &[Cell], scene: &str, at: &At, metric: &str, technique: &str| {
        cells
            .iter()
            .find(|c| c.scene == scene && c.at == *at && c.metric == metric)
            .and_then(|c| c.places.iter().find(|p| p.technique == technique))
            .is_some_and(|p| !p.tied_with.is_empty())
    };
    let mut by_scene: BTreeMap<&str, Vec<_>> = BTreeMap::new();
    for r in &index.runs {
        by_scene.entry(r.scene.as_str()).or_default().push(r);
    }
    let arrow = |m: &str| if lower_is_better(m) { "↓" } else { "↑" };
    for (scene, mut runs) in by_scene {
        runs.sort_by(|a, b| (a.spp, &a.technique).cmp(&(b.spp, &b.technique)));
        println!("\n{scene}");
        let mut header = vec!["technique".to_string(), "spp".into(), "seeds".into(), "status".into()];
        header.extend(metrics.iter().map(|m| format!("{m} {}", arrow(m))));
        header.extend(["cost ms".into(), "start-up ms".into(), "technique ms (CV)".into(), "time to result ms".into()]);
        let rows: Vec<Vec<String>> = runs
            .iter()
            .map(|r| {
                let mut row = vec![
                    r.technique.clone(),
                    r.spp.to_string(),
                    r.repeats.len().max(1).to_string(),
                    r.status.to_string(),
                ];
                let at = At::Spp { spp: r.spp };
                row.extend(metrics.iter().map(|m| {
                    let Some(v) = r.metrics.get(m) else { return "—".into() };
                    let value = match r.intervals.get(m) {
                        Some(i) => format!("{v:.6} ± {:.1e}", i.half_width()),
                        None => format!("{v:.6}"),
                    };
                    if tied(&at_spp.cells, scene, &at, m, &r.technique) {
                        format!("{value} =")
                    } else {
                        value
                    }
                }));
                row.push(format!("{:.1}", costs.of_run(r)));
                row.push(format!("{:.1}", r.startup_ms));
                row.push(match r.timing.filter(|_| r.repeats.len() > 1) {
                    Some(t) => format!("{:.1} ({:.1} %)", r.technique_ms, t.technique.cv * 100.0),
                    None => format!("{:.1}", r.technique_ms),
                });
                row.push(format!("{:.1}", r.time()));
                row
            })
            .collect();
        print_table(&header, &rows);
        // Equal time: each technique's error at the cheapest technique's cost at each budget.
        let mut points: Vec<&At> = at_time.cells.iter().filter(|c| c.scene == scene).map(|c| &c.at).collect();
        points.dedup();
        if points.is_empty() {
            continue;
        }
        println!(
            "\n{scene} at equal time (each technique's error at the cheapest one's cost: at a budget of its own \
             whose cost is the same within the noise, or read off its curve)"
        );
        let mut header = vec!["cost ms".to_string(), "cheapest".into(), "technique".into()];
        header.extend(metrics.iter().map(|m| format!("{m} {}", arrow(m))));
        let mut rows = Vec::new();
        for at in points {
            let At::Time { ms, fastest, spp } = at else { continue };
            let cells: Vec<&Cell> = at_time.cells.iter().filter(|c| c.scene == scene && c.at == *at).collect();
            let techniques: BTreeSet<&str> = cells
                .iter()
                .flat_map(|c| c.places.iter().map(|p| p.technique.as_str()).chain(c.missing.iter().map(String::as_str)))
                .collect();
            for technique in techniques {
                let mut row = vec![format!("{ms:.1}"), format!("{fastest} at {spp} spp"), technique.to_string()];
                row.extend(metrics.iter().map(|m| {
                    let place = cells
                        .iter()
                        .find(|c| c.metric == *m)
                        .and_then(|c| c.places.iter().find(|p| p.technique == technique));
                    let tie = |p: &fbksd_exchange::ranking::Place| if p.tied_with.is_empty() { "" } else { " =" };
                    match place {
                        Some(p) => match p.spp {
                            Some(spp) => format!("{:.6} (#{}{}, its {spp} spp)", p.mean, p.place, tie(p)),
                            None => format!("{:.6} (#{}{})", p.mean, p.place, tie(p)),
                        },
                        None => "— (costs more)".into(),
                    }
                }));
                rows.push(row);
            }
        }
        print_table(&header, &rows);
    }
    let time_rank: BTreeMap<&str, f64> =
        at_time.standings.iter().map(|s| (s.technique.as_str(), s.mean_rank)).collect();
    println!(
        "\nranking (mean rank over scene × spp × metric, and over scene × time point × metric at equal time; \
         differences within the noise of the repeats tie (=); a missing value ranks last)"
    );
    let rows: Vec<Vec<String>> = at_spp
        .standings
        .iter()
        .enumerate()
        .map(|(i, s)| {
            vec![
                (i + 1).to_string(),
                s.technique.clone(),
                format!("{:.3}", s.mean_rank),
                time_rank
                    .get(s.technique.as_str())
                    .filter(|r| r.is_finite())
                    .map_or("—".into(), |r| format!("{r:.3}")),
                s.tied.to_string(),
                s.ranked.to_string(),
                s.missing.to_string(),
            ]
        })
        .collect();
    print_table(
        &[
            "#".into(),
            "technique".into(),
            "mean rank (equal spp)".into(),
            "mean rank (equal time)".into(),
            "ties".into(),
            "ranked".into(),
            "missing".into(),
        ],
        &rows,
    );
    Ok(())
}

fn print_table(header: &[String], rows: &[Vec<String>]) {
    let widths: Vec<usize> = (0..header.len())
        .map(|c| rows.iter().map(|r| r[c].chars().count()).chain([header[c].chars().count()]).max().unwrap_or(0))
        .collect();
    let line = |cells: &[String]| {
        cells
            .iter()
            .zip(&widths)
            .map(|(c, w)| format!("{c}{}", " ".repeat(w - c.chars().count())))
            .collect::<Vec<_>>()
            .join("  ")
            .trim_end()
            .to_string()
    };
    println!("{}", line(header));
    for r in rows {
        println!("{}", line(r));
    }
}
