//! HTML pages (askama templates in `frontend/templates`, stylesheets and
//! scripts in `frontend/static`, compiled in): the leaderboard, private results pages, techniques,
//! jobs with their live log, access tokens and administration.
//!
//! Every form carries a CSRF token: logged-in forms the session's, the
//! log-in and registration forms a random token also set in a short-lived
//! cookie (double submit), so another site cannot post them.

use super::{cookie, SESSION_COOKIE};
use crate::accounts::{self, Email, Password, User};
use crate::error::ApiError;
use crate::leaderboard::{self, BoardQuery};
use crate::pipelines::{Request, Source};
use crate::projects;
use crate::AppState;
use askama::Template;
use axum::extract::{FromRequestParts, Path, Query, State};
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
    Ok(match (user, preparing.len()) {
        (_, 0) => Vec::new(),
        (Some(_), _) => preparing,
        (None, n) if n == connected.len() => {
            vec!["The runners are getting ready (log in to see what they prepare): jobs wait in the queue meanwhile."
                .into()]
        }
        (None, _) => Vec::new(),
    })
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
        "style.css" => (include_str!("../../../frontend/static/style.css"), "text/css; charset=utf-8"),
        "log.js" => (include_str!("../../../frontend/static/log.js"), "text/javascript; charset=utf-8"),
        _ => return (StatusCode::NOT_FOUND, "no such file").into_response(),
    };
    ([(header::CONTENT_TYPE, kind), (header::CACHE_CONTROL, "public, max-age=3600")], body).into_response()
}

/// `GET /`: the leaderboard, with how to submit while it is empty and what
/// the service is still preparing.
pub async fn home(State(state): State<AppState>, Visitor(nav): Visitor, Query(query): Query<BoardQuery>) -> PageResult {
    board_page(&state, nav, query, None, true).await
}

// ---------------------------------------------------------------- accounts

#[derive(Template)]
#[template(path = "credentials.html")]
struct CredentialsPage {
    nav: Nav,
    heading: &'static str,
    action: &'static str,
    csrf: String,
    email: String,
    error: String,
    password_autocomplete: &'static str,
}

fn credentials_page(register: bool, email: &str, error: &str, status: StatusCode) -> Response {
    let csrf = accounts::random_token();
    let page = CredentialsPage {
        nav: Nav { user: None, csrf: String::new() },
        heading: if register { "Register" } else { "Log in" },
        action: if register { "/register" } else { "/login" },
        csrf: csrf.clone(),
        email: email.into(),
        error: error.into(),
        password_autocomplete: if register { "new-password" } else { "current-password" },
    };
    let cookie = format!("{FORM_COOKIE}={csrf}; Path=/; HttpOnly; SameSite=Strict; Max-Age=3600");
    (status, [(header::SET_COOKIE, cookie)], render(&page)).into_response()
}

/// `GET /login`.
pub async fn login_form() -> Response {
    credentials_page(false, "", "", StatusCode::OK)
}

/// `GET /register`.
pub async fn register_form() -> Response {
    credentials_page(true, "", "", StatusCode::OK)
}

/// The log-in and registration forms.
#[derive(Deserialize)]
pub struct CredentialsForm {
    csrf_token: String,
    email: String,
    password: String,
}

fn check_form_cookie(headers: &axum::http::HeaderMap, sent: &str) -> Result<(), PageError> {
    if sent.is_empty() || cookie(headers, FORM_COOKIE) != Some(sent) {
        return Err(
            ApiError::forbidden("csrf", "this form is stale or was not sent by this site: reload the page").into()
        );
    }
    Ok(())
}

/// `POST /login`.
pub async fn login(
    State(state): State<AppState>,
    headers: axum::http::HeaderMap,
    Form(form): Form<CredentialsForm>,
) -> PageResult {
    check_form_cookie(&headers, &form.csrf_token)?;
    let user = match accounts::authenticate(&state.pool, &form.email, &form.password).await {
        Ok(user) => user,
        Err(e) => return Ok(credentials_page(false, &form.email, &e.message, e.status)),
    };
    let session = accounts::open_session(&state.pool, &user.id, state.config.session_hours).await?;
    let cookie = super::session_cookie(&state, &session.token);
    Ok(([(header::SET_COOKIE, cookie)], Redirect::to("/projects")).into_response())
}

