//! The Python SDK (`sdk/python`, package `fbksd`) through the whole
//! protocol: the thesis's B.1 example runs unchanged; the Python techniques
//! shipped as submission repositories run; the API behaves as documented
//! (plain scene-info values, zero-copy tiles, clear errors); the type stubs
//! match the native module.

use fbksd_tests::{analytic_scene, bin, python_path, sdk, write_script};
use std::path::Path;
use std::process::{Command, Output};

fn python(script: &Path, args: &[&str]) -> Output {
    Command::new("python3").arg(script).args(args).env("PYTHONPATH", python_path()).output().unwrap()
}

fn fbksd_run(args: &[String]) -> Output {
    Command::new(bin("fbksd")).arg("run").args(args).env("PYTHONPATH", python_path()).output().unwrap()
}

/// `fbksd run` of one technique on the ramp renderer (`sdk/python/examples/ramp_renderer.py`).
fn ramp_run(technique: String, scene: &Path, spp: &str, results: &Path) -> Output {
    fbksd_run(&[
        "-t".into(),
        technique,
        "-r".into(),
        sdk("python/examples/ramp_renderer.py").display().to_string(),
        "-s".into(),
        scene.display().to_string(),
        "--spp".into(),
        spp.into(),
        "--results".into(),
        results.display().to_string(),
    ])
}

fn read(results: &Path, technique: &str, scene: &str, spp: u32) -> Vec<f32> {
    fbksd_iqa::image::read_exr(&results.join(format!("{technique}/{scene}/{spp}_0.exr"))).unwrap().2
}

