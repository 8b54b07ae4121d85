//! `fbksd results compute` and `fbksd results show` on a real benchmark of
//! a small procedural scene, with an external metric plugged in.

use fbksd_tests::{bin, scene_meta};
use std::os::unix::fs::PermissionsExt;
use std::process::Command;

fn fbksd(args: &[&str]) -> (bool, String, String) {
    let o = Command::new(bin("fbksd")).args(args).output().unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn results_are_computed_incrementally_and_ranked() {
    let dir = tempfile::tempdir().unwrap();
    // A small scene with its metadata and a reference built by the renderer's command.
    let scenes = dir.path().join("scenes");
    let scene = scenes.join("ramp");
    std::fs::create_dir_all(&scene).unwrap();
    std::fs::write(scene.join("ramp.expr"), "width := 24;\nheight := 16;\n#\nvar v := IMAGE_X / width * LIGHT_X * 2;\nCOLOR_R := v; COLOR_G := v; COLOR_B := 1 - v;\n").unwrap();
    scene_meta(&scene, "ramp", "ramp.expr", "procedural", &[1, 8], 24, 16);
    let out = Command::new(bin("fbksd-procedural")).arg("reference").arg(&scene).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("4096 spp, estimated RMS error"));

    // An external metric in the original plug-in format: prints a constant.
    let metric = dir.path().join("constant-metric");
    std::fs::create_dir(&metric).unwrap();
    std::fs::write(metric.join("metric.sh"), "#!/bin/sh\n# args: [--map-file f] ref test\necho '{\"value\": 0.5}'\n")
        .unwrap();
    std::fs::set_permissions(metric.join("metric.sh"), std::fs::Permissions::from_mode(0o755)).unwrap();
    std::fs::write(
        metric.join("info.json"),
        r#"{"acronym": "HALF", "name": "Always a half", "reference": "", "lower_is_better": true, "has_error_map": false, "executable": "metric.sh"}"#,
    )
    .unwrap();

    let results = dir.path().join("results");
    let (ok, _, err) = fbksd(&[
        "run",
        "-t",
        &bin("box-filter"),
        "-s",
        scene.to_str().unwrap(),
        "--results",
        results.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let (r, s, m) = (results.to_str().unwrap(), scenes.to_str().unwrap(), metric.to_str().unwrap());
    let (ok, _, err) = fbksd(&["results", "compute", "--results", r, "--scenes", s, "--metric-dir", m]);
    assert!(ok, "{err}");
    assert!(err.contains("16 values computed, 0 already there, 0 runs skipped"), "{err}");
    for file in ["1_0_MSE.json", "8_0_SSIM.json", "8_0_FLIP_map.png", "1_0_HALF.json", "8_0_rMSE_map.png"] {
        assert!(results.join("box-filter/ramp").join(file).is_file(), "{file}");
    }
    // Incremental: nothing left to do.
    let (ok, _, err) = fbksd(&["results", "compute", "--results", r, "--scenes", s, "--metric-dir", m]);
    assert!(ok && err.contains("0 values computed, 16 already there"), "{err}");
    // More samples, less error.
    let index: serde_json::Value = serde_json::from_slice(&std::fs::read(results.join("index.json")).unwrap()).unwrap();
    let mse = |i: usize| index["runs"][i]["metrics"]["MSE"].as_f64().unwrap();
    assert_eq!((index["runs"][0]["spp"].as_u64(), index["runs"][1]["spp"].as_u64()), (Some(1), Some(8)));
    assert!(mse(1) < mse(0), "{} vs {}", mse(1), mse(0));
    assert_eq!(index["runs"][0]["metrics"]["HALF"], 0.5);

    let (ok, table, err) = fbksd(&["results", "show", "--results", r]);
    assert!(ok, "{err}");
    assert!(
        table.contains("ramp") && table.contains("MSE ↓") && table.contains("SSIM ↑") && table.contains("HALF ↓"),
        "{table}"
    );
    assert!(table.contains("ranking") && table.lines().any(|l| l.starts_with("1  box-filter")), "{table}");
}

#[test]
fn a_missing_reference_says_how_to_build_it() {
    let dir = tempfile::tempdir().unwrap();
    let results = dir.path().join("results");
    let sphere = format!("{}/../scenes/experimental/sphere", env!("CARGO_MANIFEST_DIR"));
    let scenes = dir.path().join("scenes");
    std::fs::create_dir(&scenes).unwrap();
    // A copy of the sphere's metadata without its reference.
    std::fs::create_dir(scenes.join("sphere")).unwrap();
    for f in ["fbksd-scene.json", "sphere.expr"] {
        std::fs::copy(format!("{sphere}/{f}"), scenes.join("sphere").join(f)).unwrap();
    }
    let (ok, _, err) = fbksd(&[
        "run",
        "-t",
        &bin("box-filter"),
        "-s",
        scenes.join("sphere").to_str().unwrap(),
        "--spp",
        "1",
        "--results",
        results.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let (ok, _, err) =
        fbksd(&["results", "compute", "--results", results.to_str().unwrap(), "--scenes", scenes.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(err.contains("no reference at") && err.contains("fbksd-procedural reference"), "{err}");
}

// Regression: the small production pool reused the full pool's scene names,
// and results are filed by name, so a run could be scored against the
// reference of the other size. Two scenes of one name are now an error.
#[test]
fn two_scenes_with_one_name_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    for sub in ["a", "b"] {
        let d = dir.path().join(sub);
        std::fs::create_dir(&d).unwrap();
        scene_meta(&d, "twin", "twin.json", "analytic", &[1], 4, 4);
    }
    let results = dir.path().join("results");
    std::fs::create_dir(&results).unwrap();
    std::fs::write(results.join("index.json"), r#"{"runs": []}"#).unwrap();
    let (ok, _, err) = fbksd(&[
        "results",
        "compute",
        "--results",
        results.to_str().unwrap(),
        "--scenes",
        dir.path().to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("two scenes are named \"twin\""), "{err}");
}