/// `POST /register`.
pub async fn register(
    State(state): State<AppState>,
    headers: axum::http::HeaderMap,
    Form(form): Form<CredentialsForm>,
) -> PageResult {
    check_form_cookie(&headers, &form.csrf_token)?;
    let checked = (Email::parse(&form.email), Password::parse(&form.password));
    let (email, password) = match checked {
        (Ok(e), Ok(p)) => (e, p),
        (Err(e), _) | (_, Err(e)) => return Ok(credentials_page(true, &form.email, &e.message, e.status)),
    };
    if let Err(e) = super::accounts::create_and_mail(&state, &email, &password).await {
        return Ok(credentials_page(true, &form.email, &e.message, e.status));
    }
    let nav = Nav { user: None, csrf: String::new() };
    Ok(message(nav, "Check your mail", format!("We sent a confirmation link to {}.", email.as_str())))
}

/// A form with only its CSRF token.
#[derive(Deserialize)]
pub struct CsrfForm {
    csrf_token: String,
}

/// `POST /logout`.
pub async fn logout(
    State(state): State<AppState>,
    visitor: Visitor,
    headers: axum::http::HeaderMap,
    Form(form): Form<CsrfForm>,
) -> PageResult {
    visitor.check(&form.csrf_token)?;
    if let Some(token) = cookie(&headers, SESSION_COOKIE) {
        accounts::close_session(&state.pool, token).await?;
    }
    Ok(([(header::SET_COOKIE, super::ENDED_SESSION_COOKIE)], Redirect::to("/results/")).into_response())
}

// ---------------------------------------------------------------- tokens

struct TokenRow {
    id: String,
    name: String,
    created: String,
    last_used: String,
}

#[derive(Template)]
#[template(path = "settings.html")]
struct SettingsPage {
    nav: Nav,
    tokens: Vec<TokenRow>,
    new_token: String,
}

async fn settings_page(state: &AppState, nav: Nav, new_token: String) -> PageResult {
    let user = nav.user.as_ref().ok_or_else(|| ApiError::unauthorized("log in first"))?;
    let tokens = accounts::access_tokens(&state.pool, &user.id)
        .await?
        .into_iter()
        .map(|t| TokenRow {
            id: t.id,
            name: t.name,
            created: when(t.created_at),
            last_used: t.last_used_at.map(when).unwrap_or_else(|| "never".into()),
        })
        .collect();
    Ok(render(&SettingsPage { nav, tokens, new_token }))
}

/// `GET /settings`.
pub async fn settings(State(state): State<AppState>, Visitor(nav): Visitor) -> PageResult {
    settings_page(&state, nav, String::new()).await
}

/// A new token's name.
#[derive(Deserialize)]
pub struct TokenForm {
    csrf_token: String,
    name: String,
}

/// `POST /settings/tokens`.
pub async fn create_token(State(state): State<AppState>, visitor: Visitor, Form(form): Form<TokenForm>) -> PageResult {
    let user = visitor.check(&form.csrf_token)?;
    let (_, token) = accounts::create_access_token(&state.pool, &user.id, &form.name).await?;
    settings_page(&state, visitor.0, token).await
}

/// `POST /settings/tokens/{id}/revoke`.
pub async fn revoke_token(
    State(state): State<AppState>,
    visitor: Visitor,
    Path(id): Path<String>,
    Form(form): Form<CsrfForm>,
) -> PageResult {
    let user = visitor.check(&form.csrf_token)?;
    accounts::revoke_access_token(&state.pool, &user.id, &id).await?;
    Ok(Redirect::to("/settings").into_response())
}

// ---------------------------------------------------------------- projects and jobs

struct ProjectRow {
    name: String,
    visibility: &'static str,
    created: String,
}

#[derive(Template)]
#[template(path = "projects.html")]
struct ProjectsPage {
    nav: Nav,
    projects: Vec<ProjectRow>,
}

