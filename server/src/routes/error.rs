//! The one HTTP error type: a status, a stable machine-readable code and a
//! message the user can act on. The service's refusals
//! ([`ServiceError`]) become one here, each kind with its status; internal
//! errors are logged in full and reach the client only as "internal error".

use crate::error::{Refusal, ServiceError};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;

/// An error answer: `{"error": code, "message": message}` with `status`.
#[derive(Debug)]
pub struct ApiError {
    /// HTTP status.
    pub status: StatusCode,
    /// Stable code, e.g. `invalid_email`.
    pub code: &'static str,
    /// What went wrong and what to do.
    pub message: String,
}

impl ApiError {
    /// An error with the given status, code and message.
    pub fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> Self {
        ApiError { status, code, message: message.into() }
    }
    /// 400: the request is malformed or a value is invalid.
    pub fn bad_request(code: &'static str, message: impl Into<String>) -> Self {
        ServiceError::invalid(code, message).into()
    }
    /// 401: not logged in, or wrong credentials.
    pub fn unauthorized(message: impl Into<String>) -> Self {
        ServiceError::unauthenticated(message).into()
    }
    /// 403: logged in but not allowed.
    pub fn forbidden(code: &'static str, message: impl Into<String>) -> Self {
        ServiceError::forbidden(code, message).into()
    }
    /// 500: logged, and hidden from the client.
    pub fn internal(error: impl std::fmt::Display) -> Self {
        ServiceError::internal(error).into()
    }
}

impl From<ServiceError> for ApiError {
    fn from(e: ServiceError) -> Self {
        let status = match e.kind {
            Refusal::Invalid => StatusCode::BAD_REQUEST,
            Refusal::Unauthenticated => StatusCode::UNAUTHORIZED,
            Refusal::Forbidden => StatusCode::FORBIDDEN,
            Refusal::NotFound => StatusCode::NOT_FOUND,
            Refusal::Conflict => StatusCode::CONFLICT,
            Refusal::Gone => StatusCode::GONE,
            Refusal::TooMany => StatusCode::TOO_MANY_REQUESTS,
            Refusal::Internal => StatusCode::INTERNAL_SERVER_ERROR,
        };
        ApiError { status, code: e.code, message: e.message }
    }
}

impl From<sqlx::Error> for ApiError {
    fn from(e: sqlx::Error) -> Self {
        ServiceError::from(e).into()
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        (self.status, Json(serde_json::json!({ "error": self.code, "message": self.message }))).into_response()
    }
}
