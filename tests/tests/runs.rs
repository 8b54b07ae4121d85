//! End-to-end runs through real processes: manager, analytic renderer and
//! techniques, each scenario a user could meet.

use fbksd_iqa::image::read_exr;
use fbksd_manager::{Benchmark, Limits, RunRecord, RunStatus, SceneRunner, SceneSpec, TechniqueLaunch, TechniqueSpec};
use fbksd_tests::{analytic_scene, bin, renderer_argv};
use std::path::Path;
use std::time::Duration;

fn technique(mode: &str) -> TechniqueSpec {
    TechniqueSpec { name: mode.into(), argv: vec![bin("fbksd-test-technique"), mode.into()] }
}

fn limits(seconds: u64) -> Limits {
    Limits { time_limit: Some(Duration::from_secs(seconds)), ..Limits::default() }
}

/// Runs techniques on one analytic scene and returns the records.
fn bench(dir: &Path, techniques: Vec<TechniqueSpec>, spps: &[u64], flags: &[&str], limit_s: u64) -> Vec<RunRecord> {
    let scene = analytic_scene(dir, "analytic", 37, 23);
    Benchmark {
        techniques,
        scenes: vec![SceneSpec {
            name: "analytic".into(),
            renderer_argv: renderer_argv(&scene, flags),
            spps: spps.to_vec(),
        }],
        results: dir.join("results"),
        limits: limits(limit_s),
        launcher: std::sync::Arc::new(fbksd_manager::LocalLauncher),
        repeats: 1,
    }
    .run(|_| {})
    .unwrap()
}

fn assert_status(r: &RunRecord, status: RunStatus, message_part: &str) {
    assert_eq!(r.status, status, "{} at {} spp: {}", r.technique, r.spp_budget, r.message);
    assert!(r.message.contains(message_part), "message {:?} lacks {message_part:?}", r.message);
}

#[test]
fn every_layout_element_arrives_intact_and_the_result_is_saved() {
    let dir = tempfile::tempdir().unwrap();
    let records = bench(dir.path(), vec![technique("all-elements")], &[1, 5], &[], 60);
    for r in &records {
        assert_status(r, RunStatus::Ok, "");
        assert_eq!(r.used_samples, r.samples_budget);
        assert_eq!(r.samples_budget, r.spp_budget * 37 * 23);
        assert!(r.times.technique_ms > 0.0 && r.times.render_ms > 0.0 && r.times.cpu_ms > 0.0);
        assert!(r.peak_memory_bytes > 0);
    }
    // The box filter of the analytic colour: red and green are exact per pixel.
    let image = dir.path().join("results/all-elements/analytic/5_0.exr");
    let (w, h, rgb) = read_exr(&image).unwrap();
    assert_eq!((w, h), (37, 23));
    for y in 0..h {
        for x in 0..w {
            let p = ((y * w + x) * 3) as usize;
            assert!((rgb[p] - (x as f32 + 0.5) / 37.0).abs() < 1e-6);
            assert!((rgb[p + 1] - (y as f32 + 0.5) / 23.0).abs() < 1e-6);
            assert!((0.0..1.0).contains(&rgb[p + 2]));
        }
    }
    // Logs keep the original's fields, and the index lists both runs.
    let log: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("results/all-elements/analytic/5_0_log.json")).unwrap())
            .unwrap();
    for key in ["date", "spp_budget", "samples_budget", "used_samples", "aborted", "exec_time", "status", "times"] {
        assert!(log.get(key).is_some(), "log lacks {key}");
    }
    let index: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("results/index.json")).unwrap()).unwrap();
    assert_eq!(index["runs"].as_array().unwrap().len(), 2);
    assert_eq!(index["runs"][1]["image"], "all-elements/analytic/5_0.exr");
}

#[test]
fn budget_is_spent_exactly_across_requests_of_every_kind() {
    let dir = tempfile::tempdir().unwrap();
    let records = bench(dir.path(), vec![technique("exact-budget")], &[3], &[], 60);
    assert_status(&records[0], RunStatus::Ok, "");
    assert_eq!(records[0].used_samples, 3 * 37 * 23);
    assert_eq!(records[0].requests, 3);
}

#[test]
fn a_request_beyond_the_budget_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let records = bench(dir.path(), vec![technique("over-budget")], &[2], &[], 60);
    assert_status(&records[0], RunStatus::OverBudget, "requested 1 samples but only 0 of the budget of 1702");
    assert!(records[0].aborted);
}

#[test]
fn input_parameters_are_honoured_in_spp_and_count_requests() {
    let dir = tempfile::tempdir().unwrap();
    let records = bench(dir.path(), vec![technique("input-spp"), technique("input-count")], &[4], &[], 60);
    for r in &records {
        assert_status(r, RunStatus::Ok, "");
    }
}

