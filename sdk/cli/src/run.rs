//! `fbksd run`: techniques × scenes × budgets into a results directory.

use anyhow::{bail, Context};
use clap::Args;
use fbksd_exchange::ranking::{At, TooClose};
use fbksd_exchange::scenes::SceneMeta;
use fbksd_manager::evaluation::{find_scenes, AnyMetric};
use fbksd_manager::more_seeds::settle;
use fbksd_manager::{Benchmark, Limits, Progress, RunRecord, RunStatus, SceneSpec, TechniqueSpec};
use std::collections::{BTreeMap, BTreeSet};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::Duration;

#[derive(Args)]
pub struct RunArgs {
    /// A technique: `[NAME=]COMMAND` (the name defaults to the program's file name). Repeatable.
    #[arg(long = "technique", short = 't', required = true)]
    techniques: Vec<String>,
    /// The renderer command for plain scene files (the file is appended to
    /// it); scene directories name their renderer in fbksd-scene.json.
    #[arg(long, short = 'r')]
    renderer: Option<String>,
    /// A scene: a directory with fbksd-scene.json (or that file), or a plain
    /// scene file for --renderer (named by its file stem). Repeatable.
    #[arg(long = "scene", short = 's', required = true)]
    scenes: Vec<PathBuf>,
    /// Budgets in samples per pixel, comma-separated [default: each scene's
    /// own budgets, or 1,4,16 for plain scene files].
    #[arg(long, value_delimiter = ',')]
    spp: Vec<u64>,
    /// Where results go.
    #[arg(long, default_value = "fbksd-results")]
    results: PathBuf,
    /// Wall-time limit of each run (e.g. 90s, 10m, 2h); 0 for none.
    #[arg(long, default_value = "30m", value_parser = humantime::parse_duration)]
    time_limit: Duration,
    /// Make each run this many times, with the renderer's sample seeds 0,
    /// 1, …: metric values then carry confidence intervals, times their
    /// spread, and the ranking ties what the noise cannot tell apart.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1000))]
    repeats: u32,
    /// More seeds where they decide: after the repeats, the runs behind a
    /// tie that this many seeds per run could break (in values, or in
    /// cost at an equal-time point) are made again with the next seeds,
    /// doubling each round, up to this many. Needs scene directories with
    /// references: metric values are computed between rounds.
    #[arg(long, value_parser = clap::value_parser!(u32).range(2..=1000))]
    max_repeats: Option<u32>,
    /// With --max-repeats: the built-in metrics whose ties decide,
    /// comma-separated [default: all].
    #[arg(long, value_delimiter = ',', requires = "max_repeats")]
    metrics: Vec<String>,
}

fn technique_spec(arg: &str) -> anyhow::Result<TechniqueSpec> {
    // NAME=COMMAND when the part before '=' is a plain name with no blanks.
    let (name, command) = match arg.split_once('=') {
        Some((n, c)) if !n.is_empty() && n.chars().all(|ch| ch.is_ascii_alphanumeric() || "-_.".contains(ch)) => {
            (Some(n.to_string()), c)
        }
        _ => (None, arg),
    };
    let argv = shell_words::split(command).with_context(|| format!("--technique {arg:?}"))?;
    let Some(program) = argv.first() else { bail!("--technique {arg:?} has no command") };
    let name = name.unwrap_or_else(|| {
        PathBuf::from(program).file_stem().map_or("technique".into(), |s| s.to_string_lossy().into_owned())
    });
    Ok(TechniqueSpec { name, argv })
}

pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let techniques = args.techniques.iter().map(|t| technique_spec(t)).collect::<anyhow::Result<Vec<_>>>()?;
    if args.spp.contains(&0) {
        bail!("--spp takes positive budgets, e.g. --spp 1,4,16");
    }
    let renderer = match &args.renderer {
        Some(r) => {
            let argv = shell_words::split(r).with_context(|| format!("--renderer {r:?}"))?;
            if argv.is_empty() {
                bail!("--renderer is empty");
            }
            Some(argv)
        }
        None => None,
    };
    let mut scenes = Vec::new();
    for path in &args.scenes {
        if SceneMeta::is_meta(path) {
            let meta = SceneMeta::load(path)?;
            let program = fbksd_exchange::scenes::renderer_program(&meta.renderer)
                .map_err(anyhow::Error::msg)?
                .to_string_lossy()
                .into_owned();
            let file = std::fs::canonicalize(meta.scene_file())
                .with_context(|| format!("scene {}: {}", meta.name, meta.scene_file().display()))?;
            let renderer_argv = vec![program, file.to_string_lossy().into_owned()];
            let spps = if args.spp.is_empty() { meta.spp.clone() } else { args.spp.clone() };
            scenes.push(SceneSpec { name: meta.name, renderer_argv, spps });
            continue;
        }
        if !path.is_file() {
            bail!(
                "scene {} does not exist (give a scene directory, its fbksd-scene.json, or a scene file)",
                path.display()
            );
        }
        let Some(renderer) = &renderer else {
            bail!("scene file {} has no metadata: say which renderer loads it with --renderer", path.display());
        };
        let mut renderer_argv = renderer.clone();
        renderer_argv.push(std::fs::canonicalize(path)?.to_string_lossy().into_owned());
        let name = path.file_stem().map_or("scene".into(), |s| s.to_string_lossy().into_owned());
        let spps = if args.spp.is_empty() { vec![1, 4, 16] } else { args.spp.clone() };
        scenes.push(SceneSpec { name, renderer_argv, spps });
    }
    let settle = match args.max_repeats {
        Some(cap) if cap <= args.repeats => {
            bail!(
                "--max-repeats {cap} must be more than --repeats {} (each run already has that many seeds)",
                args.repeats
            )
        }
        Some(cap) => Some((cap, settle_inputs(&args)?)),
        None => None,
    };
    let limits = Limits { time_limit: (!args.time_limit.is_zero()).then_some(args.time_limit), ..Limits::default() };
    let benchmark = Benchmark {
        techniques,
        scenes,
        results: args.results.clone(),
        limits,
        launcher: std::sync::Arc::new(fbksd_manager::LocalLauncher),
        repeats: args.repeats,
    };
    let live = std::io::stderr().is_terminal();
    let mut records = benchmark.run(|p| report(p, live))?;
    if let Some((cap, (scenes, metrics))) = settle {
        records.extend(more_seeds(&benchmark, &scenes, &metrics, cap, live)?);
    }
    print_summary(&records);
    eprintln!("results in {}", args.results.display());
    if records.iter().any(|r| r.status != RunStatus::Ok) {
        std::process::exit(2);
    }
    Ok(())
}

/// The scenes (with their references) and metrics that decide which ties
/// are too close to call.
fn settle_inputs(args: &RunArgs) -> anyhow::Result<(BTreeMap<String, SceneMeta>, Vec<AnyMetric>)> {
    let mut dirs = Vec::new();
    for path in &args.scenes {
        if !SceneMeta::is_meta(path) {
            bail!(
                "--max-repeats compares metric values, so it needs scene directories with references; \
                 {} is a plain scene file",
                path.display()
            );
        }
        dirs.push(if path.is_file() { path.parent().unwrap_or(path).to_path_buf() } else { path.clone() });
    }
    let scenes = find_scenes(&dirs).context("reading the scene directories")?;
    if let Some(meta) = scenes.values().find(|m| !m.reference_file().is_file()) {
        bail!(
            "--max-repeats compares metric values, and scene {} has no reference at {} (build it: fbksd-{} reference {})",
            meta.name,
            meta.reference_file().display(),
            meta.renderer,
            meta.dir.display()
        );
    }
    Ok((scenes, crate::results::builtin_metrics(&args.metrics)?))
}

