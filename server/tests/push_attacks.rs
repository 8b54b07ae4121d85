//! Pushes built to hurt the server: each is contained with a typed outcome
//! and a message its author can act on, and another user's push is served
//! normally in the same test.

mod common;

use common::{json_of, project_jobs, push, spawn_with, technique_repository, Db, FakeRunner, TestServer, TestUser};
use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

/// Runs git in `dir` with `input` on its standard input; its trimmed output.
fn git_with_input(dir: &Path, args: &[&str], input: &str) -> String {
    let mut child = std::process::Command::new("git")
        .current_dir(dir)
        .args(args)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("git runs");
    child.stdin.take().unwrap().write_all(input.as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "git {args:?}");
    String::from_utf8(out.stdout).unwrap().trim().to_string()
}

/// A repository whose `main` holds a valid info.json beside `bomb/`: ten
/// levels of ten directories over one file, 10¹⁰ paths in a few KB.
fn git_bomb() -> tempfile::TempDir {
    let repo = technique_repository("box-filter-python");
    let dir = repo.path();
    let blob = git_with_input(dir, &["hash-object", "-w", "--stdin"], "x\n");
    let mut tree =
        git_with_input(dir, &["mktree"], &(0..10).map(|i| format!("100644 blob {blob}\tf{i}\n")).collect::<String>());
    for _ in 0..9 {
        tree = git_with_input(
            dir,
            &["mktree"],
            &(0..10).map(|i| format!("040000 tree {tree}\td{i}\n")).collect::<String>(),
        );
    }
    let mut root = String::from_utf8(common::git(dir, &["ls-tree", "HEAD"]).stdout).unwrap();
    root.push_str(&format!("040000 tree {tree}\tbomb\n"));
    let root = git_with_input(dir, &["mktree"], &root);
    let commit =
        String::from_utf8(common::git(dir, &["commit-tree", &root, "-p", "HEAD", "-m", "bomb"]).stdout).unwrap();
    assert!(common::git(dir, &["update-ref", "refs/heads/main", commit.trim()]).status.success());
    repo
}

/// The newest job of a project.
async fn newest(server: &TestServer, user: &TestUser, project: &str) -> serde_json::Value {
    project_jobs(server, user, project).await.into_iter().next().expect("a job")
}

