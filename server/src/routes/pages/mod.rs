//! HTML pages (askama templates in `frontend/templates`, stylesheets and
//! scripts in `frontend/static`, compiled in): the leaderboard, private results pages, techniques,
//! jobs with their live log, access tokens and administration.
//!
//! Every form carries a CSRF token: logged-in forms the session's, the
//! log-in and registration forms a random token also set in a short-lived
//! cookie (double submit), so another site cannot post them.
//!
//! This module holds what every page shares (the visitor, error pages, the
//! submission how-to, formatting); the pages live by area: [`account`]
//! (log-in, registration, access tokens), [`techniques`] (projects and
//! jobs), [`boards`] (the leaderboard and private results) and
//! [`administration`].

mod account;
mod administration;
mod boards;
mod techniques;

pub use account::*;
pub use administration::*;
pub use boards::*;
pub use techniques::*;

use super::{cookie, SESSION_COOKIE};
use crate::accounts::{self, Email, Password, User};
use crate::leaderboard::{self, BoardQuery};
use crate::pipelines::{Request, Source};
use crate::projects;
use crate::routes::ApiError;
use crate::AppState;
use askama::Template;
use axum::extract::{FromRequest, FromRequestParts, Path, Query, State};
use axum::http::request::Parts;
use axum::http::{header, StatusCode};
use axum::response::{Html, IntoResponse, Redirect, Response};
use axum::Form;
use serde::Deserialize;

/// Cookie holding the pre-login forms' CSRF token.
const FORM_COOKIE: &str = "fbksd_form";

/// What every page's header needs.
pub struct Nav {
    user: Option<User>,
    csrf: String,
}

/// The page visitor: a session's user and its CSRF token, or anonymous.
pub struct Visitor(Nav);

impl FromRequestParts<AppState> for Visitor {
    type Rejection = PageError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, Self::Rejection> {
        let Some(token) = cookie(&parts.headers, SESSION_COOKIE) else {
            return Ok(Visitor(Nav { user: None, csrf: String::new() }));
        };
        let session = accounts::session_user(&state.pool, token).await.map_err(ApiError::from)?;
        // Until a one-time password is replaced, the settings page (where it
        // is) and logging out are all a session may see.
        let path = parts.uri.path();
        let allowed = path == "/settings" || path == "/settings/password" || path == "/logout";
        if session.as_ref().is_some_and(|(user, _)| user.must_change_password) && !allowed {
            return Err(crate::routes::password_change_required().into());
        }
        Ok(Visitor(match session {
            Some((user, csrf)) => Nav { user: Some(user), csrf },
            None => Nav { user: None, csrf: String::new() },
        }))
    }
}

impl Visitor {
    /// The user, if the form's CSRF token is the session's; else an error page.
    fn check(&self, csrf: &str) -> Result<&User, PageError> {
        let user = self.0.user.as_ref().ok_or_else(|| ApiError::unauthorized("log in first"))?;
        if csrf.is_empty() || csrf != self.0.csrf {
            return Err(ApiError::forbidden(
                "csrf",
                "this form is stale or was not sent by this site: reload the page",
            )
            .into());
        }
        Ok(user)
    }
}

/// An error shown as a page.
pub struct PageError(ApiError);

impl From<ApiError> for PageError {
    fn from(e: ApiError) -> Self {
        PageError(e)
    }
}

impl From<crate::error::ServiceError> for PageError {
    fn from(e: crate::error::ServiceError) -> Self {
        PageError(e.into())
    }
}

impl From<sqlx::Error> for PageError {
    fn from(e: sqlx::Error) -> Self {
        PageError(e.into())
    }
}

/// An error page's heading and text, kept on its response so that
/// [`error_pages_keep_the_header`] can render it again for the visitor.
#[derive(Clone)]
struct ShownError {
    heading: String,
    text: String,
}

impl IntoResponse for PageError {
    fn into_response(self) -> Response {
        let shown = ShownError {
            heading: self.0.status.canonical_reason().unwrap_or("Error").to_string(),
            text: self.0.message,
        };
        let page = error_page(Nav { user: None, csrf: String::new() }, &shown);
        let mut response = (self.0.status, page).into_response();
        response.extensions_mut().insert(shown);
        response
    }
}

fn error_page(nav: Nav, shown: &ShownError) -> Response {
    render(&MessagePage { nav, heading: shown.heading.clone(), text: shown.text.clone(), kind: "error", link: None })
}

