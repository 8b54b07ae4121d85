//! Mitsuba 3 behind the protocol (`renderers/mitsuba/fbksd-mitsuba`, on
//! `fbksd.renderer`): a scene served to `fbksd run` agrees with Mitsuba's
//! own `mi.render`; the first hit's features and INPUT positions come
//! through; features it cannot compute are refused with a message;
//! Mitsuba agrees with our Embree path tracer on the Cornell box; a sample
//! replays whatever it is evaluated with; and references follow the
//! renderers' shared rule.

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
    let scene = repo("scenes/experimental/spheres-sky/scene.xml");
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
    let scene = repo("scenes/experimental/spheres-sky/scene.xml");
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

#[test]
fn a_sample_has_the_same_value_in_any_batch_and_order() {
    // Mitsuba draws each sample's random numbers from the key the SDK gives
    // it, so a sample's value does not depend on its neighbours: the same
    // samples evaluated at once, and reversed in batches of 173, agree bit for
    // bit; other keys give other paths.
    let script = format!(
        r#"
import importlib.machinery, importlib.util
import numpy as np
loader = importlib.machinery.SourceFileLoader("fbksd_mitsuba", {mitsuba:?})
spec = importlib.util.spec_from_loader("fbksd_mitsuba", loader)
m = importlib.util.module_from_spec(spec)
loader.exec_module(m)
r = m.Renderer({scene:?})
rng = np.random.default_rng(7)
n = 1500
positions = rng.random((n, 7))
positions[:, 0] *= r.width
positions[:, 1] *= r.height
keys = rng.integers(0, 2**63, n, dtype=np.uint64)
together, aov = r.evaluate(positions, keys, True, True)
order = np.arange(n)[::-1]
parts = [r.evaluate(positions[order[i:i + 173]], keys[order[i:i + 173]], True, True) for i in range(0, n, 173)]
apart = np.concatenate([p[0] for p in parts], axis=1)[:, np.argsort(order)]
apart_aov = np.concatenate([p[1] for p in parts], axis=1)[:, np.argsort(order)]
assert np.array_equal(together, apart), np.abs(together - apart).max()
assert np.array_equal(aov, apart_aov)
other, _ = r.evaluate(positions, keys ^ np.uint64(1), True, False)
assert (other != together).any(axis=0).mean() > 0.5, "other keys, other paths"
print("replay ok")
"#,
        mitsuba = mitsuba(),
        scene = repo("scenes/experimental/spheres-sky/scene.xml").display().to_string()
    );
    let out = run(Command::new("python3").args(["-c", &script]).env("PYTHONPATH", python_path()));
    assert!(String::from_utf8_lossy(&out.stdout).contains("replay ok"));
}

#[test]
fn references_follow_the_rule_every_renderer_shares() {
    // A copy of a pool scene at 16 spp: `reference --key` prints the key the
    // note of the reference it then makes has (as the runner checks), with
    // the feature buffers beside it; a second call keeps it.
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("spheres-sky");
    std::fs::create_dir(&scene).unwrap();
    for name in ["scene.xml", "fbksd-scene.json"] {
        std::fs::copy(repo("scenes/experimental/spheres-sky").join(name), scene.join(name)).unwrap();
    }
    let meta = std::fs::read_to_string(scene.join("fbksd-scene.json")).unwrap();
    std::fs::write(scene.join("fbksd-scene.json"), meta.replace("\"spp\": 4096", "\"spp\": 16")).unwrap();
    let reference = |args: &[&str]| {
        let out = run(Command::new(mitsuba()).arg("reference").args(args).arg(&scene).env("PYTHONPATH", python_path()));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let key = reference(&["--key"]);
    let key = key.split_whitespace().next().unwrap().to_string();
    assert!(key.starts_with("sha256:"), "{key}");
    let made = reference(&[]);
    assert!(made.contains("16 spp, estimated RMS error"), "{made}");
    let note = std::fs::read(scene.join("reference.json")).unwrap();
    assert_eq!(fbksd_exchange::scenes::note_reference_key(&note).unwrap(), key);
    // Kernels are compiled for the one pinned target wherever the CPU runs it,
    // so runners of different CPUs render the same values; the note names it.
    let generator = serde_json::from_slice::<serde_json::Value>(&note).unwrap()["generator"].to_string();
    let cpu = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    if cpu.contains(" avx2") && cpu.contains(" fma") {
        assert!(generator.contains("llvm_ad_rgb x86-64-v3x8"), "{generator}");
    }
    let (w, h, rgb) = fbksd_iqa::image::read_exr(&scene.join("reference.exr")).unwrap();
    assert_eq!((w, h), (256, 192));
    assert!(rgb.iter().all(|v| v.is_finite()) && rgb.iter().any(|v| *v > 0.0));
    for buffer in fbksd_exchange::scenes::FEATURE_BUFFERS {
        let (bw, bh, values) = fbksd_iqa::image::read_exr(&scene.join(format!("reference-{buffer}.exr"))).unwrap();
        assert_eq!((bw, bh), (w, h), "{buffer}");
        assert!(values.iter().any(|v| *v != 0.0), "{buffer} is all zero");
    }
    // Kept: the same note, not rendered again.
    let modified = std::fs::metadata(scene.join("reference.exr")).unwrap().modified().unwrap();
    reference(&[]);
    assert_eq!(std::fs::metadata(scene.join("reference.exr")).unwrap().modified().unwrap(), modified);
    // --force rebuilds it; the same seeds give the same image.
    let before = std::fs::read(scene.join("reference.exr")).unwrap();
    reference(&["--force"]);
    assert_ne!(std::fs::metadata(scene.join("reference.exr")).unwrap().modified().unwrap(), modified);
    assert_eq!(std::fs::read(scene.join("reference.exr")).unwrap(), before);
    // Another renderer's scene is refused, naming the program that makes it.
    let out = Command::new(mitsuba())
        .arg("reference")
        .arg(repo("scenes/experimental/sphere"))
        .env("PYTHONPATH", python_path())
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && text.contains("make its reference with fbksd-procedural reference"), "{text}");
    // The scene's files changed: another key.
    std::fs::write(scene.join("scene.xml"), std::fs::read_to_string(scene.join("scene.xml")).unwrap() + "\n").unwrap();
    assert_ne!(reference(&["--key"]).split_whitespace().next().unwrap(), key);
    // Metadata without its image size is refused as the built-in renderers
    // refuse it: the file and the missing field named, no traceback.
    let meta = std::fs::read_to_string(scene.join("fbksd-scene.json")).unwrap();
    std::fs::write(scene.join("fbksd-scene.json"), meta.replace("\"width\": 256,", "")).unwrap();
    let out = Command::new(mitsuba()).arg("reference").arg(&scene).env("PYTHONPATH", python_path()).output().unwrap();
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{text}");
    assert!(text.contains("fbksd-scene.json: missing field `width`") && !text.contains("Traceback"), "{text}");
}
