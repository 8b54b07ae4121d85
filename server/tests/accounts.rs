//! Accounts through the real HTTP API, on SQLite and on PostgreSQL:
//! register → the verification mail in the outbox → verify → log in → who
//! am I → log out; and every way it refuses bad input.

mod common;

use common::{json_of, spawn, Db, FakeRunner};
use serde_json::{json, Value};

async fn register(client: &reqwest::Client, url: &str, email: &str, password: &str) -> reqwest::Response {
    client
        .post(format!("{url}/api/v1/accounts"))
        .json(&json!({ "email": email, "password": password }))
        .send()
        .await
        .unwrap()
}

async fn log_in(client: &reqwest::Client, url: &str, email: &str, password: &str) -> reqwest::Response {
    client
        .post(format!("{url}/api/v1/sessions"))
        .json(&json!({ "email": email, "password": password }))
        .send()
        .await
        .unwrap()
}

async fn error_code(response: reqwest::Response) -> (u16, String) {
    let status = response.status().as_u16();
    let body: Value = response.json().await.unwrap();
    (status, body["error"].as_str().unwrap_or_default().to_string())
}

on_both_databases!(register_verify_log_in_and_out, |db: Db| async move {
    let server = spawn(db).await;
    let browser = server.browser();
    let created = register(&browser, &server.url, "Ada@Example.org", "analytical engine").await;
    assert_eq!(created.status(), 201);

    // Not verified yet: logging in says what to do.
    assert_eq!(
        error_code(log_in(&browser, &server.url, "ada@example.org", "analytical engine").await).await,
        (403, "email_not_verified".into())
    );

    // The link, read from the mail file as it is (7-bit: nothing to decode), verifies the address, once.
    assert!(server.mails_to("ada@example.org")[0].contains("Content-Transfer-Encoding: 7bit"));
    let link = server.link_in_mail("ada@example.org", "/accounts/verify?token=");
    let page = browser.get(&link).send().await.unwrap();
    assert_eq!(page.status(), 200);
    assert!(page.text().await.unwrap().contains("confirmed"));
    assert_eq!(browser.get(&link).send().await.unwrap().status(), 400, "a used link is refused");

    let session = log_in(&browser, &server.url, "ADA@example.org ", "analytical engine").await;
    assert_eq!(session.status(), 200);
    let body: Value = session.json().await.unwrap();
    let csrf = body["csrf_token"].as_str().unwrap().to_string();
    let me: Value = browser.get(format!("{}/api/v1/me", server.url)).send().await.unwrap().json().await.unwrap();
    assert_eq!(me["email"], "ada@example.org");
    assert_eq!(me["is_admin"], false);

    // Logging out is a state change: without the CSRF token it is refused.
    let forged = browser.delete(format!("{}/api/v1/sessions", server.url)).send().await.unwrap();
    assert_eq!(error_code(forged).await, (403, "csrf".into()));
    let out =
        browser.delete(format!("{}/api/v1/sessions", server.url)).header("X-CSRF-Token", &csrf).send().await.unwrap();
    assert_eq!(out.status(), 204);
    assert_eq!(browser.get(format!("{}/api/v1/me", server.url)).send().await.unwrap().status(), 401);
});

on_both_databases!(bad_registrations_and_logins_are_refused_clearly, |db: Db| async move {
    let server = spawn(db).await;
    let client = server.browser();
    assert_eq!(
        error_code(register(&client, &server.url, "not-an-address", "analytical engine").await).await,
        (400, "invalid_email".into())
    );
    assert_eq!(
        error_code(register(&client, &server.url, "bob@example.org", "short").await).await,
        (400, "weak_password".into())
    );
    assert_eq!(register(&client, &server.url, "bob@example.org", "difference engine").await.status(), 201);
    assert_eq!(
        error_code(register(&client, &server.url, "BOB@example.org", "another password").await).await,
        (409, "email_taken".into())
    );
    // Wrong password and unknown address get the same answer.
    let wrong = error_code(log_in(&client, &server.url, "bob@example.org", "wrong password!").await).await;
    let unknown = error_code(log_in(&client, &server.url, "nobody@example.org", "wrong password!").await).await;
    assert_eq!(wrong, (401, "unauthorized".into()));
    assert_eq!(wrong, unknown);
    let bogus = client
        .post(format!("{}/api/v1/accounts/verify", server.url))
        .json(&json!({"token": "0".repeat(64)}))
        .send()
        .await
        .unwrap();
    assert_eq!(error_code(bogus).await, (400, "invalid_token".into()));
    // Unknown fields are refused rather than ignored.
    let extra = client
        .post(format!("{}/api/v1/accounts", server.url))
        .json(&json!({"email": "c@example.org", "password": "0123456789", "admin": true}))
        .send()
        .await
        .unwrap();
    assert_eq!(extra.status(), 422);
});

