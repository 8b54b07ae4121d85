//! Mitsuba 3 behind the protocol (`renderers/mitsuba/fbksd-mitsuba`, on
//! `fbksd.renderer`): a scene served to `fbksd run` agrees with Mitsuba's
//! own `mi.render`; the first hit's features and INPUT positions come
//! through; features it cannot compute are refused with a message; and
//! Mitsuba agrees with our Embree path tracer on the Cornell box.

use fbksd_tests::{bin, python_path, run, sdk, write_script};
use std::path::{Path, PathBuf};
use std::process::Command;

fn repo(path: &str) -> PathBuf {
    sdk("..").join(path)
}

fn mitsuba() -> String {
    repo("renderers/mitsuba/fbksd-mitsuba").display().to_string()
}

/// `fbksd run` of one technique with fbksd-mitsuba on `scene`.
fn fbksd_run(technique: &str, scene: &Path, spp: u32, results: &Path) -> Command {
    let mut cmd = Command::new(bin("fbksd"));
    cmd.args(["run", "-t", technique, "-r", &mitsuba(), "-s", &scene.display().to_string()])
        .args(["--spp", &spp.to_string(), "--results", &results.display().to_string()])
        .env("PYTHONPATH", python_path());
    cmd
}

fn means(path: &Path) -> [f64; 3] {
    let (_, _, rgb) = fbksd_iqa::image::read_exr(path).unwrap();
    let n = (rgb.len() / 3) as f64;
    std::array::from_fn(|c| rgb.iter().skip(c).step_by(3).map(|v| *v as f64).sum::<f64>() / n)
}

#[test]
fn a_scene_served_to_fbksd_run_agrees_with_mitsubas_own_render() {
    let dir = tempfile::tempdir().unwrap();
    let scene = repo("scenes/mitsuba/spheres-sky/scene.xml");
    run(&mut fbksd_run(&format!("box={}", bin("box-filter")), &scene, 64, &dir.path().join("results")));
    let ours = means(&dir.path().join("results/box/scene/64_0.exr"));
    // Mitsuba's own render of the same file, at more samples.
    let theirs = dir.path().join("mitsuba.exr");
    let script = format!(
        "import mitsuba as mi\nmi.set_variant('llvm_ad_rgb')\nmi.util.write_bitmap({:?}, mi.render(mi.load_file({:?}), spp=256))\n",
        theirs.display(),
        scene.display()
    );
    run(Command::new("python3").args(["-c", &script]));
    let theirs = means(&theirs);
    for c in 0..3 {
        assert!((ours[c] - theirs[c]).abs() < 0.01 * theirs[c], "channel {c}: {} vs Mitsuba's {}", ours[c], theirs[c]);
    }
}

#[test]
fn features_and_input_positions_come_through_and_unknown_features_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scene = repo("scenes/mitsuba/spheres-sky/scene.xml");
    // Every sample at the image centre (INPUT): the same camera ray, so the
    // same first hit: the middle sphere, rough gold, whose albedo Mitsuba
    // reports; the normal faces the viewer.
    let technique = dir.path().join("probe.py");
    write_script(
        &technique,
        r#"#!/usr/bin/env python3
import numpy as np
import fbksd.client as fc
c = fc.BenchmarkClient()
info = c.get_scene_info()
w, h = info.get("width"), info.get("height")
c.set_sample_layout([("IMAGE_X", fc.INPUT), ("IMAGE_Y", fc.INPUT), "DEPTH", "NORMAL_X", "NORMAL_Y", "NORMAL_Z", "WORLD_Y", "COLOR_R"])
seen = []
def produce(tile, offset):
    tile[..., 0] = w / 2
    tile[..., 1] = h / 2
def consume(tile, offset):
    seen.append(tile.reshape(-1, tile.shape[-1]).copy())
c.evaluate_input_samples(1, produce, consume)
s = np.concatenate(seen)
assert (s[:, 0] == w / 2).all() and (s[:, 1] == h / 2).all(), "INPUT positions kept"
assert s[:, 2].min() > 0 and np.ptp(s[:, 2]) < 1e-4, ("one camera ray, one depth", s[:, 2].min(), s[:, 2].max())
n = s[:, 3:6]
assert np.allclose(np.linalg.norm(n, axis=1), 1, atol=1e-4) and (n[:, 2] > 0).all(), "a unit normal towards the camera"
assert np.allclose(s[:, 6], s[0, 6]) and 0 < s[0, 6] < 1, "the sphere's point"
assert np.ptp(s[:, 7]) > 0, "colour differs from sample to sample: each path its own"
c.send_result()
print("probe: all checks passed")
"#,
    );
    let out = run(&mut fbksd_run(&format!("probe={}", technique.display()), &scene, 1, &dir.path().join("r1")));
    assert!(String::from_utf8_lossy(&out.stdout).contains(" ok "), "{}", String::from_utf8_lossy(&out.stdout));
    // DIRECT_LIGHT has no Mitsuba counterpart: the run fails with the renderer's reason.
    let refused = dir.path().join("refused.py");
    write_script(
        &refused,
        "#!/usr/bin/env python3\nimport fbksd.client as fc\nc = fc.BenchmarkClient()\nc.set_sample_layout(['COLOR_R', 'DIRECT_LIGHT_R'])\nc.evaluate_samples(1, lambda t, o: None)\nc.send_result()\n",
    );
    let out = fbksd_run(&format!("refused={}", refused.display()), &scene, 1, &dir.path().join("r2")).output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(text.contains("DIRECT_LIGHT_R is not computed by fbksd-mitsuba"), "{text}");
}

#[test]
fn mitsuba_and_the_embree_path_tracer_agree_on_the_cornell_box() {
    let dir = tempfile::tempdir().unwrap();
    let cornell = repo("scenes/production/cornell-box/small.pbrt");
    let export = dir.path().join("export");
    run(Command::new(bin("fbksd-embree")).arg("export-mitsuba").arg(&cornell).arg(&export));
    let (ours, theirs) = (dir.path().join("embree.exr"), dir.path().join("mitsuba.exr"));
    run(Command::new(bin("fbksd-embree")).arg("render").arg(&cornell).args(["--spp", "64", "--out"]).arg(&ours));
    run(Command::new(mitsuba())
        .arg("render")
        .arg(export.join("scene.xml"))
        .args(["--spp", "64", "--out"])
        .arg(&theirs)
        .env("PYTHONPATH", python_path()));
    let (a, b) = (means(&ours), means(&theirs));
    for c in 0..3 {
        assert!((a[c] - b[c]).abs() < 0.01 * b[c], "channel {c}: Embree {} vs Mitsuba {}", a[c], b[c]);
    }
}
