//! The service's main path through the real HTTP API, real git and a fake
//! runner, on SQLite and on PostgreSQL: register → verify → create project →
//! `git push` → build job → FBKSD_RUN → results uploaded → private page →
//! publish → leaderboard; and who may do what on the way.

mod common;

use common::{json_of, log_text, project_jobs, push, spawn, spawn_with, technique_repository, Db, FakeRunner};
use reqwest::Method;
use serde_json::json;

on_both_databases!(push_build_run_publish_and_the_leaderboard, |db: Db| async move {
    let server = spawn(db).await;
    let ada = server.user("ada@example.org").await;
    let project = server.create_project(&ada, "box-filter-cpp", "private").await;
    assert!(project["clone_url"].as_str().unwrap().ends_with("/git/box-filter-cpp.git"));

    // A push with real git starts a build job.
    let repo = technique_repository("box-filter-cpp");
    let (pushed, output) = push(repo.path(), &server.clone_url("box-filter-cpp", &ada.token), &[]);
    assert!(pushed, "{output}");
    let jobs = project_jobs(&server, &ada, "box-filter-cpp").await;
    assert_eq!(jobs.len(), 1);
    assert_eq!((jobs[0]["kind"].as_str(), jobs[0]["state"].as_str()), (Some("build"), Some("queued")));
    let head = String::from_utf8(common::git(repo.path(), &["rev-parse", "HEAD"]).stdout).unwrap().trim().to_string();
    assert_eq!(jobs[0]["commit_sha"], head);

    // A runner claims it, clones the commit with its job token, reports.
    let runner = FakeRunner::register(&server, "runner-1").await;
    let build = runner.claim(5).await.expect("the build job");
    assert_eq!(build.body["commit"], head);
    let clone = tempfile::tempdir().unwrap();
    let url = server.clone_url("box-filter-cpp", &build.token);
    let cloned = common::git(clone.path(), &["clone", "-q", &url, "src"]);
    assert!(cloned.status.success(), "{}", String::from_utf8_lossy(&cloned.stderr));
    assert!(clone.path().join("src/info.json").is_file());
    assert_eq!(build.send(&runner, Method::POST, "heartbeat", "".into()).await, 200);
    assert_eq!(build.send(&runner, Method::POST, "log", "cmake --build: ok\n".into()).await, 204);
    assert_eq!(build.finish(&runner, json!({ "state": "succeeded" })).await.0, 200);
    assert!(log_text(&server, &ada, &build.id).await.contains("cmake --build: ok"));
    // The job is over: its token is worthless, also for git.
    assert_eq!(build.send(&runner, Method::POST, "heartbeat", "".into()).await, 410);
    assert!(!common::git(clone.path(), &["clone", "-q", &url, "again"]).status.success());

    // FBKSD_RUN from a push: a benchmark job.
    common::commit_all(repo.path(), "run it");
    let (pushed, output) = push(repo.path(), &server.clone_url("box-filter-cpp", &ada.token), &["FBKSD_RUN"]);
    assert!(pushed, "{output}");
    let bench = runner.claim(5).await.expect("the benchmark job");
    assert_eq!(bench.body["job"]["kind"], "benchmark");
    common::upload_results(&runner, &bench, 1.0).await;
    let (status, done) = bench.finish(&runner, json!({ "state": "succeeded" })).await;
    assert_eq!(status, 200, "{done}");
    let result_id = done["result_id"].as_str().unwrap().to_string();
    let private_url = format!("{}/results/{result_id}", server.url);
    assert!(log_text(&server, &ada, &bench.id).await.contains(&private_url), "the private URL is in the job log");
    assert!(server.mails_to("ada@example.org").last().unwrap().contains(&private_url), "and in a mail");

    // The private result: its owner sees it beside the (empty) leaderboard.
    let (status, result) =
        json_of(ada.api(Method::GET, format!("{}/api/v1/results/{result_id}", server.url)).send().await.unwrap()).await;
    assert_eq!(status, 200, "{result}");
    assert_eq!(result["runs"].as_array().unwrap().len(), 4);
    assert_eq!(result["result"]["commit_sha"].as_str().unwrap().len(), 40);
    assert_eq!(result["result"]["provenance"]["image_digest"], "sha256:0123");
    assert_eq!(result["result"]["info"]["short_name"], "box-filter-cpp");
    assert_eq!(result["board"]["standings"][0]["highlighted"], true);
    let image = reqwest::get(format!("{private_url}/files/sin-bands/4_0.png")).await.unwrap();
    assert_eq!(image.status(), 404, "anonymous users cannot fetch a private result's files");

    // Another user can see none of it.
    let bob = server.user("bob@example.org").await;
    let bob_get = |path: String| bob.api(Method::GET, format!("{}{path}", server.url)).send();
    assert_eq!(bob_get(format!("/api/v1/results/{result_id}")).await.unwrap().status(), 404);
    assert_eq!(bob_get(format!("/api/v1/jobs/{}/log", bench.id)).await.unwrap().status(), 404);
    assert_eq!(bob_get("/api/v1/projects/box-filter-cpp".into()).await.unwrap().status(), 404);
    for (method, tail) in [(Method::POST, "/publish"), (Method::POST, "/unpublish"), (Method::DELETE, "")] {
        let response =
            bob.api(method, format!("{}/api/v1/results/{result_id}{tail}", server.url)).send().await.unwrap();
        assert_eq!(response.status(), 404, "bob {tail}");
    }
    let (pushed, output) = push(repo.path(), &server.clone_url("box-filter-cpp", &bob.token), &[]);
    assert!(!pushed && output.contains("not found"), "bob cannot push (nor learn the project exists): {output}");
    let (pushed, output) = push(repo.path(), &server.clone_url("box-filter-cpp", "fbksd_wrong"), &[]);
    assert!(!pushed && output.contains("Authentication failed"), "{output}");

    // Publishing puts it on the public leaderboard.
    let leaderboard =
        || async { json_of(reqwest::get(format!("{}/api/v1/leaderboard", server.url)).await.unwrap()).await.1 };
    assert_eq!(leaderboard().await["standings"].as_array().unwrap().len(), 0);
    let published =
        ada.api(Method::POST, format!("{}/api/v1/results/{result_id}/publish", server.url)).send().await.unwrap();
    assert_eq!(published.status(), 200);
    let board = leaderboard().await;
    assert_eq!(board["standings"][0]["technique"], "box-filter-cpp");
    assert_eq!(board["groups"].as_array().unwrap().len(), 4, "two scenes at two budgets");
    assert_eq!(board["sort"], "MSE");
    assert_eq!(reqwest::get(format!("{private_url}/files/sin-bands/4_0.png")).await.unwrap().status(), 200);
    assert_eq!(
        bob_get(format!("/api/v1/results/{result_id}")).await.unwrap().status(),
        200,
        "published: everyone sees it"
    );

    // Unpublish, then publish again with FBKSD_PUBLISH through the API.
    ada.api(Method::POST, format!("{}/api/v1/results/{result_id}/unpublish", server.url)).send().await.unwrap();
    assert_eq!(leaderboard().await["standings"].as_array().unwrap().len(), 0);
    let (status, body) = json_of(
        ada.api(Method::POST, format!("{}/api/v1/projects/box-filter-cpp/pipelines", server.url))
            .json(&json!({ "variables": { "FBKSD_PUBLISH": result_id } }))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(status, 201, "{body}");
    assert_eq!((body["job"]["kind"].as_str(), body["job"]["state"].as_str()), (Some("publish"), Some("succeeded")));
    assert_eq!(leaderboard().await["standings"][0]["result_id"], result_id.as_str());

    // Discard: gone for everyone, the owner too.
    let discarded = ada.api(Method::DELETE, format!("{}/api/v1/results/{result_id}", server.url)).send().await.unwrap();
    assert_eq!(discarded.status(), 204);
    assert_eq!(
        ada.api(Method::GET, format!("{}/api/v1/results/{result_id}", server.url)).send().await.unwrap().status(),
        404
    );
    assert_eq!(leaderboard().await["standings"].as_array().unwrap().len(), 0);
});

on_both_databases!(a_lost_lease_queues_the_job_again_for_another_runner, |db: Db| async move {
    let server = spawn_with(db, |c| c.lease_seconds = 1).await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "lease", "private").await;
    let repo = technique_repository("box-filter-python");
    assert!(push(repo.path(), &server.clone_url("lease", &ada.token), &[]).0);

    let (first, second) = (FakeRunner::register(&server, "dies").await, FakeRunner::register(&server, "lives").await);
    let lost = first.claim(5).await.unwrap();
    assert_eq!(second.claim(0).await.map(|j| j.id), None, "a running job is not handed out twice");
    // `first` stops heart-beating; after the lease, `second` gets the job.
    let taken = second.claim(5).await.expect("requeued after the lease");
    assert_eq!(taken.id, lost.id);
    assert_eq!(taken.body["job"]["attempts"], 2);
    assert_eq!(lost.send(&first, Method::POST, "heartbeat", "".into()).await, 410, "the old token is void");
    assert_eq!(lost.send(&first, Method::POST, "log", "late\n".into()).await, 410);
    assert_eq!(taken.finish(&second, json!({ "state": "succeeded" })).await.0, 200);
    let log = log_text(&server, &ada, &taken.id).await;
    assert!(log.contains("lease expired") && !log.contains("late"), "{log}");
});