#[test]
fn the_thesis_example_b1_and_the_python_box_filter_match_the_rust_box_filter() {
    let dir = tempfile::tempdir().unwrap();
    let scene = analytic_scene(dir.path(), "b1", 40, 24);
    let results = dir.path().join("results");
    let output = fbksd_run(&[
        "-t".into(),
        format!("rust={}", bin("box-filter")),
        "-t".into(),
        format!("b1={}", sdk("python/examples/b1_box_filter.py").display()),
        "-t".into(),
        format!("py={}", sdk("techniques/box-filter-python/box_filter.py").display()),
        "-r".into(),
        bin("fbksd-analytic-renderer"),
        "-s".into(),
        scene.display().to_string(),
        "--spp".into(),
        "1,16".into(),
        "--results".into(),
        results.display().to_string(),
    ]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    for spp in [1, 16] {
        let rust = read(&results, "rust", "b1", spp);
        for technique in ["b1", "py"] {
            let py = read(&results, technique, "b1", spp);
            assert_eq!(py.len(), rust.len());
            // numpy averages in single precision (pairwise), the Rust box filter in double.
            for (p, r) in py.iter().zip(&rust) {
                assert!((p - r).abs() <= 2e-6 * r.abs().max(1e-3), "{technique} at {spp} spp: {p} vs {r}");
            }
        }
    }
}

#[test]
fn a_renderer_written_in_python_serves_exact_samples_to_a_technique() {
    // The ramp renderer's colour is where each sample lies: red x / width,
    // green y / height. The box filter's pixel means are then each pixel's
    // centre, up to the stratified jitter (4 × 4 strata at 16 spp).
    let dir = tempfile::tempdir().unwrap();
    let scene = analytic_scene(dir.path(), "ramp", 24, 10);
    let results = dir.path().join("results");
    let output = ramp_run(format!("box={}", bin("box-filter")), &scene, "1,16", &results);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    for (spp, slack) in [(1, 0.5), (16, 0.5 / 4.0)] {
        let image = read(&results, "box", "ramp", spp);
        for y in 0..10 {
            for x in 0..24 {
                let p = &image[(y * 24 + x) * 3..][..3];
                let (cx, cy) = ((x as f32 + 0.5) / 24.0, (y as f32 + 0.5) / 10.0);
                assert!((p[0] - cx).abs() <= slack / 24.0 + 1e-6, "{spp} spp, pixel ({x}, {y}): red {} vs {cx}", p[0]);
                assert!(
                    (p[1] - cy).abs() <= slack / 10.0 + 1e-6,
                    "{spp} spp, pixel ({x}, {y}): green {} vs {cy}",
                    p[1]
                );
            }
        }
    }
}

#[test]
fn a_python_renderer_that_refuses_a_feature_says_so() {
    // The ramp renderer computes colour only: asked for DEPTH, the run fails with its message.
    let dir = tempfile::tempdir().unwrap();
    let scene = analytic_scene(dir.path(), "ramp", 8, 8);
    let script = dir.path().join("depth.py");
    write_script(
        &script,
        "#!/usr/bin/env python3\nimport fbksd.client as fc\nc = fc.BenchmarkClient()\nc.set_sample_layout(['COLOR_R', 'DEPTH'])\nc.evaluate_samples(1, lambda t, o: None)\nc.send_result()\n",
    );
    let output = ramp_run(format!("depth={}", script.display()), &scene, "1", &dir.path().join("results"));
    let text = format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    assert!(text.contains("DEPTH is not computed by the ramp renderer"), "{text}");
}

#[test]
fn the_adaptive_python_technique_spends_exactly_its_budget() {
    let dir = tempfile::tempdir().unwrap();
    let scene = analytic_scene(dir.path(), "adaptive", 32, 20);
    let results = dir.path().join("results");
    let output = fbksd_run(&[
        "-t".into(),
        format!("adaptive={}", sdk("techniques/adaptive-python/adaptive.py").display()),
        "-r".into(),
        bin("fbksd-analytic-renderer"),
        "-s".into(),
        scene.display().to_string(),
        "--spp".into(),
        "1,8".into(),
        "--results".into(),
        results.display().to_string(),
    ]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    for spp in [1u64, 8] {
        let log: serde_json::Value = serde_json::from_slice(
            &std::fs::read(results.join(format!("adaptive/adaptive/{spp}_0_log.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(log["used_samples"], spp * 32 * 20, "{log}");
        let image = read(&results, "adaptive", "adaptive", spp as u32);
        assert!(image.iter().all(|v| v.is_finite()) && image.iter().any(|v| *v > 0.0));
    }
}

#[test]
fn the_python_api_behaves_as_documented() {
    let dir = tempfile::tempdir().unwrap();
    let scene = analytic_scene(dir.path(), "api", 20, 12);
    let script = dir.path().join("api.py");
    std::fs::write(
        &script,
        r#"
import sys
import numpy as np
import fbksd.client as fc

# Not started by a manager: a clear error, not a crash.
try:
    fc.BenchmarkClient([])
    raise SystemExit("connected without a manager")
except fc.FbksdError as e:
    assert "fbksd run" in str(e), e

# Debug mode: the client starts its own manager and renderer.
client = fc.BenchmarkClient(["api.py", "--fbksd-renderer", sys.argv[1] + " " + sys.argv[2],
                             "--fbksd-spp", "4", "--fbksd-output", sys.argv[3]])
info = client.get_scene_info()
assert info.get("width") == 20 and type(info.get("width")) is int, info
assert info.get("max_spp") == 4
assert type(info.get("has_dof")) is bool, info
assert info.has("height") and not info.has("nope") and "width" in info
try:
    info.get("nope")
    raise SystemExit("missing key accepted")
except KeyError as e:
    assert "nope" in str(e)

for bad, kind, words in [([42], TypeError, "element 0"), (["COLOR_R", "NOPE"], fc.FbksdError, "NOPE"),
                         ([("IMAGE_X", "SIDEWAYS")], ValueError, "INPUT")]:
    try:
        client.set_sample_layout(bad)
        raise SystemExit(f"layout {bad} accepted")
    except kind as e:
        assert words in str(e), (bad, e)

client.set_sample_layout([("IMAGE_X", fc.INPUT), ("IMAGE_Y", fc.INPUT), "COLOR_R", "COLOR_G", "COLOR_B", ("WORLD_X", 1)])
assert client.sample_size() == 6
result = client.get_result_buffer()
assert result.shape == (12, 20, 3) and result.dtype == np.float32 and not result.flags.owndata

seen = []
def produce(tile, offset):
    assert tile.dtype == np.float32 and tile.ndim == 4 and tile.shape[2:] == (1, 6), tile.shape
    assert not tile.flags.owndata and tile.flags.writeable
    (ny, nx, _, _) = tile.shape
    (bx, by) = offset
    tile[..., 0] = (bx + np.arange(nx) + 0.25)[None, :, None]
    tile[..., 1] = (by + np.arange(ny) + 0.75)[:, None, None]
def consume(tile, offset):
    (ny, nx, _, _) = tile.shape
    (bx, by) = offset
    assert client.sample_size() == 6, "callbacks can ask the sample size"
    assert np.array_equal(tile[..., 0, 0], np.broadcast_to(bx + np.arange(nx) + 0.25, (ny, nx)))
    seen.append(ny * nx)
    result[by:by + ny, bx:bx + nx] = tile[:, :, 0, 2:5]
client.evaluate_input_samples(1, produce, consume)
assert sum(seen) == 240, seen
assert client.remaining_samples() == 3 * 240

# An exception in a callback stops the callbacks and is raised once the request is over.
calls = []
def fails(samples):
    calls.append(len(samples))
    raise ValueError("bad tile")
try:
    client.evaluate_input_sample_count(100, fails, fails)
    raise SystemExit("callback error swallowed")
except ValueError as e:
    assert str(e) == "bad tile" and len(calls) == 1
assert client.remaining_samples() == 3 * 240 - 100

# Callbacks cannot start another request.
def nested(samples):
    client.evaluate_input_sample_count(1, lambda s: None, lambda s: None)
try:
    client.evaluate_input_sample_count(10, nested, lambda s: None)
    raise SystemExit("nested request accepted")
except fc.FbksdError as e:
    assert "in progress" in str(e)

client.send_result()
try:
    client.send_result()
    raise SystemExit("second send accepted")
except fc.FbksdError as e:
    assert "already sent" in str(e)
print("ok")
"#,
    )
    .unwrap();
    let image = dir.path().join("debug.exr");
    let output = python(&script, &[&bin("fbksd-analytic-renderer"), scene.to_str().unwrap(), image.to_str().unwrap()]);
    assert!(
        output.status.success(),
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    assert_eq!(String::from_utf8_lossy(&output.stdout).trim(), "ok");
    assert!(image.is_file(), "debug mode wrote the image");
}

#[test]
fn the_type_stubs_match_the_native_module_and_type_check_the_examples() {
    let run = |args: &[&str]| {
        let out = Command::new("python3").args(args).env("PYTHONPATH", python_path()).output().unwrap();
        assert!(
            out.status.success(),
            "python3 {args:?}:\n{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let cache = tempfile::tempdir().unwrap();
    let cache = cache.path().to_str().unwrap();
    run(&["-m", "mypy.stubtest", "--mypy-config-file", "/dev/null", "fbksd._native", "fbksd.client", "fbksd.renderer"]);
    run(&[
        "-m",
        "mypy",
        "--cache-dir",
        cache,
        "--strict",
        "--allow-untyped-calls",
        sdk("techniques/box-filter-python/box_filter.py").to_str().unwrap(),
        sdk("techniques/adaptive-python/adaptive.py").to_str().unwrap(),
    ]);
    run(&["-m", "mypy", "--cache-dir", cache, sdk("python/examples/b1_box_filter.py").to_str().unwrap()]);
}

#[test]
fn the_package_installs_with_pip_into_a_fresh_virtualenv_and_runs_a_technique() {
    let dir = tempfile::tempdir().unwrap();
    let venv = dir.path().join("venv");
    // numpy from the system keeps the test off the network but for the build backend (maturin).
    let status = Command::new("python3").args(["-m", "venv", "--system-site-packages"]).arg(&venv).status().unwrap();
    assert!(status.success(), "python3 -m venv failed (Debian: apt-get install python3-venv)");
    let pip = Command::new(venv.join("bin/pip"))
        .args(["install", "--quiet", "--disable-pip-version-check"])
        .arg(sdk("python"))
        // The debug profile reuses what `cargo build --workspace` compiled.
        .env("MATURIN_PEP517_ARGS", "--profile dev")
        .output()
        .unwrap();
    assert!(pip.status.success(), "pip install sdk/python: {}", String::from_utf8_lossy(&pip.stderr));

    let scene = analytic_scene(dir.path(), "pip", 16, 8);
    let results = dir.path().join("results");
    let technique = format!(
        "py={} {}",
        venv.join("bin/python").display(),
        sdk("techniques/box-filter-python/box_filter.py").display()
    );
    let output = Command::new(bin("fbksd"))
        .args(["run", "-t", &technique, "-t", &format!("rust={}", bin("box-filter"))])
        .args(["-r", &bin("fbksd-analytic-renderer"), "-s", scene.to_str().unwrap()])
        .args(["--spp", "4", "--results", results.to_str().unwrap()])
        .env_remove("PYTHONPATH")
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let (py, rust) = (read(&results, "py", "pip", 4), read(&results, "rust", "pip", 4));
    for (p, r) in py.iter().zip(&rust) {
        assert!((p - r).abs() <= 2e-6 * r.abs().max(1e-3), "{p} vs {r}");
    }
}

#[test]
fn each_sample_has_one_key_whatever_tile_it_is_served_in() {
    // A Python renderer records the key the SDK gives each pixel sample,
    // served in tiles of 4 and then of 7 pixels: every sample has the same
    // key both times, and no two samples share one.
    let dir = tempfile::tempdir().unwrap();
    let scene = analytic_scene(dir.path(), "keys", 13, 9);
    let renderer = dir.path().join("keys_renderer.py");
    write_script(
        &renderer,
        r#"#!/usr/bin/env python3
import json, os, sys
import fbksd.renderer as fr
scene = json.load(open(sys.argv[1]))
log = open(os.environ["KEYS_LOG"], "a")
def fill(tile, positions, samples):
    i = 0
    for y in range(tile["y0"], tile["y1"]):
        for x in range(tile["x0"], tile["x1"]):
            for s in range(tile["spp"]):
                log.write(f"{x} {y} {s} {int(tile['keys'][i])}\n")
                i += 1
    assert i == len(tile["keys"]) == len(positions)
    log.flush()
fr.RenderingServer(lambda: {"width": scene["width"], "height": scene["height"], "max_depth": 1,
                            "random_parameters": "IMAGE_X,IMAGE_Y"},
                   fill, tile_size=int(os.environ["KEYS_TILE"])).run()
"#,
    );
    let keys = |tile: &str| {
        let log = dir.path().join(format!("keys-{tile}.txt"));
        let out = Command::new(bin("fbksd"))
            .arg("run")
            .args(["-t", &format!("box={}", bin("box-filter")), "-r", &renderer.display().to_string()])
            .args(["-s", &scene.display().to_string(), "--spp", "4", "--results"])
            .arg(dir.path().join(format!("results-{tile}")))
            .env("PYTHONPATH", python_path())
            .env("KEYS_LOG", &log)
            .env("KEYS_TILE", tile)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let mut keys: Vec<(String, u64)> = std::fs::read_to_string(&log)
            .unwrap()
            .lines()
            .map(|l| l.rsplit_once(' ').map(|(at, key)| (at.to_string(), key.parse().unwrap())).unwrap())
            .collect();
        keys.sort();
        keys
    };
    let (fours, sevens) = (keys("4"), keys("7"));
    assert_eq!(fours.len(), 13 * 9 * 4);
    assert_eq!(fours, sevens);
    let mut distinct: Vec<u64> = fours.iter().map(|(_, k)| *k).collect();
    distinct.sort();
    distinct.dedup();
    assert_eq!(distinct.len(), fours.len(), "every sample its own key");
}
