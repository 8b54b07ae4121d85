//! Registration, e-mail verification, logging in and out, password
//! resets and access tokens. Log-ins and account mails pass the rate
//! limits first (`throttle`): refused, they answer 429 with `Retry-After`.

use super::{Caller, SessionUser};
use crate::accounts::{self, Email, Password};
use crate::routes::ApiError;
use crate::throttle::{ClientIp, Limited};
use crate::AppState;
use axum::extract::{Query, State};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
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

/// A refusal: an error, or a rate limit (which carries `Retry-After`).
pub enum Refused {
    /// Any other refusal.
    Error(ApiError),
    /// Over a rate limit.
    Limited(Limited),
}

impl From<ApiError> for Refused {
    fn from(e: ApiError) -> Self {
        Refused::Error(e)
    }
}

impl From<crate::error::ServiceError> for Refused {
    fn from(e: crate::error::ServiceError) -> Self {
        Refused::Error(e.into())
    }
}

impl From<sqlx::Error> for Refused {
    fn from(e: sqlx::Error) -> Self {
        Refused::Error(e.into())
    }
}

impl From<Limited> for Refused {
    fn from(l: Limited) -> Self {
        Refused::Limited(l)
    }
}

impl IntoResponse for Refused {
    fn into_response(self) -> Response {
        match self {
            Refused::Error(e) => e.into_response(),
            Refused::Limited(l) => l.into_response(),
        }
    }
}

/// `POST /api/v1/accounts`: creates an account and mails a verification link.
pub async fn register(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    Json(body): Json<Credentials>,
) -> Result<Response, Refused> {
    let email = Email::parse(&body.email)?;
    let password = Password::parse(&body.password)?;
    state.throttle.mail(ip, email.as_str())?;
    let user = accounts::register(&state, &email, &password).await?;
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
    let verified = match accounts::redeem_email_token(&state.pool, &body.token, "verify").await {
        Ok(user_id) => accounts::mark_verified(&state.pool, &user_id).await.map_err(ApiError::from),
        Err(e) => Err(e.into()),
    };
    let log_in = Some(("/login", "Log in"));
    match verified {
        Ok(()) => super::pages::message_with_link(
            "Address confirmed",
            "Your e-mail address is confirmed: log in, create an access token, and push your technique.",
            log_in,
            true,
        ),
        Err(e) => {
            let page = super::pages::message_with_link("This link does not work", &e.message, log_in, false);
            (e.status, page).into_response()
        }
    }
}

/// An address asking for something by mail.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AddressBody {
    email: String,
}

/// The answer to a verification request, the same whether or not the
/// address has an account waiting, so it reveals no accounts.
pub const VERIFICATION_SENT: &str = "if this address has an account waiting for confirmation, a new link is on its way";

/// `POST /api/v1/accounts/verification`: mails the verification link again.
pub async fn resend_verification(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    Json(body): Json<AddressBody>,
) -> Result<(StatusCode, Json<serde_json::Value>), Refused> {
    let email = Email::parse(&body.email)?;
    state.throttle.mail(ip, email.as_str())?;
    accounts::resend_verification(&state, &email).await?;
    Ok((StatusCode::ACCEPTED, Json(json!({ "message": VERIFICATION_SENT }))))
}

/// `POST /api/v1/sessions`: logs in; sets the session cookie and returns the CSRF token.
pub async fn log_in(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    Json(body): Json<Credentials>,
) -> Result<Response, Refused> {
    let attempt = state.throttle.log_in(ip, &body.email)?;
    let user = accounts::authenticate(&state.pool, &body.email, &body.password).await?;
    attempt.succeeded();
    let session = accounts::open_session(&state.pool, &user.id, state.config.session_hours).await?;
    let cookie = super::session_cookie(&state, &session.token);
    Ok(([(header::SET_COOKIE, cookie)], Json(json!({ "user": user, "csrf_token": session.csrf_token })))
        .into_response())
}

/// `DELETE /api/v1/sessions`: logs out (CSRF-checked).
pub async fn log_out(State(state): State<AppState>, session: SessionUser) -> Result<Response, ApiError> {
    accounts::close_session(&state.pool, &session.token).await?;
    Ok(([(header::SET_COOKIE, super::ENDED_SESSION_COOKIE)], StatusCode::NO_CONTENT).into_response())
}