on_both_databases!(an_attempt_past_max_job_seconds_fails_however_its_runner_beats, |db: Db| async move {
    let server = spawn_with(db, |c| c.max_job_seconds = 2).await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "slow", "private").await;
    let repo = technique_repository("box-filter-python");
    assert!(push(repo.path(), &server.clone_url("slow", &ada.token), &[]).0);
    let runner = FakeRunner::register(&server, "r").await;
    let job = runner.claim(5).await.unwrap();
    // The runner keeps its lease alive, as a runner holding a job for ever would.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    loop {
        let status = job.send(&runner, Method::POST, "heartbeat", "".into()).await;
        if status == 410 {
            break;
        }
        assert_eq!(status, 200);
        assert!(std::time::Instant::now() < deadline, "the attempt was never stopped");
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    let jobs = project_jobs(&server, &ada, "slow").await;
    assert_eq!((jobs[0]["state"].as_str(), jobs[0]["failure_reason"].as_str()), (Some("failed"), Some("timeout")));
    let message = jobs[0]["message"].as_str().unwrap();
    assert!(message.contains("past the service's limit of 2 s per attempt (max_job_seconds)"), "{message}");
    assert_eq!(job.finish(&runner, json!({ "state": "succeeded" })).await.0, 410, "its token is void");
});

