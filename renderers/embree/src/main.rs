//! `fbksd-embree <scene.pbrt>` serves a scene to `fbksd run` (the manager
//! appends the scene file to the renderer command). Subcommands check,
//! render, build references and measure speed.

use anyhow::Context;
use clap::{Parser, Subcommand};
use fbksd_embree::{pbrt, reference, render};
use std::path::{Path, PathBuf};

/// The Embree path tracer.
#[derive(Parser)]
#[command(name = "fbksd-embree", version, args_conflicts_with_subcommands = true)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// Serve this scene to the manager (how `fbksd run` starts renderers).
    scene: Option<PathBuf>,
}

#[derive(Subcommand)]
enum Command {
    /// What a scene file uses, whether it loads, and what it would need:
    /// every unsupported construct with its file and line, every
    /// conversion (pbrt-v3 forms, hints), and the scene info. Exits with
    /// status 1 when the scene does not load.
    Check { scene: PathBuf },
    /// Render a scene's colour at N stratified samples per pixel (box
    /// filter) to an EXR file, or an sRGB preview when OUT ends in .png.
    Render {
        scene: PathBuf,
        #[arg(long, default_value_t = 64)]
        spp: u64,
        #[arg(long)]
        out: PathBuf,
        /// Threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Request number: another number draws other samples.
        #[arg(long, default_value_t = 0)]
        request: u64,
    },
    /// Build the reference image of scene directories (their fbksd-scene.json says how).
    Reference {
        #[arg(required = true)]
        scenes: Vec<PathBuf>,
        /// Rebuild even when a reference exists.
        #[arg(long)]
        force: bool,
        /// Print each scene's reference key (what makes it, of which files)
        /// instead of building anything.
        #[arg(long, conflicts_with = "force")]
        key: bool,
        /// Override the metadata's spp (quick, unconverged references).
        #[arg(long)]
        spp: Option<u64>,
    },
    /// Samples and rays per second on one thread and on all cores.
    Bench {
        /// Scenes to time (scene files).
        #[arg(required = true)]
        scenes: Vec<PathBuf>,
        /// Samples per pixel.
        #[arg(long, default_value_t = 64)]
        spp: u64,
        /// Also write each image here (EXR), to compare with other renderers.
        #[arg(long)]
        out_dir: Option<PathBuf>,
    },
    /// Write a diffuse mesh scene as PLY files and scene.json for bench/mitsuba_bench.py.
    ExportMitsuba { scene: PathBuf, dir: PathBuf },
    /// How far two EXR renderings of one scene agree (means and block means).
    Compare {
        a: PathBuf,
        b: PathBuf,
        /// Block side in pixels.
        #[arg(long, default_value_t = 16)]
        block: usize,
    },
}

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn load(path: &Path) -> anyhow::Result<fbksd_embree::scene::Scene> {
    Ok(pbrt::load(path)?)
}

fn run() -> anyhow::Result<()> {
    let cli = Cli::parse();
    if cli.command.is_some() {
        fbksd_renderer::end_quietly_when_stdout_closes();
    }
    match (cli.command, cli.scene) {
        (None, Some(scene)) => fbksd_embree::serve(load(&scene)?)?,
        (None, None) => anyhow::bail!("usage: fbksd-embree <scene.pbrt> (see --help)"),
        (Some(Command::Check { scene: path }), _) => {
            let survey = pbrt::survey(&path);
            println!("{} uses:", path.display());
            for (what, count) in &survey.uses {
                println!("  {count:>6} × {what}");
            }
            if !survey.problems.is_empty() {
                println!("It does not load. It would need ({} problems):", survey.problems.len());
                for line in pbrt::summarize(&survey.problems) {
                    println!("  {line}");
                }
            }
            if !survey.warnings.is_empty() {
                println!("Read with conversions ({}):", survey.warnings.len());
                for line in pbrt::summarize(&survey.warnings) {
                    println!("  {line}");
                }
            }
            match survey.scene {
                Some(scene) => {
                    println!("It loads:");
                    for (k, v) in scene.info().iter() {
                        println!("  {k} = {v}");
                    }
                }
                None => std::process::exit(1),
            }
        }
        (Some(Command::Render { scene, spp, out, threads, request }), _) => {
            let scene = load(&scene)?;
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads.unwrap_or(0)).build()?;
            let image = pool.install(|| render::render_image(&scene, spp, request));
            if image.repairs > 0 {
                eprintln!("warning: {} samples had non-finite values (replaced by 0)", image.repairs);
            }
            if out.extension().is_some_and(|e| e == "png") {
                fbksd_iqa::image::write_png_preview(&out, scene.width(), scene.height(), &image.rgb, 0.0)?;
            } else {
                fbksd_iqa::image::write_exr(&out, scene.width(), scene.height(), &image.rgb)?;
            }
        }
        (Some(Command::Reference { scenes, force, key, spp }), _) => {
            for dir in scenes {
                let meta = reference::SceneMeta::load(&dir)?;
                meta.expect_renderer("embree").map_err(anyhow::Error::msg)?;
                if key {
                    println!("{} {}", reference::key(&meta, spp)?, dir.display());
                    continue;
                }
                let note =
                    reference::build(&meta, force, spp).with_context(|| format!("reference of {}", meta.name))?;
                println!("{}: {note}", meta.name);
            }
        }
        (Some(Command::Bench { scenes, spp, out_dir }), _) => {
            fbksd_embree::bench::run(&scenes, spp, out_dir.as_deref())?
        }
        (Some(Command::ExportMitsuba { scene, dir }), _) => fbksd_embree::bench::export_for_mitsuba(&scene, &dir)?,
        (Some(Command::Compare { a, b, block }), _) => println!("{}", fbksd_embree::bench::compare(&a, &b, block)?),
    }
    Ok(())
}