/// Gives the runs behind ties too close to call more seeds, saying why and
/// what it cost.
fn more_seeds(
    benchmark: &Benchmark,
    scenes: &BTreeMap<String, SceneMeta>,
    metrics: &[AnyMetric],
    cap: u32,
    live: bool,
) -> anyhow::Result<Vec<RunRecord>> {
    let mut records = Vec::new();
    let rounds = settle(
        benchmark,
        scenes,
        metrics,
        cap,
        |round| {
            let seeds: std::collections::BTreeSet<String> =
                round.runs.values().map(|r| format!("{}–{}", r.start, r.end - 1)).collect();
            eprintln!(
                "more seeds: {} ties too close to call, {} runs get seeds {}",
                round.close.len(),
                round.runs.len(),
                seeds.into_iter().collect::<Vec<_>>().join(", ")
            );
            for close in &round.close {
                eprintln!("  {}", describe(close));
            }
        },
        |p| {
            if let Progress::RunFinished(r) = &p {
                records.push((*r).clone());
            }
            report(p, live)
        },
    )?;
    let extra: usize = rounds.iter().map(|r| r.runs.values().map(|s| s.len()).sum::<usize>()).sum();
    let wall: Duration = rounds.iter().map(|r| r.wall).sum();
    match rounds.len() {
        0 => eprintln!("more seeds: no tie too close to call at {cap} seeds per run"),
        n => eprintln!(
            "more seeds: {n} round{}, {extra} more runs, {:.1} s",
            if n == 1 { "" } else { "s" },
            wall.as_secs_f64()
        ),
    }
    Ok(records)
}

/// A tie too close to call, in a line.
fn describe(close: &TooClose) -> String {
    let at = match &close.at {
        At::Spp { spp } => format!("{spp} spp"),
        At::Time { ms, fastest, spp } => format!("{ms:.1} ms ({fastest} at {spp} spp)"),
    };
    let what = close.metric.as_deref().map_or("cost".to_string(), |m| m.to_string());
    let tie = format!("{} {what} at {at}: {} ~ {}", close.scene, close.techniques[0], close.techniques[1]);
    let peers: BTreeSet<&str> = close.peers.iter().map(|k| k.technique.as_str()).collect();
    if peers.is_empty() {
        return tie;
    }
    // Their seeds follow the tie's, so a user sees why their runs are made again.
    format!("{tie} (alike: {})", peers.into_iter().collect::<Vec<_>>().join(", "))
}

fn report(progress: Progress<'_>, live: bool) {
    match progress {
        Progress::RunStarted { scene, technique, spp, repeat: 0 } => eprintln!("▶ {scene} · {technique} · {spp} spp"),
        Progress::RunStarted { scene, technique, spp, repeat } => {
            eprintln!("▶ {scene} · {technique} · {spp} spp · seed {repeat}")
        }
        Progress::Samples { delivered, budget } if live => {
            eprint!("\r  {delivered} / {budget} samples ({:.0}%)   ", delivered as f64 * 100.0 / budget.max(1) as f64)
        }
        Progress::Samples { .. } => {}
        Progress::RunFinished(r) => {
            if live {
                eprint!("\r\x1b[K");
            }
            let what =
                if r.status == RunStatus::Ok { "ok".to_string() } else { format!("{}: {}", r.status, r.message) };
            eprintln!("  {what} ({:.1} ms technique, {:.1} ms render)", r.times.technique_ms, r.times.render_ms);
        }
    }
}

fn print_summary(records: &[RunRecord]) {
    let header =
        ["scene", "technique", "spp", "seed", "status", "technique ms", "render ms", "wall ms", "samples", "peak MB"];
    let rows: Vec<[String; 10]> = records
        .iter()
        .map(|r| {
            [
                r.scene.clone(),
                r.technique.clone(),
                r.spp_budget.to_string(),
                r.seed.to_string(),
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
        .map(|c| rows.iter().map(|r| r[c].chars().count()).chain([header[c].len()]).max().unwrap())
        .collect();
    let line = |cells: Vec<&str>| {
        cells.iter().zip(&widths).map(|(c, w)| format!("{c:<w$}")).collect::<Vec<_>>().join("  ").trim_end().to_string()
    };
    println!("{}", line(header.to_vec()));
    for r in &rows {
        println!("{}", line(r.iter().map(String::as_str).collect()));
    }
}
