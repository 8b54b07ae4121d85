//! Projects, pipelines and jobs as their users see them (API), and the git
//! smart-HTTP endpoint.

use super::{Caller, MaybeUser};
use crate::accounts::User;
use crate::jobs::{Job, JobState};
use crate::pipelines::{Request, Source};
use crate::projects::{self, Project};
use crate::routes::ApiError;
use crate::AppState;
use axum::body::Body;
use axum::extract::{Path, Query, State};
use axum::http::{header, HeaderMap, Method, StatusCode, Uri};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::Json;
use base64::Engine;
use serde::Deserialize;
use serde_json::json;
use std::collections::BTreeMap;

/// A new project.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NewProject {
    name: String,
    #[serde(default = "private")]
    visibility: String,
}

fn private() -> String {
    "private".into()
}

/// How a project is shown: with its clone URL.
fn project_json(state: &AppState, project: &Project) -> serde_json::Value {
    json!({
        "id": project.id,
        "name": project.name,
        "visibility": project.visibility,
        "owner_id": project.owner_id,
        "created_at": project.created_at,
        "clone_url": state.clone_url(&project.name),
    })
}

/// `POST /api/v1/projects`: creates a project and its empty repository.
pub async fn create(
    State(state): State<AppState>,
    caller: Caller,
    Json(body): Json<NewProject>,
) -> Result<(StatusCode, Json<serde_json::Value>), ApiError> {
    let project = projects::create(&state, &caller.user, &body.name, &body.visibility).await?;
    Ok((StatusCode::CREATED, Json(project_json(&state, &project))))
}

/// Where a list of projects starts: after the name `after` (none: the first).
#[derive(serde::Deserialize, Default)]
pub struct ListPage {
    /// A project name (names are plain: lower-case letters, digits, `-` and `_`).
    #[serde(default)]
    pub after: String,
}

/// `GET /api/v1/projects[?after=<name>]`: the projects the caller can see,
/// by name, [`projects::PAGE`] at a time; when more follow, a `Link`
/// header names the next page (`rel="next"`).
pub async fn list(
    State(state): State<AppState>,
    MaybeUser(user): MaybeUser,
    Query(page): Query<ListPage>,
) -> Result<Response, ApiError> {
    let (list, more) = projects::visible(&state.pool, user.as_ref(), &page.after).await?;
    let body = Json(json!(list.iter().map(|p| project_json(&state, p)).collect::<Vec<_>>()));
    Ok(match (more, list.last()) {
        (true, Some(last)) => {
            let next = format!("<{}/api/v1/projects?after={}>; rel=\"next\"", state.public_url, last.name);
            ([(header::LINK, next)], body).into_response()
        }
        _ => body.into_response(),
    })
}

/// `GET /api/v1/projects/{name}`: a project, its jobs and result sets.
pub async fn show(
    State(state): State<AppState>,
    MaybeUser(user): MaybeUser,
    Path(name): Path<String>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let project = projects::readable(&state.pool, &name, user.as_ref()).await?;
    let jobs = crate::jobs::of_project(&state.pool, &project.id, 100).await?;
    let owner = user.as_ref().is_some_and(|u| u.id == project.owner_id || u.is_admin);
    // Others see only published result sets.
    let results: Vec<_> = crate::results::of_project(&state.pool, &project.id)
        .await?
        .into_iter()
        .filter(|r| owner || r.is_public())
        .collect();
    // A job names its result set, which stays its owner's until published.
    let public: std::collections::HashSet<&str> =
        results.iter().filter(|r| r.is_public()).map(|r| r.id.as_str()).collect();
    let jobs: Vec<Job> = jobs
        .into_iter()
        .map(|job| match &job.result_id {
            Some(id) if !owner && !public.contains(id.as_str()) => job.without_result(),
            _ => job,
        })
        .collect();
    let mut body = project_json(&state, &project);
    body["jobs"] = json!(jobs);
    body["results"] = json!(results);
    Ok(Json(body))
}

