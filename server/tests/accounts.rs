//! Accounts through the real HTTP API, on SQLite and on PostgreSQL:
//! register → the verification mail in the outbox → verify → log in → who
//! am I → log out; and every way it refuses bad input.

mod common;

use common::{json_of, spawn, Db};
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

    // The link in the mail verifies the address, once.
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
