//! `fbksd results compute` and `fbksd results show` on a real benchmark of
//! a small procedural scene, with an external metric plugged in.

use fbksd_tests::{bin, python_path, scene_meta, sdk};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::Command;

fn fbksd(args: &[&str]) -> (bool, String, String) {
    let o = Command::new(bin("fbksd")).args(args).env("PYTHONPATH", python_path()).output().unwrap();
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

/// A noisy procedural scene with its reference, under `dir/scenes/noisy`.
fn noisy_scene(dir: &std::path::Path) -> std::path::PathBuf {
    let scene = dir.join("scenes/noisy");
    std::fs::create_dir_all(&scene).unwrap();
    std::fs::write(
        scene.join("noisy.expr"),
        "width := 20;\nheight := 12;\n#\nvar v := IMAGE_X / width * LIGHT_X * 2;\nCOLOR_R := v; COLOR_G := v * LIGHT_Y; COLOR_B := 1 - v;\n",
    )
    .unwrap();
    scene_meta(&scene, "noisy", "noisy.expr", "procedural", &[1, 4, 16], 20, 12);
    let out = Command::new(bin("fbksd-procedural")).arg("reference").arg(&scene).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    scene
}

/// `fbksd run --repeats 3`: each run is made with seeds 0, 1 and 2, whose
/// images differ; the index carries every repeat, each value's confidence
/// interval and the times' spread; the Rust and the Python box filter
/// (the same filter, equal to float rounding) tie in every cell instead of
/// ranking 1st and 2nd on rounding; the tables show intervals, ties and the
/// equal-time ranking.
#[test]
fn repeated_runs_carry_intervals_and_equal_techniques_tie() {
    let dir = tempfile::tempdir().unwrap();
    let scene = noisy_scene(dir.path());
    let results = dir.path().join("results");
    let python_box = format!("python={}", sdk("techniques/box-filter-python/box_filter.py").display());
    let rust_box = format!("rust={}", bin("box-filter"));
    let r = results.to_str().unwrap();
    let (ok, summary, err) = fbksd(&[
        "run",
        "-t",
        &rust_box,
        "-t",
        &python_box,
        "-s",
        scene.to_str().unwrap(),
        "--repeats",
        "3",
        "--results",
        r,
    ]);
    assert!(ok, "{err}");
    assert!(summary.lines().filter(|l| l.starts_with("noisy")).count() == 2 * 3 * 3, "{summary}");
    let seed = |k: u32| fbksd_iqa::image::read_exr(&results.join(format!("rust/noisy/4_{k}.exr"))).unwrap().2;
    assert_ne!(seed(0), seed(1), "another seed, other samples");
    assert_ne!(seed(1), seed(2));

    let s = dir.path().join("scenes");
    let (ok, _, err) =
        fbksd(&["results", "compute", "--results", r, "--scenes", s.to_str().unwrap(), "--metrics", "MSE,rMSE"]);
    assert!(ok, "{err}");
    assert!(err.contains("36 values computed"), "{err}");
    let index: serde_json::Value = serde_json::from_slice(&std::fs::read(results.join("index.json")).unwrap()).unwrap();
    for run in index["runs"].as_array().unwrap() {
        let what = format!("{} at {} spp", run["technique"], run["spp"]);
        let seeds: Vec<u64> = run["repeats"].as_array().unwrap().iter().map(|r| r["seed"].as_u64().unwrap()).collect();
        assert_eq!(seeds, [0, 1, 2], "{what}");
        let mse = &run["intervals"]["MSE"];
        let (low, mean, high) =
            (mse["low"].as_f64().unwrap(), mse["mean"].as_f64().unwrap(), mse["high"].as_f64().unwrap());
        assert!(low < mean && mean < high && mean == run["metrics"]["MSE"].as_f64().unwrap(), "{what}: {mse}");
        let timing = &run["timing"]["technique"];
        assert!(timing["min"].as_f64() <= timing["median"].as_f64() && timing["cv"].as_f64().unwrap() >= 0.0, "{what}");
        assert!(run["time_ms"].as_f64().unwrap() > 0.0, "{what}");
    }
    // Every equal-spp cell: the two box filters tie, sharing places 1 and 2.
    let cells = index["rankings"]["equal_spp"]["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 3 * 2);
    for cell in cells {
        let places: Vec<f64> =
            cell["places"].as_array().unwrap().iter().map(|p| p["place"].as_f64().unwrap()).collect();
        assert_eq!(places, [1.5, 1.5], "{cell}");
    }
    let standings = index["rankings"]["equal_spp"]["standings"].as_array().unwrap();
    assert!(standings.iter().all(|s| s["mean_rank"] == 1.5 && s["tied"] == 6), "{standings:?}");
    // Equal time is ranked too (the Python filter, slower to start, cannot
    // answer at the Rust one's 1 spp time: it ranks last there).
    assert!(!index["rankings"]["equal_time"]["cells"].as_array().unwrap().is_empty());

    let (ok, table, err) = fbksd(&["results", "show", "--results", r]);
    assert!(ok, "{err}");
    assert!(table.contains(" ± ") && table.contains(" =") && table.contains("technique ms (CV)"), "{table}");
    assert!(table.contains("noisy at equal time") && table.contains("mean rank (equal time)"), "{table}");
    assert!(table.lines().any(|l| l.starts_with("1  python") || l.starts_with("1  rust")), "{table}");
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

/// A small procedural scene of sine bands (160×120, 4 and 16 spp) under
/// `root/scenes/bands`, with its reference.
fn bands_scene(root: &Path) -> PathBuf {
    let scene = root.join("scenes/bands");
    std::fs::create_dir_all(&scene).unwrap();
    std::fs::write(
        scene.join("bands.expr"),
        "width := 160;\nheight := 120;\n#\nvar v := sin(IMAGE_X * 0.3 + LIGHT_X * 3) * 0.5 + 0.5;\n\
         COLOR_R := v; COLOR_G := v * LIGHT_Y; COLOR_B := 1 - v;\n",
    )
    .unwrap();
    scene_meta(&scene, "bands", "bands.expr", "procedural", &[4, 16], 160, 120);
    let out = Command::new(bin("fbksd-procedural")).arg("reference").arg(&scene).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    scene
}

/// The equal-time rule against noise, as `fbksd run` is used: the same
/// program under two names ties at equal samples and at equal time (its
/// copies' costs differ only by noise), and the same program with a busy
/// loop that doubles its work ranks below it at equal time, while tying at
/// equal samples (its images are the same).
#[test]
fn equal_time_ties_copies_and_ranks_doubled_work_below() {
    let dir = tempfile::tempdir().unwrap();
    let scene = bands_scene(dir.path());
    let results = dir.path().join("results");
    let r = results.to_str().unwrap();
    // Thirty rounds of arithmetic per sample weigh about as much as rendering it.
    let box_filter = |name: &str, mode: &str| format!("{name}={} {mode} 30", bin("fbksd-test-technique"));
    let (a, b, doubled) =
        (box_filter("a", "box-filter"), box_filter("b", "box-filter"), box_filter("doubled", "box-filter-doubled"));
    let scene = scene.to_str().unwrap();
    let (ok, _, err) =
        fbksd(&["run", "-t", &a, "-t", &b, "-t", &doubled, "-s", scene, "--repeats", "3", "--results", r]);
    assert!(ok, "{err}");
    let s = dir.path().join("scenes");
    let (ok, _, err) =
        fbksd(&["results", "compute", "--results", r, "--scenes", s.to_str().unwrap(), "--metrics", "MSE"]);
    assert!(ok, "{err}");
    let index: serde_json::Value = serde_json::from_slice(&std::fs::read(results.join("index.json")).unwrap()).unwrap();
    let rank = |kind: &str, t: &str| {
        let standings = index["rankings"][kind]["standings"].as_array().unwrap();
        standings.iter().find(|s| s["technique"] == t).unwrap()["mean_rank"].as_f64().unwrap()
    };
    let runs = index["runs"].as_array().unwrap();
    let costs: Vec<String> = runs
        .iter()
        .map(|run| {
            let cpu: Vec<String> =
                run["repeats"].as_array().unwrap().iter().map(|p| format!("{:.1}", p["technique_cpu_ms"])).collect();
            format!("{} {} spp: technique CPU {}", run["technique"], run["spp"], cpu.join("/"))
        })
        .collect();
    // The index records the costs the ranking charged, one per run and seed.
    let charged = index["rankings"]["costs"].as_array().unwrap();
    assert_eq!(charged.len(), runs.len());
    assert!(charged.iter().all(|c| c["by_seed"].as_object().unwrap().len() == 3), "{charged:?}");
    let cells = &index["rankings"]["equal_time"]["cells"];
    for t in ["a", "b", "doubled"] {
        assert_eq!(rank("equal_spp", t), 2.0, "the same images tie at equal samples");
    }
    assert_eq!(rank("equal_time", "a"), rank("equal_time", "b"), "copies tie at equal time: {costs:?}\n{cells}");
    assert!(rank("equal_time", "doubled") > rank("equal_time", "a"), "doubled work ranks below: {costs:?}\n{cells}");
}

/// More seeds where they decide (`fbksd run --max-repeats`): a box filter
/// whose error moves by a seed-dependent few per cent ties the box filter
/// on three seeds (t = 2.0 where 4.3 would show a difference), so the runs
/// behind that tie are made again, three seeds to six to twelve, where the
/// difference shows (t = 2.8 > 2.2) and it ranks below at equal samples.
/// The copies' equal values never ask for a seed.
#[test]
fn more_seeds_settle_a_tie_too_close_to_call() {
    let dir = tempfile::tempdir().unwrap();
    let scene = bands_scene(dir.path());
    let results = dir.path().join("results");
    let r = results.to_str().unwrap();
    let technique = |name: &str, mode: &str| format!("{name}={} {mode}", bin("fbksd-test-technique"));
    let (a, b, jittered) =
        (technique("a", "box-filter"), technique("b", "box-filter"), technique("jittered", "box-filter-jittered 0.03"));
    let scene = scene.to_str().unwrap();
    let run = ["run", "-t", &a, "-t", &b, "-t", &jittered, "-s", scene, "--repeats", "3", "--results", r];
    let (ok, _, err) = fbksd(&[&run[..], &["--max-repeats", "12", "--metrics", "MSE"]].concat());
    assert!(ok, "{err}");
    assert!(err.contains("bands MSE at 4 spp: a ~ jittered"), "{err}");
    assert!(err.contains("bands MSE at 16 spp: a ~ jittered"), "{err}");
    assert!(err.contains("more seeds: 2 rounds"), "three seeds to six to twelve: {err}");
    assert!(!err.contains("MSE at 4 spp: a ~ b") && !err.contains("MSE at 16 spp: a ~ b"), "{err}");
    let s = dir.path().join("scenes");
    let (ok, _, err) =
        fbksd(&["results", "compute", "--results", r, "--scenes", s.to_str().unwrap(), "--metrics", "MSE"]);
    assert!(ok, "{err}");
    let index: serde_json::Value = serde_json::from_slice(&std::fs::read(results.join("index.json")).unwrap()).unwrap();
    for run in index["runs"].as_array().unwrap() {
        assert_eq!(run["repeats"].as_array().unwrap().len(), 12, "every run ties with jittered: {}", run["technique"]);
    }
    for cell in index["rankings"]["equal_spp"]["cells"].as_array().unwrap() {
        let place =
            |t: &str| cell["places"].as_array().unwrap().iter().find(|p| p["technique"] == t).unwrap()["place"].clone();
        assert_eq!((place("a"), place("b"), place("jittered")), (1.5.into(), 1.5.into(), 3.0.into()), "{cell}");
    }
}
