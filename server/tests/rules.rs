//! Bad input, quotas and administration, through the real API and real
//! git: each refusal says what was wrong, and nothing is half-written.

mod common;

use common::{json_of, project_jobs, push, spawn, spawn_with, technique_repository, Db, FakeRunner};
use reqwest::Method;
use serde_json::{json, Value};

async fn run_pipeline(
    server: &common::TestServer,
    user: &common::TestUser,
    name: &str,
    variables: Value,
) -> (u16, Value) {
    json_of(
        user.api(Method::POST, format!("{}/api/v1/projects/{name}/pipelines", server.url))
            .json(&json!({ "variables": variables }))
            .send()
            .await
            .unwrap(),
    )
    .await
}

on_both_databases!(a_broken_repository_fails_its_build_at_once_and_mails_the_author, |db: Db| async move {
    let server = spawn(db).await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "broken", "private").await;
    let repo = technique_repository("box-filter-cpp");
    std::fs::write(repo.path().join("info.json"), r#"{"short_name": "broken", "technique_type": "filter"}"#).unwrap();
    common::commit_all(repo.path(), "typo");
    assert!(push(repo.path(), &server.clone_url("broken", &ada.token), &[]).0, "the push itself lands");

    let jobs = project_jobs(&server, &ada, "broken").await;
    assert_eq!(jobs[0]["state"], "failed");
    assert_eq!(jobs[0]["failure_reason"], "build_failed");
    let message = jobs[0]["message"].as_str().unwrap();
    assert!(message.contains("\"technique_type\" \"filter\" is unknown"), "{message}");
    let mail = server.mails_to("ada@example.org").pop().unwrap();
    assert!(mail.contains("failed") && mail.contains("technique_type"), "{mail}");
    // No runner is ever given it.
    let runner = FakeRunner::register(&server, "r").await;
    assert!(runner.claim(0).await.is_none());
    // The API (and the Run button) make a failed job of the same commit
    // too: in the history, mailed, and answered 422 with the job.
    let (status, body) = run_pipeline(&server, &ada, "broken", json!({ "FBKSD_RUN": "1" })).await;
    assert_eq!(status, 422, "{body}");
    assert_eq!(body["job"]["state"], "failed");
    assert!(body["job"]["message"].as_str().unwrap().contains("\"technique_type\""), "{body}");
    assert_eq!(project_jobs(&server, &ada, "broken").await.len(), 2);
    assert_eq!(server.mails_to("ada@example.org").iter().filter(|m| m.contains("failed")).count(), 2);
    assert!(runner.claim(0).await.is_none());

    // An environment the service does not have: the push's answer says so
    // and lists the ones it has, with where to read their contents.
    std::fs::write(
        repo.path().join("info.json"),
        r#"{"short_name": "broken", "technique_type": "denoiser", "environment": "cuda"}"#,
    )
    .unwrap();
    common::commit_all(repo.path(), "cuda");
    let (pushed, output) = push(repo.path(), &server.clone_url("broken", &ada.token), &[]);
    assert!(pushed, "{output}");
    assert!(output.contains("failed: info.json line 1: \"environment\" \"cuda\" is unknown: use \"cpp\" (CMake, gcc and C++ libraries) or \"python\""), "{output}");
    assert!(output.contains("/environments"), "{output}");
    assert!(runner.claim(0).await.is_none());
});