on_both_databases!(the_first_start_creates_an_administrator_once, |db: Db| async move {
    let server = spawn(db).await;
    let (email, password) = server.admin.clone().expect("first start prints an administrator");
    let client = server.browser();
    let body: Value = log_in(&client, &server.url, &email, &password).await.json().await.unwrap();
    assert_eq!(body["user"]["is_admin"], true);
});

/// The service's own addresses cannot be registered, in any case. Before,
/// whoever registered `References@localhost.localdomain` first held the
/// references' account, and every reference request answered 409 for ever.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_services_addresses_cannot_be_taken() {
    let server = spawn(Db::Sqlite).await;
    let client = server.browser();
    for address in
        ["References@localhost.localdomain", "baselines@LOCALHOST.localdomain", "someone@localhost.localdomain"]
    {
        let answer = register(&client, &server.url, address, "analytical engine").await;
        let (status, body) = json_of(answer).await;
        assert_eq!((status, body["error"].as_str()), (400, Some("reserved_email")), "{address}: {body}");
        assert!(body["message"].as_str().unwrap().contains("register with your own"), "{body}");
    }
    let runner = FakeRunner::register(&server, "r").await;
    let key = fbksd_exchange::scenes::reference_key("test renderer 1", 4, "sha256:scene");
    let (status, body) = runner
        .post("runners/references", json!({ "key": key, "scene": "experimental/sphere", "name": "sphere" }))
        .await;
    assert_eq!((status, body["state"].as_str()), (200, Some("building")), "{body}");
}

/// Registers, verifies and logs in `email`; the browser and its CSRF token.
async fn signed_in(server: &common::TestServer, email: &str, password: &str) -> (reqwest::Client, String) {
    let browser = server.browser();
    assert_eq!(register(&browser, &server.url, email, password).await.status(), 201);
    let link = server.link_in_mail(email, "/accounts/verify?token=");
    assert_eq!(browser.get(&link).send().await.unwrap().status(), 200);
    let body: Value = log_in(&browser, &server.url, email, password).await.json().await.unwrap();
    (browser, body["csrf_token"].as_str().unwrap().to_string())
}

on_both_databases!(a_forgotten_password_is_reset_by_mail_and_ends_every_session, |db: Db| async move {
    let server = spawn(db).await;
    let (browser, _) = signed_in(&server, "eve@example.org", "first password").await;
    let anonymous = server.browser();
    let ask = |email: &'static str| {
        let (c, url) = (anonymous.clone(), server.url.clone());
        async move { c.post(format!("{url}/api/v1/password-resets")).json(&json!({ "email": email })).send().await.unwrap() }
    };
    // The same answer for an unknown address, and no mail.
    let (known, unknown) = (ask("eve@example.org").await, ask("nobody@example.org").await);
    assert_eq!((known.status(), unknown.status()), (reqwest::StatusCode::ACCEPTED, reqwest::StatusCode::ACCEPTED));
    assert_eq!(known.text().await.unwrap(), unknown.text().await.unwrap());
    assert!(server.mails_to("nobody@example.org").is_empty());

    let mail = server.mails_to("eve@example.org").pop().unwrap();
    let token = mail
        .split_whitespace()
        .find(|w| w.len() == 64 && w.chars().all(|c| c.is_ascii_hexdigit()))
        .unwrap()
        .to_string();
    let confirm = |password: &'static str| {
        let (c, url, token) = (anonymous.clone(), server.url.clone(), token.clone());
        async move {
            c.post(format!("{url}/api/v1/password-resets/confirm"))
                .json(&json!({ "token": token, "password": password }))
                .send()
                .await
                .unwrap()
        }
    };
    assert_eq!(
        error_code(confirm("short").await).await,
        (400, "weak_password".into()),
        "checked before the token is used"
    );
    assert_eq!(confirm("second password").await.status(), 200);
    assert_eq!(error_code(confirm("third password").await).await, (400, "invalid_token".into()), "once only");

    assert_eq!(
        browser.get(format!("{}/api/v1/me", server.url)).send().await.unwrap().status(),
        401,
        "old sessions end"
    );
    assert_eq!(log_in(&anonymous, &server.url, "eve@example.org", "first password").await.status(), 401);
    assert_eq!(log_in(&anonymous, &server.url, "eve@example.org", "second password").await.status(), 200);
});

