//! Why the service refused an operation, in the service's own terms.
//!
//! Domain modules (accounts, projects, jobs, pipelines, results, admin,
//! runners) return [`ServiceError`]: a kind, a stable machine-readable code
//! and a message the user can act on. They know nothing of HTTP; the routes
//! turn a kind into a status (`routes::error`). Internal errors are logged
//! in full where they happen and reach users only as "internal error".

/// What kind of refusal it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// A value is malformed or invalid.
    Invalid,
    /// Nobody is logged in, or the credentials are wrong.
    Unauthenticated,
    /// Logged in, but not allowed.
    Forbidden,
    /// No such thing (or not visible to the caller).
    NotFound,
    /// It clashes with what exists (a taken name, a job that has ended).
    Conflict,
    /// The thing has gone (a job no longer running).
    Gone,
    /// Over a quota.
    TooMany,
    /// The service failed (logged).
    Internal,
}

/// A refused operation: kind, stable code (e.g. `invalid_email`) and message.
#[derive(Debug)]
pub struct ServiceError {
    /// What kind of refusal.
    pub kind: Refusal,
    /// Stable code, e.g. `invalid_email`.
    pub code: &'static str,
    /// What went wrong and what to do.
    pub message: String,
}

impl ServiceError {
    /// A refusal of the given kind.
    pub fn new(kind: Refusal, code: &'static str, message: impl Into<String>) -> Self {
        ServiceError { kind, code, message: message.into() }
    }
    /// A malformed or invalid value.
    pub fn invalid(code: &'static str, message: impl Into<String>) -> Self {
        Self::new(Refusal::Invalid, code, message)
    }
    /// Not logged in, or wrong credentials.
    pub fn unauthenticated(message: impl Into<String>) -> Self {
        Self::new(Refusal::Unauthenticated, "unauthorized", message)
    }
    /// Logged in but not allowed.
    pub fn forbidden(code: &'static str, message: impl Into<String>) -> Self {
        Self::new(Refusal::Forbidden, code, message)
    }
    /// No such thing for this caller.
    pub fn not_found(message: impl Into<String>) -> Self {
        Self::new(Refusal::NotFound, "not_found", message)
    }
    /// A clash with what exists.
    pub fn conflict(code: &'static str, message: impl Into<String>) -> Self {
        Self::new(Refusal::Conflict, code, message)
    }
    /// The thing has gone.
    pub fn gone(code: &'static str, message: impl Into<String>) -> Self {
        Self::new(Refusal::Gone, code, message)
    }
    /// Over a quota.
    pub fn too_many(code: &'static str, message: impl Into<String>) -> Self {
        Self::new(Refusal::TooMany, code, message)
    }
    /// The service failed: logged in full, shown as "internal error".
    pub fn internal(error: impl std::fmt::Display) -> Self {
        tracing::error!("internal error: {error}");
        Self::new(Refusal::Internal, "internal_error", "internal error (logged on the server)")
    }
}

impl From<sqlx::Error> for ServiceError {
    fn from(e: sqlx::Error) -> Self {
        ServiceError::internal(e)
    }
}

impl From<crate::mail::MailError> for ServiceError {
    fn from(e: crate::mail::MailError) -> Self {
        ServiceError::internal(e)
    }
}