#[test]
fn misbehaving_techniques_get_typed_statuses_and_the_benchmark_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let techniques = ["crash", "hang", "no-result", "nan-result", "wrong-size", "duplicate-layout", "all-elements"]
        .into_iter()
        .map(technique)
        .collect();
    let records = bench(dir.path(), techniques, &[2], &[], 3);
    let by = |name: &str| records.iter().find(|r| r.technique == name).unwrap();
    assert_status(by("crash"), RunStatus::Crashed, "signal 6 (SIGABRT)");
    assert_status(by("hang"), RunStatus::Timeout, "time limit of 3s");
    assert_status(by("no-result"), RunStatus::NoResult, "without sending a result");
    assert_status(by("nan-result"), RunStatus::InvalidOutput, "1 NaN or infinite values (first at pixel x=1, y=0)");
    assert!(dir.path().join("results/nan-result/analytic/2_0.exr").is_file(), "invalid image kept for inspection");
    assert_status(by("wrong-size"), RunStatus::InvalidOutput, "the result is 1×1×3 but the scene is 37×23×3");
    assert_status(
        by("duplicate-layout"),
        RunStatus::InvalidLayout,
        "layout element 2 (\"COLOR_R\", number 0): duplicate",
    );
    // The renderer survived all of that.
    assert_status(by("all-elements"), RunStatus::Ok, "");
    // A hung technique's time is not free: it is charged up to the limit.
    assert!(by("hang").times.technique_ms >= 2900.0);
}

#[test]
fn a_crashing_renderer_fails_its_run_and_is_restarted_for_the_next() {
    let dir = tempfile::tempdir().unwrap();
    let records = bench(dir.path(), vec![technique("all-elements")], &[1, 2, 4], &["--fault", "crash-at-spp=2"], 60);
    assert_status(&records[0], RunStatus::Ok, "");
    assert_status(&records[1], RunStatus::RendererFailed, "the renderer died (killed by signal 6 (SIGABRT))");
    assert_status(&records[2], RunStatus::Ok, "");
}

#[test]
fn a_renderer_that_delivers_too_few_samples_or_none_is_blamed() {
    let dir = tempfile::tempdir().unwrap();
    let short = bench(dir.path(), vec![technique("all-elements")], &[1], &["--fault", "short"], 60);
    assert_status(&short[0], RunStatus::RendererFailed, "finished a request with");
    let dir = tempfile::tempdir().unwrap();
    let twice = bench(dir.path(), vec![technique("all-elements")], &[1], &["--fault", "duplicate"], 60);
    assert_status(&twice[0], RunStatus::RendererFailed, "pixel (0, 0) is in two tiles of the same request");
    let dir = tempfile::tempdir().unwrap();
    let hang = bench(dir.path(), vec![technique("all-elements")], &[1], &["--fault", "hang"], 2);
    assert_status(&hang[0], RunStatus::RendererFailed, "while the technique waited for the renderer");
    let dir = tempfile::tempdir().unwrap();
    let dead = bench(dir.path(), vec![technique("all-elements")], &[1, 2], &["--fault", "exit-at-start"], 60);
    assert_status(&dead[0], RunStatus::RendererFailed, "exited (exit code 3) before it was ready");
    assert!(dead[1].message.contains("exiting at start as asked"), "renderer log quoted: {}", dead[1].message);
}

#[test]
fn two_runs_at_once_on_one_host_do_not_interfere() {
    let handles: Vec<_> = (0..2)
        .map(|_| {
            std::thread::spawn(|| {
                let dir = tempfile::tempdir().unwrap();
                bench(dir.path(), vec![technique("all-elements")], &[3], &[], 60)
            })
        })
        .collect();
    for h in handles {
        let records = h.join().unwrap();
        assert_status(&records[0], RunStatus::Ok, "");
    }
}