on_both_databases!(access_tokens_authenticate_scripts_until_revoked, |db: Db| async move {
    let server = spawn(db).await;
    let (browser, csrf) = signed_in(&server, "tim@example.org", "tims password").await;
    signed_in(&server, "ann@example.org", "anns password").await;
    let created = create_token(&browser, &server.url, &csrf, "laptop git").await;
    let token = created["token"].as_str().unwrap().to_string();
    assert!(token.starts_with("fbksd_"));

    let script = reqwest::Client::new();
    let me = script.get(format!("{}/api/v1/me", server.url)).bearer_auth(&token).send().await.unwrap();
    assert_eq!(me.json::<Value>().await.unwrap()["email"], "tim@example.org");
    let (_, listed) =
        json_of(script.get(format!("{}/api/v1/tokens", server.url)).bearer_auth(&token).send().await.unwrap()).await;
    assert_eq!(listed[0]["name"], "laptop git");
    assert!(listed[0]["last_used_at"].is_i64(), "use is recorded");
    assert!(!listed.to_string().contains(&token[6..]), "the secret is never listed");

    // Another user cannot revoke it; its owner can.
    let ann = signed_in_token(&server, "ann@example.org", "anns password").await;
    let id = created["id"].as_str().unwrap();
    let theirs = script.delete(format!("{}/api/v1/tokens/{id}", server.url)).bearer_auth(&ann).send().await.unwrap();
    assert_eq!(theirs.status(), 404);
    assert_eq!(
        script.delete(format!("{}/api/v1/tokens/{id}", server.url)).bearer_auth(&token).send().await.unwrap().status(),
        204
    );
    let revoked = script.get(format!("{}/api/v1/me", server.url)).bearer_auth(&token).send().await.unwrap();
    assert_eq!(error_code(revoked).await, (401, "unauthorized".into()));
    let bogus = script.get(format!("{}/api/v1/me", server.url)).bearer_auth("fbksd_nope").send().await.unwrap();
    assert_eq!(bogus.status(), 401);
});

/// A fresh access token of an already registered, verified user.
async fn signed_in_token(server: &common::TestServer, email: &str, password: &str) -> String {
    let browser = server.browser();
    let body: Value = log_in(&browser, &server.url, email, password).await.json().await.unwrap();
    let csrf = body["csrf_token"].as_str().unwrap();
    create_token(&browser, &server.url, csrf, "test").await["token"].as_str().unwrap().to_string()
}

/// Creates an access token from a logged-in browser; the answer (`id`, `token`).
async fn create_token(browser: &reqwest::Client, url: &str, csrf: &str, name: &str) -> Value {
    let response = browser
        .post(format!("{url}/api/v1/tokens"))
        .header("X-CSRF-Token", csrf)
        .json(&json!({ "name": name }))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status(), 201);
    response.json().await.unwrap()
}

