//! `fbksd run`: techniques × scenes × budgets into a results directory.

use anyhow::{bail, Context};
use clap::Args;
use fbksd_manager::{Benchmark, Limits, Progress, RunRecord, RunStatus, SceneSpec, TechniqueSpec};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::Duration;

#[derive(Args)]
pub struct RunArgs {
    /// A technique: `[NAME=]COMMAND` (the name defaults to the program's file name). Repeatable.
    #[arg(long = "technique", short = 't', required = true)]
    techniques: Vec<String>,
    /// The renderer command; each scene file is appended to it.
    #[arg(long, short = 'r')]
    renderer: String,
    /// A scene file (its name is the file stem). Repeatable.
    #[arg(long = "scene", short = 's', required = true)]
    scenes: Vec<PathBuf>,
    /// Budgets in samples per pixel, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,4,16")]
    spp: Vec<u64>,
    /// Where results go.
    #[arg(long, default_value = "fbksd-results")]
    results: PathBuf,
    /// Wall-time limit of each run (e.g. 90s, 10m, 2h); 0 for none.
    #[arg(long, default_value = "30m", value_parser = humantime::parse_duration)]
    time_limit: Duration,
}

fn technique_spec(arg: &str) -> anyhow::Result<TechniqueSpec> {
    // NAME=COMMAND when the part before '=' is a plain name with no blanks.
    let (name, command) = match arg.split_once('=') {
        Some((n, c))
            if !n.is_empty()
                && n.chars()
                    .all(|ch| ch.is_ascii_alphanumeric() || "-_.".contains(ch)) =>
        {
            (Some(n.to_string()), c)
        }
        _ => (None, arg),
    };
    let argv = shell_words::split(command).with_context(|| format!("--technique {arg:?}"))?;
    let Some(program) = argv.first() else {
        bail!("--technique {arg:?} has no command")
    };
    let name = name.unwrap_or_else(|| {
        PathBuf::from(program)
            .file_stem()
            .map_or("technique".into(), |s| s.to_string_lossy().into_owned())
    });
    Ok(TechniqueSpec { name, argv })
}

pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let techniques = args
        .techniques
        .iter()
        .map(|t| technique_spec(t))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let renderer = shell_words::split(&args.renderer)
        .with_context(|| format!("--renderer {:?}", args.renderer))?;
    if renderer.is_empty() {
        bail!("--renderer is empty");
    }
    let mut scenes = Vec::new();
    for path in &args.scenes {
        if !path.is_file() {
            bail!("scene file {} does not exist", path.display());
        }
        let mut renderer_argv = renderer.clone();
        renderer_argv.push(std::fs::canonicalize(path)?.to_string_lossy().into_owned());
        let name = path
            .file_stem()
            .map_or("scene".into(), |s| s.to_string_lossy().into_owned());
        scenes.push(SceneSpec {
            name,
            renderer_argv,
        });
    }
    if args.spp.is_empty() || args.spp.contains(&0) {
        bail!("--spp takes positive budgets, e.g. --spp 1,4,16");
    }
    let limits = Limits {
        time_limit: (!args.time_limit.is_zero()).then_some(args.time_limit),
        ..Limits::default()
    };
    let benchmark = Benchmark {
        techniques,
        scenes,
        spps: args.spp,
        results: args.results.clone(),
        limits,
    };
    let live = std::io::stderr().is_terminal();
    let records = benchmark.run(|p| report(p, live))?;
    print_summary(&records);
    eprintln!("results in {}", args.results.display());
    if records.iter().any(|r| r.status != RunStatus::Ok) {
        std::process::exit(2);
    }
    Ok(())
}

fn report(progress: Progress<'_>, live: bool) {
    match progress {
        Progress::RunStarted {
            scene,
            technique,
            spp,
        } => eprintln!("▶ {scene} · {technique} · {spp} spp"),
        Progress::Samples { delivered, budget } if live => {
            eprint!(
                "\r  {delivered} / {budget} samples ({:.0}%)   ",
                delivered as f64 * 100.0 / budget.max(1) as f64
            )
        }
        Progress::Samples { .. } => {}
        Progress::RunFinished(r) => {
            if live {
                eprint!("\r\x1b[K");
            }
            let what = if r.status == RunStatus::Ok {
                "ok".to_string()
            } else {
                format!("{}: {}", r.status, r.message)
            };
            eprintln!(
                "  {what} ({:.1} ms technique, {:.1} ms render)",
                r.times.technique_ms, r.times.render_ms
            );
        }
    }
}

fn print_summary(records: &[RunRecord]) {
    let header = [
        "scene",
        "technique",
        "spp",
        "status",
        "technique ms",
        "render ms",
        "wall ms",
        "samples",
        "peak MB",
    ];
    let rows: Vec<[String; 9]> = records
        .iter()
        .map(|r| {
            [
                r.scene.clone(),
                r.technique.clone(),
                r.spp_budget.to_string(),
                r.status.to_string(),
                format!("{:.1}", r.times.technique_ms),
                format!("{:.1}", r.times.render_ms),
                format!("{:.1}", r.times.wall_ms),
                r.used_samples.to_string(),
                format!("{:.1}", r.peak_memory_bytes as f64 / 1e6),
            ]
        })
        .collect();
    let widths: Vec<usize> = (0..header.len())
        .map(|c| {
            rows.iter()
                .map(|r| r[c].chars().count())
                .chain([header[c].len()])
                .max()
                .unwrap()
        })
        .collect();
    let line = |cells: Vec<&str>| {
        cells
            .iter()
            .zip(&widths)
            .map(|(c, w)| format!("{c:<w$}"))
            .collect::<Vec<_>>()
            .join("  ")
            .trim_end()
            .to_string()
    };
    println!("{}", line(header.to_vec()));
    for r in &rows {
        println!("{}", line(r.iter().map(String::as_str).collect()));
    }
}