/// `GET /projects`.
pub async fn projects_page(State(state): State<AppState>, Visitor(nav): Visitor) -> PageResult {
    let projects = projects::visible(&state.pool, nav.user.as_ref())
        .await?
        .into_iter()
        .map(|p| ProjectRow { name: p.name, visibility: p.visibility.as_str(), created: when(p.created_at) })
        .collect();
    Ok(render(&ProjectsPage { nav, projects }))
}

/// The new-project form.
#[derive(Deserialize)]
pub struct ProjectForm {
    csrf_token: String,
    name: String,
    visibility: String,
}

/// `POST /projects`.
pub async fn create_project(
    State(state): State<AppState>,
    visitor: Visitor,
    Form(form): Form<ProjectForm>,
) -> PageResult {
    let user = visitor.check(&form.csrf_token)?;
    let project = super::projects::create_with_repository(&state, user, &form.name, &form.visibility).await?;
    Ok(Redirect::to(&format!("/projects/{}", project.name)).into_response())
}

struct JobRow {
    id: String,
    short_id: String,
    project: String,
    kind: &'static str,
    commit: String,
    state: String,
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
        state: job.state.clone(),
        reason: job.failure_reason.clone().unwrap_or_default(),
        created: when(job.created_at),
    }
}

struct ResultRow {
    id: String,
    commit: String,
    season: i64,
    created: String,
    status: String,
}

#[derive(Template)]
#[template(path = "project.html")]
struct ProjectPage {
    nav: Nav,
    name: String,
    full_name: String,
    visibility: &'static str,
    technique_type: String,
    comment: String,
    citation: String,
    /// Only the public description: the visitor cannot read the repository
    /// but the technique has published results.
    public_only: bool,
    clone_url: String,
    owner: bool,
    how_to: HowTo,
    results: Vec<ResultRow>,
    jobs: Vec<JobRow>,
}

/// `GET /projects/{name}`: the technique page (its info.json at the
/// latest commit) and its history. A visitor who cannot read the
/// repository still sees a technique with published results: its public
/// description (the info.json it was published with) and those results,
/// never its code or jobs.
pub async fn project_page(
    State(state): State<AppState>,
    Visitor(nav): Visitor,
    Path(name): Path<String>,
) -> PageResult {
    let (project, public_only) = match projects::readable(&state.pool, &name, nav.user.as_ref()).await {
        Ok(project) => (project, false),
        Err(hidden) => match projects::by_name(&state.pool, &name).await? {
            Some(project) => (project, true),
            None => return Err(hidden.into()),
        },
    };
    let owner = !public_only && nav.user.as_ref().is_some_and(|u| project.writable_by(u) || u.is_admin);
    let sets: Vec<_> = crate::results::of_project(&state.pool, &project.id)
        .await?
        .into_iter()
        .filter(|r| owner || r.is_public())
        .collect();
    let info = if public_only {
        // The newest published description; no published result, no page.
        let Some(set) = sets.iter().max_by_key(|r| r.published_at) else {
            // The same answer as for no project at all: a private name stays private.
            return Err(projects::not_found(&name).into());
        };
        serde_json::from_value::<fbksd_manager::technique::TechniqueInfo>(set.info.clone()).ok()
    } else {
        match state.git.resolve(&project.id, "main").await {
            Some(commit) => crate::pipelines::sanity_check(&state, &project, &commit).await.ok(),
            None => None,
        }
    };
    let results = sets
        .into_iter()
        .map(|r| ResultRow {
            status: match (&r.hidden_reason, r.published_at) {
                (Some(_), _) => "hidden".into(),
                (None, Some(_)) => "published".into(),
                (None, None) => "private".into(),
            },
            id: r.id,
            commit: r.commit_sha[..12.min(r.commit_sha.len())].to_string(),
            season: r.season,
            created: when(r.created_at),
        })
        .collect();
    let jobs = match public_only {
        true => Vec::new(),
        false => crate::jobs::of_project(&state.pool, &project.id, 50).await?.iter().map(job_row).collect(),
    };
    let page = ProjectPage {
        full_name: info.as_ref().map(|i| i.full_name.clone()).unwrap_or_else(|| project.name.clone()),
        technique_type: info.as_ref().map(|i| format!("{:?}", i.technique_type).to_lowercase()).unwrap_or_default(),
        comment: info.as_ref().map(|i| i.comment.clone()).unwrap_or_default(),
        citation: info.as_ref().map(|i| i.citation.clone()).unwrap_or_default(),
        clone_url: state.clone_url(&project.name),
        how_to: how_to(&state, nav.user.as_ref(), Some(&project.name)),
        visibility: project.visibility.as_str(),
        public_only,
        name: project.name,
        owner,
        results,
        jobs,
        nav,
    };
    Ok(render(&page))
}

