//! Administration (API): jobs, runners, the registration token, seasons.

use super::Admin;
use crate::routes::ApiError;
use crate::AppState;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::Json;
use serde::Deserialize;
use serde_json::json;

/// `GET /api/v1/admin/jobs`: the latest jobs of everyone.
pub async fn jobs(State(state): State<AppState>, Admin(_): Admin) -> Result<Json<Vec<crate::jobs::Job>>, ApiError> {
    Ok(Json(crate::jobs::all(&state.pool, 500).await?))
}

/// `POST /api/v1/admin/jobs/{id}/requeue`.
pub async fn requeue(
    State(state): State<AppState>,
    Admin(admin): Admin,
    Path(id): Path<String>,
) -> Result<Json<crate::jobs::Job>, ApiError> {
    crate::jobs::requeue(&state.pool, &id, &admin.email).await?;
    state.job_queued.notify_waiters();
    crate::jobs::get(&state.pool, &id)
        .await?
        .map(Json)
        .ok_or_else(|| ApiError::new(StatusCode::NOT_FOUND, "not_found", "no such job"))
}

/// `GET /api/v1/admin/runners`: runners and their health.
pub async fn runners(State(state): State<AppState>, Admin(_): Admin) -> Result<Json<serde_json::Value>, ApiError> {
    let now = crate::now_ms();
    let list: Vec<_> = crate::runners::all(&state.pool)
        .await?
        .into_iter()
        .map(|r| {
            let healthy = r.healthy(&state.config, now);
            json!({ "runner": r, "healthy": healthy, "seconds_since_seen": (now - r.last_seen_at) / 1000 })
        })
        .collect();
    Ok(Json(json!(list)))
}

/// `DELETE /api/v1/admin/runners/{id}`: forgets a runner; its jobs are queued again.
pub async fn remove_runner(
    State(state): State<AppState>,
    Admin(_): Admin,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    if crate::runners::remove(&state.pool, &id).await? {
        crate::jobs::expire_leases(&state.pool).await?;
        state.job_queued.notify_waiters();
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(ApiError::new(StatusCode::NOT_FOUND, "not_found", format!("no runner {id}")))
    }
}

/// `POST /api/v1/admin/runner-registration-token`: a new token (the old one stops working).
pub async fn rotate_registration_token(
    State(state): State<AppState>,
    Admin(_): Admin,
) -> Result<Json<serde_json::Value>, ApiError> {
    let token = crate::runners::rotate_registration_token(&state.pool).await?;
    Ok(Json(json!({ "registration_token": token })))
}

/// A new season.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NewSeason {
    note: String,
    /// The runner class its times come from (default: that of its first
    /// result measured on a named class).
    #[serde(default)]
    runner_class: Option<String>,
}

/// `POST /api/v1/admin/seasons`: the scene pool changed. Starts a season
/// (the old boards stay readable) and queues a benchmark of every technique
/// published in the previous one, at the same commit, published on success.
pub async fn new_season(
    State(state): State<AppState>,
    Admin(_): Admin,
    Json(body): Json<NewSeason>,
) -> Result<(StatusCode, Json<crate::admin::SeasonStarted>), ApiError> {
    Ok((StatusCode::CREATED, Json(crate::admin::start_season(&state, &body.note, body.runner_class.as_deref()).await?)))
}
