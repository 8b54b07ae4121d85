//! `fbksd bench`: sample-transport throughput and memory, and the speed of
//! scoring a results directory.
//!
//! `transport` streams a `width × height × spp` request of 14-float samples from the
//! analytic renderer (constant pattern: it only writes memory) to the Rust
//! box filter (which reads every sample's colour), through a real manager,
//! and prints the throughput beside this machine's single-thread memcpy
//! bandwidth, and the peak RSS of manager, renderer and technique.
//!
//! `metrics` scores runs on synthetic scenes with every built-in metric as
//! a runner does ([`fbksd_manager::evaluation::compute`]: in parallel, each
//! reference prepared once) and, on a copy of the same directory, one pair
//! and one metric at a time (the way it was done before), and prints both.

use anyhow::{bail, Context};
use clap::{Args, Subcommand};
use fbksd_manager::process::self_peak_rss;
use fbksd_manager::{Limits, RunStatus, SceneRunner, TechniqueLaunch};
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Subcommand)]
pub enum BenchCommand {
    /// Sample-transport throughput against memcpy, and peak memory.
    Transport(TransportArgs),
    /// Scoring runs with the seven built-in metrics, as a runner does and one pair at a time.
    Metrics(MetricsArgs),
}

#[derive(Args)]
pub struct MetricsArgs {
    /// Runs to score (spread over five scenes).
    #[arg(long, default_value_t = 50)]
    runs: usize,
    /// Image side.
    #[arg(long, default_value_t = 512)]
    size: u32,
    /// Build the scenes and results here and keep them (default: a temporary directory).
    #[arg(long)]
    dir: Option<PathBuf>,
}

#[derive(Args)]
pub struct TransportArgs {
    /// Image width.
    #[arg(long, default_value_t = 1920)]
    width: u32,
    /// Image height.
    #[arg(long, default_value_t = 1080)]
    height: u32,
    /// Samples per pixel.
    #[arg(long, default_value_t = 256)]
    spp: u64,
    /// The analytic renderer (default: next to this program, else on PATH).
    #[arg(long)]
    renderer: Option<PathBuf>,
    /// The box-filter technique (default: next to this program, else on PATH).
    #[arg(long)]
    technique: Option<PathBuf>,
}

const SAMPLE_FLOATS: u64 = 14;

pub fn bench(command: BenchCommand) -> anyhow::Result<()> {
    match command {
        BenchCommand::Transport(args) => transport(args),
        BenchCommand::Metrics(args) => metrics(args),
    }
}

fn sibling_or_path(name: &str, given: Option<PathBuf>) -> anyhow::Result<PathBuf> {
    if let Some(p) = given {
        return Ok(p);
    }
    let exe = std::env::current_exe()?;
    let sibling = exe.with_file_name(name);
    if sibling.is_file() {
        return Ok(sibling);
    }
    let on_path = std::env::var_os("PATH")
        .into_iter()
        .flat_map(|p| std::env::split_paths(&p).collect::<Vec<_>>())
        .map(|d| d.join(name))
        .find(|p| p.is_file());
    on_path
        .with_context(|| format!("cannot find {name}: build it (cargo build --release --workspace) or pass its path"))
}

/// Best of several single-thread copies of 256 MiB, in bytes per second.
fn memcpy_bandwidth() -> f64 {
    let n = 256 << 20;
    let src = vec![1u8; n];
    let mut dst = vec![0u8; n];
    dst.copy_from_slice(&src); // fault the pages in
    (0..5)
        .map(|_| {
            let t = Instant::now();
            dst.copy_from_slice(std::hint::black_box(&src));
            std::hint::black_box(&dst);
            n as f64 / t.elapsed().as_secs_f64()
        })
        .fold(0.0, f64::max)
}

