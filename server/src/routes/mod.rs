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
//!
//! Every answer gets the security headers of [`limits`], which also counts
//! the live-log streams a caller holds and times out silent connections.

mod accounts;
mod admin;
pub mod error;
pub mod limits;
mod operations;
mod pages;
mod public_boards;

pub use public_boards::{PublicBoards, Rendering};
mod projects;
mod results;
mod runner;

use crate::accounts::User;
use crate::AppState;
use axum::extract::FromRequestParts;
use axum::http::request::Parts;
use axum::http::Method;
use axum::routing::{any, delete, get, post, put};
use axum::Router;
pub use error::ApiError;

/// Name of the session cookie.
pub const SESSION_COOKIE: &str = "fbksd_session";

/// A `Set-Cookie` value that ends the session cookie.
pub(crate) const ENDED_SESSION_COOKIE: &str = "fbksd_session=; Path=/; HttpOnly; SameSite=Lax; Max-Age=0";

/// The `Set-Cookie` value of a new session (Secure when the server is reached over HTTPS).
fn session_cookie(state: &AppState, token: &str) -> String {
    let secure = if state.public_url.starts_with("https://") { "; Secure" } else { "" };
    let max_age = state.config.session_hours * 3600;
    format!("{SESSION_COOKIE}={token}; Path=/; HttpOnly; SameSite=Lax; Max-Age={max_age}{secure}")
}

/// `/metrics`: on the public router, or alone on `metrics_bind`'s listener
/// ([`crate::Application`]).
pub fn metrics_router() -> Router<AppState> {
    Router::new().route("/metrics", get(operations::metrics))
}

