//! `fbksd bench transport`: sample-transport throughput and memory.
//!
//! Streams a `width × height × spp` request of 14-float samples from the
//! analytic renderer (constant pattern: it only writes memory) to the Rust
//! box filter (which reads every sample's colour), through a real manager,
//! and prints the throughput beside this machine's single-thread memcpy
//! bandwidth, and the peak RSS of manager, renderer and technique.

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
