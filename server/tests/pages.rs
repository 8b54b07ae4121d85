//! The HTML pages as a browser uses them: forms with their CSRF tokens,
//! the private results page beside the leaderboard, who sees what; and
//! one test in a real browser (Chromium, headless) that the job page
//! streams a running job's log live.

mod common;

use common::{push, spawn, technique_repository, Db, FakeRunner};
use reqwest::Method;
use serde_json::json;

/// The value of the hidden `csrf_token` field in a page.
fn csrf_in(page: &str) -> String {
    let at = page.find("name=\"csrf_token\" value=\"").expect("a form with a CSRF token") + 25;
    page[at..].split('"').next().unwrap().to_string()
}

async fn text(response: reqwest::Response) -> (u16, String) {
    (response.status().as_u16(), response.text().await.unwrap())
}

on_both_databases!(forms_register_log_in_and_create_projects_with_csrf_tokens, |db: Db| async move {
    let server = spawn(db).await;
    let browser = server.browser();
    let form = |path: &str, fields: &[(&str, &str)]| {
        let fields: Vec<(String, String)> = fields.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        browser.post(format!("{}{path}", server.url)).form(&fields).send()
    };

    // Registration: the form's token must match its cookie.
    let (_, page) = text(browser.get(format!("{}/register", server.url)).send().await.unwrap()).await;
    let csrf = csrf_in(&page);
    let forged = server
        .browser()
        .post(format!("{}/register", server.url))
        .form(&[("csrf_token", csrf.as_str()), ("email", "x@example.org"), ("password", "long enough pass")])
        .send()
        .await
        .unwrap();
    assert_eq!(forged.status(), 403, "another site's post has no form cookie");
    let (status, page) = text(
        form("/register", &[("csrf_token", &csrf), ("email", "ada@example.org"), ("password", "short")]).await.unwrap(),
    )
    .await;
    assert_eq!(status, 400);
    assert!(page.contains("at least 10 characters"), "the form shows what was wrong");
    let csrf = csrf_in(&page);
    let (status, page) = text(
        form("/register", &[("csrf_token", &csrf), ("email", "ada@example.org"), ("password", "long enough pass")])
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(status, 200);
    assert!(page.contains("Check your mail"));
    browser.get(server.link_in_mail("ada@example.org", "/accounts/verify")).send().await.unwrap();

    // Log in, then create a project with the session's token.
    let (_, page) = text(browser.get(format!("{}/login", server.url)).send().await.unwrap()).await;
    let login = form(
        "/login",
        &[("csrf_token", &csrf_in(&page)), ("email", "ada@example.org"), ("password", "long enough pass")],
    )
    .await
    .unwrap();
    let (status, page) = text(login).await;
    assert_eq!(status, 200, "{page}");
    assert!(page.contains("Log out ada@example.org"));
    let session_csrf = csrf_in(&page);
    let (status, _) =
        text(form("/projects", &[("csrf_token", "wrong"), ("name", "mine"), ("visibility", "public")]).await.unwrap())
            .await;
    assert_eq!(status, 403, "a wrong CSRF token is refused");
    let (status, page) = text(
        form("/projects", &[("csrf_token", &session_csrf), ("name", "mine"), ("visibility", "public")]).await.unwrap(),
    )
    .await;
    assert_eq!(status, 200);
    assert!(page.contains("git clone") && page.contains("/git/mine.git"), "{page}");
    // A post without a visibility (by hand, say) makes a private project;
    // one without a name is answered with a page that says so.
    let (status, page) =
        text(form("/projects", &[("csrf_token", &session_csrf), ("name", "quiet")]).await.unwrap()).await;
    assert_eq!(status, 200, "{page}");
    assert!(page.contains("/git/quiet.git") && page.contains("quiet · private"), "{page}");
    let (status, page) =
        text(form("/projects", &[("csrf_token", &session_csrf), ("visibility", "public")]).await.unwrap()).await;
    assert_eq!(status, 422, "{page}");
    assert!(page.contains("<html") && page.contains("missing field `name`"), "{page}");

    // Access tokens from the settings page are shown once and work.
    let (_, page) =
        text(form("/settings/tokens", &[("csrf_token", &session_csrf), ("name", "laptop")]).await.unwrap()).await;
    let at = page.find("id=\"new-token\">").unwrap() + 15;
    let token = &page[at..at + 70].split('<').next().unwrap();
    let me = reqwest::Client::new().get(format!("{}/api/v1/me", server.url)).bearer_auth(token).send().await.unwrap();
    assert_eq!(me.status(), 200);

    // Logging out needs the token too, and ends the session.
    assert_eq!(form("/logout", &[("csrf_token", "nope")]).await.unwrap().status(), 403);
    form("/logout", &[("csrf_token", &session_csrf)]).await.unwrap();
    let (_, page) = text(browser.get(format!("{}/projects", server.url)).send().await.unwrap()).await;
    assert!(page.contains("Log in") && !page.contains("New project"));
});

on_both_databases!(the_private_page_shows_a_result_beside_the_leaderboard_to_its_owner_only, |db: Db| async move {
    let server = spawn(db).await;
    let ada = server.user("ada@example.org").await;
    let bob = server.user("bob@example.org").await;
    let runner = FakeRunner::register(&server, "r").await;
    // Bob's technique is published; Ada's is not yet.
    let mut results = Vec::new();
    for (user, name, quality) in [(&bob, "bob-filter", 2.0), (&ada, "ada-filter", 1.0)] {
        server.create_project(user, name, "public").await;
        let repo = technique_repository("box-filter-python");
        assert!(push(repo.path(), &server.clone_url(name, &user.token), &["FBKSD_RUN"]).0);
        let job = runner.claim(1).await.unwrap();
        common::upload_results(&runner, &job, quality).await;
        results.push(
            job.finish(&runner, json!({ "state": "succeeded" })).await.1["result_id"].as_str().unwrap().to_string(),
        );
    }
    let (bobs, adas) = (&results[0], &results[1]);
    bob.api(Method::POST, format!("{}/api/v1/results/{bobs}/publish", server.url)).send().await.unwrap();

    let page = |client: reqwest::Client, path: String| {
        let url = format!("{}{path}", server.url);
        async move { text(client.get(url).send().await.unwrap()).await }
    };
    let (status, private) = page(ada.browser.clone(), format!("/results/{adas}")).await;
    assert_eq!(status, 200);
    assert!(private.contains("Private") && private.contains("bob-filter") && private.contains("class=\"highlight\""));
    // Ada's (better) technique ranks first on her private page.
    let standings = &private[private.find("id=\"standings\"").unwrap()..];
    assert!(standings.find("ada-filter").unwrap() < standings.find("bob-filter").unwrap());
    // The page's board is kept once assembled, and assembled anew when the
    // published board changes: Bob's set leaves it and comes back.
    for (action, shown) in [("unpublish", false), ("publish", true)] {
        bob.api(Method::POST, format!("{}/api/v1/results/{bobs}/{action}", server.url)).send().await.unwrap();
        let (status, private) = page(ada.browser.clone(), format!("/results/{adas}")).await;
        assert_eq!((status, private.contains("bob-filter")), (200, shown), "after Bob's {action}");
    }
    for (client, who) in [(bob.browser.clone(), "another user"), (reqwest::Client::new(), "anonymous")] {
        assert_eq!(page(client, format!("/results/{adas}")).await.0, 404, "{who}");
    }
    assert_eq!(page(reqwest::Client::new(), "/results/not-a-uuid".into()).await.0, 400);

    // Anonymous visitors share one rendered board, revalidated by its ETag.
    let anonymous = reqwest::Client::new();
    let first = anonymous.get(format!("{}/results/", server.url)).send().await.unwrap();
    let etag = first.headers()["etag"].to_str().unwrap().to_string();
    let (_, before) = text(first).await;
    assert!(before.contains("bob-filter") && !before.contains("ada-filter"));
    let again = anonymous.get(format!("{}/results/", server.url)).header("if-none-match", &etag).send().await.unwrap();
    assert_eq!((again.status().as_u16(), again.text().await.unwrap().len()), (304, 0));
    // A browser asks for gzip: the same page, compressed once per board version, under its own ETag.
    let gzip = |etag: Option<&str>| {
        let request = anonymous.get(format!("{}/results/", server.url)).header("accept-encoding", "gzip, deflate, br");
        match etag {
            Some(etag) => request.header("if-none-match", etag),
            None => request,
        }
        .send()
    };
    let zipped = gzip(None).await.unwrap();
    assert_eq!(
        (zipped.status().as_u16(), zipped.headers().get("content-encoding")),
        (200, Some(&"gzip".parse().unwrap()))
    );
    let zipped_etag = zipped.headers()["etag"].to_str().unwrap().to_string();
    assert_ne!(zipped_etag, etag, "another representation, another ETag");
    let mut unzipped = String::new();
    std::io::Read::read_to_string(&mut flate2::read::GzDecoder::new(&zipped.bytes().await.unwrap()[..]), &mut unzipped)
        .unwrap();
    assert_eq!(unzipped, before, "the gzip copy is the page");
    assert_eq!(gzip(Some(&zipped_etag)).await.unwrap().status(), 304);
    let api = anonymous.get(format!("{}/api/v1/leaderboard", server.url)).send().await.unwrap();
    let api_etag = api.headers()["etag"].to_str().unwrap().to_string();
    assert_ne!(api_etag, etag, "the JSON and the page are told apart");
    assert!(api.text().await.unwrap().contains("\"bob-filter\""));
    let api_again =
        anonymous.get(format!("{}/api/v1/leaderboard", server.url)).header("if-none-match", &api_etag).send().await;
    assert_eq!(api_again.unwrap().status(), 304);
    let signed_in = ada.browser.get(format!("{}/results/", server.url)).send().await.unwrap();
    assert!(signed_in.headers().get("etag").is_none(), "a user's page is their own");
    assert!(text(signed_in).await.1.contains("ada@example.org"));

    // Publishing from the page puts it on the leaderboard.
    let publish = ada
        .browser
        .post(format!("{}/results/{adas}/publish", server.url))
        .form(&[("csrf_token", ada.csrf.as_str())])
        .send()
        .await
        .unwrap();
    assert_eq!(publish.status(), 200);
    let forged = bob
        .browser
        .post(format!("{}/results/{adas}/unpublish", server.url))
        .form(&[("csrf_token", bob.csrf.as_str())])
        .send()
        .await
        .unwrap();
    assert_eq!(forged.status(), 404, "only the owner unpublishes");
    let changed =
        anonymous.get(format!("{}/results/", server.url)).header("if-none-match", &etag).send().await.unwrap();
    assert_eq!(changed.status(), 200, "the board changed: the page is new");
    assert_ne!(changed.headers()["etag"].to_str().unwrap(), etag);
    let (status, board) = page(reqwest::Client::new(), "/results/".into()).await;
    assert_eq!(status, 200);
    assert!(board.contains("ada-filter") && board.contains("bob-filter"));
    assert!(board.contains("sin-bands") && board.contains("16 spp"));
    // Hovering "Technique time" says it holds start-up, which the equal-time cost leaves out.
    assert!(
        board.contains("start-up (process start, imports, model loading) included. Equal time uses Cost"),
        "the technique time's title"
    );
    // Sorting by SSIM (higher is better) and filtering by tag.
    let (_, by_tag) = page(reqwest::Client::new(), "/results/?sort=SSIM&tag=dof".into()).await;
    assert!(
        by_tag.contains("Ranking by SSIM")
            && by_tag.contains("defocus-checkerboard")
            && !by_tag.contains("<h3>sin-bands")
    );
    // The technique page shows info.json and the history.
    let (_, technique) = page(reqwest::Client::new(), "/projects/ada-filter".into()).await;
    assert!(technique.contains("Box filter (Python)") && technique.contains("published"));
});

on_both_databases!(a_newcomer_is_told_how_to_submit_and_what_is_being_prepared, |db: Db| async move {
    let server = spawn(db).await;
    let anonymous = reqwest::Client::new();
    let home = |client: reqwest::Client| {
        let url = format!("{}/", server.url);
        async move { text(client.get(url).send().await.unwrap()).await }
    };
    // The empty board says how to submit, and that no runner is there yet.
    let (status, page) = home(anonymous.clone()).await;
    assert_eq!(status, 200, "the home page is the board itself");
    assert!(page.contains("How to submit a technique") && page.contains("href=\"/register\""), "{page}");
    assert!(page.contains("git push -o FBKSD_RUN") && page.contains("sends no options"), "{page}");
    assert!(page.contains("No runner is connected yet"), "{page}");
    // No result has named a metric yet: no empty "Sort by" choice, no "Ranking by" nothing.
    assert!(!page.contains("Sort by") && page.contains("<h2>Ranking</h2>"), "{page}");

    // A runner preparing its references says so there, and the page refreshes itself.
    let runner = FakeRunner::register(&server, "r1").await;
    let status = reqwest::Client::new()
        .post(format!("{}/api/v1/runners/status", server.url))
        .bearer_auth(&runner.token)
        .json(&json!({ "preparing": "making reference 2 of 8: experimental/sphere (500×500, closed form)" }))
        .send()
        .await
        .unwrap();
    assert_eq!(status.status(), 204);
    let (_, page) = home(anonymous.clone()).await;
    assert!(page.contains("The runners are getting ready") && !page.contains("r1"), "anonymous: no details: {page}");
    assert!(page.contains("http-equiv=\"refresh\"") && !page.contains("No runner is connected"), "{page}");
    let ada = server.user("ada@example.org").await;
    let (_, page) = home(ada.browser.clone()).await;
    assert!(page.contains("Runner r1: making reference 2 of 8: experimental/sphere"), "{page}");
    reqwest::Client::new()
        .post(format!("{}/api/v1/runners/status", server.url))
        .bearer_auth(&runner.token)
        .json(&json!({ "preparing": null }))
        .send()
        .await
        .unwrap();
    let (_, page) = home(anonymous.clone()).await;
    assert!(!page.contains("Getting ready"), "a ready runner leaves nothing to say: {page}");

    // Logged in: the clone URL carries a user name; an error page keeps the header.
    server.create_project(&ada, "private-filter", "private").await;
    let (_, page) =
        text(ada.browser.get(format!("{}/projects/private-filter", server.url)).send().await.unwrap()).await;
    let host = server.url.trim_start_matches("http://");
    assert!(page.contains(&format!("git clone http://ada@{host}/git/private-filter.git")), "{page}");
    let (status, page) =
        text(ada.browser.get(format!("{}/projects/nothing-here", server.url)).send().await.unwrap()).await;
    assert_eq!(status, 404);
    assert!(page.contains("Log out ada@example.org"), "the error page keeps the logged-in header: {page}");

    // A published technique of a private repository: its public description for anyone, never its code.
    let repo = technique_repository("box-filter-python");
    assert!(push(repo.path(), &server.clone_url("private-filter", &ada.token), &["FBKSD_RUN"]).0);
    let job = runner.claim(1).await.unwrap();
    common::upload_results(&runner, &job, 1.0).await;
    let result =
        job.finish(&runner, json!({ "state": "succeeded" })).await.1["result_id"].as_str().unwrap().to_string();
    let (status, hidden) =
        text(anonymous.get(format!("{}/projects/private-filter", server.url)).send().await.unwrap()).await;
    assert_eq!(status, 404, "nothing published yet: nothing to show");
    let (_, missing) =
        text(anonymous.get(format!("{}/projects/private-filtex", server.url)).send().await.unwrap()).await;
    assert_eq!(hidden.replace("private-filter", "private-filtex"), missing, "a private name is not given away");
    ada.api(Method::POST, format!("{}/api/v1/results/{result}/publish", server.url)).send().await.unwrap();
    let (_, board) = home(anonymous.clone()).await;
    assert!(board.contains("Box filter (Python)") && board.contains("href=\"/projects/private-filter\""), "{board}");
    assert!(!board.contains("How to submit a technique"), "a board with techniques leads with them");
    let (status, page) =
        text(anonymous.get(format!("{}/projects/private-filter", server.url)).send().await.unwrap()).await;
    assert_eq!(status, 200, "{page}");
    assert!(page.contains("Box filter (Python)") && page.contains("repository is not public"), "{page}");
    assert!(!page.contains("git clone") && !page.contains("History"), "no code, no jobs: {page}");

    // A failed job's message keeps its lines, first line first.
    commit_all_and_push(&repo, &server.clone_url("private-filter", &ada.token)).await;
    let build = runner.claim(1).await.unwrap();
    let message = "the build failed (exit code 2): main.cpp:3:1: error: expected ';'\n\nlast lines of the build:\nmake: *** Error 2";
    build.finish(&runner, json!({ "state": "failed", "reason": "build_failed", "message": message })).await;
    let (_, page) = text(ada.browser.get(format!("{}/jobs/{}", server.url, build.id)).send().await.unwrap()).await;
    assert!(page.contains("class=\"failure\"") && page.contains("error: expected &#39;;&#39;\n\nlast lines"), "{page}");
    let (_, css) = text(anonymous.get(format!("{}/static/style.css", server.url)).send().await.unwrap()).await;
    assert!(css.contains("dd.failure { white-space: pre-wrap;"), "line breaks are shown");
});

async fn commit_all_and_push(repo: &tempfile::TempDir, url: &str) {
    common::commit_all(repo.path(), "again");
    assert!(push(repo.path(), url, &[]).0);
}

on_both_databases!(a_running_jobs_log_streams_live_to_a_real_browser, |db: Db| async move {
    let Some(chromium) = ["chromium", "chromium-browser"].into_iter().find(|c| which(c)) else {
        panic!("Chromium is not installed: deploy/setup.sh installs it");
    };
    let server = spawn(db).await;
    let ada = server.user("ada@example.org").await;
    server.create_project(&ada, "live", "public").await;
    let repo = technique_repository("box-filter-python");
    assert!(push(repo.path(), &server.clone_url("live", &ada.token), &[]).0);
    let runner = FakeRunner::register(&server, "r").await;
    let job = runner.claim(1).await.unwrap();

    // A first start builds Chromium's caches (slow on a fresh machine); warm it up
    // so the timed start below opens the page within the writer's delay.
    let profile = tempfile::tempdir().unwrap();
    let warm_up = tokio::process::Command::new(chromium)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--dump-dom", "about:blank"])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .output()
        .await;
    assert!(warm_up.is_ok_and(|o| o.status.success()), "Chromium starts");

    // The browser opens the page while the job runs; the runner writes
    // after the page has loaded, then ends the job.
    let url = format!("{}/jobs/{}", server.url, job.id);
    let browser = tokio::process::Command::new(chromium)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=8000", "--dump-dom"])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg(&url)
        .output();
    let writer = async {
        tokio::time::sleep(std::time::Duration::from_millis(2500)).await;
        assert_eq!(job.send(&runner, Method::POST, "log", "step 1: cmake configured\n".into()).await, 204);
        tokio::time::sleep(std::time::Duration::from_millis(300)).await;
        assert_eq!(job.send(&runner, Method::POST, "log", "step 2: built\n".into()).await, 204);
        job.finish(&runner, json!({ "state": "succeeded" })).await;
    };
    let (output, ()) = tokio::join!(browser, writer);
    let dom = String::from_utf8_lossy(&output.unwrap().stdout).into_owned();
    assert!(dom.contains("data-live=\"true\""), "the page was served while the job ran: {dom}");
    assert!(dom.contains("step 1: cmake configured") && dom.contains("step 2: built"), "{dom}");
    assert!(dom.contains("class=\"state-succeeded\""), "the end event updates the state: {dom}");
});

on_both_databases!(the_environments_page_lists_what_each_image_holds, |db: Db| async move {
    let server = spawn(db).await;
    let (status, page) = text(reqwest::get(format!("{}/environments", server.url)).await.unwrap()).await;
    assert_eq!(status, 200);
    for shown in [
        "<h2 id=\"cpp\">",
        "<h2 id=\"python\">",
        "OpenEXR",
        "3.1.5",
        "Eigen",
        "OpenCV",
        "FFTW",
        "Boost",
        "oneTBB",
        "omp.h",
        "Intel Open Image Denoise",
        "pyoidn",
        "scipy",
    ] {
        assert!(page.contains(shown), "{shown} is not on the page:\n{page}");
    }
    // Every page links to it.
    let (_, home) = text(reqwest::get(&server.url).await.unwrap()).await;
    assert!(home.contains("<a href=\"/environments\">"), "{home}");
});

fn which(program: &str) -> bool {
    std::process::Command::new("sh")
        .args(["-c", &format!("command -v {program}")])
        .output()
        .is_ok_and(|o| o.status.success())
}