/// The router of the whole server.
pub fn router(state: AppState) -> Router {
    Router::new()
        // Users, from browsers or scripts.
        .route("/api/v1/accounts", post(accounts::register))
        .route("/api/v1/accounts/verify", post(accounts::verify))
        .route("/api/v1/accounts/verification", post(accounts::resend_verification))
        .route("/accounts/verify", get(accounts::verify_link))
        .route("/api/v1/sessions", post(accounts::log_in).delete(accounts::log_out))
        .route("/api/v1/me", get(accounts::me).patch(accounts::change_password).delete(accounts::delete_account))
        .route("/api/v1/password-resets", post(accounts::request_password_reset))
        .route("/api/v1/password-resets/confirm", post(accounts::reset_password))
        .route("/api/v1/tokens", post(accounts::create_token).get(accounts::list_tokens))
        .route("/api/v1/tokens/{id}", delete(accounts::revoke_token))
        .route("/api/v1/projects", post(projects::create).get(projects::list))
        .route("/api/v1/projects/{name}", get(projects::show).delete(projects::delete))
        .route("/api/v1/projects/{name}/pipelines", post(projects::run_pipeline))
        .route("/api/v1/jobs/{id}", get(projects::job))
        .route("/api/v1/jobs/{id}/log", get(projects::log).post(runner::append_log))
        .route("/api/v1/jobs/{id}/log/stream", get(projects::log_stream))
        .route("/api/v1/jobs/{id}/cancel", post(projects::cancel))
        .route("/api/v1/results/{id}", get(results::show).delete(results::discard))
        .route("/api/v1/results/{id}/viewer", get(results::viewer))
        .route("/api/v1/results/{id}/publish", post(results::publish))
        .route("/api/v1/results/{id}/unpublish", post(results::unpublish))
        .route("/api/v1/leaderboard", get(results::board))
        .route("/results/{id}/files/{*name}", get(results::file))
        .route("/results/{id}/references/{scene}", get(results::reference))
        .route("/results/{id}/references/{scene}/{buffer}", get(results::reference_buffer))
        // Git, with personal access tokens (HTTP Basic password) or a job token.
        .route("/git/{repo}/{*rest}", any(projects::git))
        // Runners, with their runner token or a job token.
        .route("/api/v1/runners", post(runner::register))
        .route("/api/v1/runners/jobs", post(runner::claim))
        .route("/api/v1/runners/status", post(runner::status))
        .route("/api/v1/runners/references", post(runner::request_reference))
        .route("/api/v1/runners/references/{key}/files/{name}", get(runner::reference_file))
        .route("/api/v1/jobs/{id}/heartbeat", post(runner::heartbeat))
        .route("/api/v1/jobs/{id}/results", put(runner::put_results))
        .route("/api/v1/jobs/{id}/files/{*name}", put(runner::put_file))
        .route("/api/v1/jobs/{id}/references/{hash}", get(runner::has_reference))
        .route("/api/v1/jobs/{id}/finish", post(runner::finish))
        // Administrators.
        .route("/api/v1/admin/jobs", get(admin::jobs))
        .route("/api/v1/admin/jobs/{id}/requeue", post(admin::requeue))
        .route("/api/v1/admin/runners", get(admin::runners))
        .route("/api/v1/admin/runners/{id}", delete(admin::remove_runner))
        .route("/api/v1/admin/runner-registration-token", post(admin::rotate_registration_token))
        .route("/api/v1/admin/results/{id}/hide", post(results::hide).delete(results::unhide))
        .route("/api/v1/admin/seasons", post(admin::new_season))
        // Pages, with CSRF-checked forms.
        .route("/", get(pages::home))
        .route("/static/{name}", get(pages::static_file))
        .route("/static/viewer/{name}", get(pages::viewer_file))
        .route("/login", get(pages::login_form).post(pages::login))
        .route("/register", get(pages::register_form).post(pages::register))
        .route("/accounts/verification", post(pages::resend_verification))
        .route("/logout", post(pages::logout))
        .route("/settings", get(pages::settings))
        .route("/settings/tokens", post(pages::create_token))
        .route("/settings/password", post(pages::change_password))
        .route("/settings/tokens/{id}/revoke", post(pages::revoke_token))
        .route("/projects", get(pages::projects_page).post(pages::create_project))
        .route("/environments", get(pages::environments_page))
        .route("/projects/{name}", get(pages::project_page))
        .route("/projects/{name}/run", post(pages::run_project))
        .route("/jobs/{id}", get(pages::job_page))
        .route("/jobs/{id}/cancel", post(pages::cancel_job))
        .route("/results/", get(pages::leaderboard_page))
        .route("/results/{id}", get(pages::result_page))
        .route("/results/{id}/{action}", post(pages::result_action))
        .route("/admin", get(pages::admin_page))
        .route("/admin/jobs/{id}/requeue", post(pages::admin_requeue))
        .route("/admin/hide", post(pages::admin_hide))
        .route("/admin/seasons", post(pages::admin_season))
        // Operators and orchestrators.
        .route("/healthz", get(operations::healthz))
        .route("/readyz", get(operations::readyz))
        .merge(if state.config.metrics_bind.is_empty() { metrics_router() } else { Router::new() })
        // After routing, so that answers are timed by their route's pattern.
        .route_layer(axum::middleware::from_fn_with_state(state.clone(), operations::track))
        .layer(axum::middleware::from_fn_with_state(state.clone(), pages::error_pages_keep_the_header))
        .layer(axum::Extension(limits::StreamSlots::default()))
        .with_state(state)
        // A bug in one handler answers 500 instead of dropping the connection.
        .layer(tower_http::catch_panic::CatchPanicLayer::new())
        // Pages, documents, scripts and styles gzipped when the browser
        // accepts it. Pixel files and downloads are compressed already, git
        // answers are packs, and live logs must not wait in a compressor.
        .layer(tower_http::compression::CompressionLayer::new().compress_when(compressible()))
        // Outermost, so that every answer has them, errors and panics included.
        .layer(axum::middleware::map_response(limits::security_headers))
}

/// What [`router`] compresses: text answers (the default rule leaves out
/// images, event streams and tiny bodies), not the files that are
/// compressed already or git's packs.
fn compressible() -> impl tower_http::compression::Predicate {
    use tower_http::compression::predicate::{DefaultPredicate, NotForContentType, Predicate};
    DefaultPredicate::new()
        .and(NotForContentType::const_new("application/octet-stream"))
        .and(NotForContentType::const_new("application/gzip"))
        .and(NotForContentType::const_new("application/x-git"))
        .and(NotForContentType::const_new("application/zip"))
}

/// The value of cookie `name` in the request.
fn cookie<'a>(headers: &'a axum::http::HeaderMap, name: &str) -> Option<&'a str> {
    headers
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
        let token =
            cookie(&parts.headers, SESSION_COOKIE).ok_or_else(|| ApiError::unauthorized("log in first"))?.to_string();
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

/// What a user who must choose a password first may still do through the
/// API: choose it (`PATCH /api/v1/me`), read who they are, and log out.
fn allowed_before_password_change(parts: &Parts) -> bool {
    let path = parts.uri.path();
    (path == "/api/v1/me" && (parts.method == Method::PATCH || parts.method == Method::GET))
        || (path == "/api/v1/sessions" && parts.method == Method::DELETE)
}