on_both_databases!(bad_variables_and_push_options_are_refused_before_anything_is_written, |db: Db| async move {
    let server = spawn(db).await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "vars", "private").await;
    let repo = technique_repository("box-filter-python");
    let url = server.clone_url("vars", &ada.token);

    let (pushed, output) = push(repo.path(), &url, &["FBKSD_RUNN"]);
    assert!(!pushed);
    assert!(output.contains("unknown push option 'FBKSD_RUNN'"), "{output}");
    assert!(output.contains("FBKSD_RUN (build and benchmark) and FBKSD_PUBLISH=<uuid>"), "the known ones: {output}");
    let (pushed, output) = push(repo.path(), &url, &["FBKSD_PUBLISH=not-a-uuid"]);
    assert!(!pushed && output.contains("needs the UUID"), "{output}");
    // Two requests in one push: refused by the hook with the API's own words.
    let key = uuid::Uuid::new_v4().to_string();
    let (pushed, hook_output) = push(repo.path(), &url, &["FBKSD_RUN", &format!("FBKSD_PUBLISH={key}")]);
    assert!(!pushed && hook_output.contains("cannot be combined"), "{hook_output}");
    assert!(project_jobs(&server, &ada, "vars").await.is_empty(), "no pipeline, and the refs did not move");
    assert_eq!(common::git(repo.path(), &["ls-remote", &url]).stdout.len(), 0);

    assert!(push(repo.path(), &url, &[]).0);
    for (variables, code) in [
        (json!({ "FBKSD_RNU": "1" }), "unknown_variable"),
        (json!({ "FBKSD_PUBLISH": "1234" }), "invalid_variable"),
        (json!({ "FBKSD_RUN": "1", "FBKSD_PUBLISH": key }), "conflicting_variables"),
    ] {
        let (status, body) = run_pipeline(&server, &ada, "vars", variables.clone()).await;
        assert_eq!((status, body["error"].as_str()), (400, Some(code)), "{variables}: {body}");
        if code == "conflicting_variables" {
            let rule = body["message"].as_str().unwrap();
            assert!(hook_output.contains(rule), "one rule in the hook and the API: {rule:?} vs {hook_output}");
        }
    }
    let (status, body) =
        run_pipeline(&server, &ada, "vars", json!({ "FBKSD_PUBLISH": uuid::Uuid::new_v4().to_string() })).await;
    assert_eq!((status, body["error"].as_str()), (404, Some("not_found")), "{body}");
    assert_eq!(project_jobs(&server, &ada, "vars").await.len(), 1, "only the push's build job");

    // Invalid UUIDs and unknown projects.
    let bad = ada.api(Method::GET, format!("{}/api/v1/results/not-a-uuid", server.url)).send().await.unwrap();
    assert_eq!(json_of(bad).await.1["error"], "invalid_uuid");
    let (status, body) = json_of(
        ada.api(Method::POST, format!("{}/api/v1/projects", server.url))
            .json(&json!({ "name": "Bad Name" }))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!((status, body["error"].as_str()), (400, Some("invalid_name")));
    let (status, _) = json_of(
        ada.api(Method::POST, format!("{}/api/v1/projects", server.url))
            .json(&json!({ "name": "vars" }))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(status, 409);
});

on_both_databases!(oversized_pushes_and_uploads_are_refused, |db: Db| async move {
    let server = spawn_with(db, |c| {
        c.max_push_bytes = 64 * 1024;
        c.max_upload_bytes = 4096;
    })
    .await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "big", "private").await;
    let repo = technique_repository("box-filter-python");
    // Well over the limit.
    std::fs::write(repo.path().join("weights.bin"), common::noise(400_000, 0x9e37_79b9_7f4a_7c15)).unwrap();
    common::commit_all(repo.path(), "big weights");
    let (pushed, output) = push(repo.path(), &server.clone_url("big", &ada.token), &[]);
    assert!(!pushed, "{output}");
    assert!(output.contains("maximum allowed size") || output.contains("413"), "{output}");
    assert!(project_jobs(&server, &ada, "big").await.is_empty());

    // A small push, then uploads over the job's limit.
    assert!(common::git(repo.path(), &["reset", "-q", "--hard", "HEAD~1"]).status.success());
    assert!(push(repo.path(), &server.clone_url("big", &ada.token), &["FBKSD_RUN"]).0);
    let runner = FakeRunner::register(&server, "r").await;
    let job = runner.claim(1).await.unwrap();
    let status = job.send(&runner, Method::PUT, "files/a.png", vec![0u8; 5000].into()).await;
    assert_eq!(status, 413);
    let status = job.send(&runner, Method::PUT, "files/../escape.png", vec![0u8; 10].into()).await;
    assert!(status == 400 || status == 404, "{status}");
    // Inconsistent results are refused with the problem named.
    let mut upload = common::results_upload(1.0);
    upload["runs"][0]["scene"] = json!("nowhere");
    let response =
        runner.job_request(Method::PUT, &job.id, &job.token, "results").body(upload.to_string()).send().await.unwrap();
    let (status, body) = json_of(response).await;
    assert_eq!((status, body["error"].as_str()), (400, Some("invalid_output")));
    assert!(body["message"].as_str().unwrap().contains("\"nowhere\" is not in \"scenes\""), "{body}");
    // Success without results stores nothing.
    let (status, body) = job.finish(&runner, json!({ "state": "succeeded" })).await;
    assert_eq!((status, body["error"].as_str()), (409, Some("no_results")));
    let (status, body) = job.finish(&runner, json!({ "state": "failed" })).await;
    assert_eq!((status, body["error"].as_str()), (400, Some("missing_reason")));
    let (status, _) = job
        .finish(&runner, json!({ "state": "failed", "reason": "invalid_output", "message": "NaN in 3 pixels" }))
        .await;
    assert_eq!(status, 200);
    let jobs = project_jobs(&server, &ada, "big").await;
    assert_eq!(
        (jobs[0]["state"].as_str(), jobs[0]["failure_reason"].as_str()),
        (Some("failed"), Some("invalid_output"))
    );
    assert!(jobs[0]["result_id"].is_null());
});

on_both_databases!(quotas_bound_queued_jobs_and_daily_runs, |db: Db| async move {
    let server = spawn_with(db, |c| {
        c.max_queued_jobs_per_user = 2;
        c.max_runs_per_day = 2;
    })
    .await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "quota", "private").await;
    let repo = technique_repository("box-filter-python");
    assert!(push(repo.path(), &server.clone_url("quota", &ada.token), &[]).0, "one build queued");
    let run = || run_pipeline(&server, &ada, "quota", json!({ "FBKSD_RUN": "1" }));
    let (status, first) = run().await;
    assert_eq!(status, 201);
    let (status, body) = run().await;
    assert_eq!((status, body["error"].as_str()), (429, Some("quota_queued")), "{body}");

    // Cancelled before starting: it does not count.
    let cancel =
        ada.api(Method::POST, format!("{}/api/v1/jobs/{}/cancel", server.url, first["job"]["id"].as_str().unwrap()));
    assert_eq!(cancel.send().await.unwrap().status(), 200);
    let runner = FakeRunner::register(&server, "r").await;
    runner.claim(0).await.unwrap().finish(&runner, json!({ "state": "succeeded" })).await;

    // An infrastructure failure on the last attempt does not count either.
    let (status, _) = run().await;
    assert_eq!(status, 201);
    for _ in 0..3 {
        let job = runner.claim(1).await.unwrap();
        job.finish(
            &runner,
            json!({ "state": "failed", "reason": "infrastructure_error", "message": "docker is down" }),
        )
        .await;
    }
    let (status, body) = run().await;
    assert_eq!(status, 201, "{body}");
    let job = runner.claim(1).await.unwrap();
    job.finish(&runner, json!({ "state": "failed", "reason": "crashed", "message": "segfault" })).await;
    let (status, _) = run().await;
    assert_eq!(status, 201, "two runs count now");
    let (status, body) = run().await;
    assert_eq!((status, body["error"].as_str()), (429, Some("quota_runs")), "{body}");
});

