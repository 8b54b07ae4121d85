//! For operators and orchestrators: `/healthz` (the process answers),
//! `/readyz` (it can serve: database and data directory), `/metrics`
//! (Prometheus), and the middleware that times every answer by route.

use crate::AppState;
use axum::extract::{MatchedPath, Request, State};
use axum::http::{header, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::time::Instant;

/// `GET /healthz`: 200 while the process serves requests.
pub async fn healthz() -> &'static str {
    "ok\n"
}

/// `GET /readyz`: 200 when the database answers and the data directory
/// takes a file; 503 saying which does not.
pub async fn readyz(State(state): State<AppState>) -> Response {
    match crate::telemetry::ready(&state).await {
        Ok(()) => "ready\n".into_response(),
        Err(problem) => (StatusCode::SERVICE_UNAVAILABLE, format!("not ready: {problem}\n")).into_response(),
    }
}

/// `GET /metrics`: Prometheus' text format.
pub async fn metrics(State(state): State<AppState>) -> Response {
    match state.telemetry.render(&state).await {
        Ok(text) => ([(header::CONTENT_TYPE, "text/plain; version=0.0.4; charset=utf-8")], text).into_response(),
        Err(e) => {
            (StatusCode::SERVICE_UNAVAILABLE, format!("metrics: the database does not answer: {e}\n")).into_response()
        }
    }
}

/// Times an answer (to its headers: a stream counts until it starts) under
/// its route's pattern.
pub async fn track(State(state): State<AppState>, request: Request, next: Next) -> Response {
    let started = Instant::now();
    let method = crate::telemetry::method_label(request.method()).to_string();
    let route = request.extensions().get::<MatchedPath>().map_or("unmatched".into(), |p| p.as_str().to_string());
    let response = next.run(request).await;
    let labels = crate::telemetry::HttpLabels { method, route, status: response.status().as_u16() };
    state.telemetry.http(labels, started.elapsed().as_secs_f64());
    response
}
