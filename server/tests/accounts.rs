//! Accounts through the real HTTP API, on SQLite and on PostgreSQL:
//! register → the verification mail in the outbox → verify → log in → who
//! am I → log out; and every way it refuses bad input.

mod common;

use common::{spawn, Db};
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
