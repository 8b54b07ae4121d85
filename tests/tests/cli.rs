//! `fbksd run` as a user types it.

use fbksd_tests::{analytic_scene, bin, scene_meta};
use std::process::Command;

#[test]
fn fbksd_run_writes_results_and_prints_a_summary() {
    let dir = tempfile::tempdir().unwrap();
    let a = analytic_scene(dir.path(), "small", 16, 8);
    let b = analytic_scene(dir.path(), "wide", 40, 4);
    let results = dir.path().join("out");
    let output = Command::new(bin("fbksd"))
        .args(["run", "--technique", &bin("box-filter"), "--renderer", &bin("fbksd-analytic-renderer")])
        .args(["--scene", a.to_str().unwrap(), "--scene", b.to_str().unwrap(), "--spp", "1,8"])
        .args(["--results", results.to_str().unwrap()])
        .output()
        .unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    assert!(output.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.lines().next().unwrap().starts_with("scene  "), "{stdout}");
    assert_eq!(stdout.lines().filter(|l| l.contains("box-filter") && l.contains(" ok ")).count(), 4, "{stdout}");
    assert!(stderr.contains("▶ small · box-filter · 8 spp"), "{stderr}");
    for scene in ["small", "wide"] {
        for spp in [1, 8] {
            assert!(results.join(format!("box-filter/{scene}/{spp}_0.exr")).is_file());
            assert!(results.join(format!("box-filter/{scene}/{spp}_0_log.json")).is_file());
        }
    }
}

#[test]
fn fbksd_run_names_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| {
        let o = Command::new(bin("fbksd")).arg("run").args(args).current_dir(dir.path()).output().unwrap();
        (o.status.code(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    let (code, err) = run(&["-t", "x", "-r", "y", "-s", "nowhere.json"]);
    assert_ne!(code, Some(0));
    assert!(err.contains("scene nowhere.json does not exist"), "{err}");
    let scene = analytic_scene(dir.path(), "s", 4, 4);
    let (code, err) = run(&["-t", "x", "-s", scene.to_str().unwrap()]);
    assert_ne!(code, Some(0));
    assert!(err.contains("has no metadata: say which renderer loads it with --renderer"), "{err}");
    let (code, err) = run(&["-t", "x", "-r", "y", "-s", scene.to_str().unwrap(), "--spp", "0"]);
    assert_ne!(code, Some(0));
    assert!(err.contains("--spp takes positive budgets"), "{err}");
    // A technique that cannot start: the run is recorded and the exit code says so.
    let (code, err) = run(&[
        "-t",
        "/no/such/technique",
        "-r",
        &bin("fbksd-analytic-renderer"),
        "-s",
        scene.to_str().unwrap(),
        "--spp",
        "1",
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("launch_failed") && err.contains("/no/such/technique"), "{err}");
}

#[test]
fn killing_fbksd_run_takes_its_technique_and_renderer_along() {
    let dir = tempfile::tempdir().unwrap();
    let scene = analytic_scene(dir.path(), "s", 8, 8);
    // A unique argument lets pgrep find exactly this test's technique.
    let marker = format!("marker-{}", std::process::id());
    let technique = format!("{} hang {marker}", bin("fbksd-test-technique"));
    let mut fbksd = Command::new(bin("fbksd"))
        .args(["run", "-t", &technique, "-r", &bin("fbksd-analytic-renderer"), "-s", scene.to_str().unwrap()])
        .args(["--spp", "1", "--time-limit", "60s", "--results", dir.path().join("r").to_str().unwrap()])
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let running = || Command::new("pgrep").args(["-f", &marker]).output().unwrap().status.success();
    let until = |want: bool| {
        for _ in 0..100 {
            if running() == want {
                return true;
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        false
    };
    assert!(until(true), "the technique never started");
    fbksd.kill().unwrap();
    fbksd.wait().unwrap();
    assert!(until(false), "the technique outlived its manager");
}

#[test]
fn a_scene_directory_brings_its_renderer_and_budgets() {
    let dir = tempfile::tempdir().unwrap();
    let scene_dir = dir.path().join("tiny");
    std::fs::create_dir(&scene_dir).unwrap();
    analytic_scene(&scene_dir, "tiny", 6, 5);
    scene_meta(&scene_dir, "tiny", "tiny.json", "analytic", &[2, 3], 6, 5);
    let results = dir.path().join("out");
    let output = Command::new(bin("fbksd"))
        .args([
            "run",
            "-t",
            &bin("box-filter"),
            "-s",
            scene_dir.to_str().unwrap(),
            "--results",
            results.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    assert!(results.join("box-filter/tiny/2_0.exr").is_file() && results.join("box-filter/tiny/3_0.exr").is_file());
    // The procedural scenes of the pool run the same way.
    let sphere = format!("{}/../scenes/experimental/sphere", env!("CARGO_MANIFEST_DIR"));
    let output = Command::new(bin("fbksd"))
        .args(["run", "-t", &bin("box-filter"), "-s", &sphere, "--spp", "1", "--results", results.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let (w, h, _) = fbksd_iqa::image::read_exr(&results.join("box-filter/sphere/1_0.exr")).unwrap();
    assert_eq!((w, h), (500, 500));
}

#[test]
fn two_fbksd_run_processes_at_once_on_one_host() {
    let dir = tempfile::tempdir().unwrap();
    let scene = analytic_scene(dir.path(), "both", 30, 20);
    let runs: Vec<_> = (0..2)
        .map(|i| {
            Command::new(bin("fbksd"))
                .args([
                    "run",
                    "-t",
                    &bin("box-filter"),
                    "-r",
                    &bin("fbksd-analytic-renderer"),
                    "-s",
                    scene.to_str().unwrap(),
                ])
                .args(["--spp", "1,16", "--results", dir.path().join(format!("r{i}")).to_str().unwrap()])
                .stderr(std::process::Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    for (i, run) in runs.into_iter().enumerate() {
        let out = run.wait_with_output().unwrap();
        assert!(out.status.success(), "run {i}: {}", String::from_utf8_lossy(&out.stderr));
        assert!(dir.path().join(format!("r{i}/box-filter/both/16_0.exr")).is_file());
    }
}
