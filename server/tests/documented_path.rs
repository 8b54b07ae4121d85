//! The researcher's loop exactly as README starts it: the real
//! `fbksd-server` binary with no configuration, in a fresh working
//! directory (so its data directory is the default, relative
//! `fbksd-data`), driven with real `git` and a runner speaking the real
//! runner API.
//!
//! Regression: every push once did nothing on this path. The bare
//! repositories got `core.hooksPath = fbksd-data/git-hooks`, which git
//! resolves inside each repository, so no hook ever ran; every other test
//! gave the server an absolute data directory and did not see it.

mod common;

use common::{commit_all, git, json_of, push, technique_repository, Captured, FakeRunner, TestServer};
use reqwest::Method;
use serde_json::{json, Value};
use std::process::Command;
use std::time::{Duration, Instant};

/// The server process and everything it printed.
struct ServerProcess(Captured);

impl ServerProcess {
    /// `fbksd-server` as README runs it, in `dir`. Only the port differs
    /// from the defaults (port 0: tests run side by side; the server prints
    /// the URL it bound).
    fn start(dir: &std::path::Path) -> ServerProcess {
        let mut command = Command::new(env!("CARGO_BIN_EXE_fbksd-server"));
        for (key, _) in std::env::vars() {
            if key.starts_with("FBKSD_SERVER_") {
                command.env_remove(key);
            }
        }
        command.current_dir(dir).env("FBKSD_SERVER_BIND", "127.0.0.1:0");
        ServerProcess(Captured::spawn(command))
    }

    fn output(&self) -> String {
        self.0.output()
    }

    fn line_with(&self, text: &str) -> String {
        self.0.line_with(text, Duration::from_secs(60))
    }
}

impl Drop for ServerProcess {
    fn drop(&mut self) {
        let _ = self.0.child.kill();
        let _ = self.0.child.wait();
    }
}

/// The text after `marker` on `line`, up to the next space.
fn word_after(line: &str, marker: &str) -> String {
    line.split_once(marker).unwrap().1.split_whitespace().next().unwrap().to_string()
}

/// Registers `email` as a newcomer does: the verification link comes from
/// the server's output (where README says to look), then logs in and
/// makes an access token.
async fn newcomer(server: &TestServer, process: &ServerProcess, email: &str) -> common::TestUser {
    let browser = server.browser();
    let created = browser
        .post(format!("{}/api/v1/accounts", server.url))
        .json(&json!({ "email": email, "password": "a long enough password" }))
        .send()
        .await
        .unwrap();
    assert_eq!(created.status(), 201);
    process.line_with(&format!("mail to {email}"));
    let deadline = Instant::now() + Duration::from_secs(10);
    let link = loop {
        // The link printed after this mail's line.
        let output = process.output();
        let (_, after) = output.rsplit_once(&format!("mail to {email}")).unwrap();
        if let Some(line) = after.lines().find(|l| l.contains("link: ") && l.contains("/accounts/verify?token=")) {
            break word_after(line, "link: ");
        }
        assert!(Instant::now() < deadline, "no verification link printed:\n{output}");
        std::thread::sleep(Duration::from_millis(50));
    };
    let page = browser.get(&link).send().await.unwrap();
    assert_eq!(page.status(), 200);
    let page = page.text().await.unwrap();
    assert!(page.contains("Address confirmed") && page.contains("href=\"/login\""), "{page}");
    server.log_in(email, "a long enough password", browser).await
}

async fn project_jobs(server: &TestServer, user: &common::TestUser, name: &str) -> Vec<Value> {
    common::project_jobs(server, user, name).await
}