/// Another user's push still starts its build.
async fn others_are_served(server: &TestServer) {
    let bea = server.user("bea@example.org").await;
    server.create_project(&bea, "box-filter-cpp", "private").await;
    let repo = technique_repository("box-filter-cpp");
    let (pushed, output) = push(repo.path(), &server.clone_url("box-filter-cpp", &bea.token), &[]);
    assert!(pushed, "{output}");
    let job = newest(server, &bea, "box-filter-cpp").await;
    assert_eq!(job["state"], "queued", "{job}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_git_bomb_fails_its_job_at_once_and_its_pages_still_answer() {
    let server = spawn_with(Db::Sqlite, |_| {}).await;
    let mallory = server.user("mallory@example.org").await;
    server.create_project(&mallory, "bomb", "public").await;
    let repo = git_bomb();
    let started = Instant::now();
    let (pushed, output) = push(repo.path(), &server.clone_url("bomb", &mallory.token), &[]);
    assert!(pushed, "the push itself is small: {output}");
    let job = newest(&server, &mallory, "bomb").await;
    assert_eq!((job["state"].as_str(), job["failure_reason"].as_str()), (Some("failed"), Some("build_failed")));
    assert!(job["message"].as_str().unwrap().contains("more than 20000 files"), "{job}");
    assert!(output.contains("more than 20000 files"), "the pusher is told: {output}");
    // Reading stops at the cap: well within git's time limit, not after 10¹⁰ paths.
    assert!(started.elapsed() < Duration::from_secs(25), "{:?}", started.elapsed());
    // Its public technique page reads the repository too, and answers.
    let page = reqwest::get(format!("{}/projects/bomb", server.url)).await.unwrap();
    assert!(page.status().as_u16() < 500, "{}", page.status());
    others_are_served(&server).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_huge_info_json_is_refused_by_its_size_before_it_is_read() {
    let server = spawn_with(Db::Sqlite, |_| {}).await;
    let mallory = server.user("mallory@example.org").await;
    server.create_project(&mallory, "zeros", "private").await;
    let repo = technique_repository("box-filter-python");
    // 256 MiB of zeros: about 256 KiB once compressed, well under the push limit.
    let file = std::fs::File::create(repo.path().join("info.json")).unwrap();
    file.set_len(256 << 20).unwrap();
    common::commit_all(repo.path(), "zeros");
    let (pushed, output) = push(repo.path(), &server.clone_url("zeros", &mallory.token), &["FBKSD_RUN"]);
    assert!(pushed, "{output}");
    let job = newest(&server, &mallory, "zeros").await;
    assert_eq!((job["state"].as_str(), job["failure_reason"].as_str()), (Some("failed"), Some("build_failed")));
    assert!(job["message"].as_str().unwrap().contains("info.json is 268435456 bytes, larger than 65536"), "{job}");
    others_are_served(&server).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_symlinked_info_json_is_refused() {
    let server = spawn_with(Db::Sqlite, |_| {}).await;
    let mallory = server.user("mallory@example.org").await;
    server.create_project(&mallory, "link", "private").await;
    let repo = technique_repository("box-filter-python");
    let info = repo.path().join("info.json");
    std::fs::remove_file(&info).unwrap();
    // The server would read the link's text; a runner's checkout would follow it.
    std::os::unix::fs::symlink("/etc/fbksd/info.json", &info).unwrap();
    common::commit_all(repo.path(), "link");
    let (pushed, output) = push(repo.path(), &server.clone_url("link", &mallory.token), &[]);
    assert!(pushed, "{output}");
    let job = newest(&server, &mallory, "link").await;
    assert_eq!(job["failure_reason"], "build_failed", "{job}");
    assert!(job["message"].as_str().unwrap().contains("info.json is a symbolic link"), "{job}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_branch_flood_starts_five_pipelines_and_says_so() {
    let server = spawn_with(Db::Sqlite, |c| c.max_queued_jobs_per_user = 100).await;
    let mallory = server.user("mallory@example.org").await;
    server.create_project(&mallory, "flood", "private").await;
    let repo = technique_repository("box-filter-python");
    for i in 0..40 {
        assert!(common::git(repo.path(), &["branch", &format!("b{i}")]).status.success());
    }
    let out = common::git(repo.path(), &["push", "--porcelain", &server.clone_url("flood", &mallory.token), "--all"]);
    let output = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{output}");
    assert!(output.contains("36 more branches moved, but a push starts at most 5 pipelines"), "{output}");
    assert_eq!(project_jobs(&server, &mallory, "flood").await.len(), 5);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn builds_have_a_quota_and_runners_serve_users_in_turn() {
    let server = spawn_with(Db::Sqlite, |c| c.max_queued_jobs_per_user = 3).await;
    let mallory = server.user("mallory@example.org").await;
    server.create_project(&mallory, "many", "private").await;
    let repo = technique_repository("box-filter-python");
    for i in 0..3 {
        assert!(common::git(repo.path(), &["branch", &format!("b{i}")]).status.success());
    }
    let out = common::git(repo.path(), &["push", "--porcelain", &server.clone_url("many", &mallory.token), "--all"]);
    let output = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{output}");
    // Four branches, three queued builds allowed: the fourth is not built, and says why.
    let jobs = project_jobs(&server, &mallory, "many").await;
    let states: Vec<_> = jobs.iter().map(|j| j["state"].as_str().unwrap()).collect();
    assert_eq!(states.iter().filter(|s| **s == "queued").count(), 3, "{states:?}");
    assert_eq!(states.iter().filter(|s| **s == "cancelled").count(), 1, "{states:?}");
    assert!(output.contains("not built: you have 3 jobs queued"), "{output}");

    let (status, quota) = json_of(
        mallory
            .api(reqwest::Method::POST, format!("{}/api/v1/projects/many/pipelines", server.url))
            .json(&serde_json::json!({ "ref": "main" }))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(status, 429, "the API refuses a build over the quota: {quota}");

    // Bea queues one build after Mallory's three: the second claim is hers.
    let bea = server.user("bea@example.org").await;
    server.create_project(&bea, "one", "private").await;
    let repo = technique_repository("box-filter-python");
    assert!(push(repo.path(), &server.clone_url("one", &bea.token), &[]).0);
    let runner = FakeRunner::register(&server, "runner-1").await;
    let first = runner.claim(5).await.expect("a job");
    let second = runner.claim(5).await.expect("a job");
    let project = |job: &common::HeldJob| job.body["job"]["project"].as_str().unwrap_or_default().to_string();
    assert_eq!((project(&first), project(&second)), ("many".to_string(), "one".to_string()));
}
