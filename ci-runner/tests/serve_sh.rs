//! `deploy/serve.sh`, the script README tells users to run, end to end:
//! server and runner from the script, its relative data directory, real
//! Docker and real git. The service answers before the runner is ready;
//! the C++ box filter goes from push to its private results page, ahead of
//! the baselines the first start submits, which are then published and
//! shown beside it. Options keep it small for CI: the debug build the tests
//! already made, one scene at 1 and 4 spp, one baseline, and a port of its
//! own. Prints the times (see README).

mod common;

use common::*;
use std::os::unix::process::CommandExt;
use std::process::Command;
use std::time::{Duration, Instant};

/// `bash deploy/serve.sh` in its own process group, and what it printed.
struct Serve(Captured);

impl Serve {
    fn start(env: &[(&str, String)]) -> Serve {
        let mut command = Command::new("bash");
        command.arg("deploy/serve.sh").current_dir(workspace()).process_group(0);
        for (key, _) in std::env::vars() {
            if key.starts_with("FBKSD_") {
                command.env_remove(key);
            }
        }
        for (key, value) in env {
            command.env(key, value);
        }
        Serve(Captured::spawn(command))
    }

    fn output(&self) -> String {
        self.0.output()
    }

    /// Stops it as Ctrl-C would (SIGINT to its process group); whether it ended in time.
    fn interrupt(&mut self) -> bool {
        unsafe { libc::kill(-(self.0.child.id() as i32), libc::SIGINT) };
        let deadline = Instant::now() + Duration::from_secs(30);
        while Instant::now() < deadline {
            if self.0.child.try_wait().ok().flatten().is_some() {
                return true;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        false
    }
}

impl Drop for Serve {
    fn drop(&mut self) {
        unsafe { libc::kill(-(self.0.child.id() as i32), libc::SIGKILL) };
        let _ = self.0.child.wait();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn serve_sh_takes_a_push_to_its_private_results_page() {
    // A fresh, relative data directory under the workspace, as README's default is.
    let data_rel = "target/serve-sh-test/fbksd-data";
    let _ = std::fs::remove_dir_all(workspace().join("target/serve-sh-test"));
    // The scene without its reference, so the runner makes it (other tests share the workspace's).
    let scene_root = workspace().join("target/serve-sh-test/scenes");
    let sphere = scene_root.join("experimental/sphere");
    std::fs::create_dir_all(&sphere).unwrap();
    for entry in std::fs::read_dir(workspace().join("scenes/experimental/sphere")).unwrap() {
        let path = entry.unwrap().path();
        if !path.file_name().unwrap().to_string_lossy().starts_with("reference") {
            std::fs::copy(&path, sphere.join(path.file_name().unwrap())).unwrap();
        }
    }
    // One baseline of the list serve.sh submits by default.
    let baselines = workspace().join("target/serve-sh-test/baselines.txt");
    std::fs::write(&baselines, format!("{}\n", workspace().join("sdk/techniques/gaussian-filter").display())).unwrap();
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let url = format!("http://127.0.0.1:{port}");
    let started = Instant::now();
    let mut serve = Serve::start(&[
        ("FBKSD_PROFILE", "debug".into()),
        ("FBKSD_DATA_DIR", data_rel.into()),
        ("FBKSD_SERVER_BIND", format!("127.0.0.1:{port}")),
        ("FBKSD_CI_SCENES", "experimental/sphere".into()),
        ("FBKSD_CI_SCENE_ROOT", scene_root.display().to_string()),
        ("FBKSD_CI_SPP", "1,4".into()),
        ("FBKSD_CI_RUN_TIMEOUT", "60s".into()),
        ("FBKSD_BASELINES", baselines.display().to_string()),
        ("RUST_LOG", "info".into()),
    ]);
    serve.0.line_with(&format!("FBKSD server: {url}"), Duration::from_secs(300));
    let answered = started.elapsed();
    let home = reqwest::get(format!("{url}/")).await.unwrap().text().await.unwrap();
    assert!(home.contains("How to submit a technique"), "the empty board says how to submit:\n{home}");

    let server = TestServer::at(url.clone(), workspace().join(data_rel).join("outbox"));
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "box-filter-cpp", "private").await;
    let repo = technique_repository("box-filter-cpp");
    let remote = server.clone_url("box-filter-cpp", &ada.token);
    let (pushed, output) = push(repo.path(), &remote, &["FBKSD_RUN"]);
    assert!(pushed, "{output}");
    assert!(output.contains("remote: FBKSD: benchmark of main at"), "{output}");
    let pushed_at = Instant::now();

    let job = newest_job(&server, &ada, "box-filter-cpp", "benchmark").await;
    let ended = finished_job(&server, &ada, &job, Duration::from_secs(900)).await;
    let log = log_text(&server, &ada, &job).await;
    assert_eq!(ended["state"], "succeeded", "{ended}\n{log}\nserve.sh:\n{}", serve.output());
    let private = private_results_url(&log);
    assert!(private.starts_with(&format!("{url}/results/")), "{private}");
    let page = ada.browser.get(&private).send().await.unwrap();
    assert_eq!(page.status(), 200);
    let page = page.text().await.unwrap();
    assert!(page.contains("Box filter"), "the private page names the technique:\n{page}");
    assert_eq!(reqwest::get(&private).await.unwrap().status(), 404, "and only to its owner");

    // The page's viewer loads its document, which holds the run's image and
    // the reference it was scored against, both fetchable by the owner.
    let document = page
        .split("data-document=\"")
        .nth(1)
        .and_then(|rest| rest.split('"').next())
        .unwrap_or_else(|| panic!("the private page has no viewer:\n{page}"));
    let viewer: serde_json::Value =
        ada.browser.get(format!("{url}{document}")).send().await.unwrap().json().await.unwrap();
    let scene = &viewer["scenes"][0];
    assert_eq!(scene["name"], "sphere", "{viewer}");
    let run = viewer["techniques"][0]["runs"]
        .as_array()
        .and_then(|runs| runs.iter().find(|run| run["spp"] == 4))
        .unwrap_or_else(|| panic!("no run at 4 spp: {viewer}"));
    assert_eq!(run["status"], "ok", "{viewer}");
    // The service's default: each run made with three sample seeds, so its
    // values carry intervals and the ranking its ties.
    assert_eq!(run["seeds"], 3, "{run}");
    assert!(run["intervals"]["MSE"]["low"].as_f64() < run["intervals"]["MSE"]["high"].as_f64(), "{run}");
    assert!(log.contains("sphere at 4 spp (seed 2)"), "{log}");
    assert!(!viewer["rankings"]["equal_time"].as_array().unwrap().is_empty(), "{viewer}");
    for file in [&run["pixels"], &scene["reference"]] {
        let file = file.as_str().unwrap_or_else(|| panic!("a pixel file is missing: {viewer}"));
        let fetched = ada.browser.get(format!("{url}{file}")).send().await.unwrap();
        assert_eq!(fetched.status(), 200, "{file}");
        assert!(fetched.bytes().await.unwrap().len() > 20, "{file} is empty");
    }
    // The baselines waited for Ada's job, then went on the board, and her
    // page now shows them beside her technique.
    let deadline = Instant::now() + Duration::from_secs(600);
    let board = loop {
        let board = reqwest::get(format!("{url}/api/v1/leaderboard")).await.unwrap().text().await.unwrap();
        if board.contains("gaussian-filter") || Instant::now() > deadline {
            break board;
        }
        tokio::time::sleep(Duration::from_secs(2)).await;
    };
    assert!(board.contains("gaussian-filter"), "no baseline on the board:\n{board}\n{}", serve.output());
    // The log line may trail the board by a moment.
    serve.0.line_with("baselines: gaussian-filter published", Duration::from_secs(30));
    let viewer: serde_json::Value =
        ada.browser.get(format!("{url}{document}")).send().await.unwrap().json().await.unwrap();
    let names: Vec<&str> = viewer["techniques"].as_array().unwrap().iter().filter_map(|t| t["name"].as_str()).collect();
    assert!(names.contains(&"gaussian-filter"), "the private page's viewer lacks the baseline: {names:?}");

    eprintln!(
        "FIGURE serve.sh: answered {:.1} s after start; push (FBKSD_RUN) to private results {:.1} s",
        answered.as_secs_f64(),
        pushed_at.elapsed().as_secs_f64()
    );

    // The runner made the missing reference before it took the job.
    assert!(serve.output().contains("making reference 1 of 1: experimental/sphere"), "{}", serve.output());
    assert!(sphere.join("reference.exr").is_file());

    // Ctrl-C stops the server and the runner.
    assert!(serve.interrupt(), "serve.sh did not stop on Ctrl-C:\n{}", serve.output());
    assert!(std::net::TcpStream::connect(("127.0.0.1", port)).is_err(), "the server still answers");
    let left = Command::new("pgrep").args(["-f", "target/serve-sh-test"]).output().unwrap();
    assert!(left.stdout.is_empty(), "processes left: {}", String::from_utf8_lossy(&left.stdout));
}
