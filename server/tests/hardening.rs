//! What one client may take from the server or learn about others: security
//! headers on every answer, a cap on live-log streams, result files
//! streamed from disk, private result sets kept out of public jobs, result
//! sets that belong to their project (not its name), owner-only modes in
//! the data directory, request bodies streamed rather than held, results
//! a runner may upload only against the service's references, every field
//! checked, git processes that slow clones cannot all hold, and what an
//! account makes (rows, repositories on disk) bounded.

mod common;

use common::{json_of, push, spawn, spawn_with, technique_repository, Db, FakeRunner, TestServer, TestUser};
use reqwest::Method;
use serde_json::{json, Value};
use std::time::Duration;

/// A benchmark of `project` (created `visibility` for `user` unless it
/// exists) that a runner completes, with `sin-bands/4_0.png` of `image`
/// bytes; (job id, result set id).
async fn benchmark(
    server: &TestServer,
    user: &TestUser,
    project: &str,
    visibility: &str,
    image: Vec<u8>,
) -> (String, String) {
    let (status, _) =
        json_of(user.api(Method::GET, format!("{}/api/v1/projects/{project}", server.url)).send().await.unwrap()).await;
    if status == 404 {
        server.create_project(user, project, visibility).await;
    }
    let repo = technique_repository("box-filter-cpp");
    let (pushed, output) = push(repo.path(), &server.clone_url(project, &user.token), &["FBKSD_RUN"]);
    assert!(pushed, "{output}");
    let runner = FakeRunner::register(server, "runner").await;
    let job = runner.claim(5).await.expect("the benchmark job");
    assert_eq!(job.body["job"]["kind"], "benchmark");
    let upload = common::results_upload(1.0);
    for scene in ["sin-bands", "defocus-checkerboard"] {
        common::stored_reference(&runner, scene).await;
    }
    for run in upload["runs"].as_array().unwrap() {
        let name = run["image"].as_str().unwrap();
        let bytes = if name == "sin-bands/4_0.png" { image.clone() } else { b"\x89PNG fake".to_vec() };
        assert_eq!(job.send(&runner, Method::PUT, &format!("files/{name}"), bytes.into()).await, 204, "{name}");
    }
    assert_eq!(job.send(&runner, Method::PUT, "results", upload.to_string().into()).await, 204);
    let (status, done) = job.finish(&runner, json!({ "state": "succeeded" })).await;
    assert_eq!(status, 200, "{done}");
    (job.id.clone(), done["result_id"].as_str().unwrap().to_string())
}