on_both_databases!(runners_racing_for_jobs_get_each_job_once, |db: Db| async move {
    let server = spawn(db).await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "race", "private").await;
    let repo = technique_repository("box-filter-python");
    for i in 0..3 {
        common::commit_all(repo.path(), &format!("commit {i}"));
        assert!(push(repo.path(), &server.clone_url("race", &ada.token), &[]).0);
    }
    // On PostgreSQL, half the runners talk to a second server instance.
    let second = match db {
        Db::Postgres => Some(server.another_instance().await),
        Db::Sqlite => None,
    };
    let mut runners = Vec::new();
    for i in 0..8 {
        let instance = if i % 2 == 1 { second.as_ref().unwrap_or(&server) } else { &server };
        runners.push(FakeRunner::register(instance, &format!("r{i}")).await);
    }
    let claims = futures_util::future::join_all(runners.iter().map(|r| r.claim(1))).await;
    let mut ids: Vec<String> = claims.into_iter().flatten().map(|j| j.id).collect();
    ids.sort();
    let count = ids.len();
    ids.dedup();
    assert_eq!((count, ids.len()), (3, 3), "three jobs, each claimed by exactly one of eight runners");
    let runners_seen: std::collections::BTreeSet<String> =
        futures_util::future::join_all(runners.iter().map(|r| r.claim(0)))
            .await
            .into_iter()
            .flatten()
            .map(|j| j.id)
            .collect();
    assert!(runners_seen.is_empty(), "nothing left to claim");
});