/// `DELETE /api/v1/projects/{name}`: deletes the project, its repository,
/// jobs and unpublished results (published ones stay on the leaderboard).
pub async fn delete(
    State(state): State<AppState>,
    caller: Caller,
    Path(name): Path<String>,
) -> Result<StatusCode, ApiError> {
    let project = projects::writable(&state.pool, &name, &caller.user).await?;
    projects::delete(&state, &project).await?;
    Ok(StatusCode::NO_CONTENT)
}

/// A pipeline request.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NewPipeline {
    /// Branch, tag or commit; the default branch `main` if absent.
    #[serde(rename = "ref", default)]
    git_ref: Option<String>,
    #[serde(default)]
    variables: BTreeMap<String, String>,
}

/// `POST /api/v1/projects/{name}/pipelines`: runs a pipeline (e.g. with
/// `FBKSD_RUN`) at a ref: 201 with the pipeline and its job, or 422 with
/// the failed job when the repository fails its checks.
pub async fn run_pipeline(
    State(state): State<AppState>,
    caller: Caller,
    Path(name): Path<String>,
    Json(body): Json<NewPipeline>,
) -> Result<(StatusCode, Json<crate::pipelines::Started>), ApiError> {
    let project = projects::writable(&state.pool, &name, &caller.user).await?;
    let request = Request::parse(body.variables.iter().map(|(k, v)| (k.as_str(), v.as_str())))?;
    let git_ref = body.git_ref.unwrap_or_else(|| "main".into());
    let commit = state.git.resolve(&project.id, &git_ref).await.ok_or_else(|| {
        ApiError::bad_request("unknown_ref", format!("{git_ref:?} names no commit of {name}: push first"))
    })?;
    let started =
        crate::pipelines::start(&state, &project, &caller.user, &commit, &git_ref, request, Source::Api).await?;
    // A repository that fails its checks is a failed job (in the history, mailed),
    // and the caller is told at once.
    let status =
        if started.job.state == JobState::Failed { StatusCode::UNPROCESSABLE_ENTITY } else { StatusCode::CREATED };
    Ok((status, Json(started)))
}

/// `GET /api/v1/jobs/{id}`: without its result set unless the caller may see it.
pub async fn job(
    State(state): State<AppState>,
    MaybeUser(user): MaybeUser,
    Path(id): Path<String>,
) -> Result<Json<Job>, ApiError> {
    let (job, _) = crate::jobs::readable(&state.pool, &id, user.as_ref()).await?;
    match crate::results::private_result_of(&state.pool, &job, user.as_ref()).await? {
        Some(_) => Ok(Json(job.without_result())),
        None => Ok(Json(job)),
    }
}

/// Where to continue a log.
#[derive(Deserialize)]
pub struct After {
    #[serde(default)]
    after: i64,
}

/// `GET /api/v1/jobs/{id}/log?after=N`: log chunks after sequence number N.
pub async fn log(
    State(state): State<AppState>,
    MaybeUser(user): MaybeUser,
    Path(id): Path<String>,
    Query(after): Query<After>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let (job, _) = crate::jobs::readable(&state.pool, &id, user.as_ref()).await?;
    let private = crate::results::private_result_of(&state.pool, &job, user.as_ref()).await?;
    let chunks = crate::jobs::log_since(&state.pool, &id, after.after).await?;
    Ok(Json(json!({
        "state": job.state,
        "chunks": chunks
            .iter()
            .map(|(seq, text)| json!({ "seq": seq, "text": shown(text, private.as_deref()) }))
            .collect::<Vec<_>>(),
    })))
}

/// A log chunk as its reader may see it: without a private result set's id.
fn shown(text: &str, private: Option<&str>) -> String {
    match private {
        Some(id) => crate::jobs::hide_result(text, id),
        None => text.to_string(),
    }
}