fn assert_secure(response: &reqwest::Response, what: &str) {
    let header = |name: &str| response.headers().get(name).and_then(|v| v.to_str().ok()).map(str::to_string);
    let csp = header("content-security-policy").unwrap_or_else(|| panic!("{what}: no Content-Security-Policy"));
    assert!(csp.contains("default-src 'self'") && csp.contains("img-src 'self' data: blob:"), "{what}: {csp}");
    assert!(!csp.contains("script-src") || !csp.contains("unsafe-inline"), "{what}: inline scripts allowed: {csp}");
    assert_eq!(header("x-frame-options").as_deref(), Some("DENY"), "{what}");
    assert_eq!(header("x-content-type-options").as_deref(), Some("nosniff"), "{what}");
    assert_eq!(header("referrer-policy").as_deref(), Some("same-origin"), "{what}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_answer_carries_the_security_headers() {
    let server = spawn(Db::Sqlite).await;
    for (path, status) in [
        ("/", 200),
        ("/results/", 200),
        ("/static/log.js", 200),
        ("/api/v1/leaderboard", 200),
        ("/api/v1/jobs/no-such-job", 404),
        ("/no/such/page", 404),
    ] {
        let response = reqwest::get(format!("{}{path}", server.url)).await.unwrap();
        assert_eq!(response.status().as_u16(), status, "{path}");
        assert_secure(&response, path);
    }
    let refused = reqwest::Client::new().post(format!("{}/api/v1/projects", server.url)).send().await.unwrap();
    assert_eq!(refused.status(), 401);
    assert_secure(&refused, "a refused API call");
}

/// Opens a job's live log; the answer (headers received).
async fn stream(server: &TestServer, user: Option<&TestUser>, job: &str) -> reqwest::Response {
    let url = format!("{}/api/v1/jobs/{job}/log/stream", server.url);
    let request = match user {
        Some(user) => user.api(Method::GET, url),
        None => reqwest::Client::new().get(url),
    };
    tokio::time::timeout(Duration::from_secs(10), request.send()).await.expect("the stream answers").unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn live_logs_are_capped_per_user_and_a_closed_one_frees_its_place() {
    let server = spawn(Db::Sqlite).await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "box-filter-cpp", "public").await;
    let repo = technique_repository("box-filter-cpp");
    assert!(push(repo.path(), &server.clone_url("box-filter-cpp", &ada.token), &[]).0);
    let job = common::project_jobs(&server, &ada, "box-filter-cpp").await[0]["id"].as_str().unwrap().to_string();

    let mut open = Vec::new();
    for i in 0..8 {
        let response = stream(&server, Some(&ada), &job).await;
        assert_eq!(response.status(), 200, "stream {i}");
        assert!(response.headers()["content-type"].to_str().unwrap().starts_with("text/event-stream"));
        open.push(response);
    }
    let refused = stream(&server, Some(&ada), &job).await;
    assert_eq!(refused.status(), 429);
    let (_, body) = json_of(refused).await;
    assert_eq!(body["error"], "too_many_streams", "{body}");
    assert!(body["message"].as_str().unwrap().contains("close another job's page"), "{body}");

    // The cap is the user's: someone else (here anonymous) still follows the log.
    let anonymous = stream(&server, None, &job).await;
    assert_eq!(anonymous.status(), 200);
    drop(anonymous);

    // A closed stream gives its place back (once the server notices the client left).
    drop(open.pop());
    let deadline = tokio::time::Instant::now() + Duration::from_secs(40);
    loop {
        let again = stream(&server, Some(&ada), &job).await;
        if again.status() == 200 {
            open.push(again);
            break;
        }
        assert_eq!(again.status(), 429);
        assert!(tokio::time::Instant::now() < deadline, "the closed stream's place never came back");
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    assert_eq!(stream(&server, Some(&ada), &job).await.status(), 429, "at the cap again");

    // When the job ends, every stream ends with it and gives its place back.
    let cancel = ada.api(Method::POST, format!("{}/api/v1/jobs/{job}/cancel", server.url)).send().await.unwrap();
    assert_eq!(cancel.status(), 200);
    for response in open {
        let text = tokio::time::timeout(Duration::from_secs(10), response.text()).await.expect("the stream ends");
        assert!(text.unwrap().contains("event: end\ndata: cancelled"));
    }
    let deadline = tokio::time::Instant::now() + Duration::from_secs(5);
    while stream(&server, Some(&ada), &job).await.status() != 200 {
        assert!(tokio::time::Instant::now() < deadline, "the ended streams' places never came back");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_large_result_file_is_streamed_whole_with_its_length() {
    let server = spawn(Db::Sqlite).await;
    let ada = server.user("ada@example.org").await;
    // 24 MiB that no compression or off-by-one could pass for the original.
    let big: Vec<u8> = (0..24u32 << 20).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8).collect();
    let (_, result) = benchmark(&server, &ada, "box-filter-cpp", "private", big.clone()).await;

    let url = format!("{}/results/{result}/files/sin-bands/4_0.png", server.url);
    let response = ada.browser.get(&url).send().await.unwrap();
    assert_eq!(response.status(), 200);
    assert_eq!(response.headers()["content-length"].to_str().unwrap(), big.len().to_string());
    assert_eq!(response.headers()["content-type"], "image/png");
    assert_secure(&response, "a result file");
    let bytes = response.bytes().await.unwrap();
    assert!(bytes.len() == big.len() && bytes[..] == big[..], "the file arrives as it was uploaded");

    // Read from disk as it is sent, not whole first: a file cut short while
    // it is being downloaded arrives cut short (a whole read would have
    // sent all of it). Sparse, so its 256 MiB take no disk.
    let huge = server.config().data_dir.join("results").join(&result).join("sin-bands/huge.exr");
    std::fs::File::create(&huge).unwrap().set_len(256 << 20).unwrap();
    let url = format!("{}/results/{result}/files/sin-bands/huge.exr", server.url);
    let mut response = ada.browser.get(&url).send().await.unwrap();
    assert_eq!(response.headers()["content-length"].to_str().unwrap(), (256u64 << 20).to_string());
    let mut received = response.chunk().await.unwrap().expect("a first chunk").len();
    std::fs::File::options().write(true).open(&huge).unwrap().set_len(0).unwrap();
    while let Ok(Some(chunk)) = response.chunk().await {
        received += chunk.len();
    }
    assert!(received < 64 << 20, "{received} bytes arrived after the file was cut: it was read whole");

    // A folder or a missing file is not found.
    for missing in ["sin-bands", "sin-bands/nothing.png"] {
        let response = ada.browser.get(format!("{}/results/{result}/files/{missing}", server.url)).send().await;
        assert_eq!(response.unwrap().status(), 404, "{missing}");
    }
}

on_both_databases!(others_read_a_public_projects_job_without_its_private_result_set, |db: Db| async move {
    let server = spawn(db).await;
    let ada = server.user("ada@example.org").await;
    let bob = server.user("bob@example.org").await;
    let (job, result) = benchmark(&server, &ada, "box-filter-cpp", "public", b"png".to_vec()).await;

    // Its owner sees the link everywhere.
    let owner_job = json_of(ada.api(Method::GET, format!("{}/api/v1/jobs/{job}", server.url)).send().await.unwrap());
    assert_eq!(owner_job.await.1["result_id"], result.as_str());
    assert!(common::log_text(&server, &ada, &job).await.contains(&result));

    // Bob and anonymous visitors read the job, its log and its page, never the id.
    let anonymous = reqwest::Client::new();
    for who in ["bob", "anonymous"] {
        let get = |path: String| match who {
            "bob" => bob.api(Method::GET, format!("{}{path}", server.url)),
            _ => anonymous.get(format!("{}{path}", server.url)),
        };
        let (status, body) = json_of(get(format!("/api/v1/jobs/{job}")).send().await.unwrap()).await;
        assert_eq!(status, 200, "{who}: {body}");
        assert_eq!(body["result_id"], Value::Null, "{who}: {body}");
        assert_eq!(body["state"], "succeeded");
        assert!(!body.to_string().contains(&result), "{who}: {body}");
        let (status, project) = json_of(get("/api/v1/projects/box-filter-cpp".into()).send().await.unwrap()).await;
        assert_eq!(status, 200);
        assert!(!project.to_string().contains(&result), "{who}: {project}");
        let log = get(format!("/api/v1/jobs/{job}/log")).send().await.unwrap().text().await.unwrap();
        assert!(log.contains("[fbksd] private results:") && !log.contains(&result), "{who}: {log}");
        let events = get(format!("/api/v1/jobs/{job}/log/stream")).send().await.unwrap().text().await.unwrap();
        assert!(events.contains("event: end") && !events.contains(&result), "{who}: {events}");
    }
    let page = bob.browser.get(format!("{}/jobs/{job}", server.url)).send().await.unwrap().text().await.unwrap();
    assert!(page.contains("succeeded") && !page.contains(&result), "{page}");
    let page = reqwest::get(format!("{}/jobs/{job}", server.url)).await.unwrap().text().await.unwrap();
    assert!(!page.contains(&result), "{page}");
    let page = ada.browser.get(format!("{}/jobs/{job}", server.url)).send().await.unwrap().text().await.unwrap();
    assert!(page.contains(&format!("/results/{result}")), "the owner's page links the set");

    // Published, the set is everyone's: the job links it for all.
    let published = ada.api(Method::POST, format!("{}/api/v1/results/{result}/publish", server.url)).send().await;
    assert_eq!(published.unwrap().status(), 200);
    let (_, body) =
        json_of(bob.api(Method::GET, format!("{}/api/v1/jobs/{job}", server.url)).send().await.unwrap()).await;
    assert_eq!(body["result_id"], result.as_str());
});

on_both_databases!(a_deleted_projects_name_taken_again_never_reaches_its_result_sets, |db: Db| async move {
    let server = spawn(db).await;
    let ada = server.user("ada@example.org").await;
    let bob = server.user("bob@example.org").await;
    let (_, old) = benchmark(&server, &ada, "box-filter-cpp", "public", b"png".to_vec()).await;
    let published = ada.api(Method::POST, format!("{}/api/v1/results/{old}/publish", server.url)).send().await;
    assert_eq!(published.unwrap().status(), 200);
    let deleted = ada.api(Method::DELETE, format!("{}/api/v1/projects/box-filter-cpp", server.url)).send().await;
    assert_eq!(deleted.unwrap().status(), 204);

    // Bob takes the name and publishes his own set: ada's stays on the board.
    let (_, new) = benchmark(&server, &bob, "box-filter-cpp", "public", b"png".to_vec()).await;
    for path in [format!("/api/v1/results/{old}/publish"), format!("/api/v1/results/{old}/unpublish")] {
        let (status, body) =
            json_of(bob.api(Method::POST, format!("{}{path}", server.url)).send().await.unwrap()).await;
        assert_eq!(status, 404, "{path}: {body}");
    }
    let (status, body) = json_of(
        bob.api(Method::POST, format!("{}/api/v1/projects/box-filter-cpp/pipelines", server.url))
            .json(&json!({ "variables": { "FBKSD_PUBLISH": old } }))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(status, 404, "{body}");
    let published = bob.api(Method::POST, format!("{}/api/v1/results/{new}/publish", server.url)).send().await;
    assert_eq!(published.unwrap().status(), 200);
    let (status, set) = json_of(reqwest::get(format!("{}/api/v1/results/{old}", server.url)).await.unwrap()).await;
    assert_eq!(status, 200, "ada's set is still published: {set}");
    assert_eq!(set["result"]["project"], Value::Null, "and belongs to no project");
    let (_, board) = json_of(reqwest::get(format!("{}/api/v1/leaderboard", server.url)).await.unwrap()).await;
    let mut on_board: Vec<&str> =
        board["standings"].as_array().unwrap().iter().map(|s| s["result_id"].as_str().unwrap()).collect();
    on_board.sort();
    let mut both = vec![old.as_str(), new.as_str()];
    both.sort();
    assert_eq!(on_board, both, "{board}");

    // A new season re-runs bob's technique in bob's project, and not ada's
    // set there: its project is gone.
    let admin = server.admin().await;
    let (status, season) = json_of(
        admin
            .api(Method::POST, format!("{}/api/v1/admin/seasons", server.url))
            .json(&json!({ "note": "new scenes" }))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(status, 201, "{season}");
    assert_eq!(season["queued"].as_array().unwrap().len(), 1, "{season}");
    assert_eq!(season["skipped"][0]["why"], "its project or owner was deleted", "{season}");
    let jobs = common::project_jobs(&server, &bob, "box-filter-cpp").await;
    assert_eq!(jobs[0]["id"], season["queued"][0]["job"]);
});

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_data_directory_is_the_owners_alone() {
    use std::os::unix::fs::PermissionsExt;
    let server = spawn(Db::Sqlite).await;
    let ada = server.user("ada@example.org").await;
    benchmark(&server, &ada, "box-filter-cpp", "private", b"png".to_vec()).await;
    let data = server.config().data_dir.clone();
    let mode = |path: &std::path::Path| std::fs::metadata(path).unwrap().permissions().mode() & 0o777;
    let check = || {
        assert_eq!(mode(&data), 0o700, "{}", data.display());
        for dir in ["outbox", "results", "uploads", "git"] {
            assert_eq!(mode(&data.join(dir)), 0o700, "{dir}");
        }
        assert_eq!(mode(&data.join("fbksd.sqlite3")), 0o600, "the database");
    };
    check();
    assert!(std::fs::read_dir(data.join("outbox")).unwrap().count() > 0, "mail was written inside");
    assert!(std::fs::read_dir(data.join("results")).unwrap().count() > 0, "a set was stored inside");

    // A data directory left open (an older version, a careless copy) is closed at the next start.
    for path in [data.clone(), data.join("outbox"), data.join("results")] {
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    std::fs::set_permissions(data.join("fbksd.sqlite3"), std::fs::Permissions::from_mode(0o644)).unwrap();
    let _again = server.another_instance().await;
    check();
}

/// Request bodies are streamed to disk, never held whole: before, each git
/// request was read into memory up to 2 × `max_push_bytes` + 1 MiB (also
/// anonymous fetches of a public project, before any git slot was asked
/// for), and each runner upload up to 256 MiB before the job's budget was
/// charged. The peak is the process's (nextest runs each test in its own).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn request_bodies_are_streamed_not_held() {
    const MIB: u64 = 1 << 20;
    let server = spawn_with(Db::Sqlite, |c| {
        c.max_push_bytes = 32 * MIB;
        c.max_upload_bytes = 200 * MIB;
    })
    .await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "box-filter-cpp", "public").await;
    let repo = technique_repository("box-filter-cpp");
    let (pushed, output) = push(repo.path(), &server.clone_url("box-filter-cpp", &ada.token), &["FBKSD_RUN"]);
    assert!(pushed, "{output}");
    let runner = FakeRunner::register(&server, "runner").await;
    let job = runner.claim(5).await.expect("the benchmark job");
    let before = common::peak_memory();

    // Push requests of 60 MiB each, at once: git answers them, none is held.
    let git = "/git/box-filter-cpp.git";
    use base64::Engine;
    let basic = base64::engine::general_purpose::STANDARD.encode(format!("git:{}", ada.token));
    let push_headers =
        format!("Authorization: Basic {basic}\r\nContent-Type: application/x-git-receive-pack-request\r\n");
    let receive_pack = format!("{git}/git-receive-pack");
    let pushes = (0..4).map(|_| common::send_zeros(&server.url, "POST", &receive_pack, 60 * MIB, &push_headers));
    let answers = futures_util::future::join_all(pushes).await;
    assert!(answers.iter().all(|s| *s != 413 && *s != 401), "within the cap: {answers:?}");
    let after_pushes = common::peak_memory();
    assert!(
        after_pushes - before < 16 * MIB,
        "4 pushes of 60 MiB raised the peak by {} MiB",
        (after_pushes - before) / MIB
    );
    // Past the cap (2 × 32 + 1 MiB), refused; an anonymous fetch request past 16 MiB too.
    assert_eq!(common::send_zeros(&server.url, "POST", &receive_pack, 70 * MIB, &push_headers).await, 413);
    let fetch_headers = "Content-Type: application/x-git-upload-pack-request\r\n";
    assert_eq!(
        common::send_zeros(&server.url, "POST", &format!("{git}/git-upload-pack"), 20 * MIB, fetch_headers).await,
        413
    );
    // Nothing of them is left beside the repositories.
    let spool = server.config().data_dir.join("git-spool");
    assert_eq!(std::fs::read_dir(&spool).unwrap().count(), 0, "{}", spool.display());

    // A runner's 150 MiB file lands whole on disk.
    let auth = format!("Authorization: Bearer {}\r\n", job.token);
    let file = format!("/api/v1/jobs/{}/files/sin-bands/big.exr", job.id);
    assert_eq!(common::send_zeros(&server.url, "PUT", &file, 150 * MIB, &auth).await, 204);
    let staged = server.config().data_dir.join("uploads").join(&job.id).join("sin-bands");
    assert_eq!(std::fs::metadata(staged.join("big.exr")).unwrap().len(), 150 * MIB);
    let after_upload = common::peak_memory();
    assert!(
        after_upload - before < 16 * MIB,
        "a 150 MiB upload raised the peak by {} MiB",
        (after_upload - before) / MIB
    );
    // The next 100 MiB pass the job's 200 MiB budget: refused there, and nothing of them kept.
    let over = format!("/api/v1/jobs/{}/files/sin-bands/over.exr", job.id);
    assert_eq!(common::send_zeros(&server.url, "PUT", &over, 100 * MIB, &auth).await, 413);
    let left: Vec<_> = std::fs::read_dir(&staged).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left, ["big.exr"], "the refused upload left a file");
    // What the refused upload had charged was given back: 40 MiB more still fit.
    let more = format!("/api/v1/jobs/{}/files/sin-bands/more.exr", job.id);
    assert_eq!(
        common::send_zeros(&server.url, "PUT", &more, 40 * MIB, &auth).await,
        204,
        "the budget was kept charged"
    );
}

/// PUTs `upload` as the results of `job`; the answer's status, error code and message.
async fn put_results(runner: &FakeRunner, job: &common::HeldJob, upload: &Value) -> (u16, String, String) {
    let response = runner.job_request(Method::PUT, &job.id, &job.token, "results").body(upload.to_string()).send();
    let (status, body) = json_of(response.await.unwrap()).await;
    let text = |key: &str| body[key].as_str().unwrap_or_default().to_string();
    (status, text("error"), text("message"))
}

on_both_databases!(
    a_runner_scores_only_against_the_services_references_with_every_field_checked,
    |db: Db| async move {
        let server = spawn(db).await;
        let ada = server.user("ada@example.org").await;
        server.create_project(&ada, "box", "public").await;
        let repo = technique_repository("box-filter-cpp");
        assert!(push(repo.path(), &server.clone_url("box", &ada.token), &["FBKSD_RUN"]).0);
        let runner = FakeRunner::register(&server, "r").await;
        let job = runner.claim(5).await.expect("the benchmark job");
        let honest = common::results_upload(1.0);
        for run in honest["runs"].as_array().unwrap() {
            let name = run["image"].as_str().unwrap();
            assert_eq!(job.send(&runner, Method::PUT, &format!("files/{name}"), b"PNG".to_vec().into()).await, 204);
        }

        // Scored against images the service never stored: refused, so no set
        // of a runner's own making can take a scene's board from the others.
        let (status, code, message) = put_results(&runner, &job, &honest).await;
        assert_eq!((status, code.as_str()), (400, "unknown_reference"), "{message}");
        assert!(message.contains("scenes[0] (sin-bands): reference sha256:"), "{message}");
        assert!(message.contains("is not one the service stores"), "{message}");

        // Against a stored reference of another scene: refused too.
        for scene in ["sin-bands", "defocus-checkerboard"] {
            common::stored_reference(&runner, scene).await;
        }
        let mut swapped = honest.clone();
        swapped["scenes"][1]["reference_hash"] = honest["scenes"][0]["reference_hash"].clone();
        let (status, code, message) = put_results(&runner, &job, &swapped).await;
        assert_eq!((status, code.as_str()), (400, "unknown_reference"), "{message}");
        assert!(message.contains("scenes[1] (defocus-checkerboard)"), "{message}");
        assert!(
            message.contains("was made for fake/sin-bands, and no runner asked for it under the name"),
            "{message}"
        );

        // Fields the server joins to its folders, shows or stores row by row.
        let many_runs: Vec<Value> = (0..4097).map(|_| honest["runs"][0].clone()).collect();
        let cases: [(&str, Value, &str); 8] = [
            (
                "/runs/0/log",
                json!("/etc/passwd"),
                "runs[0] (sin-bands at 4 spp): log \"/etc/passwd\" is not a relative path",
            ),
            ("/runs/1/log", json!("../../users.db"), "runs[1] (sin-bands at 16 spp): log \"../../users.db\""),
            ("/runs/2/spp", json!(0), "runs[2] (defocus-checkerboard at 0 spp): spp must be 1 to"),
            ("/scenes/0/name", json!("<b>x</b>"), "scenes[0]: name \"<b>x</b>\" must be 1 to 100 letters"),
            ("/scenes/1/tags/0", json!("<script>"), "scenes[1] (defocus-checkerboard): tag \"<script>\" must be"),
            ("/scenes/1/scene_hash", json!("h"), "scenes[1] (defocus-checkerboard): scene_hash \"h\" is not sha256:"),
            ("/metrics/0/acronym", json!("M S E"), "metrics[0]: acronym \"M S E\" must be 1 to 32"),
            ("/runs", json!(many_runs), "results: 4097 runs; at most 4096 are stored"),
        ];
        for (pointer, value, expected) in cases {
            let mut bad = honest.clone();
            *bad.pointer_mut(pointer).unwrap() = value;
            let (status, code, message) = put_results(&runner, &job, &bad).await;
            assert_eq!((status, code.as_str()), (400, "invalid_output"), "{pointer}: {message}");
            assert!(message.contains(expected), "{pointer}: {message}");
        }

        // The honest upload is kept and stored.
        assert_eq!(put_results(&runner, &job, &honest).await.0, 204);
        let (status, done) = job.finish(&runner, json!({ "state": "succeeded" })).await;
        assert_eq!(status, 200, "{done}");
        let set = done["result_id"].as_str().unwrap();
        let (status, body) =
            json_of(ada.api(Method::GET, format!("{}/api/v1/results/{set}", server.url)).send().await.unwrap()).await;
        assert_eq!((status, body["runs"].as_array().map(Vec::len)), (200, Some(4)), "{body}");
    }
);

/// Runs git with `args` in `dir` off the runtime's threads (the server runs
/// in this process); (success, stdout and stderr).
async fn git_off_thread(dir: &std::path::Path, args: &[&str]) -> (bool, String) {
    let (dir, args) = (dir.to_path_buf(), args.iter().map(|a| a.to_string()).collect::<Vec<_>>());
    let out =
        tokio::task::spawn_blocking(move || common::git(&dir, &args.iter().map(String::as_str).collect::<Vec<_>>()))
            .await
            .unwrap();
    (out.status.success(), String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr))
}

/// One series of the server's `/metrics`.
async fn metric(server: &TestServer, series: &str) -> f64 {
    let text = reqwest::get(format!("{}/metrics", server.url)).await.unwrap().text().await.unwrap();
    common::sample(&text, series).unwrap_or_else(|| panic!("no {series} in {text}"))
}

/// Clones last as long as their clients read, and a git process serves
/// each. Before, 16 slow anonymous clones of a public project held all 16
/// processes, and pushes, signed-in clones and project pages waited behind
/// them (with no end: a client that reads a byte now and then is never
/// idle). Now all anonymous clients together have 4 requests at a time
/// (more are asked to sign in, so that git sends the token it has: a
/// signed-in clone of a public project starts anonymous), each caller 4,
/// the server's own reads (pages) their own processes, and a page reads a
/// commit's files once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn slow_clones_leave_git_to_everyone_else() {
    let server = spawn(Db::Sqlite).await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "big-box", "public").await;
    // A pack larger than every buffer between git and a client that stops
    // reading (pipe, sockets, the server's own): random bytes do not compress.
    let repo = common::repository_too_big_to_buffer();
    let owner_url = server.clone_url("big-box", &ada.token);
    let (pushed, output) = git_off_thread(repo.path(), &["push", &owner_url, "main"]).await;
    assert!(pushed, "{output}");
    let commit = String::from_utf8(common::git(repo.path(), &["rev-parse", "HEAD"]).stdout).unwrap();

    // 16 anonymous clients clone and stop reading: 4 are served, 12 are asked to sign in.
    let mut held = Vec::new();
    let mut statuses = Vec::new();
    for _ in 0..16 {
        let (status, stream) = common::slow_clone(&server.url, "big-box", commit.trim()).await;
        statuses.push(status);
        held.push(stream);
    }
    assert_eq!(statuses.iter().filter(|s| **s == 200).count(), 4, "{statuses:?}");
    assert_eq!(statuses.iter().filter(|s| **s == 401).count(), 12, "{statuses:?}");
    assert_eq!(metric(&server, "fbksd_git_requests_refused_total").await, 12.0);
    let anonymous_url = format!("{}/git/big-box.git", server.url);
    let (listed, output) = git_off_thread(repo.path(), &["ls-remote", &anonymous_url]).await;
    // git asks for credentials (here, with no terminal, it cannot).
    assert!(!listed && output.contains("could not read Username"), "{output}");

    // Everyone else is served meanwhile: the owner pushes, another user clones, the page shows.
    std::fs::write(repo.path().join("notes.txt"), "second\n").unwrap();
    common::commit_all(repo.path(), "second");
    let (pushed, output) = git_off_thread(repo.path(), &["push", &owner_url, "main"]).await;
    assert!(pushed, "the owner's push: {output}");
    let bob = server.user("bob@example.org").await;
    let clone = tempfile::tempdir().unwrap();
    let bob_url = server.clone_url("big-box", &bob.token);
    let (cloned, output) = git_off_thread(clone.path(), &["clone", "-q", &bob_url, "copy"]).await;
    assert!(cloned, "a signed-in clone: {output}");
    assert!(clone.path().join("copy/notes.txt").is_file());
    let read_before = metric(&server, "fbksd_git_processes_started_total{kind=\"read\"}").await;
    for view in 0..4 {
        let page = reqwest::get(format!("{}/projects/big-box", server.url)).await.unwrap();
        assert_eq!(page.status(), 200, "view {view}");
        assert!(page.text().await.unwrap().contains("Box filter (C++)"), "view {view}");
    }
    // The push's pipeline read the new head's files (ls-tree, cat-file): each view reads only which commit main is.
    let reads = metric(&server, "fbksd_git_processes_started_total{kind=\"read\"}").await - read_before;
    assert_eq!(reads, 4.0, "git reads for 4 views of one commit");

    // The slow clients go: their places come back.
    drop(held);
    let since = std::time::Instant::now();
    loop {
        let (listed, output) = git_off_thread(repo.path(), &["ls-remote", &anonymous_url]).await;
        if listed {
            break;
        }
        assert!(since.elapsed() < Duration::from_secs(60), "anonymous clients still refused: {output}");
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// What an account's repositories hold together is bounded, checked on
/// every push before anything is written. Before, only one push's size
/// was: 100 projects could each grow by a push at a time, for ever.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_accounts_repositories_hold_a_bounded_size_together() {
    let server = spawn_with(Db::Sqlite, |c| c.max_repository_mib_per_user = 1).await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "first", "private").await;
    server.create_project(&ada, "second", "private").await;
    let repo = technique_repository("box-filter-python");
    std::fs::write(repo.path().join("weights.bin"), common::noise(600_000, 0x9e37_79b9_7f4a_7c15)).unwrap();
    common::commit_all(repo.path(), "weights");
    let (pushed, output) = push(repo.path(), &server.clone_url("first", &ada.token), &[]);
    assert!(pushed, "600 KB fit in 1 MiB: {output}");

    // Another 600 KB, to the other project: the two would hold more than 1 MiB.
    let other = technique_repository("box-filter-python");
    std::fs::write(other.path().join("weights.bin"), common::noise(600_000, 0x2545_f491_4f6c_dd1d)).unwrap();
    common::commit_all(other.path(), "other weights");
    let (pushed, output) = push(other.path(), &server.clone_url("second", &ada.token), &["FBKSD_RUN"]);
    assert!(!pushed, "{output}");
    assert!(
        output.contains("FBKSD: this push brings 0.") && output.contains("of the 1 MiB one account may keep"),
        "the pusher is told why: {output}"
    );
    assert!(output.contains("delete a project you no longer need"), "and what to do: {output}");
    assert!(common::project_jobs(&server, &ada, "second").await.is_empty(), "a refused push starts nothing");
    let listed = common::git(other.path(), &["ls-remote", &server.clone_url("second", &ada.token)]);
    assert!(listed.status.success() && listed.stdout.is_empty(), "nothing was written: {listed:?}");

    // Room made by deleting the first project, the same push goes through.
    let response = ada.api(Method::DELETE, format!("{}/api/v1/projects/first", server.url)).send().await.unwrap();
    assert!(response.status().is_success(), "{}", response.status());
    let (pushed, output) = push(other.path(), &server.clone_url("second", &ada.token), &["FBKSD_RUN"]);
    assert!(pushed, "{output}");
    assert_eq!(common::project_jobs(&server, &ada, "second").await.len(), 1);
}