/// Each push over a quota was kept as a cancelled job (and each broken
/// commit as a failed one, mailed), and pushes of empty commits are cheap:
/// a loop of them filled the jobs table and the outbox without end. Now a
/// day keeps 20 refusals per user; later ones are told, not kept.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn refusals_over_a_quota_are_kept_only_so_many_a_day() {
    let server = spawn_with(Db::Sqlite, |c| c.max_queued_jobs_per_user = 1).await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "pushy", "private").await;
    let repo = technique_repository("box-filter-python");
    let url = server.clone_url("pushy", &ada.token);
    assert!(push(repo.path(), &url, &["FBKSD_RUN"]).0, "one run queued");
    let kept = fbksd_server::pipelines::REFUSALS_KEPT_PER_DAY as usize;
    for n in 0..kept + 2 {
        common::commit_all(repo.path(), &format!("again {n}"));
        let (pushed, output) = push(repo.path(), &url, &["FBKSD_RUN"]);
        assert!(pushed && output.contains("not run: you have 1 job queued"), "push {n}: {output}");
        assert_eq!(output.contains("not kept"), n >= kept, "push {n}: {output}");
    }
    // A broken commit past the day's most: told, neither kept nor mailed.
    let mails = server.mails_to("ada@example.org").len();
    std::fs::remove_file(repo.path().join("info.json")).unwrap();
    common::commit_all(repo.path(), "broken");
    let (pushed, output) = push(repo.path(), &url, &[]);
    assert!(pushed && output.contains("no info.json") && output.contains("not kept"), "{output}");
    assert_eq!(server.mails_to("ada@example.org").len(), mails, "no mail past the day's most");
    let jobs = project_jobs(&server, &ada, "pushy").await;
    let cancelled = jobs.iter().filter(|j| j["state"] == "cancelled").count();
    assert_eq!((jobs.len(), cancelled), (1 + kept, kept), "the queued run and {kept} refusals");
}

on_both_databases!(administrators_cancel_requeue_hide_and_start_seasons, |db: Db| async move {
    let server = spawn(db).await;
    let admin = server.admin().await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "seasoned", "private").await;
    let repo = technique_repository("box-filter-python");
    assert!(push(repo.path(), &server.clone_url("seasoned", &ada.token), &["FBKSD_RUN"]).0);
    let runner = FakeRunner::register(&server, "r").await;
    let job = runner.claim(1).await.unwrap();

    // Runners and their health.
    let (_, runners) =
        json_of(admin.api(Method::GET, format!("{}/api/v1/admin/runners", server.url)).send().await.unwrap()).await;
    assert_eq!(runners[0]["runner"]["running_jobs"], 1);
    assert_eq!(runners[0]["healthy"], true);
    assert_eq!(runners[0]["runner"]["machine"]["cpu_model"], "test CPU");
    // A runner busy with one job claims no other: the job's heartbeats keep it connected.
    let seen_at_claim = runners[0]["runner"]["last_seen_at"].as_i64().unwrap();
    tokio::time::sleep(std::time::Duration::from_millis(5)).await; // the next millisecond, at least
    assert_eq!(job.send(&runner, Method::POST, "heartbeat", "".into()).await, 200);
    let (_, runners) =
        json_of(admin.api(Method::GET, format!("{}/api/v1/admin/runners", server.url)).send().await.unwrap()).await;
    assert!(runners[0]["runner"]["last_seen_at"].as_i64().unwrap() > seen_at_claim, "{runners}");

    // Cancel a running job: the runner learns it at its next report.
    let cancelled =
        admin.api(Method::POST, format!("{}/api/v1/jobs/{}/cancel", server.url, job.id)).send().await.unwrap();
    assert_eq!(cancelled.status(), 200);
    assert_eq!(job.send(&runner, Method::POST, "heartbeat", "".into()).await, 410);
    // Requeue it; it runs to the end this time.
    let requeued =
        admin.api(Method::POST, format!("{}/api/v1/admin/jobs/{}/requeue", server.url, job.id)).send().await.unwrap();
    assert_eq!(requeued.status(), 200);
    let job = runner.claim(1).await.unwrap();
    common::upload_results(&runner, &job, 1.0).await;
    let result_id =
        job.finish(&runner, json!({ "state": "succeeded" })).await.1["result_id"].as_str().unwrap().to_string();
    ada.api(Method::POST, format!("{}/api/v1/results/{result_id}/publish", server.url)).send().await.unwrap();

    // Hide it: off the leaderboard, and its owner cannot publish it again.
    let hide = admin
        .api(Method::POST, format!("{}/api/v1/admin/results/{result_id}/hide", server.url))
        .json(&json!({ "reason": "tuned on the references" }));
    assert_eq!(hide.send().await.unwrap().status(), 204);
    let board = json_of(reqwest::get(format!("{}/api/v1/leaderboard", server.url)).await.unwrap()).await.1;
    assert!(board["standings"].as_array().unwrap().is_empty());
    let (status, body) = json_of(
        ada.api(Method::POST, format!("{}/api/v1/results/{result_id}/publish", server.url)).send().await.unwrap(),
    )
    .await;
    assert_eq!((status, body["error"].as_str()), (403, Some("hidden")));
    let unhide = admin.api(Method::DELETE, format!("{}/api/v1/admin/results/{result_id}/hide", server.url));
    assert_eq!(unhide.send().await.unwrap().status(), 204);

    // A new season re-runs every published technique; the old board stays.
    let (status, season) = json_of(
        admin
            .api(Method::POST, format!("{}/api/v1/admin/seasons", server.url))
            .json(&json!({ "note": "added caustics scenes" }))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!((status, season["season"].as_i64()), (201, Some(2)), "{season}");
    assert_eq!(season["queued"].as_array().unwrap().len(), 1);
    let url = server.url.clone();
    let board = |season: i64| {
        let url = url.clone();
        async move { json_of(reqwest::get(format!("{url}/api/v1/leaderboard?season={season}")).await.unwrap()).await.1 }
    };
    assert!(board(2).await["standings"].as_array().unwrap().is_empty());
    assert_eq!(board(1).await["standings"][0]["technique"], "seasoned");
    let rerun = runner.claim(1).await.unwrap();
    assert_eq!(rerun.body["job"]["season"], 2);
    common::upload_results(&runner, &rerun, 0.5).await;
    rerun.finish(&runner, json!({ "state": "succeeded" })).await;
    assert_eq!(board(2).await["standings"][0]["technique"], "seasoned", "published on success");
    assert_eq!(board(1).await["standings"][0]["result_id"], result_id.as_str(), "the old season is kept");
});