/// `GET /api/v1/jobs/{id}/log/stream`: the log as server-sent events
/// (`log` events with the text, then one `end` event with the final
/// state). It polls the database, so it works behind several server
/// instances. A stream lasts as long as its job, so each caller (a user,
/// or an anonymous address) may hold only a few at once, and the server a
/// bounded number ([`limits`](super::limits)): over either, 429.
pub async fn log_stream(
    State(state): State<AppState>,
    MaybeUser(user): MaybeUser,
    axum::Extension(slots): axum::Extension<super::limits::StreamSlots>,
    crate::throttle::ClientIp(ip): crate::throttle::ClientIp,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    crate::jobs::readable(&state.pool, &id, user.as_ref()).await?;
    let caller = match &user {
        Some(user) => format!("user {}", user.id),
        None => format!("address {ip}"),
    };
    let slot = slots.take(&caller)?;
    // A running benchmark's set is stored at its end: decided then, per event.
    let stream = async_stream(state, id, user, slot);
    Ok(Sse::new(stream).keep_alive(KeepAlive::default()).into_response())
}

fn async_stream(
    state: AppState,
    id: String,
    user: Option<User>,
    slot: super::limits::StreamSlot,
) -> impl futures_util::Stream<Item = Result<Event, std::convert::Infallible>> {
    // The slot lives in the stream's state: dropped with it, however it ends.
    futures_util::stream::unfold(
        (state, id, user, slot, 0i64, false),
        |(state, id, user, slot, after, done)| async move {
            if done {
                return None;
            }
            loop {
                let chunks = crate::jobs::log_since(&state.pool, &id, after).await.unwrap_or_default();
                let job = crate::jobs::get(&state.pool, &id).await.ok().flatten();
                if let Some((seq, _)) = chunks.last() {
                    let private = match &job {
                        Some(job) => {
                            crate::results::private_result_of(&state.pool, job, user.as_ref()).await.ok().flatten()
                        }
                        None => None,
                    };
                    let text: String = chunks.iter().map(|(_, t)| shown(t, private.as_deref())).collect();
                    let event = Event::default().event("log").id(seq.to_string()).data(text);
                    return Some((Ok(event), (state, id, user, slot, *seq, false)));
                }
                match job.map(|j| j.state) {
                    Some(live) if live.is_live() => tokio::time::sleep(std::time::Duration::from_millis(300)).await,
                    other => {
                        let event = Event::default().event("end").data(other.map_or("gone", JobState::as_str));
                        return Some((Ok(event), (state, id, user, slot, after, true)));
                    }
                }
            }
        },
    )
}

