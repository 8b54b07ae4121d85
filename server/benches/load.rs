//! Load benchmark of the pages users hit most: the public leaderboard and a
//! private results page, at 100 concurrent connections on loopback.
//!
//! `cargo bench -p fbksd-server --bench load [-- SECONDS [CONNECTIONS [TECHNIQUES]]]`
//!
//! The pages: the leaderboard (as HTML, gzipped as a browser asks, and as
//! JSON), a private results page and its viewer document.
//!
//! It starts a server on SQLite (or on PostgreSQL with
//! `FBKSD_BENCH_POSTGRES=1`, on the test server `deploy/setup.sh` starts),
//! publishes TECHNIQUES techniques (default 20) benchmarked on 10 scenes at
//! 4 budgets through the real API, then runs CONNECTIONS client tasks,
//! each on its own keep-alive connection, for SECONDS per page and prints
//! requests per second and latency percentiles; then the same pages and a
//! job page again while an attacker floods the log-in (wrong passwords from
//! many addresses, as fast as 8 connections go) and 20 live job logs stream;
//! then the leaderboard and the private page once more, under git and
//! metrics attacks (16 slow anonymous clones, 10 connections of oversized
//! fetch requests, a flood of made-up methods), with the owner's push, the
//! attackers' answers, the metric series and the peak memory.

#[path = "../tests/common/mod.rs"]
mod common;

use common::{push, spawn_with, technique_repository, Db, FakeRunner};
use reqwest::Method;
use serde_json::json;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The bench's 10 scenes.
fn scenes() -> Vec<String> {
    (0..10).map(|i| format!("scene-{i:02}")).collect()
}

/// Results of one technique: 10 scenes × 4 budgets, values scaled by
/// `quality`, scored against the scenes' [`common::fake_reference`]s.
fn upload(quality: f64) -> serde_json::Value {
    let scenes = scenes();
    let mut runs = Vec::new();
    for (i, scene) in scenes.iter().enumerate() {
        for spp in [4u64, 16, 64, 256] {
            let mse = quality * (1.0 + i as f64) / spp as f64;
            runs.push(json!({
                "technique": "t", "scene": scene, "spp": spp, "status": "ok", "message": "", "log": "", "image": null,
                "technique_ms": 10.0 * quality, "render_ms": 100.0, "used_samples": spp * 4096,
                "metrics": { "MSE": mse, "SSIM": 1.0 / (1.0 + mse) }
            }));
        }
    }
    json!({
        "runs": runs,
        "metrics": [
            { "acronym": "MSE", "name": "MSE", "reference": "", "lower_is_better": true, "has_error_map": false },
            { "acronym": "SSIM", "name": "SSIM", "reference": "", "lower_is_better": false, "has_error_map": false }
        ],
        "scenes": scenes.iter().enumerate().map(|(i, s)| json!({
            "name": s, "tags": if i % 2 == 0 { vec!["even"] } else { vec!["odd"] }, "scene_hash": common::fake_scene_hash(s), "reference_hash": common::fake_reference(s).1
        })).collect::<Vec<_>>(),
        "provenance": { "runner": "bench" }
    })
}

struct Figures {
    requests: usize,
    errors: usize,
    latencies: Vec<Duration>,
    elapsed: Duration,
    /// Body bytes received, over all requests.
    bytes: usize,
}

/// Request headers, as (name, value).
type Headers<'a> = [(&'a str, &'a str)];

