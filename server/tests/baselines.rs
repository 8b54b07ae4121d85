//! `fbksd-server baselines`: the listed techniques reach the board by a
//! researcher's path (project, push with FBKSD_RUN, FBKSD_PUBLISH) under the
//! `baselines` service account, which no quota stops and whose jobs wait
//! while a user's is queued; a second run finds them published and pushes
//! nothing.

mod common;

use common::*;
use serde_json::json;
use std::time::Duration;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn baselines_are_published_by_the_push_path_behind_users_jobs_and_only_once() {
    // Quotas a single user could not get two baselines through.
    let server = spawn_with(Db::Sqlite, |c| {
        c.max_queued_jobs_per_user = 1;
        c.max_runs_per_day = 1;
    })
    .await;
    let folder = tempfile::tempdir().unwrap();
    for name in ["first-box", "second-box"] {
        let repo = technique_repository("box-filter-python");
        std::fs::create_dir(folder.path().join(name)).unwrap();
        for file in ["info.json", "box_filter.py"] {
            std::fs::copy(repo.path().join(file), folder.path().join(name).join(file)).unwrap();
        }
    }
    let list = folder.path().join("baselines.txt");
    std::fs::write(&list, "# two copies of the Python box filter\nfirst-box\nsecond-box\n").unwrap();
    let submit = |server: &TestServer| {
        let (config, list, url) = (server.config().clone(), list.clone(), server.url.clone());
        tokio::spawn(async move { fbksd_server::baselines::submit(&config, &list, Some(url)).await })
    };
    let submitting = submit(&server);

    // Both baselines are queued before Ada pushes; her job is still claimed first.
    let admin = server.admin().await;
    let queued = |jobs: &serde_json::Value| {
        jobs.as_array().unwrap().iter().filter(|j| j["kind"] == "benchmark" && j["state"] == "queued").count()
    };
    for _ in 0..100 {
        let jobs = admin.api(reqwest::Method::GET, format!("{}/api/v1/admin/jobs", server.url)).send().await.unwrap();
        if queued(&jobs.json().await.unwrap()) == 2 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    // Stopped while waiting (serve.sh's Ctrl-C) and started again: the
    // queued jobs are taken up, not pushed twice.
    submitting.abort();
    let submitting = submit(&server);
    tokio::time::sleep(Duration::from_secs(2)).await;
    let jobs = admin.api(reqwest::Method::GET, format!("{}/api/v1/admin/jobs", server.url)).send().await.unwrap();
    assert_eq!(queued(&jobs.json().await.unwrap()), 2, "a restart pushed the baselines again");

    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "ada-box", "private").await;
    let repo = technique_repository("box-filter-python");
    let (pushed, output) = push(repo.path(), &server.clone_url("ada-box", &ada.token), &["FBKSD_RUN"]);
    assert!(pushed, "{output}");

    let runner = FakeRunner::register(&server, "runner-1").await;
    let mut order = Vec::new();
    for _ in 0..3 {
        let job = runner.claim(5).await.expect("a job");
        order.push(job.body["job"]["project"].as_str().unwrap().to_string());
        upload_results(&runner, &job, 1.0).await;
        assert_eq!(job.finish(&runner, json!({ "state": "succeeded" })).await.0, 200);
    }
    assert_eq!(order, ["ada-box", "first-box", "second-box"], "users' jobs go first");
    tokio::time::timeout(Duration::from_secs(30), submitting).await.unwrap().unwrap().unwrap();

    // Both are public, owned by the service account, on the board.
    let board: serde_json::Value =
        reqwest::get(format!("{}/api/v1/leaderboard", server.url)).await.unwrap().json().await.unwrap();
    let text = board.to_string();
    assert!(text.contains("first-box") && text.contains("second-box"), "{board}");
    let project: serde_json::Value =
        reqwest::get(format!("{}/api/v1/projects/first-box", server.url)).await.unwrap().json().await.unwrap();
    assert_eq!(project["visibility"], "public");
    assert!(project["results"][0]["published_at"].is_i64(), "{project}");

    // Again: nothing to do, and no job.
    tokio::time::timeout(Duration::from_secs(30), submit(&server)).await.unwrap().unwrap().unwrap();
    assert!(runner.claim(1).await.is_none(), "a published baseline was pushed again");
}

#[tokio::test]
async fn a_list_naming_a_missing_folder_is_refused_with_its_line() {
    let server = spawn(Db::Sqlite).await;
    let folder = tempfile::tempdir().unwrap();
    let list = folder.path().join("baselines.txt");
    std::fs::write(&list, "\nno-such-technique\n").unwrap();
    let e = fbksd_server::baselines::submit(server.config(), &list, Some(server.url.clone())).await.unwrap_err();
    let e = e.to_string();
    assert!(e.contains("baselines.txt:2") && e.contains("no-such-technique"), "{e}");
}