/// Creates `user`'s private project `name` and pushes the Python box
/// filter to it with FBKSD_RUN: a benchmark job is queued.
async fn queue_benchmark(server: &common::TestServer, user: &common::TestUser, name: &str) {
    server.create_project(user, name, "private").await;
    let repo = technique_repository("box-filter-python");
    assert!(push(repo.path(), &server.clone_url(name, &user.token), &["FBKSD_RUN"]).0);
}

/// The viewer document of result set `id`, as `user` gets it.
async fn viewer_of(server: &common::TestServer, user: &common::TestUser, id: &str) -> Value {
    let url = format!("{}/api/v1/results/{id}/viewer", server.url);
    json_of(user.api(Method::GET, url).send().await.unwrap()).await.1
}

/// The technique of key `key` in a viewer document.
fn technique_in(viewer: &Value, key: &str) -> Value {
    viewer["techniques"].as_array().unwrap().iter().find(|t| t["key"] == key).unwrap().clone()
}

/// A claim by `runner`, which says it is of runner class `class`.
async fn claim_as(runner: &FakeRunner, class: &str) -> Option<common::HeldJob> {
    runner.claim_with(json!({ "wait_seconds": 1, "runner_class": class })).await
}

on_both_databases!(
    a_seasons_times_come_from_one_runner_class_and_its_benchmarks_go_to_its_runners,
    |db: Db| async move {
        const SLOW: &str = "Slow CPU · x86-64-v2 · 2 cores · 8 GiB";
        const FAST: &str = "Fast CPU · x86-64-v4 · 2 cores · 8 GiB";
        let server = spawn(db).await;
        let admin = server.admin().await;
        let ada = server.user("ada@example.org").await;
        let (slow, fast) = (FakeRunner::register(&server, "slow").await, FakeRunner::register(&server, "fast").await);
        let board = |season: i64| {
            let url = server.url.clone();
            async move { json_of(reqwest::get(format!("{url}/api/v1/leaderboard?season={season}")).await.unwrap()).await.1 }
        };
        let queue = |name: &'static str| queue_benchmark(&server, &ada, name);

        // While the season names no class, any runner takes its benchmarks; the
        // first result measured on a named class names the season's.
        queue("first").await;
        queue("second").await;
        let on_slow = claim_as(&slow, SLOW).await.expect("no class named yet: any runner");
        let on_fast = claim_as(&fast, FAST).await.expect("no class named yet: any runner");
        let mut published = Vec::new();
        for (runner, job, class) in [(&slow, on_slow, SLOW), (&fast, on_fast, FAST)] {
            common::upload_results_on(runner, &job, 1.0, json!({ "cpu_model": class, "class": class })).await;
            let id =
                job.finish(runner, json!({ "state": "succeeded" })).await.1["result_id"].as_str().unwrap().to_string();
            ada.api(Method::POST, format!("{}/api/v1/results/{id}/publish", server.url)).send().await.unwrap();
            published.push(id);
        }
        let season_one = board(1).await;
        assert_eq!(season_one["runner_class"], SLOW);
        // The set measured on the faster class is ranked at equal spp only, and the board says why.
        let standing = |id: &str| {
            season_one["standings"].as_array().unwrap().iter().find(|s| s["result_id"] == id).unwrap().clone()
        };
        assert_eq!(standing(&published[0])["mean_rank_time"], 1.0, "{season_one}");
        assert!(standing(&published[1])["mean_rank_time"].is_null(), "{season_one}");
        assert_eq!(standing(&published[1])["mean_rank"], 1.5, "ties at equal spp: the same numbers");
        let note = season_one["left_out"][0].as_str().unwrap_or_default();
        assert!(
            note.contains("1 result set(s) measured on another runner class") && note.ends_with(SLOW),
            "{season_one}"
        );
        // So does its viewer: no equal-time place, no cost, its class named.
        let viewer = viewer_of(&server, &ada, &published[1]).await;
        assert_eq!(viewer["runner_class"], SLOW);
        let technique = |id: &str| technique_in(&viewer, id);
        assert_eq!(technique(&published[1])["runner_class"], FAST);
        assert!(technique(&published[1])["runs"].as_array().unwrap().iter().all(|r| r["cost_ms"] == 0.0), "{viewer}");
        let places = |at: &str| -> Vec<Value> {
            viewer["rankings"][at]
                .as_array()
                .unwrap()
                .iter()
                .flat_map(|c| c["places"].as_array().unwrap().clone())
                .collect()
        };
        assert!(places("equal_spp").iter().any(|p| p["technique"] == published[1].as_str()));
        assert!(!places("equal_time").is_empty());
        assert!(places("equal_time").iter().all(|p| p["technique"] == published[0].as_str()), "{viewer}");

        // From then on its benchmarks wait for a runner of that class, and
        // the home page says so while none of that class is connected.
        let home = || async { reqwest::get(format!("{}/", server.url)).await.unwrap().text().await.unwrap() };
        let page = home().await;
        assert!(
            page.contains("No connected runner is of this season") && page.contains(&format!("({SLOW})")),
            "{page}"
        );
        let (status, _) = slow.post("runners/status", json!({ "preparing": null, "machine": { "class": SLOW } })).await;
        assert_eq!(status, 204);
        assert!(!home().await.contains("No connected runner is of this season"), "{}", home().await);
        queue("third").await;
        assert!(claim_as(&fast, FAST).await.is_none(), "a runner of another class is not handed it");
        assert!(fast.claim(1).await.is_none(), "nor one that names no class");
        let job = claim_as(&slow, SLOW).await.expect("a runner of the season's class takes it");
        assert_eq!(job.body["job"]["season"], 1);

        // The administration page says the season's class and offers the
        // connected runners' classes for a new season, started for new
        // hardware: its re-runs go there.
        let (status, _) = fast.post("runners/status", json!({ "preparing": null, "machine": { "class": FAST } })).await;
        assert_eq!(status, 204);
        let page = admin.browser.get(format!("{}/admin", server.url)).send().await.unwrap().text().await.unwrap();
        assert!(page.contains(&format!("id=\"season-class\">{SLOW}</span>")), "{page}");
        assert!(page.contains(&format!("<option value=\"{FAST}\">")), "{page}");
        let form =
            [("csrf_token", admin.csrf.as_str()), ("note", "the fleet moved to new machines"), ("runner_class", FAST)];
        let started = admin.browser.post(format!("{}/admin/seasons", server.url)).form(&form).send().await.unwrap();
        let text = started.text().await.unwrap();
        assert!(text.contains("Season 2 started; 2 techniques queued again."), "{text}");
        assert!(claim_as(&slow, SLOW).await.is_none(), "the old class does not take the new season's re-run");
        let rerun = claim_as(&fast, FAST).await.expect("the new class does");
        assert_eq!(rerun.body["job"]["season"], 2);
        assert_eq!(board(2).await["runner_class"], FAST);
        assert_eq!(board(1).await["runner_class"], SLOW, "the old season keeps its class");
        // The API names one the same way.
        let (status, season) = json_of(
            admin
                .api(Method::POST, format!("{}/api/v1/admin/seasons", server.url))
                .json(&json!({ "note": "back to the old machines", "runner_class": SLOW }))
                .send()
                .await
                .unwrap(),
        )
        .await;
        assert_eq!(status, 201, "{season}");
        assert_eq!(board(3).await["runner_class"], SLOW);
    }
);

