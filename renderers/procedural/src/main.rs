//! `fbksd-procedural <scene>` serves a scene to `fbksd run` (the manager
//! appends the scene file to the renderer command). Subcommands check,
//! render, build references and measure speed.

use anyhow::{bail, Context};
use clap::{Parser, Subcommand};
use fbksd_procedural::{reference, Scene};
use std::path::{Path, PathBuf};

/// The procedural renderer.
#[derive(Parser)]
#[command(name = "fbksd-procedural", version, args_conflicts_with_subcommands = true)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// Serve this scene to the manager (how `fbksd run` starts renderers).
    scene: Option<PathBuf>,
}

#[derive(Subcommand)]
enum Command {
    /// Parse and compile a scene; print its scene info.
    Check { scene: PathBuf },
    /// Render a scene's colour at N stratified samples per pixel (box
    /// filter) to an EXR file, or an sRGB preview when OUT ends in .png.
    Render {
        scene: PathBuf,
        #[arg(long, default_value_t = 64)]
        spp: u64,
        #[arg(long)]
        out: PathBuf,
    },
    /// Build the reference image of a scene directory (its fbksd-scene.json says how).
    Reference {
        /// Scene directories (or their fbksd-scene.json files).
        #[arg(required = true)]
        scenes: Vec<PathBuf>,
        /// Rebuild even when a reference exists.
        #[arg(long)]
        force: bool,
        /// Print each scene's reference key (what makes it, of which files)
        /// instead of building anything.
        #[arg(long, conflicts_with = "force")]
        key: bool,
        /// Override the metadata's spp (for quick, unconverged references).
        #[arg(long)]
        spp: Option<u64>,
    },
    /// Samples per second on listing C.1 and on the Mandelbrot scene.
    Bench {
        /// The scenes directory.
        #[arg(long, default_value = "scenes/experimental")]
        scenes: PathBuf,
    },
}

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn load(path: &Path) -> anyhow::Result<Scene> {
    Scene::load(path).map_err(anyhow::Error::msg)
}

fn run() -> anyhow::Result<()> {
    let cli = Cli::parse();
    if cli.command.is_some() {
        fbksd_renderer::end_quietly_when_stdout_closes();
    }
    match (cli.command, cli.scene) {
        (None, Some(scene)) => fbksd_procedural::serve(load(&scene)?)?,
        (None, None) => bail!("usage: fbksd-procedural <scene> (see --help)"),
        (Some(Command::Check { scene }), _) => {
            let scene = load(&scene)?;
            for (k, v) in scene.info().iter() {
                println!("{k} = {v}");
            }
        }
        (Some(Command::Render { scene, spp, out }), _) => {
            let scene = load(&scene)?;
            let image = fbksd_procedural::render::render_image(&scene, spp, 0).map_err(anyhow::Error::msg)?;
            if out.extension().is_some_and(|e| e == "png") {
                fbksd_iqa::image::write_png_preview(&out, scene.width, scene.height, &image, 0.0)?;
            } else {
                fbksd_iqa::image::write_exr(&out, scene.width, scene.height, &image)?;
            }
        }
        (Some(Command::Reference { scenes, force, key, spp }), _) => {
            for dir in scenes {
                let meta = reference::SceneMeta::load(&dir)?;
                meta.expect_renderer("procedural").map_err(anyhow::Error::msg)?;
                if key {
                    println!("{} {}", reference::key(&meta, spp)?, dir.display());
                    continue;
                }
                let note =
                    reference::build(&meta, force, spp).with_context(|| format!("reference of {}", meta.name))?;
                println!("{}: {note}", meta.name);
            }
        }
        (Some(Command::Bench { scenes }), _) => reference::bench(&scenes)?,
    }
    Ok(())
}