/// `GET /api/v1/me`: who is calling.
pub async fn me(caller: Caller) -> Json<accounts::User> {
    Json(caller.user)
}

/// A password change.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PasswordChange {
    current_password: String,
    new_password: String,
}

/// `PATCH /api/v1/me`: changes the password (the current one is required);
/// every session ends, this one too.
pub async fn change_password(
    State(state): State<AppState>,
    caller: Caller,
    Json(body): Json<PasswordChange>,
) -> Result<Json<serde_json::Value>, ApiError> {
    accounts::change_password(&state.pool, &caller.user.id, &body.current_password, &body.new_password).await?;
    Ok(Json(json!({ "changed": true, "message": "password changed: log in again" })))
}

/// The password, confirming a deletion.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PasswordConfirmation {
    password: String,
}

/// `DELETE /api/v1/me`: deletes the account (password required).
pub async fn delete_account(
    State(state): State<AppState>,
    caller: Caller,
    Json(body): Json<PasswordConfirmation>,
) -> Result<StatusCode, ApiError> {
    accounts::check_password(&state.pool, &caller.user.id, &body.password).await?;
    // Projects and unpublished results go with the account; published results stay on the leaderboard.
    let projects = crate::projects::ids_of_owner(&state.pool, &caller.user.id).await?;
    crate::results::discard_unpublished_of(&state.pool, &state.config.data_dir, &caller.user.id).await?;
    accounts::delete_user(&state.pool, &caller.user.id).await?;
    for project in projects {
        state.git.delete(&project).await;
    }
    Ok(StatusCode::NO_CONTENT)
}

/// `POST /api/v1/password-resets`: mails a reset link if the address has an
/// account. The answer is the same either way, so it reveals no accounts.
pub async fn request_password_reset(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    Json(body): Json<AddressBody>,
) -> Result<(StatusCode, Json<serde_json::Value>), Refused> {
    let email = Email::parse(&body.email)?;
    state.throttle.mail(ip, email.as_str())?;
    accounts::mail_password_reset(&state, &email).await?;
    let message = "if this address has an account, a reset token is on its way";
    Ok((StatusCode::ACCEPTED, Json(json!({ "message": message }))))
}

/// A reset token and the new password.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PasswordReset {
    token: String,
    password: String,
}

/// `POST /api/v1/password-resets/confirm`: sets the new password; every
/// session and access token ends, other reset tokens die, and the address
/// counts as verified.
pub async fn reset_password(
    State(state): State<AppState>,
    Json(body): Json<PasswordReset>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let password = Password::parse(&body.password)?;
    accounts::reset_password(&state.pool, &body.token, &password).await?;
    let message = "password changed: log in again; your sessions and access tokens have ended";
    Ok(Json(json!({ "changed": true, "message": message })))
}

/// A new token's name.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TokenName {
    name: String,
}

/// `POST /api/v1/tokens`: creates a personal access token, shown once.
pub async fn create_token(
    State(state): State<AppState>,
    caller: Caller,
    Json(body): Json<TokenName>,
) -> Result<(StatusCode, Json<serde_json::Value>), ApiError> {
    let (id, token) = accounts::create_access_token(&state.pool, &caller.user.id, &body.name).await?;
    Ok((StatusCode::CREATED, Json(json!({ "id": id, "token": token, "message": "copy it now: it is shown once" }))))
}

/// `GET /api/v1/tokens`: the caller's tokens (never the secrets).
pub async fn list_tokens(
    State(state): State<AppState>,
    caller: Caller,
) -> Result<Json<Vec<accounts::AccessToken>>, ApiError> {
    Ok(Json(accounts::access_tokens(&state.pool, &caller.user.id).await?))
}

/// `DELETE /api/v1/tokens/{id}`: revokes one of the caller's tokens.
pub async fn revoke_token(
    State(state): State<AppState>,
    caller: Caller,
    axum::extract::Path(id): axum::extract::Path<String>,
) -> Result<StatusCode, ApiError> {
    if accounts::revoke_access_token(&state.pool, &caller.user.id, &id).await? {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(ApiError::new(StatusCode::NOT_FOUND, "not_found", format!("you have no token {id}")))
    }
}