on_both_databases!(
    a_runner_whose_calibration_drifted_is_held_back_and_its_set_left_out_of_equal_time_until_measured_again,
    |db: Db| async move {
        const CLASS: &str = "Some CPU · x86-64-v3 · 2 cores · 8 GiB";
        let machine = |cpu_ms: f64| json!({ "class": CLASS, "calibration": { "workload": "fbksd-calibration-1", "cpu_ms": cpu_ms } });
        let server = spawn(db).await;
        let admin = server.admin().await;
        let ada = server.user("ada@example.org").await;
        let runner = FakeRunner::register(&server, "drifting").await;
        let queue = |name: &'static str| queue_benchmark(&server, &ada, name);
        // Three sets of one class; the third measured while its runner ran 14 % slower.
        let mut published = Vec::new();
        for (name, cpu_ms) in [("steady", 40.0), ("steadier", 40.4), ("slowed", 46.0)] {
            queue(name).await;
            let job = claim_as(&runner, CLASS).await.expect("a runner of the class takes it");
            common::upload_results_on(&runner, &job, 1.0, machine(cpu_ms)).await;
            let id =
                job.finish(&runner, json!({ "state": "succeeded" })).await.1["result_id"].as_str().unwrap().to_string();
            ada.api(Method::POST, format!("{}/api/v1/results/{id}/publish", server.url)).send().await.unwrap();
            published.push(id);
        }
        let board = json_of(reqwest::get(format!("{}/api/v1/leaderboard", server.url)).await.unwrap()).await.1;
        let standing =
            |id: &str| board["standings"].as_array().unwrap().iter().find(|s| s["result_id"] == id).unwrap().clone();
        assert_eq!(standing(&published[0])["mean_rank_time"], 1.5, "tied with steadier, the same numbers: {board}");
        assert!(standing(&published[2])["mean_rank_time"].is_null(), "{board}");
        assert_eq!(standing(&published[2])["mean_rank"], standing(&published[0])["mean_rank"], "equal spp keeps it");
        let note = board["left_out"][0].as_str().unwrap_or_default();
        assert!(
            note.starts_with("1 result set(s) measured while their runner's calibration was more than 10 %")
                && note.ends_with("slowed (46.0 ms against 40.4 ms, +14 %)"),
            "{board}"
        );
        // The viewer says why it is off the time axis.
        let viewer = viewer_of(&server, &ada, &published[2]).await;
        let technique = |id: &str| technique_in(&viewer, id);
        assert_eq!(technique(&published[2])["untimed"], "its runner's calibration +14 % from its class's", "{viewer}");
        assert!(technique(&published[0]).get("untimed").is_none(), "{viewer}");

        // The service queues a benchmark that measures it again, and says why.
        let again = loop {
            let jobs = common::project_jobs(&server, &ada, "slowed").await;
            if let Some(job) = jobs.iter().find(|j| j["state"] == "queued") {
                break job.clone();
            }
            tokio::time::sleep(std::time::Duration::from_millis(100)).await;
        };
        assert_eq!(again["kind"], "benchmark", "{again}");
        assert_eq!(again["measures_again"], published[2].as_str(), "{again}");
        let message = again["message"].as_str().unwrap();
        assert!(
            message
                .starts_with(&format!("measured again: result set {} was measured while its runner's", published[2]))
                && message.contains("(46.0 ms against 40.4 ms, +14 %)")
                && message.ends_with("(try 1 of 2)"),
            "{message}"
        );

        // A runner that reports such a calibration now is not handed the
        // season's benchmarks, and the pages say why.
        let (status, _) = runner.post("runners/status", json!({ "preparing": null, "machine": machine(45.0) })).await;
        assert_eq!(status, 204);
        queue("waiting").await;
        assert!(claim_as(&runner, CLASS).await.is_none(), "held back while its calibration is off, from both");
        // A benchmark that has waited longer than the hold goes to it anyway:
        // a season must not wait for good on a calibration that will not come back.
        let pool = fbksd_server::db::connect(&server.config().database_url()).await.unwrap();
        let waited = fbksd_server::now_ms() - 16 * 60_000;
        sqlx::query("UPDATE jobs SET created_at = $1 WHERE state = 'queued' AND measures_again IS NULL")
            .bind(waited)
            .execute(&pool)
            .await
            .unwrap();
        let job = claim_as(&runner, CLASS).await.expect("a benchmark waits 15 minutes at most");
        assert_eq!(job.body["job"]["project"], "waiting", "{}", job.body);
        let (status, _) = job.finish(&runner, json!({ "state": "failed", "reason": "crashed", "message": "x" })).await;
        assert_eq!(status, 200);
        queue("waiting-again").await;
        assert!(claim_as(&runner, CLASS).await.is_none(), "a new benchmark waits again");
        let page = admin.browser.get(format!("{}/admin", server.url)).send().await.unwrap().text().await.unwrap();
        assert!(
            page.contains("held back from season 1&#39;s benchmarks: its calibration is off its class&#39;s (45.0 ms against 40.4 ms, +11 %)"),
            "{page}"
        );
        let home = reqwest::get(format!("{}/", server.url)).await.unwrap().text().await.unwrap();
        assert!(
            home.contains("The runners of this season&#39;s class are held back from its benchmarks")
                && home.contains("drifting: 45.0 ms against 40.4 ms, +11 %"),
            "{home}"
        );
        // Back within 10 %, it takes them again, the oldest first: the set
        // measured again, which takes the old set's place on the board.
        let (status, _) = runner.post("runners/status", json!({ "preparing": null, "machine": machine(41.0) })).await;
        assert_eq!(status, 204);
        let job = claim_as(&runner, CLASS).await.expect("back within the limit");
        assert_eq!(job.body["job"]["project"], "slowed", "{}", job.body);
        common::upload_results_on(&runner, &job, 1.0, machine(41.0)).await;
        let (status, done) = job.finish(&runner, json!({ "state": "succeeded" })).await;
        assert_eq!(status, 200, "{done}");
        let remeasured = done["result_id"].as_str().unwrap().to_string();
        let board = json_of(reqwest::get(format!("{}/api/v1/leaderboard", server.url)).await.unwrap()).await.1;
        let standings = board["standings"].as_array().unwrap();
        let slowed: Vec<&Value> = standings.iter().filter(|s| s["technique"] == "slowed").collect();
        assert_eq!(slowed.len(), 1, "{board}");
        assert_eq!(slowed[0]["result_id"], remeasured.as_str(), "{board}");
        assert_eq!(slowed[0]["mean_rank_time"], 2.0, "on the time axis, tied with the others: {board}");
        assert!(board["left_out"].as_array().unwrap().is_empty(), "{board}");
        let log = common::log_text(&server, &ada, &job.id).await;
        assert!(log.contains(&format!("[fbksd] published in the place of result set {}", published[2])), "{log}");
        let mails = server.mails_to("ada@example.org");
        let about = mails.iter().filter(|m| m.contains("[FBKSD] slowed results")).count();
        assert_eq!(about, 1, "the owner was mailed for the first benchmark, not for this one: {mails:?}");
    }
);

