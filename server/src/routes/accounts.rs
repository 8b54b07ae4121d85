//! Registration, e-mail verification, logging in and out.

use super::{SessionUser, SESSION_COOKIE};
use crate::accounts::{self, Email, Password};
use crate::error::ApiError;
use crate::AppState;
use axum::extract::{Query, State};
use axum::http::{header, StatusCode};
use axum::response::{Html, IntoResponse, Response};
use axum::Json;
use serde::Deserialize;
use serde_json::json;

/// Credentials in a request body.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Credentials {
    email: String,
    password: String,
}

/// `POST /api/v1/accounts`: creates an account and mails a verification link.
pub async fn register(State(state): State<AppState>, Json(body): Json<Credentials>) -> Result<Response, ApiError> {
    let email = Email::parse(&body.email)?;
    let password = Password::parse(&body.password)?;
    let user = accounts::create_user(&state.pool, &email, &password, false, false).await?;
    let token = accounts::issue_email_token(&state.pool, &user.id, "verify").await?;
    let link = format!("{}/accounts/verify?token={token}", state.public_url);
    let body = format!(
        "Welcome to FBKSD.\n\nConfirm your e-mail address to use your account:\n\n{link}\n\n\
         The link works once, for 48 hours. If you did not register, ignore this message.\n"
    );
    state.mailer.send(&state.config.mail_from, email.as_str(), "Confirm your FBKSD account", body).await?;
    Ok((StatusCode::CREATED, Json(json!({ "id": user.id, "email": user.email, "verified": false }))).into_response())
}

/// A verification token.
#[derive(Deserialize)]
pub struct TokenBody {
    token: String,
}

/// `POST /api/v1/accounts/verify`: confirms the address with the mailed token.
pub async fn verify(
    State(state): State<AppState>,
    Json(body): Json<TokenBody>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let user_id = accounts::redeem_email_token(&state.pool, &body.token, "verify").await?;
    accounts::mark_verified(&state.pool, &user_id).await?;
    Ok(Json(json!({ "verified": true })))
}

/// `GET /accounts/verify?token=…`: the link in the e-mail.
pub async fn verify_link(State(state): State<AppState>, Query(body): Query<TokenBody>) -> Response {
    match accounts::redeem_email_token(&state.pool, &body.token, "verify").await {
        Ok(user_id) => match accounts::mark_verified(&state.pool, &user_id).await {
            Ok(()) => {
                Html("<!doctype html><title>FBKSD</title><p>Your e-mail address is confirmed: you can log in.</p>")
                    .into_response()
            }
            Err(e) => ApiError::from(e).into_response(),
        },
        Err(e) => (e.status, Html(format!("<!doctype html><title>FBKSD</title><p>{}</p>", e.message))).into_response(),
    }
}

/// `POST /api/v1/sessions`: logs in; sets the session cookie and returns the CSRF token.
pub async fn log_in(State(state): State<AppState>, Json(body): Json<Credentials>) -> Result<Response, ApiError> {
    let user = accounts::authenticate(&state.pool, &body.email, &body.password).await?;
    let session = accounts::open_session(&state.pool, &user.id, state.config.session_hours).await?;
    let secure = if state.public_url.starts_with("https://") { "; Secure" } else { "" };
    let cookie = format!(
        "{SESSION_COOKIE}={}; Path=/; HttpOnly; SameSite=Lax; Max-Age={}{secure}",
        session.token,
        state.config.session_hours * 3600
    );
    Ok(([(header::SET_COOKIE, cookie)], Json(json!({ "user": user, "csrf_token": session.csrf_token })))
        .into_response())
}

/// `DELETE /api/v1/sessions`: logs out (CSRF-checked).
pub async fn log_out(State(state): State<AppState>, session: SessionUser) -> Result<Response, ApiError> {
    accounts::close_session(&state.pool, &session.token).await?;
    let cookie = format!("{SESSION_COOKIE}=; Path=/; HttpOnly; SameSite=Lax; Max-Age=0");
    Ok(([(header::SET_COOKIE, cookie)], StatusCode::NO_CONTENT).into_response())
}

/// `GET /api/v1/me`: who is logged in.
pub async fn me(session: SessionUser) -> Json<accounts::User> {
    Json(session.user)
}