fn transport(args: TransportArgs) -> anyhow::Result<()> {
    let renderer = sibling_or_path("fbksd-analytic-renderer", args.renderer)?;
    let technique = sibling_or_path("box-filter", args.technique)?;
    let work = tempfile::tempdir()?;
    let scene = work.path().join("transport.json");
    std::fs::write(
        &scene,
        format!(r#"{{"width": {}, "height": {}, "pattern": "constant", "tile_size": 16}}"#, args.width, args.height),
    )?;
    // The technique inherits this and asks for 14 floats per sample.
    std::env::set_var("FBKSD_BOX_EXTRA_FEATURES", "1");

    let log = work.path().join("renderer.log");
    let argv = |p: &Path| p.to_string_lossy().into_owned();
    let mut runner = SceneRunner::new(vec![argv(&renderer), argv(&scene)], Some(log.clone()), Limits::default())?;
    let technique_log = work.path().join("technique.log");
    let started = Instant::now();
    let outcome = runner.run(args.spp, &TechniqueLaunch::Command(vec![argv(&technique)]), &technique_log);
    let wall = started.elapsed();
    if outcome.status != RunStatus::Ok {
        bail!(
            "the transport run failed: {}: {}\ntechnique log:\n{}",
            outcome.status,
            outcome.message,
            std::fs::read_to_string(&technique_log).unwrap_or_default()
        );
    }
    let renderer_exit = runner.finish();
    let manager_peak = self_peak_rss();
    // Measured last: Linux carries a forked child's pre-exec peak RSS into
    // its ru_maxrss, so the 512 MiB touched here must not precede the run.
    let memcpy = memcpy_bandwidth();
    println!("memcpy (1 thread, 256 MiB):         {:6.2} GB/s", memcpy / 1e9);
    let bytes = outcome.used_samples as f64 * SAMPLE_FLOATS as f64 * 4.0;
    let transport = bytes / (outcome.times.render_ms / 1e3);
    println!(
        "transport ({}×{}, {} spp, {} floats/sample = {:.1} GB):",
        args.width,
        args.height,
        args.spp,
        SAMPLE_FLOATS,
        bytes / 1e9
    );
    println!(
        "  throughput (request → renderer done): {:6.2} GB/s  = {:.2} × memcpy",
        transport / 1e9,
        transport / memcpy
    );
    println!(
        "  whole run incl. start-up:          {:6.2} GB/s  ({:.2} s)",
        bytes / wall.as_secs_f64() / 1e9,
        wall.as_secs_f64()
    );
    println!("  technique time (excl. waiting):    {:8.1} ms", outcome.times.technique_ms);
    println!("peak RSS:");
    println!("  manager:   {:7.1} MB", manager_peak as f64 / 1e6);
    match renderer_exit {
        Some(r) => println!("  renderer:  {:7.1} MB", r.peak_rss as f64 / 1e6),
        None => println!("  renderer:  unknown (did not exit in time)"),
    }
    println!("  technique: {:7.1} MB", outcome.peak_memory_bytes as f64 / 1e6);
    Ok(())
}

/// Writes five scenes (metadata and an HDR reference) and a results
/// directory of `runs` runs on them (noisy copies of the references).
fn metrics_fixture(root: &Path, runs: usize, size: u32) -> anyhow::Result<()> {
    use fbksd_exchange::results::{IndexEntry, Repeat, ResultsDir, RunFiles};
    use fbksd_iqa::image::write_exr;
    let n = size as usize;
    let mut noise = crate::iqa::noise(0x9E37_79B9_7F4A_7C15);
    let scenes = 5;
    let references: Vec<Vec<f32>> = (0..scenes)
        .map(|s| {
            (0..n * n * 3)
                .map(|i| {
                    let (x, y, c) = ((i / 3) % n, i / 3 / n, i % 3);
                    let v = ((x as f32 * 0.02 + s as f32).sin() * (y as f32 * 0.03 + c as f32).cos()).abs();
                    // An HDR range: a few bright spots over a dim background.
                    if (x / 37 + y / 29 + s) % 11 == 0 {
                        8.0 * v
                    } else {
                        0.4 * v
                    }
                })
                .collect()
        })
        .collect();
    for (s, reference) in references.iter().enumerate() {
        let dir = root.join("scenes").join(format!("scene-{s}"));
        std::fs::create_dir_all(&dir)?;
        write_exr(&dir.join("reference.exr"), size, size, reference)?;
        let meta = serde_json::json!({
            "name": format!("scene-{s}"), "path": "scene.txt", "ref-img": "reference.exr",
            "renderer": "procedural", "category": "experimental", "tags": [], "spp": [4, 16],
            "width": size, "height": size, "reference": {"method": "render", "spp": 4096}, "description": "bench"
        });
        std::fs::write(dir.join(fbksd_exchange::scenes::META_FILE), serde_json::to_vec_pretty(&meta)?)?;
        std::fs::write(dir.join("scene.txt"), "bench")?;
    }
    let results = ResultsDir::create(&root.join("results"))?;
    let mut index = results.read_index()?;
    for run in 0..runs {
        // Five techniques on five scenes per budget: 4, 8, 16, … spp.
        let (scene, technique, spp) = (run % scenes, run / scenes % 5, 4u64 << (run / 25));
        let mut entry = IndexEntry::new(&format!("technique-{technique}"), &format!("scene-{scene}"), spp);
        let dir = results.run_dir(&entry.technique, &entry.scene)?;
        let files = RunFiles { spp: entry.spp, repeat: 0 };
        let amount = 1.0 / (spp as f32).sqrt();
        let test: Vec<f32> = references[scene].iter().map(|v| (v * (1.0 + amount * noise())).max(0.0)).collect();
        write_exr(&dir.join(files.image()), size, size, &test)?;
        let image = dir.join(files.image()).strip_prefix(results.root())?.to_string_lossy().into_owned();
        entry.repeats.push(Repeat {
            seed: 0,
            status: RunStatus::Ok,
            message: String::new(),
            log: String::new(),
            image: Some(image),
            technique_ms: 1.0,
            render_ms: 1.0,
            wall_ms: 1.0,
            cpu_ms: 1.0,
            waiting_ms: 0.0,
            technique_cpu_ms: 0.0,
            render_cpu_ms: 0.0,
            sample_floats: 0,
            startup_ms: 0.0,
            peak_memory_bytes: 0,
            used_samples: 0,
            metrics: Default::default(),
        });
        entry.summarize();
        index.runs.push(entry);
    }
    results.write_index(index)?;
    Ok(())
}

fn metrics(args: MetricsArgs) -> anyhow::Result<()> {
    use fbksd_exchange::results::{ResultsDir, RunFiles};
    use fbksd_iqa::image::Image;
    use fbksd_iqa::{evaluate, Metric, ValueRecord};
    use fbksd_manager::evaluation::{compute, find_scenes, AnyMetric};
    let work = tempfile::tempdir()?;
    let root = args.dir.clone().unwrap_or_else(|| work.path().to_path_buf());
    let (runner_root, one_root) = (root.join("runner"), root.join("one-at-a-time"));
    for root in [&runner_root, &one_root] {
        metrics_fixture(root, args.runs, args.size)?;
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "{} runs ({}×{}, five scenes), 7 metrics each, error maps for every run, {cores} cores:",
        args.runs, args.size, args.size
    );

    let metrics: Vec<AnyMetric> = Metric::ALL.iter().map(|m| AnyMetric::Builtin(*m)).collect();
    let scenes = find_scenes(&[runner_root.join("scenes")])?;
    let start = Instant::now();
    let summary = compute(&ResultsDir::create(&runner_root.join("results"))?, &scenes, &metrics, |_, _| {})?;
    let ours = start.elapsed().as_secs_f64();
    if summary.computed != args.runs * metrics.len() || !summary.skipped.is_empty() {
        bail!("compute scored {} values and skipped {:?}", summary.computed, summary.skipped);
    }

    // One pair and one metric at a time: each run's image read once (and its
    // viewer pixel file written), the scene's reference image kept, every
    // metric from scratch.
    let scenes = find_scenes(&[one_root.join("scenes")])?;
    let results = ResultsDir::create(&one_root.join("results"))?;
    let start = Instant::now();
    let mut references = std::collections::BTreeMap::new();
    for entry in results.read_index()?.runs {
        let reference = match references.entry(entry.scene.clone()) {
            std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::btree_map::Entry::Vacant(e) => {
                e.insert(Image::read(&scenes[&entry.scene].reference_file())?)
            }
        };
        let test_path = results.root().join(entry.repeats[0].image.as_deref().context("an image")?);
        let test = Image::read(&test_path)?;
        let files = RunFiles { spp: entry.spp, repeat: 0 };
        std::fs::write(test_path.with_file_name(files.pixels()), test.pixels_file())?;
        for metric in Metric::ALL {
            let e = evaluate(metric, reference, &test)?;
            if let Some(map) = &e.map {
                map.write_png(&test_path.with_file_name(files.error_map(metric.acronym())))?;
            }
            let record = ValueRecord {
                metric: metric.acronym().into(),
                value: e.value,
                nonfinite_reference: e.nonfinite_reference,
                nonfinite_test: e.nonfinite_test,
            };
            std::fs::write(
                test_path.with_file_name(files.metric_value(metric.acronym())),
                serde_json::to_vec(&record)?,
            )?;
        }
    }
    let theirs = start.elapsed().as_secs_f64();
    println!("  as a runner scores them (fbksd_manager::evaluation::compute): {ours:6.2} s  (target ≤ 4 s)");
    println!("  one pair and one metric at a time:                           {theirs:6.2} s");
    println!("  {:.1}× faster", theirs / ours);
    Ok(())
}