on_both_databases!(deleting_an_account_deletes_its_projects_and_unpublished_results_only, |db: Db| async move {
    let server = spawn(db).await;
    let ada = server.user("ada@example.org").await;
    let runner = FakeRunner::register(&server, "r").await;
    let mut results = Vec::new();
    for name in ["kept", "dropped"] {
        server.create_project(&ada, name, "private").await;
        let repo = technique_repository("box-filter-python");
        assert!(push(repo.path(), &server.clone_url(name, &ada.token), &["FBKSD_RUN"]).0);
        let job = runner.claim(1).await.unwrap();
        common::upload_results(&runner, &job, 1.0).await;
        results.push(
            job.finish(&runner, json!({ "state": "succeeded" })).await.1["result_id"].as_str().unwrap().to_string(),
        );
    }
    ada.api(Method::POST, format!("{}/api/v1/results/{}/publish", server.url, results[0])).send().await.unwrap();
    let deleted = ada
        .browser
        .delete(format!("{}/api/v1/me", server.url))
        .header("X-CSRF-Token", &ada.csrf)
        .json(&json!({ "password": "a long enough password" }))
        .send()
        .await
        .unwrap();
    assert_eq!(deleted.status(), 204);
    let anonymous = reqwest::Client::new();
    let get = |path: String| anonymous.get(format!("{}{path}", server.url)).send();
    assert_eq!(get(format!("/api/v1/results/{}", results[0])).await.unwrap().status(), 200, "published stays");
    let image = get(format!("/results/{}/files/sin-bands/4_0.png", results[0])).await.unwrap();
    assert_eq!(image.status(), 200, "with its files");
    let admin = server.admin().await;
    let unpublished =
        admin.api(Method::GET, format!("{}/api/v1/results/{}", server.url, results[1])).send().await.unwrap();
    assert_eq!(unpublished.status(), 404, "unpublished results go with the account");
    let project = admin.api(Method::GET, format!("{}/api/v1/projects/kept", server.url)).send().await.unwrap();
    assert_eq!(project.status(), 404, "projects go with the account");
    let board = json_of(get("/api/v1/leaderboard".into()).await.unwrap()).await.1;
    assert_eq!(board["standings"][0]["technique"], "kept");
});