on_both_databases!(changing_the_password_or_deleting_the_account_needs_the_password, |db: Db| async move {
    let server = spawn(db).await;
    let (browser, csrf) = signed_in(&server, "kim@example.org", "kims password").await;
    let token = signed_in_token(&server, "kim@example.org", "kims password").await;
    let patch = |current: &'static str| {
        let (b, url, csrf) = (browser.clone(), server.url.clone(), csrf.clone());
        async move {
            b.patch(format!("{url}/api/v1/me"))
                .header("X-CSRF-Token", csrf)
                .json(&json!({ "current_password": current, "new_password": "kims new password" }))
                .send()
                .await
                .unwrap()
        }
    };
    assert_eq!(error_code(patch("guess").await).await, (403, "wrong_password".into()));
    assert_eq!(patch("kims password").await.status(), 200);
    assert_eq!(browser.get(format!("{}/api/v1/me", server.url)).send().await.unwrap().status(), 401, "sessions end");

    let script = reqwest::Client::new();
    let delete = |password: &'static str| {
        let (c, url, token) = (script.clone(), server.url.clone(), token.clone());
        async move {
            c.delete(format!("{url}/api/v1/me"))
                .bearer_auth(token)
                .json(&json!({ "password": password }))
                .send()
                .await
                .unwrap()
        }
    };
    assert_eq!(
        error_code(delete("kims password").await).await,
        (403, "wrong_password".into()),
        "the old one no longer works"
    );
    assert_eq!(delete("kims new password").await.status(), 204);
    assert_eq!(script.get(format!("{}/api/v1/me", server.url)).bearer_auth(&token).send().await.unwrap().status(), 401);
    assert_eq!(log_in(&script, &server.url, "kim@example.org", "kims new password").await.status(), 401);
    // The address is free again.
    assert_eq!(register(&script, &server.url, "kim@example.org", "a fresh start").await.status(), 201);
});

// ------------------------------------------------------------ hardening

use fbksd_server::config::RateLimit;
use std::time::{Duration, Instant};

/// A client (with cookies) whose connections come from `ip`: any 127.x
/// address reaches the loopback server, so a test has many clients.
fn client_from(ip: &str) -> reqwest::Client {
    let ip: std::net::IpAddr = ip.parse().unwrap();
    reqwest::Client::builder().cookie_store(true).local_address(ip).build().unwrap()
}

/// Registers `email` from `client` and follows the mailed link.
async fn verified(server: &common::TestServer, client: &reqwest::Client, email: &str, password: &str) {
    assert_eq!(register(client, &server.url, email, password).await.status(), 201);
    let link = server.link_in_mail(email, "/accounts/verify?token=");
    assert_eq!(client.get(&link).send().await.unwrap().status(), 200);
}

/// A 429's Retry-After seconds and message, checking the body's code.
async fn limited(response: reqwest::Response) -> (u64, String) {
    assert_eq!(response.status(), 429);
    let retry: u64 = response.headers()["retry-after"].to_str().unwrap().parse().unwrap();
    assert!(retry > 0);
    let body: Value = response.json().await.unwrap();
    assert_eq!(body["error"], "rate_limited");
    assert_eq!(body["retry_after_seconds"], retry);
    (retry, body["message"].as_str().unwrap().to_string())
}

/// The hidden CSRF field of a page's form.
fn csrf_in(page: &str) -> String {
    let at = page.find("name=\"csrf_token\" value=\"").expect("a form with a CSRF token") + 25;
    page[at..at + page[at..].find('"').unwrap()].to_string()
}