on_both_databases!(tokens_only_do_what_they_are_for, |db: Db| async move {
    let server = spawn(db).await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "tokens", "public").await;
    let repo = technique_repository("box-filter-python");
    assert!(push(repo.path(), &server.clone_url("tokens", &ada.token), &[]).0);
    common::commit_all(repo.path(), "second");
    assert!(push(repo.path(), &server.clone_url("tokens", &ada.token), &[]).0);
    let runner = FakeRunner::register(&server, "r").await;
    let (a, b) = (runner.claim(1).await.unwrap(), runner.claim(1).await.unwrap());

    // A job token cannot touch another job.
    let cross = runner.job_request(Method::POST, &b.id, &a.token, "heartbeat").send().await.unwrap();
    assert_eq!(
        json_of(cross).await,
        (403, json!({ "error": "wrong_job", "message": "this job token belongs to another job" }))
    );
    // Runner and job tokens cannot act as a user, nor push.
    for token in [&runner.token, &a.token] {
        let me =
            reqwest::Client::new().get(format!("{}/api/v1/me", server.url)).bearer_auth(token).send().await.unwrap();
        assert_eq!(json_of(me).await.1["error"], "not_a_user_token");
        let (pushed, _) = push(repo.path(), &server.clone_url("tokens", token), &[]);
        assert!(!pushed);
    }
    // A user token cannot claim jobs; a bad registration token registers nothing.
    let claim = reqwest::Client::new()
        .post(format!("{}/api/v1/runners/jobs", server.url))
        .bearer_auth(&ada.token)
        .send()
        .await
        .unwrap();
    assert_eq!(claim.status(), 401);
    let register = reqwest::Client::new()
        .post(format!("{}/api/v1/runners", server.url))
        .json(&json!({ "registration_token": "guess", "name": "x" }))
        .send()
        .await
        .unwrap();
    assert_eq!(register.status(), 401);
    // A user cannot report on a job with their own token.
    let forged = runner
        .job_request(Method::POST, &a.id, &ada.token, "finish")
        .json(&json!({ "state": "succeeded" }))
        .send()
        .await
        .unwrap();
    assert_eq!(forged.status(), 401);
    // Only administrators administer.
    let admin_only = ada.api(Method::GET, format!("{}/api/v1/admin/jobs", server.url)).send().await.unwrap();
    assert_eq!(json_of(admin_only).await.1["error"], "not_admin");
});