/// Results of [`common::results_upload`] with a repeat per seed of `seeds`,
/// each run's MSE moved by `wobble(seed)` (relative). A benchmark's
/// (`seeds` from 0) keeps the first seed's image; a seeds job's values only.
fn seeded_upload(seeds: std::ops::Range<u64>, wobble: impl Fn(u64) -> f64) -> Value {
    let mut upload = common::results_upload(1.0);
    for run in upload["runs"].as_array_mut().unwrap() {
        let mse = run["metrics"]["MSE"].as_f64().unwrap();
        let repeats: Vec<Value> = seeds
            .clone()
            .map(|seed| {
                let value = mse * (1.0 + wobble(seed));
                json!({
                    "seed": seed, "status": "ok", "log": "",
                    "image": if seed == 0 { run["image"].clone() } else { Value::Null },
                    "technique_ms": 12.5, "render_ms": 100.0, "wall_ms": 120.0, "cpu_ms": 12.5, "waiting_ms": 0.0,
                    "peak_memory_bytes": 1000, "used_samples": run["used_samples"],
                    "metrics": { "MSE": value, "SSIM": 1.0 - value }
                })
            })
            .collect();
        run["repeats"] = Value::Array(repeats);
        if seeds.start > 0 {
            run["image"] = Value::Null;
            run["log"] = json!("");
        }
    }
    upload
}

/// The next job `runner` is handed (waiting for the server to queue one),
/// claiming as a runner that takes seeds jobs, as a seeds job.
async fn seeds_job(runner: &FakeRunner) -> common::HeldJob {
    let job = runner.claim_with(json!({ "wait_seconds": 20, "more_seeds": true })).await.expect("a seeds job");
    assert_eq!(job.body["job"]["kind"], "seeds", "{}", job.body);
    job
}