/// `POST /projects/{name}/run`: FBKSD_RUN at the head of `main`.
pub async fn run_project(
    State(state): State<AppState>,
    visitor: Visitor,
    Path(name): Path<String>,
    Form(form): Form<CsrfForm>,
) -> PageResult {
    let user = visitor.check(&form.csrf_token)?;
    let project = projects::writable(&state.pool, &name, user).await?;
    let commit =
        state.git.resolve(&project.id, "main").await.ok_or_else(|| {
            ApiError::bad_request("unknown_ref", format!("{name} has no commit on main yet: push first"))
        })?;
    let started = crate::pipelines::start(&state, &project, user, &commit, "main", Request::Run, Source::Api).await?;
    Ok(Redirect::to(&format!("/jobs/{}", started.job.id)).into_response())
}

#[derive(Template)]
#[template(path = "job.html")]
struct JobPage {
    nav: Nav,
    job: JobRow,
    message: String,
    attempts: String,
    result_id: Option<String>,
    can_cancel: bool,
    live: bool,
    log: String,
}

/// `GET /jobs/{id}`: a job and its log, streamed live while it runs.
pub async fn job_page(State(state): State<AppState>, Visitor(nav): Visitor, Path(id): Path<String>) -> PageResult {
    let (job, project) = super::projects::readable_job(&state, &id, nav.user.as_ref()).await?;
    let log: String = crate::jobs::log_since(&state.pool, &job.id, 0).await?.into_iter().map(|(_, t)| t).collect();
    let live = job.state == "queued" || job.state == "running";
    let can_cancel = live && nav.user.as_ref().is_some_and(|u| project.writable_by(u) || u.is_admin);
    let page = JobPage {
        job: job_row(&job),
        message: job.message.clone(),
        attempts: format!("{} of {}", job.attempts, job.max_attempts),
        result_id: job.result_id.clone(),
        can_cancel,
        live,
        log,
        nav,
    };
    Ok(render(&page))
}

/// `POST /jobs/{id}/cancel`.
pub async fn cancel_job(
    State(state): State<AppState>,
    visitor: Visitor,
    Path(id): Path<String>,
    Form(form): Form<CsrfForm>,
) -> PageResult {
    let user = visitor.check(&form.csrf_token)?;
    super::projects::cancel_as(&state, &id, user).await?;
    Ok(Redirect::to(&format!("/jobs/{id}")).into_response())
}

// ---------------------------------------------------------------- results

struct EntryView {
    technique: String,
    highlighted: bool,
    status: String,
    message: String,
    values: Vec<String>,
    time: String,
    image: String,
}

struct GroupView {
    scene: String,
    tags: Vec<String>,
    spp: i64,
    entries: Vec<EntryView>,
}

struct StandingView {
    technique: String,
    full_name: String,
    citation: String,
    result_id: String,
    highlighted: bool,
    mean_rank: String,
    missing: usize,
}

struct ResultView {
    id: String,
    technique: String,
    full_name: String,
    commit: String,
    season: i64,
    created: String,
    published: bool,
    hidden_reason: String,
    owner: bool,
    provenance: String,
}

#[derive(Template)]
#[template(path = "board.html")]
struct BoardPage {
    nav: Nav,
    title: String,
    result: Option<ResultView>,
    seasons: Vec<(i64, String)>,
    season: i64,
    metrics: Vec<fbksd_iqa::MetricInfo>,
    sort: String,
    tags: Vec<String>,
    tag: String,
    tag_query: String,
    standings: Vec<StandingView>,
    groups: Vec<GroupView>,
    /// Shown on the public board while it is empty.
    how_to: Option<HowTo>,
    /// What the service still prepares (home page only).
    preparing: Vec<String>,
}