/// Middleware: an error page keeps the logged-in header. Errors are raised
/// deep in handlers (`?`) where the visitor is not at hand, so the page is
/// rendered again here with the session's user.
pub async fn error_pages_keep_the_header(
    State(state): State<AppState>,
    request: axum::extract::Request,
    next: axum::middleware::Next,
) -> Response {
    let token = cookie(request.headers(), SESSION_COOKIE).map(str::to_string);
    let response = next.run(request).await;
    let (Some(shown), Some(token)) = (response.extensions().get::<ShownError>().cloned(), token) else {
        return response;
    };
    match accounts::session_user(&state.pool, &token).await {
        Ok(Some((user, csrf))) => {
            let status = response.status();
            (status, error_page(Nav { user: Some(user), csrf }, &shown)).into_response()
        }
        _ => response,
    }
}

fn render(template: &impl Template) -> Response {
    match template.render() {
        Ok(html) => Html(html).into_response(),
        Err(e) => ApiError::internal(e).into_response(),
    }
}

type PageResult = Result<Response, PageError>;

#[derive(Template)]
#[template(path = "message.html")]
struct MessagePage {
    nav: Nav,
    heading: String,
    text: String,
    kind: &'static str,
    /// A link to go on with: (href, text).
    link: Option<(String, String)>,
}

fn message(nav: Nav, heading: &str, text: impl Into<String>) -> Response {
    render(&MessagePage { nav, heading: heading.into(), text: text.into(), kind: "ok", link: None })
}

/// A styled page for handlers outside this module (the e-mail link's
/// answer): a heading, a text, and a link to go on with.
pub fn message_with_link(heading: &str, text: &str, link: Option<(&str, &str)>, ok: bool) -> Response {
    render(&MessagePage {
        nav: Nav { user: None, csrf: String::new() },
        heading: heading.into(),
        text: text.into(),
        kind: if ok { "ok" } else { "error" },
        link: link.map(|(href, text)| (href.to_string(), text.to_string())),
    })
}

/// How to submit a technique, as the home page and the project pages say it.
pub struct HowTo {
    logged_in: bool,
    /// The project it is about, if any.
    project: Option<String>,
    /// Its clone URL with a user name (git asks for the password: a token).
    clone_url: String,
}

fn how_to(state: &AppState, user: Option<&User>, project: Option<&str>) -> HowTo {
    // Any user name works; the address's local part reads naturally when it is URL-safe.
    let name = user
        .and_then(|u| u.email.split('@').next())
        .filter(|n| !n.is_empty() && n.chars().all(|c| c.is_ascii_alphanumeric() || "._-".contains(c)))
        .unwrap_or("me");
    let (scheme, host) = state.public_url.split_once("://").unwrap_or(("http", &state.public_url));
    HowTo {
        logged_in: user.is_some(),
        project: project.map(str::to_string),
        clone_url: format!("{scheme}://{name}@{host}/git/{}.git", project.unwrap_or("<project>")),
    }
}

/// What the service is preparing before jobs can run, one line per
/// runner, or that no runner is connected. Runners' names and what they
/// say are for logged-in users; others learn only that jobs will wait.
async fn preparation(state: &AppState, user: Option<&User>) -> Result<Vec<String>, sqlx::Error> {
    let now = crate::now_ms();
    let runners = crate::runners::all(&state.pool).await?;
    let connected: Vec<_> = runners.iter().filter(|r| r.healthy(&state.config, now)).collect();
    if connected.is_empty() {
        return Ok(vec!["No runner is connected yet: pushes and runs wait in the queue until one is \
                        (deploy/serve.sh starts one as soon as it has built its images)."
            .into()]);
    }
    let preparing: Vec<String> = connected
        .iter()
        .filter_map(|r| {
            let status = r.preparing.as_ref()?;
            let seconds = (now - r.preparing_since.unwrap_or(now)).max(0) as u64 / 1000;
            let elapsed = humantime::format_duration(std::time::Duration::from_secs(seconds));
            Some(format!("Runner {}: {status}, for {elapsed}; jobs wait in the queue meanwhile.", r.name))
        })
        .collect();
    let mut lines = match (user, preparing.len()) {
        (_, 0) => Vec::new(),
        (Some(_), _) => preparing,
        (None, n) if n == connected.len() => {
            vec!["The runners are getting ready (log in to see what they prepare): jobs wait in the queue meanwhile."
                .into()]
        }
        (None, _) => Vec::new(),
    };
    // A season's benchmarks go only to runners of its class (see `jobs::claim`).
    let season = crate::results::current_season(&state.pool).await?;
    if let Some(class) = crate::results::season_class(&state.pool, season).await? {
        let of_class: Vec<_> =
            connected.iter().filter(|r| crate::results::runner_class(&r.machine) == Some(class.as_str())).collect();
        let season_data = state.boards.season(&state.pool, season).await?;
        let held: Vec<String> = of_class
            .iter()
            .filter_map(|r| season_data.drift_of(&r.machine).map(|d| format!("{}: {}", r.name, d.figures())))
            .collect();
        if of_class.is_empty() {
            lines.push(format!(
                "No connected runner is of this season's runner class ({class}): benchmarks wait in the queue \
                 until one is, or until an administrator starts a season for the runners' class."
            ));
        } else if held.len() == of_class.len() {
            lines.push(format!(
                "The runners of this season's class are held back from its benchmarks: their calibration lies \
                 more than {:.0} % from the class's ({}), so their times would not compare with the board's. \
                 Benchmarks wait in the queue until a runner's calibration is back within it (runners calibrate \
                 between jobs and every few minutes while idle).",
                100.0 * crate::leaderboard::CALIBRATION_DRIFT_LIMIT,
                held.join("; ")
            ));
        }
    }
    Ok(lines)
}