on_both_databases!(a_reference_is_made_once_for_every_runner, |db: Db| async move {
    let server = spawn(db).await;
    let (maker, other) = (FakeRunner::register(&server, "maker").await, FakeRunner::register(&server, "other").await);
    let key = fbksd_exchange::scenes::reference_key("test renderer 1", 4, "sha256:scene");
    let ask = json!({ "key": key, "scene": "experimental/sphere", "name": "sphere" });

    // Runners asking at once: one reference job for the key.
    let asks =
        (0..6).map(|i| if i % 2 == 0 { &maker } else { &other }).map(|r| r.post("runners/references", ask.clone()));
    let answers = futures_util::future::join_all(asks).await;
    let jobs: std::collections::BTreeSet<_> = answers.iter().map(|(_, a)| a["job_id"].to_string()).collect();
    assert_eq!(jobs.len(), 1, "{answers:?}");
    assert!(answers.iter().all(|(s, a)| *s == 200 && a["state"] == "building"), "{answers:?}");

    // Only a runner with that scene gets the job, before any other.
    let elsewhere = json!({ "reference_keys": ["sha256:".to_string() + &"0".repeat(64)], "references_only": true });
    assert!(other.claim_with(elsewhere).await.is_none());
    let job = maker.claim_with(json!({ "reference_keys": [key], "references_only": true })).await.unwrap();
    assert_eq!(job.body["job"]["kind"], "reference", "{}", job.body);
    assert_eq!(job.body["reference"], json!({ "key": key, "scene": "experimental/sphere" }));

    // Its end is refused until the reference is whole and its note makes the key.
    let (status, body) = job.finish(&maker, json!({ "state": "succeeded" })).await;
    assert_eq!(status, 409, "{body}");
    let wrong = json!({ "generator": "test renderer 1", "samples_per_pixel": 8, "scene_digest": "sha256:scene" });
    assert_eq!(job.send(&maker, Method::PUT, "files/reference.json", wrong.to_string().into()).await, 204);
    assert_eq!(job.send(&maker, Method::PUT, "files/reference.exr", b"EXR pixels".to_vec().into()).await, 204);
    let (status, body) = job.finish(&maker, json!({ "state": "succeeded" })).await;
    assert_eq!(status, 400, "{body}");
    assert!(body["message"].as_str().unwrap().contains("but the job makes"), "{body}");
    let note = json!({ "generator": "test renderer 1", "samples_per_pixel": 4, "scene_digest": "sha256:scene" });
    assert_eq!(job.send(&maker, Method::PUT, "files/reference.json", note.to_string().into()).await, 204);
    assert_eq!(job.send(&maker, Method::PUT, "files/reference-albedo.exr", b"albedo".to_vec().into()).await, 204);
    let (status, body) = job.finish(&maker, json!({ "state": "succeeded" })).await;
    assert_eq!(status, 200, "{body}");

    // Every other runner downloads it, and can check it.
    let (status, ready) = other.post("runners/references", ask.clone()).await;
    let digest = format!("sha256:{:x}", <sha2::Sha256 as sha2::Digest>::digest(b"EXR pixels"));
    assert_eq!((status, &ready["state"], &ready["reference_hash"]), (200, &json!("ready"), &json!(digest)), "{ready}");
    assert_eq!(ready["files"], json!(["reference-albedo.exr", "reference.exr", "reference.json"]));
    assert_eq!(ready["job_id"].to_string(), *jobs.first().unwrap());
    assert_eq!(
        other.get(&format!("runners/references/{key}/files/reference.exr")).await,
        (200, b"EXR pixels".to_vec())
    );
    assert_eq!(other.get(&format!("runners/references/{key}/files/secrets.txt")).await.0, 400);
    let unknown = "sha256:".to_string() + &"1".repeat(64);
    assert_eq!(other.get(&format!("runners/references/{unknown}/files/reference.exr")).await.0, 404);
    assert_eq!(other.post("runners/references", json!({ "key": "latest", "scene": "x", "name": "x" })).await.0, 400);
    // A runner older than the server, which sends no scene name, is told so.
    let (status, body) = other.post("runners/references", json!({ "key": key, "scene": "experimental/sphere" })).await;
    assert_eq!((status, body["error"].as_str()), (400, Some("invalid_scene")), "{body}");
    assert!(body["message"].as_str().unwrap().contains("upgrade it"), "{body}");

    // A failed reference job is retried by the next ask.
    let key2 = fbksd_exchange::scenes::reference_key("test renderer 1", 4, "sha256:other scene");
    let ask2 = json!({ "key": key2, "scene": "experimental/other", "name": "other" });
    let (_, first) = maker.post("runners/references", ask2.clone()).await;
    let failing = maker.claim_with(json!({ "reference_keys": [key2] })).await.unwrap();
    let (status, _) =
        failing.finish(&maker, json!({ "state": "failed", "reason": "crashed", "message": "renderer died" })).await;
    assert_eq!(status, 200);
    assert_eq!(other.get(&format!("runners/references/{key2}/files/reference.exr")).await.0, 404);
    let (_, again) = other.post("runners/references", ask2).await;
    assert_eq!(again["state"], "building", "{again}");
    assert_ne!(again["job_id"], first["job_id"], "a new job");

    // Users cannot take the references' project name.
    let ada = server.user("ada@example.org").await;
    let (status, body) = json_of(
        ada.api(Method::POST, format!("{}/api/v1/projects", server.url))
            .json(&json!({ "name": "scene-references" }))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(status, 409, "{body}");
});
