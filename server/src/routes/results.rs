//! Result sets and the leaderboard (API), and result files.

use super::{Admin, Caller, MaybeUser};
use crate::leaderboard::{self, BoardQuery};
use crate::results;
use crate::routes::ApiError;
use crate::AppState;
use axum::extract::{Path, Query, State};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::Deserialize;
use serde_json::json;

/// `GET /api/v1/results/{id}`: a result set with its runs and the board it sits on.
pub async fn show(
    State(state): State<AppState>,
    MaybeUser(user): MaybeUser,
    Path(id): Path<String>,
    Query(query): Query<BoardQuery>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let set = results::visible(&state.pool, &id, user.as_ref()).await?;
    let runs = results::runs(&state.pool, results::Selection::One(&set.id)).await?;
    let board = leaderboard::build(&state.pool, &state.boards, &query, Some(&set)).await?;
    Ok(Json(json!({ "result": set, "runs": runs, "board": board })))
}

/// `GET /api/v1/leaderboard?season=&sort=&tag=`: the same for every
/// reader, so rendered once per board version ([`crate::routes::PublicBoards`]).
pub async fn board(
    State(state): State<AppState>,
    Query(query): Query<BoardQuery>,
    headers: axum::http::HeaderMap,
) -> Result<Response, ApiError> {
    let render = async {
        let board = leaderboard::build(&state.pool, &state.boards, &query, None).await?;
        serde_json::to_string(&board).map_err(ApiError::internal)
    };
    state
        .public_boards
        .respond(&state.boards, &state.pool, crate::routes::Rendering::Json, &query, &headers, render)
        .await
}

/// `POST /api/v1/results/{id}/publish`: the owner publishes.
pub async fn publish(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let set = results::owned(&state.pool, &id, &caller.user.id).await?;
    results::publish(&state.pool, &set).await?;
    Ok(Json(json!({ "published": true, "leaderboard": format!("{}/results/", state.public_url) })))
}

/// `POST /api/v1/results/{id}/unpublish`: the owner takes it off the leaderboard.
pub async fn unpublish(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let set = results::owned(&state.pool, &id, &caller.user.id).await?;
    results::unpublish(&state.pool, &set.id).await?;
    Ok(Json(json!({ "published": false })))
}

/// `DELETE /api/v1/results/{id}`: the owner discards it.
pub async fn discard(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    let set = results::owned(&state.pool, &id, &caller.user.id).await?;
    results::discard(&state.pool, &state.config.data_dir, &set.id).await?;
    Ok(StatusCode::NO_CONTENT)
}

/// A reason to hide a result set.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HideRequest {
    reason: String,
}

/// `POST /api/v1/admin/results/{id}/hide`: an administrator hides a set that breaks the rules.
pub async fn hide(
    State(state): State<AppState>,
    Admin(_): Admin,
    Path(id): Path<String>,
    Json(body): Json<HideRequest>,
) -> Result<StatusCode, ApiError> {
    let reason = body.reason.trim();
    if reason.is_empty() {
        return Err(ApiError::bad_request("missing_reason", "say why the result set is hidden: its owner sees it"));
    }
    if results::set_hidden(&state.pool, &id, Some(reason)).await? {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(ApiError::new(StatusCode::NOT_FOUND, "not_found", format!("no result set {id}")))
    }
}

/// `DELETE /api/v1/admin/results/{id}/hide`: shows it again.
pub async fn unhide(
    State(state): State<AppState>,
    Admin(_): Admin,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    if results::set_hidden(&state.pool, &id, None).await? {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(ApiError::new(StatusCode::NOT_FOUND, "not_found", format!("no result set {id}")))
    }
}

/// `GET /api/v1/results/{id}/viewer`: the results viewer's document.
pub async fn viewer(
    State(state): State<AppState>,
    MaybeUser(user): MaybeUser,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let set = results::visible(&state.pool, &id, user.as_ref()).await?;
    let doc = crate::viewer::document_json(&state.pool, &state.boards, &state.config.data_dir, &set).await?;
    // Other techniques' sets change when they are published: never cached.
    let headers = [(header::CACHE_CONTROL, "private, no-cache"), (header::CONTENT_TYPE, "application/json")];
    Ok((headers, doc).into_response())
}

/// `GET /results/{id}/files/{*name}`: a file of a set the caller may see.
pub async fn file(
    State(state): State<AppState>,
    MaybeUser(user): MaybeUser,
    Path((id, name)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    let set = results::visible(&state.pool, &id, user.as_ref()).await?;
    results::check_file_name(&name)?;
    let path = results::files_dir(&state.config.data_dir, &set.id).join(&name);
    let kind = match name.rsplit_once('.').map(|(_, ext)| ext) {
        Some("png") => "image/png",
        Some("exr") => "image/x-exr",
        Some("json") => "application/json",
        Some("log") => "text/plain; charset=utf-8",
        _ => "application/octet-stream",
    };
    immutable(kind, &path)
        .await
        .ok_or_else(|| ApiError::new(StatusCode::NOT_FOUND, "not_found", format!("no file {name} in result set {id}")))
}

/// A stored file, streamed from disk (images and pixel files run to
/// hundreds of megabytes: never whole in memory), or None if there is no
/// such file. A set's files and references never change, so the browser
/// keeps them.
async fn immutable(kind: &'static str, path: &std::path::Path) -> Option<Response> {
    let file = tokio::fs::File::open(path).await.ok()?;
    let metadata = file.metadata().await.ok().filter(|m| m.is_file())?;
    let body = axum::body::Body::from_stream(tokio_util::io::ReaderStream::with_capacity(file, 64 << 10));
    let headers = [
        (header::CONTENT_TYPE, kind.to_string()),
        (header::CONTENT_LENGTH, metadata.len().to_string()),
        (header::CACHE_CONTROL, "private, max-age=86400, immutable".to_string()),
    ];
    Some((headers, body).into_response())
}

/// `GET /results/{id}/references/{scene}`: the pixel file of the reference
/// that the set's scene was scored against.
pub async fn reference(
    State(state): State<AppState>,
    MaybeUser(user): MaybeUser,
    Path((id, scene)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    reference_file(&state, user.as_ref(), &id, &scene, None).await
}

/// `GET /results/{id}/references/{scene}/{buffer}`: the pixel file of a
/// feature buffer (albedo, normal, depth) made with that reference.
pub async fn reference_buffer(
    State(state): State<AppState>,
    MaybeUser(user): MaybeUser,
    Path((id, scene, buffer)): Path<(String, String, String)>,
) -> Result<Response, ApiError> {
    reference_file(&state, user.as_ref(), &id, &scene, Some(&buffer)).await
}

/// The pixel file of the reference (or of one of its feature buffers) that
/// set `id`'s scene was scored against, for whoever may see the set.
async fn reference_file(
    state: &AppState,
    user: Option<&crate::accounts::User>,
    id: &str,
    scene: &str,
    buffer: Option<&str>,
) -> Result<Response, ApiError> {
    let set = results::visible(&state.pool, id, user).await?;
    let not_found = || {
        let what = buffer.map_or("reference".to_string(), |b| format!("{b:?} buffer of the reference"));
        ApiError::new(StatusCode::NOT_FOUND, "not_found", format!("no {what} of scene {scene:?} in result set {id}"))
    };
    let hash = results::reference_hash(&state.pool, &set.id, scene).await?.ok_or_else(not_found)?;
    let path = results::reference_pixels(&state.config.data_dir, &hash, buffer).ok_or_else(not_found)?;
    immutable("application/octet-stream", &path).await.ok_or_else(not_found)
}