/// `connections` tasks request `url` with `headers` for `seconds`, each on its own connection.
async fn hammer(url: &str, headers: &Headers<'_>, connections: usize, seconds: u64) -> Figures {
    let deadline = Instant::now() + Duration::from_secs(seconds);
    let start = Instant::now();
    let tasks: Vec<_> = (0..connections)
        .map(|_| {
            let url = url.to_string();
            let headers: Vec<(String, String)> = headers.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
            tokio::spawn(async move {
                let client = reqwest::Client::builder().pool_max_idle_per_host(1).build().unwrap();
                let (mut latencies, mut errors, mut bytes) = (Vec::new(), 0usize, 0usize);
                while Instant::now() < deadline {
                    let began = Instant::now();
                    let mut request = client.get(&url);
                    for (name, value) in &headers {
                        request = request.header(name, value);
                    }
                    match request.send().await {
                        Ok(r) if r.status().is_success() => {
                            bytes += r.bytes().await.map_or(0, |b| b.len());
                            latencies.push(began.elapsed());
                        }
                        _ => errors += 1,
                    }
                }
                (latencies, errors, bytes)
            })
        })
        .collect();
    let mut figures = Figures { requests: 0, errors: 0, latencies: Vec::new(), elapsed: Duration::ZERO, bytes: 0 };
    for task in tasks {
        let (latencies, errors, bytes) = task.await.unwrap();
        figures.errors += errors;
        figures.bytes += bytes;
        figures.latencies.extend(latencies);
    }
    figures.elapsed = start.elapsed();
    figures.requests = figures.latencies.len();
    figures.latencies.sort();
    figures
}

fn percentile(sorted: &[Duration], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[i].as_secs_f64() * 1000.0
}

#[tokio::main(flavor = "multi_thread")]
async fn main() {
    let args: Vec<u64> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let seconds = args.first().copied().unwrap_or(10);
    let connections = args.get(1).copied().unwrap_or(100) as usize;
    let techniques = args.get(2).copied().unwrap_or(20) as usize;
    let db = if std::env::var_os("FBKSD_BENCH_POSTGRES").is_some() { Db::Postgres } else { Db::Sqlite };

    let server = spawn_with(db, |c| {
        c.max_runs_per_day = 1_000;
        c.max_queued_jobs_per_user = 1_000;
    })
    .await;
    let ada = server.user("ada@example.org").await;
    let runner = FakeRunner::register(&server, "bench").await;
    for scene in scenes() {
        common::stored_reference(&runner, &scene).await;
    }
    let mut private = String::new();
    for t in 0..techniques {
        let name = format!("technique-{t:02}");
        server.create_project(&ada, &name, "public").await;
        let repo = technique_repository("box-filter-python");
        assert!(push(repo.path(), &server.clone_url(&name, &ada.token), &["FBKSD_RUN"]).0);
        let job = runner.claim(1).await.expect("a benchmark job");
        let status = job.send(&runner, Method::PUT, "results", upload(1.0 + t as f64 / 10.0).to_string().into()).await;
        assert_eq!(status, 204);
        let result =
            job.finish(&runner, json!({ "state": "succeeded" })).await.1["result_id"].as_str().unwrap().to_string();
        if t + 1 < techniques {
            ada.api(Method::POST, format!("{}/api/v1/results/{result}/publish", server.url)).send().await.unwrap();
        } else {
            private = result;
        }
    }
    // The private page needs the owner's session cookie.
    let session = reqwest::Client::builder().cookie_store(true).build().unwrap();
    let response = session
        .post(format!("{}/api/v1/sessions", server.url))
        .json(&json!({ "email": "ada@example.org", "password": "a long enough password" }))
        .send()
        .await
        .unwrap();
    let cookie = response
        .headers()
        .get("set-cookie")
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.split(';').next())
        .unwrap()
        .to_string();

    println!(
        "fbksd-server load: {:?}, {} published techniques × 10 scenes × 4 spp, {connections} connections, {seconds} s per page",
        db,
        techniques - 1
    );
    println!(
        "{:<34} {:>9} {:>9} {:>9} {:>9} {:>9} {:>7} {:>9}",
        "page", "requests", "req/s", "p50 ms", "p99 ms", "max ms", "errors", "body KB"
    );
    // A browser asks for gzip; the other rows take the body as it is.
    let gzip = [("Accept-Encoding", "gzip, deflate, br")];
    let owner = [("Cookie", cookie.as_str())];
    let pages: [(&str, String, &Headers); 5] = [
        ("GET /results/ (leaderboard)", format!("{}/results/", server.url), &[]),
        ("  … as a browser asks (gzip)", format!("{}/results/", server.url), &gzip),
        ("GET /results/<uuid> (private)", format!("{}/results/{private}", server.url), &owner),
        ("GET /api/v1/leaderboard (JSON)", format!("{}/api/v1/leaderboard", server.url), &[]),
        ("GET …/<uuid>/viewer (viewer doc)", format!("{}/api/v1/results/{private}/viewer", server.url), &owner),
    ];
    for (label, url, headers) in &pages {
        print_figures(label, &hammer(url, headers, connections, seconds).await);
    }

    // Under attack: a running job's live log read 20 times (by three users:
    // a user may hold 8), and a log-in flood.
    server.create_project(&ada, "running", "public").await;
    let repo = technique_repository("box-filter-python");
    assert!(push(repo.path(), &server.clone_url("running", &ada.token), &["FBKSD_RUN"]).0);
    let running = runner.claim(1).await.expect("a job to watch");
    let mut watchers = Vec::new();
    for u in 0..3 {
        watchers.push(server.user(&format!("watcher-{u}@example.org")).await);
    }
    let mut streams = Vec::new();
    for i in 0..20 {
        let request = watchers[i % 3].api(Method::GET, format!("{}/api/v1/jobs/{}/log/stream", server.url, running.id));
        let response = request.send().await.unwrap();
        assert_eq!(response.status(), 200, "live log {i}");
        streams.push(response);
    }
    let url = server.url.clone();
    let (going, flood) = keep_attacking(8, move |client, task, n| {
        let url = url.clone();
        async move {
            let body = json!({ "email": format!("victim-{task}-{n}@example.org"), "password": "not the password" });
            let answer = client.post(format!("{url}/api/v1/sessions")).json(&body).send().await;
            answer.ok().map(|r| r.status().as_u16())
        }
    });
    println!("under a log-in flood (8 connections) and 20 live job logs:");
    let job_page: (&str, String, &Headers) =
        ("GET /jobs/<id> (job page)", format!("{}/jobs/{}", server.url, running.id), &[]);
    // The leaderboard and the private page again, then the job page.
    for (label, url, headers) in [&pages[0], &pages[2], &job_page] {
        print_figures(label, &hammer(url, headers, connections, seconds).await);
    }
    let answers = stop(going, flood).await;
    println!("log-in flood answers (HTTP status: count): {answers:?}");
    drop(streams);

    under_git_and_metrics_attack(&server, &ada, &pages, connections, seconds).await;
}