async fn board_page(
    state: &AppState,
    nav: Nav,
    query: BoardQuery,
    result: Option<crate::results::ResultSet>,
    home: bool,
) -> PageResult {
    let query = BoardQuery { tag: query.tag.filter(|t| !t.is_empty()), ..query };
    let board = leaderboard::build(&state.pool, &state.boards, &query, result.as_ref()).await?;
    let seasons = crate::results::seasons(&state.pool).await?.into_iter().map(|(n, note, _)| (n, note)).collect();
    let title = match &result {
        Some(r) => format!("Results of {}", r.full_name()),
        None => format!("Leaderboard, season {}", board.season),
    };
    let result = result.map(|r| ResultView {
        owner: nav.user.as_ref().is_some_and(|u| r.user_id.as_deref() == Some(u.id.as_str())),
        full_name: r.full_name().to_string(),
        id: r.id,
        technique: r.technique,
        commit: r.commit_sha,
        season: r.season,
        created: when(r.created_at),
        published: r.published_at.is_some(),
        hidden_reason: r.hidden_reason.unwrap_or_default(),
        provenance: serde_json::to_string_pretty(&r.provenance).unwrap_or_default(),
    });
    let groups = board
        .groups
        .iter()
        .map(|g| GroupView {
            entries: g
                .entries
                .iter()
                .map(|e| EntryView {
                    image: e.image.as_ref().map(|i| format!("/results/{}/files/{i}", e.result_id)).unwrap_or_default(),
                    // Full names need not be unique: the project's name tells them apart.
                    technique: format!("{} ({})", e.full_name, e.technique),
                    highlighted: e.highlighted,
                    status: e.status.clone(),
                    message: e.message.clone(),
                    values: e.values.iter().copied().map(number).collect(),
                    time: format!("{:.1} ms", e.technique_ms),
                })
                .collect(),
            scene: g.scene.clone(),
            tags: g.tags.clone(),
            spp: g.spp,
        })
        .collect();
    let standings: Vec<StandingView> = board
        .standings
        .iter()
        .map(|s| StandingView {
            technique: s.technique.clone(),
            full_name: s.full_name.clone(),
            citation: s.citation.clone(),
            result_id: s.result_id.clone(),
            highlighted: s.highlighted,
            mean_rank: format!("{:.2}", s.mean_rank),
            missing: s.missing,
        })
        .collect();
    let tag = board.tag.clone().unwrap_or_default();
    // The home page alone says what is being prepared: the leaderboard's
    // own address stays one cached board and no query.
    let how_to = (result.is_none() && standings.is_empty()).then(|| how_to(state, nav.user.as_ref(), None));
    let preparing = if home { preparation(state, nav.user.as_ref()).await? } else { Vec::new() };
    let page = BoardPage {
        how_to,
        preparing,
        nav,
        title,
        result,
        seasons,
        season: board.season,
        metrics: board.metrics.clone(),
        sort: board.sort.clone(),
        tags: board.tags.clone(),
        tag_query: if tag.is_empty() { String::new() } else { format!("&tag={tag}") },
        tag,
        standings,
        groups,
    };
    Ok(render(&page))
}

/// `GET /results/`: the public leaderboard.
pub async fn leaderboard_page(
    State(state): State<AppState>,
    Visitor(nav): Visitor,
    Query(query): Query<BoardQuery>,
) -> PageResult {
    board_page(&state, nav, query, None, false).await
}

/// `GET /results/{id}`: a result set beside every published technique.
pub async fn result_page(
    State(state): State<AppState>,
    Visitor(nav): Visitor,
    Path(id): Path<String>,
    Query(query): Query<BoardQuery>,
) -> PageResult {
    let set = super::results::visible_set(&state, &id, nav.user.as_ref()).await?;
    board_page(&state, nav, query, Some(set), false).await
}

