//! Every route, grouped by who calls it, and the extractors that
//! authenticate callers.
//!
//! Callers authenticate in one of two ways ([`Caller`]):
//! - browser sessions carry a cookie (`fbksd_session`, HttpOnly,
//!   SameSite=Lax); every state-changing request of a session must also
//!   send the session's CSRF token in the `X-CSRF-Token` header (forms: the
//!   `csrf_token` field), or it is refused with 403;
//! - scripts and git send a personal access token as
//!   `Authorization: Bearer fbksd_…`; no cookie, so no CSRF check.

mod accounts;

use crate::accounts::User;
use crate::error::ApiError;
use crate::AppState;
use axum::extract::FromRequestParts;
use axum::http::request::Parts;
use axum::http::Method;
use axum::routing::{delete, get, post};
use axum::Router;

/// Name of the session cookie.
pub const SESSION_COOKIE: &str = "fbksd_session";

/// The router of the whole server.
pub fn router(state: AppState) -> Router {
    Router::new()
        // Users, from browsers or scripts.
        .route("/api/v1/accounts", post(accounts::register))
        .route("/api/v1/accounts/verify", post(accounts::verify))
        .route("/accounts/verify", get(accounts::verify_link))
        .route("/api/v1/sessions", post(accounts::log_in).delete(accounts::log_out))
        .route("/api/v1/me", get(accounts::me).patch(accounts::change_password).delete(accounts::delete_account))
        .route("/api/v1/password-resets", post(accounts::request_password_reset))
        .route("/api/v1/password-resets/confirm", post(accounts::reset_password))
        .route("/api/v1/tokens", post(accounts::create_token).get(accounts::list_tokens))
        .route("/api/v1/tokens/{id}", delete(accounts::revoke_token))
        .with_state(state)
        // A bug in one handler answers 500 instead of dropping the connection.
        .layer(tower_http::catch_panic::CatchPanicLayer::new())
}

/// The value of cookie `name` in the request.
fn cookie<'a>(parts: &'a Parts, name: &str) -> Option<&'a str> {
    parts
        .headers
        .get_all(axum::http::header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|pair| pair.trim().split_once('='))
        .find(|(k, _)| *k == name)
        .map(|(_, v)| v)
}

/// A logged-in user; for methods other than GET/HEAD the request's CSRF
/// token has been checked against the session's.
pub struct SessionUser {
    /// The user.
    pub user: User,
    /// The session cookie's token.
    pub token: String,
}

impl FromRequestParts<AppState> for SessionUser {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, Self::Rejection> {
        let token = cookie(parts, SESSION_COOKIE).ok_or_else(|| ApiError::unauthorized("log in first"))?.to_string();
        let (user, csrf) = crate::accounts::session_user(&state.pool, &token)
            .await?
            .ok_or_else(|| ApiError::unauthorized("your session has ended: log in again"))?;
        if parts.method != Method::GET && parts.method != Method::HEAD {
            let sent = parts.headers.get("x-csrf-token").and_then(|v| v.to_str().ok());
            if sent != Some(csrf.as_str()) {
                return Err(ApiError::forbidden(
                    "csrf",
                    "missing or wrong X-CSRF-Token: send the token you got when logging in",
                ));
            }
        }
        Ok(SessionUser { user, token })
    }
}

/// An authenticated caller: a browser session (CSRF-checked for state
/// changes) or a personal access token.
pub struct Caller {
    /// Who is calling.
    pub user: User,
}

impl FromRequestParts<AppState> for Caller {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, Self::Rejection> {
        let bearer = parts
            .headers
            .get(axum::http::header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.strip_prefix("Bearer "));
        if let Some(token) = bearer {
            let user = crate::accounts::token_user(&state.pool, token.trim())
                .await?
                .ok_or_else(|| ApiError::unauthorized("unknown or revoked access token"))?;
            return Ok(Caller { user });
        }
        SessionUser::from_request_parts(parts, state).await.map(|s| Caller { user: s.user })
    }
}