#[test]
fn a_technique_started_by_hand_in_debug_mode_runs_and_writes_its_image() {
    let dir = tempfile::tempdir().unwrap();
    let scene = analytic_scene(dir.path(), "debug", 20, 10);
    let out = dir.path().join("debug.exr");
    let output = std::process::Command::new(bin("box-filter"))
        .args(["--fbksd-renderer", &shell_words::join(renderer_argv(&scene, &[]))])
        .args(["--fbksd-spp", "3", "--fbksd-output", out.to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(stderr.contains("fbksd debug: ok — 600 of 600 samples"), "{stderr}");
    let (w, h, rgb) = read_exr(&out).unwrap();
    assert_eq!((w, h), (20, 10));
    assert!((rgb[3] - 1.5 / 20.0).abs() < 1e-6);
}

#[test]
fn a_technique_started_by_hand_without_a_manager_says_how_to_run_it() {
    let output = std::process::Command::new(bin("box-filter")).env_remove("FBKSD_RENDEZVOUS").output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(stderr.contains("fbksd run") && stderr.contains("--fbksd-renderer"), "{stderr}");
}

#[test]
fn a_scene_runner_serves_an_external_technique() {
    // The in-process manager that debug mode uses, driven directly.
    let dir = tempfile::tempdir().unwrap();
    let scene = analytic_scene(dir.path(), "ext", 8, 8);
    let mut runner = SceneRunner::new(renderer_argv(&scene, &[]), None, limits(60)).unwrap();
    let rendezvous = runner.dir().to_path_buf();
    let client = std::thread::spawn(move || {
        let mut c = fbksd_client::BenchmarkClient::connect_to(&rendezvous).unwrap();
        c.set_sample_layout(&fbksd_client::SampleLayout::new().with("COLOR_R")).unwrap();
        c.evaluate_samples(fbksd_client::Spp(2), |_| {}).unwrap();
        c.send_result().unwrap();
    });
    let outcome = runner.run(2, &TechniqueLaunch::External, &dir.path().join("log"));
    client.join().unwrap();
    assert_eq!(outcome.status, RunStatus::Ok, "{}", outcome.message);
    assert_eq!(outcome.used_samples, 128);
    assert!(runner.finish().is_some(), "the renderer exits when told to finish");
}

#[test]
fn a_renderer_stuck_on_the_layout_is_blamed_and_replaced() {
    let dir = tempfile::tempdir().unwrap();
    let records = bench(dir.path(), vec![technique("all-elements")], &[1, 2], &["--fault", "hang-layout"], 2);
    for r in &records {
        assert_status(r, RunStatus::RendererFailed, "while the renderer was still accepting the layout");
        // Waiting for the renderer is not the technique's time.
        assert!(r.times.technique_ms < 1000.0, "technique charged {} ms", r.times.technique_ms);
    }
}

#[test]
fn a_connection_without_the_session_token_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let records = bench(dir.path(), vec![technique("no-token")], &[1], &[], 60);
    assert_status(&records[0], RunStatus::NoResult, "");
    let log = std::fs::read_to_string(dir.path().join("results/no-token/analytic/1_0_technique.log")).unwrap();
    assert!(log.contains("FBKSD_SESSION missing or wrong"), "{log}");
}

/// Work a technique does while it holds no tile is its own time: burning
/// CPU in another thread while the renderer renders is charged (not hidden
/// in the renderer's time), and so is sleeping before a request; a
/// technique that merely waits is not charged for the wait.
#[test]
fn work_outside_tile_callbacks_is_charged_to_the_technique() {
    let dir = tempfile::tempdir().unwrap();
    let modes =
        ["idle-while-waiting", "burn-while-waiting", "sleep-before-request", "burn-in-child", "burn-before-hello"];
    let records = bench(dir.path(), modes.map(technique).to_vec(), &[1], &["--fault", "slow-ms=1500"], 60);
    let by = |mode: &str| records.iter().find(|r| r.technique == mode).unwrap();
    for r in &records {
        assert_status(r, RunStatus::Ok, "");
    }
    let idle = by("idle-while-waiting");
    assert!(idle.times.waiting_ms >= 1400.0, "{:?}", idle.times);
    assert!(idle.times.technique_ms < 700.0, "an idle wait is not the technique's time: {:?}", idle.times);
    assert!(idle.times.background_cpu_ms < 200.0, "{:?}", idle.times);
    assert!(idle.times.technique_cpu_ms < 300.0, "an idle wait costs nothing: {:?}", idle.times);
    // The burnt second is charged whether it overlaps the wait (as CPU time)
    // or outlasts it (as wall time, the technique then waits for its thread).
    let burn = by("burn-while-waiting");
    assert!(burn.times.background_cpu_ms >= 100.0, "the burn during the wait is seen: {:?}", burn.times);
    assert!(
        burn.times.technique_ms >= idle.times.technique_ms + 900.0,
        "the burnt second is charged: {:?} against idle {:?}",
        burn.times,
        idle.times
    );
    let sleep = by("sleep-before-request");
    assert!(sleep.times.technique_ms >= 1000.0, "a sleep outside a request is charged: {:?}", sleep.times);
    // The cost is CPU time after the hello, in every thread and child process.
    for r in [burn, by("burn-in-child")] {
        assert!(r.times.technique_cpu_ms >= 950.0, "{}'s burnt second is in its cost: {:?}", r.technique, r.times);
        assert!(r.times.render_cpu_ms > 0.0, "the renderer's CPU time is measured: {:?}", r.times);
    }
    // A second burnt before the hello is start-up: shown, not charged.
    let early = by("burn-before-hello");
    assert!(early.times.startup_ms >= 950.0, "{:?}", early.times);
    assert!(early.times.technique_cpu_ms < 300.0, "start-up is not in the cost: {:?}", early.times);
    assert!(early.times.cpu_ms >= 950.0, "the process's CPU time still shows it: {:?}", early.times);
    assert!(records.iter().all(|r| r.sample_floats == 1), "one float per sample (COLOR_R)");
}