/// `POST /api/v1/jobs/{id}/cancel`: the owner or an administrator cancels a job.
pub async fn cancel(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Json<Job>, ApiError> {
    crate::jobs::cancel_as(&state.pool, &id, &caller.user).await?;
    Ok(Json(crate::jobs::get(&state.pool, &id).await?.ok_or_else(|| ApiError::internal("job vanished"))?))
}

/// Who a git request authenticates as: HTTP Basic with a personal access
/// token (or a job token, for the runner's clone) as the password.
enum GitCaller {
    Anonymous,
    User(User),
    Job(String),
}

async fn git_caller(state: &AppState, headers: &HeaderMap) -> Result<GitCaller, ApiError> {
    let Some(value) = headers.get(header::AUTHORIZATION).and_then(|v| v.to_str().ok()) else {
        return Ok(GitCaller::Anonymous);
    };
    let secret = if let Some(basic) = value.strip_prefix("Basic ") {
        let decoded = base64::engine::general_purpose::STANDARD.decode(basic.trim()).unwrap_or_default();
        let text = String::from_utf8_lossy(&decoded).into_owned();
        text.split_once(':').map(|(_, p)| p.to_string()).unwrap_or_default()
    } else if let Some(bearer) = value.strip_prefix("Bearer ") {
        bearer.trim().to_string()
    } else {
        String::new()
    };
    if secret.starts_with(crate::jobs::JOB_TOKEN_PREFIX) {
        if let Some((job_id, job_state, _)) = crate::jobs::token_job(&state.pool, &secret).await? {
            if job_state == JobState::Running {
                return Ok(GitCaller::Job(job_id));
            }
        }
    } else if let Some(user) = crate::accounts::token_user(&state.pool, &secret).await? {
        return Ok(GitCaller::User(user));
    }
    Err(ApiError::unauthorized("wrong credentials"))
}

fn ask_credentials(message: &str) -> Response {
    (StatusCode::UNAUTHORIZED, [(header::WWW_AUTHENTICATE, crate::git::ASK_CREDENTIALS)], format!("{message}\n"))
        .into_response()
}

/// `/git/{name}.git/…`: smart HTTP through `git http-backend`. Reading
/// follows the project's visibility; pushing needs the owner's personal
/// access token; a running job's token may clone its own project.
pub async fn git(
    State(state): State<AppState>,
    Path((repo, rest)): Path<(String, String)>,
    method: Method,
    uri: Uri,
    headers: HeaderMap,
    body: Body,
) -> Response {
    let Some(name) = repo.strip_suffix(".git") else {
        return (StatusCode::NOT_FOUND, "repositories are at /git/<name>.git\n").into_response();
    };
    let query = uri.query().unwrap_or("");
    let push = rest == "git-receive-pack" || query.contains("service=git-receive-pack");
    let caller = match git_caller(&state, &headers).await {
        Ok(c) => c,
        Err(e) => return ask_credentials(&format!("{}: use a personal access token as the password", e.message)),
    };
    let project = match projects::by_name(&state.pool, name).await {
        Ok(Some(p)) => p,
        Ok(None) => return ask_or_hide(&caller, name),
        Err(e) => return ApiError::from(e).into_response(),
    };
    let (allowed, user) = match &caller {
        GitCaller::Anonymous => (!push && project.readable_by(None), None),
        GitCaller::User(u) => (if push { project.writable_by(u) } else { project.readable_by(Some(u)) }, Some(u)),
        GitCaller::Job(job_id) => {
            let job_project = crate::jobs::get(&state.pool, job_id).await.ok().flatten().map(|j| j.project_id);
            (!push && job_project.as_deref() == Some(project.id.as_str()), None)
        }
    };
    if !allowed {
        return match (&caller, project.readable_by(user)) {
            (GitCaller::Anonymous, _) => {
                ask_credentials("log in: user name anything, password a personal access token")
            }
            (_, true) => (StatusCode::FORBIDDEN, format!("only the owner of {name} can push to it\n")).into_response(),
            (_, false) => ask_or_hide(&caller, name),
        };
    }
    let remote_user = user.map(|u| u.email.clone()).unwrap_or_else(|| "anonymous".into());
    let caller = match &caller {
        GitCaller::Anonymous => crate::git::ANONYMOUS.to_string(),
        GitCaller::User(user) => format!("user {}", user.id),
        GitCaller::Job(job) => format!("job {job}"),
    };
    let quota = if rest == "git-receive-pack" {
        match crate::projects::repository_quota(&state, &project.owner_id).await {
            Ok(quota) => Some(quota),
            Err(e) => return ApiError::from(e).into_response(),
        }
    } else {
        None
    };
    let request =
        crate::git::GitRequest { method: &method, rest: &rest, query, headers: &headers, caller: &caller, quota };
    let served = state.git.serve(&project.id, request, body, &remote_user).await;
    match (served, user) {
        (crate::git::Served::Pushed(pushed), Some(user)) => {
            let messages = crate::pipelines::start_push(&state, &project, user, &pushed.record).await;
            pushed.respond(&messages)
        }
        (crate::git::Served::Pushed(pushed), None) => pushed.respond(&[]),
        (crate::git::Served::Answered(response), _) => response,
    }
}

fn ask_or_hide(caller: &GitCaller, name: &str) -> Response {
    match caller {
        GitCaller::Anonymous => ask_credentials("log in: user name anything, password a personal access token"),
        _ => (StatusCode::NOT_FOUND, format!("no repository {name}.git that you can see\n")).into_response(),
    }
}