/// The job ids in a push's `remote:` lines, in order.
fn job_links(output: &str, server: &TestServer) -> Vec<String> {
    output
        .lines()
        .filter(|l| l.starts_with("remote: FBKSD:"))
        .filter_map(|l| l.split_once(&format!("{}/jobs/", server.url)))
        .map(|(_, id)| id.trim().to_string())
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pushes_start_pipelines_on_the_documented_path() {
    let dir = tempfile::tempdir().unwrap();
    let process = ServerProcess::start(dir.path());
    let url = word_after(&process.line_with("FBKSD server: "), "FBKSD server: ");
    let server = TestServer::at(url.clone(), dir.path().join("fbksd-data/outbox"));
    // The start-up output tells a newcomer where to go and where mail is.
    process.line_with(&format!("Open {url}/register"));
    process.line_with("Mail goes to the file outbox ");
    let registration_token = word_after(&process.line_with("runner registration token: "), "token: ");
    let data = std::fs::canonicalize(dir.path().join("fbksd-data")).unwrap();
    assert!(process.output().contains(&format!("(data in {})", data.display())), "{}", process.output());

    let ada = newcomer(&server, &process, "ada@example.org").await;
    let project = server.create_project(&ada, "box", "private").await;
    let repository = dir.path().join("fbksd-data/git");
    let config = format!("{}.git/config", project["id"].as_str().unwrap());
    let hooks = common::git(&repository, &["config", "--file", &config, "core.hooksPath"]);
    let hooks = String::from_utf8_lossy(&hooks.stdout).trim().to_string();
    assert!(std::path::Path::new(&hooks).is_absolute(), "core.hooksPath {hooks:?} must be absolute");

    // A plain push: a build job, named in the push's output.
    let repo = technique_repository("box-filter-cpp");
    let remote = server.clone_url("box", &ada.token);
    let (pushed, output) = push(repo.path(), &remote, &[]);
    assert!(pushed, "{output}");
    let jobs = project_jobs(&server, &ada, "box").await;
    assert_eq!(jobs.len(), 1, "a plain push starts a build job: {output}");
    assert_eq!((jobs[0]["kind"].as_str(), jobs[0]["state"].as_str()), (Some("build"), Some("queued")));
    assert_eq!(job_links(&output, &server), [jobs[0]["id"].as_str().unwrap()], "{output}");
    assert!(output.contains("remote: FBKSD: build of main at "), "{output}");

    // A new commit with FBKSD_RUN: a benchmark job.
    commit_all(repo.path(), "second");
    let (pushed, output) = push(repo.path(), &remote, &["FBKSD_RUN"]);
    assert!(pushed, "{output}");
    let jobs = project_jobs(&server, &ada, "box").await;
    let benchmark = jobs.iter().find(|j| j["kind"] == "benchmark").unwrap_or_else(|| panic!("{jobs:?}\n{output}"));
    assert_eq!(job_links(&output, &server), [benchmark["id"].as_str().unwrap()], "{output}");
    assert!(output.contains("private results link"), "{output}");

    // A runner (the real API, with the printed registration token) does both jobs.
    let runner = FakeRunner::register_with(&server, "runner", &registration_token).await;
    let build = runner.claim(5).await.expect("the build job is handed out");
    assert_eq!(build.body["job"]["kind"], "build");
    assert_eq!(build.finish(&runner, json!({ "state": "succeeded" })).await.0, 200);
    let run = runner.claim(5).await.expect("the benchmark job is handed out");
    assert_eq!(run.id, benchmark["id"].as_str().unwrap());
    common::upload_results(&runner, &run, 1.0).await;
    let (status, body) = run.finish(&runner, json!({ "state": "succeeded" })).await;
    assert_eq!(status, 200, "{body}");
    let result = body["result_id"].as_str().unwrap().to_string();

    // FBKSD_PUBLISH of someone else's result: the push lands, nothing is published.
    let bob = newcomer(&server, &process, "bob@example.org").await;
    server.create_project(&bob, "bobs", "public").await;
    let bobs = technique_repository("box-filter-python");
    let (pushed, output) =
        push(bobs.path(), &server.clone_url("bobs", &bob.token), &[&format!("FBKSD_PUBLISH={result}")]);
    assert!(pushed, "{output}");
    assert!(output.contains("remote: FBKSD: publish of main at") && output.contains("failed"), "{output}");
    let board = json_of(reqwest::get(format!("{url}/api/v1/leaderboard")).await.unwrap()).await.1;
    assert!(!board.to_string().contains(&result), "not published by another user: {board}");

    // FBKSD_PUBLISH of one's own result (with a new commit): on the board.
    commit_all(repo.path(), "third");
    let (pushed, output) = push(repo.path(), &remote, &[&format!("FBKSD_PUBLISH={result}")]);
    assert!(pushed, "{output}");
    assert!(output.contains(&format!("published {url}/results/{result}")), "{output}");
    let board = json_of(reqwest::get(format!("{url}/api/v1/leaderboard")).await.unwrap()).await.1;
    assert!(board.to_string().contains(&result), "published: {board}");

    // An unknown option, and two requests at once: refused, the rule named.
    commit_all(repo.path(), "fourth");
    let (pushed, output) = push(repo.path(), &remote, &["FBKSD_RUNN"]);
    assert!(!pushed, "{output}");
    assert!(output.contains("unknown push option 'FBKSD_RUNN'"), "{output}");
    assert!(output.contains("FBKSD_RUN (build and benchmark) and FBKSD_PUBLISH=<uuid>"), "{output}");
    let (pushed, output) = push(repo.path(), &remote, &["FBKSD_RUN", &format!("FBKSD_PUBLISH={result}")]);
    assert!(!pushed, "{output}");
    assert!(output.contains("FBKSD_RUN and FBKSD_PUBLISH cannot be combined"), "{output}");
    let (status, body) = json_of(
        ada.api(Method::POST, format!("{url}/api/v1/projects/box/pipelines"))
            .json(&json!({ "variables": { "FBKSD_RUN": "1", "FBKSD_PUBLISH": result } }))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(status, 400, "{body}");
    assert!(output.contains(body["message"].as_str().unwrap()), "the hook and the API say the same: {body}");
    let before = project_jobs(&server, &ada, "box").await.len();
    assert_eq!(before, 3, "refused pushes start nothing");
    let head = String::from_utf8_lossy(&git(repo.path(), &["rev-parse", "HEAD~1"]).stdout).trim().to_string();
    let remote_head = String::from_utf8_lossy(&git(repo.path(), &["ls-remote", &remote, "main"]).stdout).to_string();
    assert!(remote_head.starts_with(&head), "refused pushes move no ref: {remote_head} vs {head}");

    // A repository an older server set up with a relative hooks path is repaired at the next start.
    drop(process);
    assert!(git(&repository, &["config", "--file", &config, "core.hooksPath", "fbksd-data/git-hooks"])
        .status
        .success());
    let process = ServerProcess::start(dir.path());
    let url = word_after(&process.line_with("FBKSD server: "), "FBKSD server: ");
    let server = TestServer::at(url, dir.path().join("fbksd-data/outbox"));
    let hooks = git(&repository, &["config", "--file", &config, "core.hooksPath"]);
    assert!(std::path::Path::new(String::from_utf8_lossy(&hooks.stdout).trim()).is_absolute());
    let (pushed, output) = push(repo.path(), &server.clone_url("box", &ada.token), &[]);
    assert!(pushed, "{output}");
    assert_eq!(job_links(&output, &server).len(), 1, "the repaired repository starts a build: {output}");
}