/// `POST /results/{id}/{action}`: publish, unpublish or discard (owner only).
pub async fn result_action(
    State(state): State<AppState>,
    visitor: Visitor,
    Path((id, action)): Path<(String, String)>,
    Form(form): Form<CsrfForm>,
) -> PageResult {
    let user = visitor.check(&form.csrf_token)?;
    let set = crate::results::owned(&state.pool, &id, &user.id).await?;
    match action.as_str() {
        "publish" => crate::results::publish(&state.pool, &set).await?,
        "unpublish" => crate::results::unpublish(&state.pool, &set.id).await?,
        "discard" => {
            crate::results::discard(&state.pool, &state.config.data_dir, &set.id).await?;
            return Ok(message(visitor.0, "Discarded", format!("Result set {id} is deleted.")));
        }
        other => return Err(ApiError::new(StatusCode::NOT_FOUND, "not_found", format!("no action {other:?}")).into()),
    }
    Ok(Redirect::to(&format!("/results/{id}")).into_response())
}

// ---------------------------------------------------------------- administration

struct RunnerRow {
    name: String,
    machine: String,
    healthy: bool,
    last_seen: String,
    running_jobs: i64,
}

#[derive(Template)]
#[template(path = "admin.html")]
struct AdminPage {
    nav: Nav,
    runners: Vec<RunnerRow>,
    jobs: Vec<JobRow>,
    season: i64,
}

fn admin_of(nav: &Nav) -> Result<&User, PageError> {
    match &nav.user {
        Some(u) if u.is_admin => Ok(u),
        Some(_) => Err(ApiError::forbidden("not_admin", "only administrators can see this page").into()),
        None => Err(ApiError::unauthorized("log in first").into()),
    }
}

/// `GET /admin`.
pub async fn admin_page(State(state): State<AppState>, Visitor(nav): Visitor) -> PageResult {
    admin_of(&nav)?;
    let now = crate::now_ms();
    let runners = crate::runners::all(&state.pool)
        .await?
        .into_iter()
        .map(|r| RunnerRow {
            healthy: r.healthy(&state.config, now),
            name: r.name,
            machine: r.machine.to_string(),
            last_seen: when(r.last_seen_at),
            running_jobs: r.running_jobs,
        })
        .collect();
    let jobs = crate::jobs::all(&state.pool, 200).await?.iter().map(job_row).collect();
    let season = crate::results::current_season(&state.pool).await?;
    Ok(render(&AdminPage { nav, runners, jobs, season }))
}

/// `POST /admin/jobs/{id}/requeue`.
pub async fn admin_requeue(
    State(state): State<AppState>,
    visitor: Visitor,
    Path(id): Path<String>,
    Form(form): Form<CsrfForm>,
) -> PageResult {
    let user = visitor.check(&form.csrf_token)?;
    admin_of(&visitor.0)?;
    crate::jobs::requeue(&state.pool, &id, &user.email).await?;
    state.job_queued.notify_waiters();
    Ok(Redirect::to("/admin").into_response())
}

/// The hide form.
#[derive(Deserialize)]
pub struct HideForm {
    csrf_token: String,
    result_id: String,
    reason: String,
}

/// `POST /admin/hide`.
pub async fn admin_hide(State(state): State<AppState>, visitor: Visitor, Form(form): Form<HideForm>) -> PageResult {
    visitor.check(&form.csrf_token)?;
    admin_of(&visitor.0)?;
    if form.reason.trim().is_empty() {
        return Err(ApiError::bad_request("missing_reason", "say why the result set is hidden").into());
    }
    if !crate::results::set_hidden(&state.pool, form.result_id.trim(), Some(form.reason.trim())).await? {
        return Err(
            ApiError::new(StatusCode::NOT_FOUND, "not_found", format!("no result set {}", form.result_id)).into()
        );
    }
    Ok(Redirect::to("/admin").into_response())
}

/// The new-season form.
#[derive(Deserialize)]
pub struct SeasonForm {
    csrf_token: String,
    note: String,
}

/// `POST /admin/seasons`.
pub async fn admin_season(State(state): State<AppState>, visitor: Visitor, Form(form): Form<SeasonForm>) -> PageResult {
    visitor.check(&form.csrf_token)?;
    admin_of(&visitor.0)?;
    let started = super::admin::start_season(&state, &form.note).await?;
    let text = format!(
        "Season {} started; {} techniques queued again.",
        started["season"],
        started["queued"].as_array().map_or(0, Vec::len)
    );
    Ok(message(visitor.0, "New season", text))
}