/// Tasks that repeat `attack(client, task, n)` until told to stop, each
/// with a client of its own (one keep-alive connection); each returns its
/// answers' statuses, counted (a request that got no answer is not).
fn keep_attacking<F, Fut>(tasks: usize, attack: F) -> (Arc<AtomicBool>, Vec<tokio::task::JoinHandle<Counts>>)
where
    F: Fn(reqwest::Client, usize, usize) -> Fut + Clone + Send + 'static,
    Fut: std::future::Future<Output = Option<u16>> + Send,
{
    let going = Arc::new(AtomicBool::new(true));
    let handles = (0..tasks)
        .map(|task| {
            let (going, attack) = (going.clone(), attack.clone());
            tokio::spawn(async move {
                let (client, mut counts, mut n) = (reqwest::Client::new(), Counts::new(), 0);
                while going.load(Ordering::Relaxed) {
                    n += 1;
                    if let Some(status) = attack(client.clone(), task, n).await {
                        *counts.entry(status).or_default() += 1;
                    }
                }
                counts
            })
        })
        .collect();
    (going, handles)
}

/// Statuses of answers: how many of each.
type Counts = std::collections::BTreeMap<u16, usize>;

async fn stop(going: Arc<AtomicBool>, tasks: Vec<tokio::task::JoinHandle<Counts>>) -> Counts {
    going.store(false, Ordering::Relaxed);
    let mut all = Counts::new();
    for task in tasks {
        for (status, n) in task.await.unwrap() {
            *all.entry(status).or_default() += n;
        }
    }
    all
}