/// Posts a pre-login form (`/login`, `/register`, ...) from `client`, with
/// the CSRF token of a freshly loaded log-in page.
async fn post_form(
    server: &common::TestServer,
    client: &reqwest::Client,
    path: &str,
    fields: &[(&str, &str)],
) -> reqwest::Response {
    let page = client.get(format!("{}/login", server.url)).send().await.unwrap().text().await.unwrap();
    let csrf = csrf_in(&page);
    let mut form = vec![("csrf_token", csrf.as_str())];
    form.extend_from_slice(fields);
    client.post(format!("{}{path}", server.url)).form(&form).send().await.unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn log_in_floods_are_refused_per_address_and_per_client() {
    let server = common::spawn_with(Db::Sqlite, |c| {
        c.login_limit_per_address = RateLimit::new(3, Duration::from_secs(15 * 60));
        c.login_limit_per_ip = RateLimit::new(6, Duration::from_secs(600));
    })
    .await;
    let home = client_from("127.0.0.1");
    for who in ["ada@example.org", "bob@example.org", "cy@example.org"] {
        verified(&server, &home, who, "the right password").await;
    }

    // Guessing ada's password from one machine: three tries, then 429.
    let attacker = client_from("127.0.0.2");
    for _ in 0..3 {
        assert_eq!(log_in(&attacker, &server.url, "ada@example.org", "a guessed password").await.status(), 401);
    }
    let (retry, message) = limited(log_in(&attacker, &server.url, "ADA@example.org", "another guess!").await).await;
    assert!(message.contains("e-mail address") && message.contains("try again in"), "{message}");
    assert!((250..=300).contains(&retry), "one attempt refills in 5 minutes: {retry}");
    // The address is locked from everywhere, even with the right password...
    let elsewhere = client_from("127.0.0.3");
    assert_eq!(log_in(&elsewhere, &server.url, "ada@example.org", "the right password").await.status(), 429);
    // ... but other addresses still log in, from the same machine too.
    assert_eq!(log_in(&attacker, &server.url, "bob@example.org", "the right password").await.status(), 200);

    // One machine trying many addresses runs into the per-client limit.
    assert_eq!(log_in(&attacker, &server.url, "nobody1@example.org", "a guessed password").await.status(), 401);
    let (_, message) = limited(log_in(&attacker, &server.url, "nobody2@example.org", "a guessed password").await).await;
    assert!(message.contains("network address"), "{message}");
    assert_eq!(log_in(&attacker, &server.url, "cy@example.org", "the right password").await.status(), 429);
    assert_eq!(log_in(&elsewhere, &server.url, "cy@example.org", "the right password").await.status(), 200);

    // The log-in form is limited alike, and says so on the page.
    let form =
        post_form(&server, &attacker, "/login", &[("email", "cy@example.org"), ("password", "the right password")])
            .await;
    assert_eq!(form.status(), 429);
    assert!(form.headers().contains_key("retry-after"));
    assert!(form.text().await.unwrap().contains("too many log-in attempts from your network address"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_first_administrator_replaces_the_one_time_password_before_anything_else() {
    let server = spawn(Db::Sqlite).await;
    let (email, one_time) = server.admin.clone().expect("first start creates an administrator");
    // Logging in through the form leads to the password form.
    let browser = server.browser();
    let logged_in = post_form(&server, &browser, "/login", &[("email", &email), ("password", &one_time)]).await;
    assert_eq!(logged_in.url().path(), "/settings");
    let settings = logged_in.text().await.unwrap();
    assert!(settings.contains("id=\"choose-password\"") && settings.contains("action=\"/settings/password\""));
    let csrf = csrf_in(&settings);

    // Until then, every page and call but the change says what to do.
    let admin_page = browser.get(format!("{}/admin", server.url)).send().await.unwrap();
    assert_eq!(admin_page.status(), 403);
    assert!(admin_page.text().await.unwrap().contains("choose your own password first"));
    let token = browser
        .post(format!("{}/api/v1/tokens", server.url))
        .header("X-CSRF-Token", &csrf)
        .json(&json!({ "name": "before" }))
        .send()
        .await
        .unwrap();
    let (status, code) = error_code(token).await;
    assert_eq!((status, code.as_str()), (403, "password_change_required"));
    let me: Value = browser.get(format!("{}/api/v1/me", server.url)).send().await.unwrap().json().await.unwrap();
    assert_eq!(me["must_change_password"], true, "{me}");

    // A wrong current password changes nothing and says so.
    let form = |current: &str| {
        let fields =
            [("csrf_token", csrf.as_str()), ("current_password", current), ("new_password", "my very own password")];
        browser.post(format!("{}/settings/password", server.url)).form(&fields).send()
    };
    let wrong = form("a guess").await.unwrap().text().await.unwrap();
    assert!(wrong.contains("the current password is wrong"), "{wrong}");
    // The right one: every session ends, and the new password opens everything.
    let changed = form(&one_time).await.unwrap().text().await.unwrap();
    assert!(changed.contains("Password changed"), "{changed}");
    assert_eq!(browser.get(format!("{}/api/v1/me", server.url)).send().await.unwrap().status(), 401);
    assert_eq!(log_in(&browser, &server.url, &email, &one_time).await.status(), 401);
    let session: Value = log_in(&browser, &server.url, &email, "my very own password").await.json().await.unwrap();
    assert_eq!(session["user"]["must_change_password"], false, "{session}");
    assert_eq!(browser.get(format!("{}/admin", server.url)).send().await.unwrap().status(), 200);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_forwarded_address_is_believed_only_from_a_trusted_proxy() {
    const PROXY: &str = "127.0.0.10";
    let server = common::spawn_with(Db::Sqlite, |c| {
        c.login_limit_per_address = RateLimit::OFF;
        c.login_limit_per_ip = RateLimit::new(3, Duration::from_secs(600));
        c.client_ip_header = "X-Forwarded-For".into();
        c.trusted_proxies = PROXY.parse().unwrap();
    })
    .await;
    let guess = |client: &reqwest::Client, forwarded: &str| {
        client
            .post(format!("{}/api/v1/sessions", server.url))
            .header("X-Forwarded-For", forwarded)
            .json(&json!({ "email": "nobody@example.org", "password": "a guessed password" }))
            .send()
    };

    // A client that reaches the server without the proxy cannot name itself
    // anyone: each guess under another made-up address counts as its own.
    let direct = client_from("127.0.0.2");
    for i in 0..3 {
        assert_eq!(guess(&direct, &format!("203.0.113.{i}")).await.unwrap().status(), 401);
    }
    let (_, message) = limited(guess(&direct, "203.0.113.99").await.unwrap()).await;
    assert!(message.contains("network address"), "{message}");

    // Through the proxy, the address it saw counts: each client behind it
    // has its own limit, and what a client writes into the header itself
    // (left of what the proxy appends) changes nothing.
    let proxy = client_from(PROXY);
    for _ in 0..3 {
        assert_eq!(guess(&proxy, "198.51.100.1").await.unwrap().status(), 401);
    }
    assert_eq!(guess(&proxy, "198.51.100.1").await.unwrap().status(), 429);
    assert_eq!(guess(&proxy, "203.0.113.7, 198.51.100.1").await.unwrap().status(), 429, "a made-up first entry");
    assert_eq!(guess(&proxy, "198.51.100.2").await.unwrap().status(), 401, "another client behind the proxy");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unknown_address_takes_as_long_as_a_wrong_password() {
    let server = common::spawn_with(Db::Sqlite, |c| {
        c.login_limit_per_address = RateLimit::OFF;
        c.login_limit_per_ip = RateLimit::OFF;
    })
    .await;
    let client = server.browser();
    verified(&server, &client, "bob@example.org", "the right password").await;
    let median = |mut times: Vec<Duration>| {
        times.sort();
        times[times.len() / 2]
    };
    let (mut wrong, mut unknown) = (Vec::new(), Vec::new());
    for i in 0..7 {
        let started = Instant::now();
        let answer = error_code(log_in(&client, &server.url, "bob@example.org", "wrong password!").await).await;
        wrong.push(started.elapsed());
        let started = Instant::now();
        let other =
            error_code(log_in(&client, &server.url, &format!("nobody{i}@example.org"), "wrong password!").await).await;
        unknown.push(started.elapsed());
        assert_eq!(answer, (401, "unauthorized".into()));
        assert_eq!(answer, other, "the same answer");
    }
    let (wrong, unknown) = (median(wrong), median(unknown));
    // Without a dummy hash an unknown address answers from one SELECT, in a
    // small fraction of an argon2 verification.
    assert!(unknown * 3 > wrong, "unknown address {unknown:?}, wrong password {wrong:?}");
}

/// The 64-hex-digit reset token in the latest reset mail to `email`.
fn reset_token(server: &common::TestServer, email: &str) -> String {
    let mail = server.mails_to(email).pop().unwrap();
    assert!(mail.contains("reset"), "{mail}");
    mail.split_whitespace().find(|w| w.len() == 64 && w.chars().all(|c| c.is_ascii_hexdigit())).unwrap().to_string()
}

async fn ask_reset(client: &reqwest::Client, url: &str, email: &str) -> reqwest::Response {
    client.post(format!("{url}/api/v1/password-resets")).json(&json!({ "email": email })).send().await.unwrap()
}

async fn confirm_reset(client: &reqwest::Client, url: &str, token: &str, password: &str) -> reqwest::Response {
    client
        .post(format!("{url}/api/v1/password-resets/confirm"))
        .json(&json!({ "token": token, "password": password }))
        .send()
        .await
        .unwrap()
}

on_both_databases!(a_reset_ends_access_tokens_and_older_reset_links_and_verifies_the_address, |db: Db| async move {
    let server = spawn(db).await;
    let (browser, _) = signed_in(&server, "eve@example.org", "first password").await;
    let token = signed_in_token(&server, "eve@example.org", "first password").await;
    let script = reqwest::Client::new();
    let me = |token: String| {
        let (c, url) = (script.clone(), server.url.clone());
        async move { c.get(format!("{url}/api/v1/me")).bearer_auth(token).send().await.unwrap().status() }
    };
    assert_eq!(me(token.clone()).await, 200);

    // Two reset mails (a thief asked too, say); the later one is used.
    assert_eq!(ask_reset(&script, &server.url, "eve@example.org").await.status(), 202);
    let older = reset_token(&server, "eve@example.org");
    assert_eq!(ask_reset(&script, &server.url, "eve@example.org").await.status(), 202);
    let newer = reset_token(&server, "eve@example.org");
    assert_ne!(older, newer);
    let done = confirm_reset(&script, &server.url, &newer, "second password").await;
    assert_eq!(done.status(), 200);
    assert!(done.text().await.unwrap().contains("access tokens have ended"));

    assert_eq!(me(token).await, 401, "the old access token ends");
    assert_eq!(browser.get(format!("{}/api/v1/me", server.url)).send().await.unwrap().status(), 401, "sessions end");
    assert_eq!(
        error_code(confirm_reset(&script, &server.url, &older, "third password").await).await,
        (400, "invalid_token".into()),
        "the older reset link no longer works"
    );
    assert_eq!(log_in(&script, &server.url, "eve@example.org", "second password").await.status(), 200);

    // Resetting the password of an unverified account verifies it: the mail was read.
    assert_eq!(register(&script, &server.url, "una@example.org", "first password").await.status(), 201);
    assert_eq!(
        error_code(log_in(&script, &server.url, "una@example.org", "first password").await).await,
        (403, "email_not_verified".into())
    );
    assert_eq!(ask_reset(&script, &server.url, "una@example.org").await.status(), 202);
    let token = reset_token(&server, "una@example.org");
    assert_eq!(confirm_reset(&script, &server.url, &token, "second password").await.status(), 200);
    let body: Value = log_in(&script, &server.url, "una@example.org", "second password").await.json().await.unwrap();
    assert_eq!(body["user"]["verified"], true, "{body}");
});

async fn resend(client: &reqwest::Client, url: &str, email: &str) -> reqwest::Response {
    client.post(format!("{url}/api/v1/accounts/verification")).json(&json!({ "email": email })).send().await.unwrap()
}

on_both_databases!(the_verification_link_is_sent_again_on_request_within_limits, |db: Db| async move {
    let server = common::spawn_with(db, |c| {
        c.mail_limit_per_address = RateLimit::new(3, Duration::from_secs(3600));
        c.mail_limit_per_ip = RateLimit::new(6, Duration::from_secs(3600));
    })
    .await;
    let client = client_from("127.0.0.1");
    assert_eq!(register(&client, &server.url, "una@example.org", "una's password").await.status(), 201);
    let first = server.link_in_mail("una@example.org", "/accounts/verify?token=");

    // Asked again: a second mail with a new link; the same answer for an
    // unknown address, which gets nothing.
    let again = resend(&client, &server.url, "una@example.org").await;
    assert_eq!(again.status(), 202);
    let unknown = resend(&client, &server.url, "nobody@example.org").await;
    assert_eq!(unknown.status(), 202);
    assert_eq!(again.text().await.unwrap(), unknown.text().await.unwrap());
    assert!(server.mails_to("nobody@example.org").is_empty());
    assert_eq!(server.mails_to("una@example.org").len(), 2);
    let second = server.link_in_mail("una@example.org", "/accounts/verify?token=");
    assert_ne!(first, second);

    // A flood of requests for one address is cut off: una's mailbox gets
    // three mails an hour at most.
    assert_eq!(resend(&client, &server.url, "una@example.org").await.status(), 202);
    let (_, message) = limited(resend(&client, &server.url, "una@example.org").await).await;
    assert!(message.contains("mails to this e-mail address"), "{message}");
    assert_eq!(server.mails_to("una@example.org").len(), 3);
    // ... and so is one client asking for many addresses (6 requests so far).
    assert_eq!(resend(&client, &server.url, "nobody2@example.org").await.status(), 202);
    let (_, message) = limited(resend(&client, &server.url, "nobody3@example.org").await).await;
    assert!(message.contains("from your network address"), "{message}");
    let (_, message) = limited(ask_reset(&client, &server.url, "una@example.org").await).await;
    assert!(message.contains("from your network address"), "password resets count as mail too: {message}");
    assert_eq!(resend(&client_from("127.0.0.2"), &server.url, "nobody3@example.org").await.status(), 202);

    // The newest link verifies.
    assert_eq!(client.get(&second).send().await.unwrap().status(), 200);
    assert_eq!(log_in(&client, &server.url, "una@example.org", "una's password").await.status(), 200);

    // The log-in page offers the link again to an unverified account.
    let browser = client_from("127.0.0.3");
    assert_eq!(register(&browser, &server.url, "ida@example.org", "ida's password").await.status(), 201);
    let refused =
        post_form(&server, &browser, "/login", &[("email", "ida@example.org"), ("password", "ida's password")]).await;
    assert_eq!(refused.status(), 403);
    let page = refused.text().await.unwrap();
    assert!(page.contains("action=\"/accounts/verification\"") && page.contains("Send the confirmation link again"));
    let sent = post_form(&server, &browser, "/accounts/verification", &[("email", "ida@example.org")]).await;
    assert_eq!(sent.status(), 200);
    assert!(sent.text().await.unwrap().contains("new link is on its way"));
    assert_eq!(server.mails_to("ida@example.org").len(), 2);
});

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_log_in_flood_does_not_stall_other_requests() {
    let server = common::spawn_with(Db::Sqlite, |c| {
        c.login_limit_per_address = RateLimit::OFF;
        c.login_limit_per_ip = RateLimit::OFF;
    })
    .await;
    let client = server.browser();
    verified(&server, &client, "bob@example.org", "the right password").await;
    let board = format!("{}/api/v1/leaderboard", server.url);
    assert_eq!(client.get(&board).send().await.unwrap().status(), 200);
    let started = Instant::now();
    assert_eq!(log_in(&client, &server.url, "bob@example.org", "a wrong password").await.status(), 401);
    let one_login = started.elapsed();

    // 40 clients logging in without pause until the board has answered: the
    // flood is under way whenever the board is asked, however fast a log-in is.
    const CLIENTS: usize = 40;
    let (flooding, done) = (
        std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true)),
        std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0)),
    );
    let flood: Vec<_> = (0..CLIENTS)
        .map(|_| {
            let (client, url, flooding, done) =
                (reqwest::Client::new(), server.url.clone(), flooding.clone(), done.clone());
            tokio::spawn(async move {
                while flooding.load(std::sync::atomic::Ordering::SeqCst) {
                    let status = log_in(&client, &url, "bob@example.org", "a wrong password").await.status();
                    assert_eq!(status, 401);
                    done.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                }
            })
        })
        .collect();
    // Under way: every hashing slot busy and log-ins queued behind them.
    while done.load(std::sync::atomic::Ordering::SeqCst) < 4 {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let started = Instant::now();
    assert_eq!(client.get(&board).send().await.unwrap().status(), 200);
    let waited = started.elapsed();
    flooding.store(false, std::sync::atomic::Ordering::SeqCst);
    for login in flood {
        login.await.unwrap();
    }
    // Hashing on the async workers would make the board wait for about
    // CLIENTS / cores hashes; with the workers free it answers at once.
    let bound = (one_login * 4).max(Duration::from_millis(200));
    let logins = done.load(std::sync::atomic::Ordering::SeqCst);
    assert!(waited < bound, "the board took {waited:?} during a flood of {logins} log-ins of {one_login:?}");
}