/// The refusal for a user who must choose a password first.
pub fn password_change_required() -> ApiError {
    ApiError::forbidden(
        "password_change_required",
        "choose your own password first: the one-time password printed at the server's first start must be \
         changed (Settings → Password on the site, or PATCH /api/v1/me with current_password and new_password)",
    )
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
            let token = token.trim();
            if token.starts_with(crate::runners::RUNNER_TOKEN_PREFIX)
                || token.starts_with(crate::jobs::JOB_TOKEN_PREFIX)
            {
                return Err(ApiError::forbidden(
                    "not_a_user_token",
                    "runner and job tokens cannot act as a user: use a personal access token",
                ));
            }
            let user = crate::accounts::token_user(&state.pool, token)
                .await?
                .ok_or_else(|| ApiError::unauthorized("unknown or revoked access token"))?;
            return Caller::unless_password_change_pending(parts, user);
        }
        let user = SessionUser::from_request_parts(parts, state).await?.user;
        Caller::unless_password_change_pending(parts, user)
    }
}

impl Caller {
    fn unless_password_change_pending(parts: &Parts, user: User) -> Result<Caller, ApiError> {
        if user.must_change_password && !allowed_before_password_change(parts) {
            return Err(password_change_required());
        }
        Ok(Caller { user })
    }
}

/// The caller if authenticated, or anonymous (for pages and reads that
/// depend on visibility). A token that is sent but invalid is refused.
pub struct MaybeUser(pub Option<User>);

impl FromRequestParts<AppState> for MaybeUser {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, Self::Rejection> {
        if parts.headers.contains_key(axum::http::header::AUTHORIZATION)
            || cookie(&parts.headers, SESSION_COOKIE).is_some()
        {
            match Caller::from_request_parts(parts, state).await {
                Ok(c) => return Ok(MaybeUser(Some(c.user))),
                // An expired session reads as anonymous; a bad token is an error.
                Err(e) if parts.headers.contains_key(axum::http::header::AUTHORIZATION) => return Err(e),
                Err(_) => {}
            }
        }
        Ok(MaybeUser(None))
    }
}

/// An administrator (session or token).
pub struct Admin(pub User);

impl FromRequestParts<AppState> for Admin {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, Self::Rejection> {
        let caller = Caller::from_request_parts(parts, state).await?;
        if caller.user.is_admin {
            Ok(Admin(caller.user))
        } else {
            Err(ApiError::forbidden("not_admin", "only administrators can do this"))
        }
    }
}

fn bearer(parts: &Parts) -> Option<&str> {
    parts
        .headers
        .get(axum::http::header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .map(str::trim)
}

/// A registered runner, by its runner token.
pub struct RunnerCaller(pub String);

impl FromRequestParts<AppState> for RunnerCaller {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, Self::Rejection> {
        let token =
            bearer(parts).ok_or_else(|| ApiError::unauthorized("send the runner token as Authorization: Bearer"))?;
        crate::runners::token_runner(&state.pool, token)
            .await?
            .map(RunnerCaller)
            .ok_or_else(|| ApiError::unauthorized("unknown runner token: register the runner again"))
    }
}

/// The job a job token was issued for, while that attempt runs; the
/// token must belong to the job in the path.
pub struct JobCaller {
    /// The job.
    pub job_id: String,
    /// The attempt the token belongs to.
    pub attempt: i64,
}

impl FromRequestParts<AppState> for JobCaller {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, Self::Rejection> {
        let axum::extract::Path(params): axum::extract::Path<std::collections::HashMap<String, String>> =
            axum::extract::Path::from_request_parts(parts, state)
                .await
                .map_err(|e| ApiError::bad_request("invalid_path", e.to_string()))?;
        let path_job = params.get("id").cloned().unwrap_or_default();
        let token = bearer(parts)
            .filter(|t| t.starts_with(crate::jobs::JOB_TOKEN_PREFIX))
            .ok_or_else(|| ApiError::unauthorized("send the job's token (fbksdj_…) as Authorization: Bearer"))?;
        let (job_id, job_state, attempt) = crate::jobs::token_job(&state.pool, token).await?.ok_or_else(|| {
            ApiError::new(
                axum::http::StatusCode::GONE,
                "lease_lost",
                "this job token is no longer valid: the job was cancelled, finished or given to another runner",
            )
        })?;
        if job_id != path_job {
            return Err(ApiError::forbidden("wrong_job", "this job token belongs to another job"));
        }
        if job_state != crate::jobs::JobState::Running {
            return Err(ApiError::new(
                axum::http::StatusCode::GONE,
                "lease_lost",
                format!("the job is {job_state}: stop working on it"),
            ));
        }
        Ok(JobCaller { job_id, attempt })
    }
}
