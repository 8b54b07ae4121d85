//! `fbksd-analytic-renderer [--fault F] <scene.json>`: see the library docs.

use anyhow::{bail, Context};
use fbksd_analytic_renderer::{serve, Fault, Scene};
use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let mut fault = None;
    let mut scene = None;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--fault" => {
                fault = Some(Fault::parse(&args.next().context("--fault needs a value")?).map_err(anyhow::Error::msg)?)
            }
            _ if scene.is_none() => scene = Some(PathBuf::from(arg)),
            _ => bail!("unexpected argument {arg:?}; usage: fbksd-analytic-renderer [--fault F] <scene.json>"),
        }
    }
    let scene = scene.context("usage: fbksd-analytic-renderer [--fault F] <scene.json>")?;
    if fault == Some(Fault::ExitAtStart) {
        eprintln!("analytic renderer: exiting at start as asked (--fault exit-at-start)");
        std::process::exit(3);
    }
    let scene = Scene::load(&scene).map_err(anyhow::Error::msg)?;
    serve(scene, fault)?;
    Ok(())
}