/// Rows a user makes stay bounded: projects and access tokens per account
/// have a most, expired sessions and mail tokens go as new ones come, and
/// the list of projects is read a page at a time. Before, each was kept
/// for ever, and `/projects` loaded every row for every anonymous view.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn what_accounts_make_stays_bounded_and_lists_come_in_pages() {
    let server = spawn_with(Db::Sqlite, |c| c.max_projects_per_user = 102).await;
    let ada = server.user("ada@example.org").await;
    for n in 0..102 {
        server.create_project(&ada, &format!("p{n:03}"), "public").await;
    }
    let create = |name: &str| {
        ada.api(Method::POST, format!("{}/api/v1/projects", server.url))
            .json(&json!({ "name": name, "visibility": "public" }))
            .send()
    };
    let (status, refused) = json_of(create("one-more").await.unwrap()).await;
    assert_eq!((status, refused["error"].as_str()), (403, Some("too_many_projects")), "{refused}");
    assert!(refused["message"].as_str().unwrap().contains("102 projects"), "{refused}");
    let bob = server.user("bob@example.org").await;
    server.create_project(&bob, "bobs-own", "private").await;

    // 100 a page, by name, the next page linked; others' private projects never listed.
    let anonymous = reqwest::get(format!("{}/api/v1/projects", server.url)).await.unwrap();
    let next = anonymous.headers().get("link").expect("a link to the next page").to_str().unwrap().to_string();
    let first: Vec<Value> = anonymous.json().await.unwrap();
    assert_eq!(first.len(), 100);
    assert_eq!((first[0]["name"].as_str(), first[99]["name"].as_str()), (Some("p000"), Some("p099")));
    let next_url = next.trim_start_matches('<').split('>').next().unwrap().to_string();
    assert!(next.ends_with("rel=\"next\"") && next_url.ends_with("?after=p099"), "{next}");
    let second = reqwest::get(&next_url).await.unwrap();
    assert!(second.headers().get("link").is_none(), "the last page links nowhere");
    let second: Vec<Value> = second.json().await.unwrap();
    let names: Vec<_> = second.iter().map(|p| p["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["p100", "p101"]);
    let (_, bobs) = json_of(bob.api(Method::GET, next_url.clone()).send().await.unwrap()).await;
    let names: Vec<_> = bobs.as_array().unwrap().iter().map(|p| p["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["p100", "p101"], "bobs-own sorts first: on bob's first page");
    let page = reqwest::get(format!("{}/projects", server.url)).await.unwrap().text().await.unwrap();
    assert!(page.contains("/projects/p099") && !page.contains("/projects/p100"), "100 on the first page");
    assert!(page.contains("href=\"/projects?after=p099\""), "a link to the next page");
    let page = reqwest::get(format!("{}/projects?after=p099", server.url)).await.unwrap().text().await.unwrap();
    assert!(page.contains("/projects/p101") && !page.contains("bobs-own") && !page.contains("Next page"));

    // Access tokens: 50 an account (ada made one when she logged in).
    let token = |name: String| {
        let create = ada.browser.post(format!("{}/api/v1/tokens", server.url)).header("X-CSRF-Token", &ada.csrf);
        create.json(&json!({ "name": name })).send()
    };
    for n in 1..50 {
        assert_eq!(token(format!("t{n}")).await.unwrap().status(), 201, "token {n}");
    }
    let (status, refused) = json_of(token("t50".into()).await.unwrap()).await;
    assert_eq!((status, refused["error"].as_str()), (403, Some("too_many_tokens")), "{refused}");

    // An expired session and mail token are gone once a new one is made.
    let db = fbksd_server::db::connect(&server.config().database_url()).await.unwrap();
    let count = |table: &'static str| {
        let db = db.clone();
        async move {
            let sql = format!("SELECT COUNT(*) FROM {table}");
            sqlx::query_scalar::<_, i64>(&sql).fetch_one(&db).await.unwrap()
        }
    };
    sqlx::query("UPDATE sessions SET expires_at = 1").execute(&db).await.unwrap();
    sqlx::query("UPDATE email_tokens SET expires_at = 1").execute(&db).await.unwrap();
    let (sessions, mail_tokens) = (count("sessions").await, count("email_tokens").await);
    assert!(sessions >= 2 && mail_tokens >= 2, "{sessions} sessions, {mail_tokens} mail tokens");
    let _again = server.log_in("bob@example.org", "a long enough password", server.browser()).await;
    assert_eq!(count("sessions").await, 1, "only the new session is left");
    let reset = reqwest::Client::new()
        .post(format!("{}/api/v1/password-resets", server.url))
        .json(&json!({ "email": "bob@example.org" }))
        .send()
        .await
        .unwrap();
    assert!(reset.status().is_success(), "{}", reset.status());
    assert_eq!(count("email_tokens").await, 1, "only the new mail token is left");
}