/// Unix ms as a UTC date and time.
fn when(ms: i64) -> String {
    let time = std::time::UNIX_EPOCH + std::time::Duration::from_millis(ms.max(0) as u64);
    humantime::format_rfc3339_seconds(time).to_string().replace('T', " ").replace('Z', " UTC")
}

/// A metric value with four significant digits.
fn number(value: Option<f64>) -> String {
    match value {
        None => "—".into(),
        Some(v) if v != 0.0 && (v.abs() < 1e-3 || v.abs() >= 1e5) => format!("{v:.3e}"),
        Some(v) => format!("{v:.4}"),
    }
}

/// Static files, compiled in.
pub async fn static_file(Path(name): Path<String>) -> Response {
    let (body, kind) = match name.as_str() {
        "style.css" => (include_str!("../../../../frontend/static/style.css"), "text/css; charset=utf-8"),
        "log.js" => (include_str!("../../../../frontend/static/log.js"), "text/javascript; charset=utf-8"),
        _ => return (StatusCode::NOT_FOUND, "no such file").into_response(),
    };
    ([(header::CONTENT_TYPE, kind), (header::CACHE_CONTROL, "public, max-age=3600")], body).into_response()
}

/// The results viewer's code (`frontend/static/viewer/`).
pub async fn viewer_file(Path(name): Path<String>) -> Response {
    let Some((_, body)) = fbksd_exchange::viewer::ASSETS.iter().find(|(n, _)| *n == name) else {
        return (StatusCode::NOT_FOUND, "no such file").into_response();
    };
    let kind = if name.ends_with(".css") { "text/css; charset=utf-8" } else { "text/javascript; charset=utf-8" };
    ([(header::CONTENT_TYPE, kind), (header::CACHE_CONTROL, "public, max-age=3600")], *body).into_response()
}

/// A page's form: as [`Form`], but one that cannot be read (a field
/// missing or malformed, as a hand-written post can send) is refused with
/// an error page that names what was wrong, not axum's bare text.
pub struct PageForm<T>(pub T);

impl<T: serde::de::DeserializeOwned> FromRequest<AppState> for PageForm<T> {
    type Rejection = PageError;

    async fn from_request(request: axum::extract::Request, state: &AppState) -> Result<Self, PageError> {
        let Form(form) = Form::<T>::from_request(request, state)
            .await
            .map_err(|e| ApiError::new(e.status(), "invalid_form", e.body_text()))?;
        Ok(PageForm(form))
    }
}

/// A form with only its CSRF token.
#[derive(Deserialize)]
pub struct CsrfForm {
    csrf_token: String,
}

/// A button's post: a logged-in visitor whose form (nothing but the CSRF
/// token) checked out. Refused like [`Visitor::check`] otherwise.
pub struct Button {
    user: User,
    nav: Nav,
}

impl FromRequest<AppState> for Button {
    type Rejection = PageError;

    async fn from_request(request: axum::extract::Request, state: &AppState) -> Result<Self, PageError> {
        let (mut parts, body) = request.into_parts();
        let visitor = Visitor::from_request_parts(&mut parts, state).await?;
        let request = axum::extract::Request::from_parts(parts, body);
        let PageForm(form) = PageForm::<CsrfForm>::from_request(request, state).await?;
        let user = visitor.check(&form.csrf_token)?.clone();
        Ok(Button { user, nav: visitor.0 })
    }
}

/// A job as the pages' tables show it.
struct JobRow {
    id: String,
    short_id: String,
    project: String,
    kind: &'static str,
    commit: String,
    state: &'static str,
    reason: String,
    created: String,
}

fn job_row(job: &crate::jobs::Job) -> JobRow {
    JobRow {
        id: job.id.clone(),
        short_id: job.id[..8.min(job.id.len())].to_string(),
        project: job.project.clone(),
        kind: job.kind.as_str(),
        commit: job.commit_sha[..12.min(job.commit_sha.len())].to_string(),
        state: job.state.as_str(),
        reason: job.failure_reason.clone().unwrap_or_default(),
        created: when(job.created_at),
    }
}
