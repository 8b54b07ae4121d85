//! What operators and orchestrators read: liveness, readiness (and why
//! not), and Prometheus metrics that follow the queue, the runners, job
//! ends and HTTP answers.

mod common;

use common::{push, spawn, technique_repository, Db, FakeRunner, TestServer};
use serde_json::json;

async fn get(server: &TestServer, path: &str) -> (u16, String) {
    let response = reqwest::get(format!("{}{path}", server.url)).await.unwrap();
    (response.status().as_u16(), response.text().await.unwrap())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn metrics_can_be_kept_off_the_public_port() {
    let server = common::spawn_with(Db::Sqlite, |c| c.metrics_bind = "127.0.0.1:0".into()).await;
    // What faces the public has no /metrics...
    assert_eq!(get(&server, "/metrics").await.0, 404);
    assert_eq!(get(&server, "/healthz").await.0, 200);
    // ... the operators' address has, and counts what the public port answered.
    let metrics_url = server.metrics_url.clone().expect("a metrics address");
    let response = reqwest::get(format!("{metrics_url}/metrics")).await.unwrap();
    assert_eq!(response.status(), 200);
    let text = response.text().await.unwrap();
    let healthz = r#"fbksd_http_request_duration_seconds_count{method="GET",route="/healthz",status="200"}"#;
    assert_eq!(common::sample(&text, healthz), Some(1.0), "{text}");
    // And nothing else is served there.
    assert_eq!(reqwest::get(format!("{metrics_url}/api/v1/me")).await.unwrap().status(), 404);
}

on_both_databases!(health_readiness_and_metrics_follow_the_service, |db: Db| async move {
    let server = spawn(db).await;
    assert_eq!(get(&server, "/healthz").await, (200, "ok\n".into()));
    assert_eq!(get(&server, "/readyz").await, (200, "ready\n".into()));

    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "box", "private").await;
    let repo = technique_repository("box-filter-cpp");
    assert!(push(repo.path(), &server.clone_url("box", &ada.token), &[]).0);
    let (status, metrics) = get(&server, "/metrics").await;
    assert_eq!(status, 200);
    assert_eq!(common::sample(&metrics, "fbksd_jobs_queued{kind=\"build\"}"), Some(1.0), "{metrics}");
    assert_eq!(common::sample(&metrics, "fbksd_runners{health=\"healthy\"}"), Some(0.0), "{metrics}");

    let runner = FakeRunner::register(&server, "runner-1").await;
    let job = runner.claim(5).await.expect("the build");
    let metrics = get(&server, "/metrics").await.1;
    assert_eq!(common::sample(&metrics, "fbksd_jobs_queued{kind=\"build\"}"), Some(0.0), "{metrics}");
    assert_eq!(common::sample(&metrics, "fbksd_jobs_running{kind=\"build\"}"), Some(1.0), "{metrics}");
    assert_eq!(common::sample(&metrics, "fbksd_runners{health=\"healthy\"}"), Some(1.0), "{metrics}");

    let (status, _) = job.finish(&runner, json!({ "state": "failed", "reason": "crashed", "message": "x" })).await;
    assert_eq!(status, 200);
    let metrics = get(&server, "/metrics").await.1;
    assert_eq!(common::sample(&metrics, "fbksd_job_failures_total{reason=\"crashed\"}"), Some(1.0), "{metrics}");
    assert_eq!(
        common::sample(&metrics, "fbksd_job_duration_seconds_count{kind=\"build\",state=\"failed\"}"),
        Some(1.0),
        "{metrics}"
    );
    // Answers are timed by route pattern, never by raw path.
    let series =
        "fbksd_http_request_duration_seconds_count{method=\"POST\",route=\"/api/v1/jobs/{id}/finish\",status=\"200\"}";
    assert_eq!(common::sample(&metrics, series), Some(1.0), "{metrics}");
    assert!(!metrics.contains(&job.id), "no series per job");

    // A data directory that takes no file: not ready, and says why.
    let uploads = server.config().data_dir.join("uploads");
    std::fs::remove_dir_all(&uploads).unwrap();
    std::fs::write(&uploads, b"in the way").unwrap();
    let (status, text) = get(&server, "/readyz").await;
    assert_eq!(status, 503);
    assert!(text.contains("the data directory takes no file"), "{text}");
    assert_eq!(get(&server, "/healthz").await.0, 200, "alive all the same");
});

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn made_up_methods_share_one_metric_series() {
    // Every label value is a series kept for the life of the process: one
    // per made-up method would let anyone grow the server without bound.
    let server = spawn(Db::Sqlite).await;
    let client = reqwest::Client::new();
    for i in 0..40 {
        let method = reqwest::Method::from_bytes(format!("FLOOD{i}").as_bytes()).unwrap();
        let status = client.request(method, format!("{}/", server.url)).send().await.unwrap().status();
        assert!(status.is_client_error(), "{status}");
    }
    let metrics = get(&server, "/metrics").await.1;
    assert!(!metrics.contains("FLOOD"), "a series per made-up method:\n{metrics}");
    let made_up: Vec<&str> =
        metrics.lines().filter(|l| l.contains("method=\"other\"") && l.contains("_count")).collect();
    let answered: f64 = made_up.iter().filter_map(|l| l.rsplit(' ').next()?.parse::<f64>().ok()).sum();
    assert_eq!(answered, 40.0, "every made-up method counted under method=\"other\": {made_up:?}");
}
