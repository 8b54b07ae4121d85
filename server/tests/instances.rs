//! Two server instances behind one address, as a deployment scales the
//! service: one PostgreSQL database and one data directory (git
//! repositories, result files, references, the outbox) shared by both, and
//! a balancer that sends each new connection to the next instance.
//!
//! One researcher's whole loop goes through the balancer with a client that
//! opens a connection per request, so consecutive requests land on
//! different instances: registration, the mailed link, log-in, a token made
//! with the session's CSRF token, a project, a `git push` (whose requests
//! are split between the instances), a runner's job, the private page and
//! the board.

mod common;

use common::{json_of, push, spawn, technique_repository, Db, FakeRunner, TestServer};
use reqwest::Method;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

/// A TCP balancer on loopback: connection `n` goes to `backends[n % len]`.
/// Returns its URL and how many connections each backend got.
async fn balancer(backends: Vec<String>) -> (String, Arc<Vec<AtomicUsize>>) {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    let counts: Arc<Vec<AtomicUsize>> = Arc::new(backends.iter().map(|_| AtomicUsize::new(0)).collect());
    let seen = counts.clone();
    tokio::spawn(async move {
        let mut next = 0usize;
        while let Ok((mut client, _)) = listener.accept().await {
            let i = next % backends.len();
            next += 1;
            seen[i].fetch_add(1, Ordering::SeqCst);
            let address = backends[i].trim_start_matches("http://").to_string();
            tokio::spawn(async move {
                if let Ok(mut backend) = tokio::net::TcpStream::connect(address).await {
                    let _ = tokio::io::copy_bidirectional(&mut client, &mut backend).await;
                }
            });
        }
    });
    (url, counts)
}

/// A browser that keeps cookies and never reuses a connection.
fn fresh_connections() -> reqwest::Client {
    reqwest::Client::builder().cookie_store(true).pool_max_idle_per_host(0).build().unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_instances_behind_one_address_serve_one_researcher_as_one_service() {
    let first = spawn(Db::Postgres).await;
    let second = first.another_instance().await;
    let (url, connections) = balancer(vec![first.url.clone(), second.url.clone()]).await;
    let front = TestServer::at(url.clone(), first.outbox.clone());

    // Registration, the mailed link and the log-in, each on whichever instance.
    let browser = fresh_connections();
    let password = "a long enough password";
    let created = browser
        .post(format!("{url}/api/v1/accounts"))
        .json(&serde_json::json!({ "email": "ada@example.org", "password": password }))
        .send()
        .await
        .unwrap();
    assert_eq!(created.status(), 201);
    let link = front.link_in_mail("ada@example.org", "/accounts/verify?token=");
    let link = url.clone() + &link[link.find("/accounts/").unwrap()..];
    assert_eq!(browser.get(&link).send().await.unwrap().status(), 200, "{link}");
    // The token is made on one instance with the session another one opened.
    let ada = front.log_in("ada@example.org", password, browser).await;
    for _ in 0..4 {
        let me = ada.browser.get(format!("{url}/api/v1/me")).send().await.unwrap();
        assert_eq!(me.status(), 200, "the session holds on both instances");
    }

    // A push through the balancer: git's requests go to both instances,
    // which read and write the one repository in the shared data directory.
    let created = ada
        .api(Method::POST, format!("{url}/api/v1/projects"))
        .json(&serde_json::json!({ "name": "ada-filter", "visibility": "private" }))
        .send()
        .await
        .unwrap();
    assert_eq!(created.status(), 201);
    let repo = technique_repository("box-filter-python");
    let (pushed, output) = push(repo.path(), &front.clone_url("ada-filter", &ada.token), &["FBKSD_RUN"]);
    assert!(pushed, "{output}");

    // A runner on the front address takes the job and uploads its results.
    let runner = FakeRunner::register(&front, "r").await;
    let job = runner.claim(5).await.expect("the pushed job, queued by whichever instance took the push");
    let scenes = [common::PicturedScene { name: "sin-bands", tags: &["bands"] }];
    let reference = |_: usize| vec![0.5f32; 8 * 8 * 3];
    let (set, _) = common::upload_pictured(
        &runner,
        &job,
        &common::Pictured {
            technique: "ada-filter",
            scenes: &scenes,
            spps: &[4, 16],
            size: (8, 8),
            reference: &reference,
            image: &|_, spp| vec![0.5 + 0.1 / spp as f32; 8 * 8 * 3],
            mse: &|_, spp| 0.01 / spp as f64,
            technique_ms: &|_, spp| spp as f64,
            exr: &|_| b"an EXR".to_vec(),
        },
    )
    .await;

    // Her private page and its viewer document answer alike from either
    // instance; another visitor gets nothing from either.
    let mut documents = Vec::new();
    for _ in 0..4 {
        let page = ada.browser.get(format!("{url}/results/{set}")).send().await.unwrap();
        assert_eq!(page.status(), 200);
        assert!(page.text().await.unwrap().contains("id=\"fbksd-viewer\""));
        let (status, doc) =
            json_of(ada.browser.get(format!("{url}/api/v1/results/{set}/viewer")).send().await.unwrap()).await;
        assert_eq!(status, 200, "{doc}");
        documents.push(doc);
    }
    assert!(documents.windows(2).all(|w| w[0] == w[1]), "the same document from both instances");
    let run = &documents[0]["techniques"][0]["runs"][0];
    for _ in 0..2 {
        let pixels = ada.browser.get(format!("{url}{}", run["pixels"].as_str().unwrap())).send().await.unwrap();
        assert_eq!(pixels.status(), 200, "the result files are shared");
        assert_eq!(reqwest::get(format!("{url}/results/{set}")).await.unwrap().status(), 404);
    }

    // Published through one instance, the board is the same on both.
    let published = ada.api(Method::POST, format!("{url}/api/v1/results/{set}/publish")).send().await.unwrap();
    assert_eq!(published.status(), 200);
    let board = |base: String| async move {
        let (status, board) = json_of(reqwest::get(format!("{base}/api/v1/leaderboard")).await.unwrap()).await;
        assert_eq!(status, 200);
        board
    };
    let (on_first, on_second) = (board(first.url.clone()).await, board(second.url.clone()).await);
    assert_eq!(on_first, on_second);
    assert!(on_first.to_string().contains("ada-filter"), "{on_first}");

    let counts: Vec<usize> = connections.iter().map(|c| c.load(Ordering::SeqCst)).collect();
    assert!(counts.iter().all(|n| *n >= 10), "both instances served the loop: {counts:?} connections");
}
