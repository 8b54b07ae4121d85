//! The Embree path tracer through the whole protocol: `fbksd run` starts
//! `fbksd-embree` on every small production scene, and the box filter's
//! image equals the renderer's own in-process rendering of the same samples.

use fbksd_tests::bin;
use std::process::Command;

fn pool() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/production-small")
}

#[test]
fn every_small_production_scene_runs_through_fbksd_run() {
    let dir = tempfile::tempdir().unwrap();
    let results = dir.path().join("results");
    let mut scenes: Vec<_> = std::fs::read_dir(pool()).unwrap().map(|e| e.unwrap().path()).collect();
    scenes.sort();
    assert_eq!(scenes.len(), 10, "the pool has ten production scenes");
    let mut cmd = Command::new(bin("fbksd"));
    cmd.args(["run", "-t", &bin("box-filter"), "--spp", "2", "--results", results.to_str().unwrap()]);
    for s in &scenes {
        cmd.arg("-s").arg(s);
    }
    let output = cmd.output().unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    // The technique's image is the box filter of exactly the samples the
    // renderer draws in process for the same request.
    let meta = fbksd_exchange::scenes::SceneMeta::load(&pool().join("cornell-box")).unwrap();
    let scene = fbksd_embree::pbrt::load(&meta.scene_file()).unwrap();
    let (w, h, served) = fbksd_iqa::image::read_exr(&results.join("box-filter/cornell-box-small/2_0.exr")).unwrap();
    assert_eq!((w, h), (128, 128));
    let ours = fbksd_embree::render::render_image(&scene, 2, 0);
    let worst = served.iter().zip(&ours.rgb).map(|(a, b)| (a - b).abs() / b.abs().max(1e-3)).fold(0f32, f32::max);
    assert!(worst < 1e-4, "served and in-process images differ by {worst} (relative)");
}