/// Issue 49's attacks at once: 16 anonymous clones of a large public
/// repository that stop reading, 10 connections sending 64 MiB anonymous
/// fetch requests again and again, and 4 flooding `/metrics` with made-up
/// methods; meanwhile the leaderboard and the private page are read and
/// the owner pushes.
async fn under_git_and_metrics_attack(
    server: &common::TestServer,
    ada: &common::TestUser,
    pages: &[(&str, String, &Headers<'_>)],
    connections: usize,
    seconds: u64,
) {
    server.create_project(ada, "big", "public").await;
    let repo = common::repository_too_big_to_buffer();
    let owner_url = server.clone_url("big", &ada.token);
    assert!(push(repo.path(), &owner_url, &[]).0);
    let commit = String::from_utf8(common::git(repo.path(), &["rev-parse", "HEAD"]).stdout).unwrap();
    // A histogram's buckets are one series with it.
    let series = |text: &str| text.lines().filter(|l| !l.starts_with('#') && !l.contains("_bucket{")).count();
    let metrics = format!("{}/metrics", server.url);
    let series_before = series(&reqwest::get(&metrics).await.unwrap().text().await.unwrap());
    let peak_before = common::peak_memory() >> 20;

    let (mut clones, mut held) = (Counts::new(), Vec::new());
    for _ in 0..16 {
        let (status, stream) = common::slow_clone(&server.url, "big", commit.trim()).await;
        *clones.entry(status).or_default() += 1;
        held.push(stream);
    }
    let url = server.url.clone();
    let (oversized, oversizing) = keep_attacking(10, move |_, _, _| {
        let url = url.clone();
        async move {
            let headers = "Content-Type: application/x-git-upload-pack-request\r\n";
            Some(common::send_zeros(&url, "POST", "/git/big.git/git-upload-pack", 64 << 20, headers).await)
        }
    });
    let url = metrics.clone();
    let (flood, flooding) = keep_attacking(4, move |_, task, n| {
        let url = url.clone();
        async move {
            let method = Method::from_bytes(format!("FLOOD{task}X{n}").as_bytes()).unwrap();
            Some(reqwest::Client::new().request(method, &url).send().await.map_or(0, |r| r.status().as_u16()))
        }
    });

    println!(
        "under 16 slow anonymous clones, 10 connections of 64 MiB fetch requests and a /metrics method flood \
         (4 connections):"
    );
    let push = {
        let (dir, url) = (repo.path().to_path_buf(), owner_url.clone());
        tokio::task::spawn_blocking(move || {
            std::fs::write(dir.join("notes.txt"), "under attack\n").unwrap();
            common::commit_all(&dir, "under attack");
            let began = Instant::now();
            (push(&dir, &url, &[]), began.elapsed())
        })
    };
    for (label, url, headers) in [&pages[0], &pages[2]] {
        print_figures(label, &hammer(url, headers, connections, seconds).await);
    }
    let ((pushed, output), took) = push.await.unwrap();
    assert!(pushed, "the owner's push under attack: {output}");
    let (oversized, flood) = (stop(oversized, oversizing).await, stop(flood, flooding).await);
    drop(held);
    let series_after = series(&reqwest::get(&metrics).await.unwrap().text().await.unwrap());
    println!("slow clones' answers: {clones:?} (4 served, the rest asked to sign in)");
    println!("oversized fetch requests' answers: {oversized:?}");
    println!("metrics flood answers: {flood:?}; /metrics series {series_before} before, {series_after} after");
    println!("the owner's push under attack: landed in {:.2} s", took.as_secs_f64());
    println!(
        "peak memory of the process (server and clients): {peak_before} MiB before, {} MiB after",
        (common::peak_memory() >> 20)
    );
}

fn print_figures(label: &str, f: &Figures) {
    println!(
        "{label:<34} {:>9} {:>9.0} {:>9.1} {:>9.1} {:>9.1} {:>7} {:>9.1}",
        f.requests,
        f.requests as f64 / f.elapsed.as_secs_f64(),
        percentile(&f.latencies, 0.5),
        percentile(&f.latencies, 0.99),
        percentile(&f.latencies, 1.0),
        f.errors,
        f.bytes as f64 / f.requests.max(1) as f64 / 1024.0
    );
}