on_both_databases!(a_tie_too_close_to_call_on_the_board_gets_more_seeds_until_it_is_settled, |db: Db| async move {
    let server = spawn(db).await;
    let ada = server.user("ada@example.org").await;
    let runner = FakeRunner::register(&server, "runner").await;
    // Two techniques whose errors differ by a few per cent, less than
    // three seeds' spread can show: a tie, which twelve seeds could settle.
    let wobble = |seed: u64| [0.0, 0.10, -0.10][seed as usize % 3];
    let gap = |seed: u64| wobble(seed) + [0.03, 0.05, -0.01][seed as usize % 3];
    let mut sets = Vec::new();
    for name in ["steady", "shaky"] {
        queue_benchmark(&server, &ada, name).await;
        let job = runner.claim(5).await.expect("the benchmark");
        let upload = if name == "steady" { seeded_upload(0..3, wobble) } else { seeded_upload(0..3, gap) };
        for scene in ["sin-bands", "defocus-checkerboard"] {
            common::stored_reference(&runner, scene).await;
        }
        for run in upload["runs"].as_array().unwrap() {
            let name = run["image"].as_str().unwrap();
            assert_eq!(job.send(&runner, Method::PUT, &format!("files/{name}"), b"png".to_vec().into()).await, 204);
        }
        assert_eq!(job.send(&runner, Method::PUT, "results", upload.to_string().into()).await, 204);
        let (_, done) = job.finish(&runner, json!({ "state": "succeeded" })).await;
        let id = done["result_id"].as_str().unwrap().to_string();
        ada.api(Method::POST, format!("{}/api/v1/results/{id}/publish", server.url)).send().await.unwrap();
        sets.push((name, id));
    }
    let board = || {
        let url = server.url.clone();
        async move { json_of(reqwest::get(format!("{url}/api/v1/leaderboard")).await.unwrap()).await.1 }
    };
    let mean_rank = |board: &Value, id: &str| {
        board["standings"].as_array().unwrap().iter().find(|s| s["result_id"] == id).unwrap()["mean_rank"].clone()
    };
    let before = board().await;
    assert_eq!(mean_rank(&before, &sets[0].1), 1.5, "a tie on three seeds: {before}");
    assert_eq!(mean_rank(&before, &sets[1].1), 1.5, "{before}");

    // Round one: both sets' runs behind the tie get seeds 3–5, the same
    // seeds; a runner that does not say it takes seeds jobs is not handed one.
    for name in ["steady", "shaky"] {
        let mut jobs = project_jobs(&server, &ada, name).await;
        while !jobs.iter().any(|j| j["kind"] == "seeds" && j["state"] == "queued") {
            tokio::time::sleep(std::time::Duration::from_millis(100)).await;
            jobs = project_jobs(&server, &ada, name).await;
        }
    }
    assert!(runner.claim(1).await.is_none(), "a runner from before seeds jobs is handed none");
    let mut round = Vec::new();
    for _ in 0..2 {
        let job = seeds_job(&runner).await;
        let runs = job.body["more_seeds"].as_array().unwrap().clone();
        assert_eq!(runs.len(), 4, "both scenes at both budgets: {}", job.body);
        assert!(runs.iter().all(|r| r["first"] == 3 && r["end"] == 6), "{}", job.body);
        round.push(job);
    }
    let id_of = |job: &common::HeldJob| {
        let project = job.body["job"]["project"].as_str().unwrap().to_string();
        sets.iter().find(|(name, _)| *name == project).map(|(name, _)| *name).unwrap()
    };
    // Repeats that are not what the job asked for are refused, saying why.
    let wrong = seeded_upload(3..5, wobble).to_string();
    let answer =
        runner.job_request(Method::PUT, &round[0].id, &round[0].token, "results").body(wrong).send().await.unwrap();
    assert_eq!(answer.status(), 400);
    let text = answer.text().await.unwrap();
    assert!(text.contains("seeds [3, 4], where the job asked for [3, 4, 5]"), "{text}");
    for job in &round {
        let upload = if id_of(job) == "steady" { seeded_upload(3..6, wobble) } else { seeded_upload(3..6, gap) };
        assert_eq!(job.send(&runner, Method::PUT, "results", upload.to_string().into()).await, 204);
        let (status, body) = job.finish(&runner, json!({ "state": "succeeded" })).await;
        assert_eq!(status, 200, "{body}");
    }
    // Six seeds still tie; round two doubles them, to the cap of twelve.
    let second = [seeds_job(&runner).await, seeds_job(&runner).await];
    for job in &second {
        assert!(job.body["more_seeds"].as_array().unwrap().iter().all(|r| r["first"] == 6 && r["end"] == 12));
        let steady = id_of(job) == "steady";
        let upload =
            seeded_upload(6..12, |s| if steady { wobble(s) } else { wobble(s) + [0.03, 0.04][s as usize % 2] });
        assert_eq!(job.send(&runner, Method::PUT, "results", upload.to_string().into()).await, 204);
        assert_eq!(job.finish(&runner, json!({ "state": "succeeded" })).await.0, 200);
    }
    // Twelve seeds tell them apart: the board ranks the shakier one below.
    let after = board().await;
    assert_eq!(mean_rank(&after, &sets[0].1), 1.0, "{after}");
    assert_eq!(mean_rank(&after, &sets[1].1), 2.0, "{after}");
    let viewer = viewer_of(&server, &ada, &sets[1].1).await;
    let run = &technique_in(&viewer, &sets[1].1)["runs"][0];
    assert_eq!(run["seeds"], 12, "the viewer counts every seed: {run}");
});
