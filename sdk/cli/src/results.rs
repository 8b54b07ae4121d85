//! `fbksd results compute | show | page`: metric values for a results
//! directory, tables and ranking, and the results viewer as a static folder.

use anyhow::Context;
use clap::Subcommand;
use fbksd_exchange::ranking::rank;
use fbksd_exchange::results::ResultsDir;
use fbksd_iqa::external::ExternalMetric;
use fbksd_iqa::Metric;
use fbksd_manager::evaluation::{compute, find_scenes, AnyMetric};
use std::collections::BTreeMap;
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
            let mut chosen = Vec::new();
            if metrics.is_empty() {
                chosen.extend(Metric::ALL.iter().map(|m| AnyMetric::Builtin(*m)));
            }
            for name in &metrics {
                let m = Metric::from_acronym(name)
                    .with_context(|| format!("unknown metric {name:?} (see fbksd iqa list)"))?;
                chosen.push(AnyMetric::Builtin(m));
            }
            for d in &metric_dirs {
                chosen.push(AnyMetric::External(ExternalMetric::load(d)?));
            }
            let summary = compute(&dir, &scenes, &chosen, |run, metric| {
                eprintln!("  {} / {} / {} spp: {metric}", run.technique, run.scene, run.spp)
            })?;
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
    let mut by_scene: BTreeMap<&str, Vec<_>> = BTreeMap::new();
    for r in &index.runs {
        by_scene.entry(r.scene.as_str()).or_default().push(r);
    }
    for (scene, mut runs) in by_scene {
        runs.sort_by(|a, b| (a.spp, &a.technique).cmp(&(b.spp, &b.technique)));
        println!("\n{scene}");
        let mut header = vec!["technique".to_string(), "spp".into(), "status".into()];
        header.extend(metrics.iter().map(|m| format!("{m} {}", if lower_is_better(m) { "↓" } else { "↑" })));
        header.push("technique ms".into());
        let rows: Vec<Vec<String>> = runs
            .iter()
            .map(|r| {
                let mut row = vec![r.technique.clone(), r.spp.to_string(), r.status.to_string()];
                row.extend(metrics.iter().map(|m| r.metrics.get(m).map_or("—".into(), |v| format!("{v:.6}"))));
                row.push(format!("{:.1}", r.technique_ms));
                row
            })
            .collect();
        print_table(&header, &rows);
    }
    let standings = rank(&index.runs, lower_is_better);
    println!("\nranking (mean rank over scene × spp × metric; a missing value ranks last)");
    let rows: Vec<Vec<String>> = standings
        .iter()
        .enumerate()
        .map(|(i, s)| {
            vec![
                (i + 1).to_string(),
                s.technique.clone(),
                format!("{:.3}", s.mean_rank),
                s.ranked.to_string(),
                s.missing.to_string(),
            ]
        })
        .collect();
    print_table(&["#".into(), "technique".into(), "mean rank".into(), "ranked".into(), "missing".into()], &rows);
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
