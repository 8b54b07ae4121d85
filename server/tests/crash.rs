//! The server killed at each step of storing a result set (as by a power
//! cut), restarted on the same data directory: the runner's retry of the
//! job's end stores the set whole, with its files, and leaves no upload
//! behind.

mod common;

use common::{json_of, push, technique_repository, Captured, FakeRunner, TestServer, REGISTRATION_TOKEN};
use reqwest::Method;
use serde_json::json;
use std::process::Command;
use std::time::Duration;

/// `fbksd-server` on `port` over `data`, ended at `crash_at` if given.
fn server_process(data: &std::path::Path, port: u16, crash_at: Option<&str>) -> Captured {
    let mut command = Command::new(env!("CARGO_BIN_EXE_fbksd-server"));
    for (key, _) in std::env::vars() {
        if key.starts_with("FBKSD_SERVER_") {
            command.env_remove(key);
        }
    }
    command
        .env("FBKSD_SERVER_DATA_DIR", data)
        .env("FBKSD_SERVER_BIND", format!("127.0.0.1:{port}"))
        .env("FBKSD_SERVER_RUNNER_REGISTRATION_TOKEN", REGISTRATION_TOKEN);
    if let Some(step) = crash_at {
        command.env("FBKSD_CRASH_AT", step);
    }
    let process = Captured::spawn(command);
    process.line_with("FBKSD server: ", Duration::from_secs(60));
    process
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_crash_at_any_step_of_storing_a_result_loses_nothing() {
    for step in ["moved", "references-kept", "committed"] {
        let dir = tempfile::tempdir().unwrap();
        let data = dir.path().join("data");
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let mut process = server_process(&data, port, Some(step));
        let server = TestServer::at(format!("http://127.0.0.1:{port}"), data.join("outbox"));
        let ada = server.user("ada@example.org").await;
        server.create_project(&ada, "box", "private").await;
        let repo = technique_repository("box-filter-cpp");
        assert!(push(repo.path(), &server.clone_url("box", &ada.token), &["FBKSD_RUN"]).0);
        let runner = FakeRunner::register(&server, "runner-1").await;
        let job = runner.claim(5).await.expect("the benchmark job");
        common::upload_results(&runner, &job, 1.0).await;

        // The end is reported; the server dies storing it.
        let client = reqwest::Client::new();
        let finish = client
            .post(format!("{}/api/v1/jobs/{}/finish", server.url, job.id))
            .bearer_auth(&job.token)
            .json(&json!({ "state": "succeeded" }))
            .send()
            .await;
        assert!(finish.is_err(), "{step}: the server was to die answering");
        let _ = process.child.wait();
        // The pipe readers may still hold the last line when the process is
        // reaped, so wait for it rather than read what arrived so far.
        process.line_with(&format!("FBKSD_CRASH_AT={step}"), Duration::from_secs(10));

        // Restarted, it answers the runner's retry.
        let mut process = server_process(&data, port, None);
        let (status, done) = job.finish(&runner, json!({ "state": "succeeded" })).await;
        let (status_job, stored) =
            json_of(ada.api(Method::GET, format!("{}/api/v1/jobs/{}", server.url, job.id)).send().await.unwrap()).await;
        assert_eq!(status_job, 200);
        assert_eq!(stored["state"], "succeeded", "{step}: {stored}\n{}", process.output());
        let result_id = stored["result_id"].as_str().expect("the job names its set").to_string();
        match step {
            // Committed before the crash: the job is over, and says so.
            "committed" => assert_eq!(status, 410, "{step}: {done}"),
            _ => assert_eq!((status, done["result_id"].as_str()), (200, Some(result_id.as_str())), "{step}: {done}"),
        }
        // Every file is there, under the set's one id.
        for name in ["sin-bands/4_0.png", "defocus-checkerboard/16_0.png"] {
            let file =
                ada.api(Method::GET, format!("{}/results/{result_id}/files/{name}", server.url)).send().await.unwrap();
            assert_eq!(file.status(), 200, "{step}: {name}");
            assert_eq!(&file.bytes().await.unwrap()[..], b"\x89PNG fake", "{step}: {name}");
        }
        let (status, set) =
            json_of(ada.api(Method::GET, format!("{}/api/v1/results/{result_id}", server.url)).send().await.unwrap())
                .await;
        assert_eq!((status, set["runs"].as_array().map(Vec::len)), (200, Some(4)), "{step}: {set}");
        assert!(!data.join("uploads").join(&job.id).exists(), "{step}: the upload is not left behind");
        let sets = std::fs::read_dir(data.join("results")).unwrap().count();
        assert_eq!(sets, 1, "{step}: one set's files, no orphan");
        let _ = process.child.kill();
        let _ = process.child.wait();
    }
}
