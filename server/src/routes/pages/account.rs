//! Pages of one's account: log-in, registration, the verification link
//! again, log-out and access tokens. The log-in and registration forms
//! pass the same rate limits as the API.

use super::*;
use crate::throttle::{ClientIp, Limited};

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
    /// Offer to mail the verification link again (the address is not verified).
    resend: bool,
}

fn credentials_page(register: bool, email: &str, error: &str, status: StatusCode) -> Response {
    credentials_page_offering(register, email, error, status, false)
}

fn credentials_page_offering(register: bool, email: &str, error: &str, status: StatusCode, resend: bool) -> Response {
    let csrf = accounts::random_token();
    let page = CredentialsPage {
        nav: Nav { user: None, csrf: String::new() },
        heading: if register { "Register" } else { "Log in" },
        action: if register { "/register" } else { "/login" },
        csrf: csrf.clone(),
        email: email.into(),
        error: error.into(),
        password_autocomplete: if register { "new-password" } else { "current-password" },
        resend,
    };
    let cookie = format!("{FORM_COOKIE}={csrf}; Path=/; HttpOnly; SameSite=Strict; Max-Age=3600");
    (status, [(header::SET_COOKIE, cookie)], render(&page)).into_response()
}

/// The form again, saying what was limited and when to retry.
fn limited_page(register: bool, email: &str, limited: Limited) -> Response {
    let mut page = credentials_page(register, email, &limited.message(), StatusCode::TOO_MANY_REQUESTS);
    let (name, value) = limited.header();
    if let Ok(value) = value.parse() {
        page.headers_mut().insert(name, value);
    }
    page
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
    ClientIp(ip): ClientIp,
    headers: axum::http::HeaderMap,
    PageForm(form): PageForm<CredentialsForm>,
) -> PageResult {
    check_form_cookie(&headers, &form.csrf_token)?;
    let attempt = match state.throttle.log_in(ip, &form.email) {
        Ok(attempt) => attempt,
        Err(limited) => return Ok(limited_page(false, &form.email, limited)),
    };
    let user = match accounts::authenticate(&state.pool, &form.email, &form.password).await {
        Ok(user) => user,
        Err(e) => {
            let unverified = e.code == "email_not_verified";
            let e = ApiError::from(e);
            return Ok(credentials_page_offering(false, &form.email, &e.message, e.status, unverified));
        }
    };
    attempt.succeeded();
    let session = accounts::open_session(&state.pool, &user.id, state.config.session_hours).await?;
    let cookie = crate::routes::session_cookie(&state, &session.token);
    let next = if user.must_change_password { "/settings#password" } else { "/projects" };
    Ok(([(header::SET_COOKIE, cookie)], Redirect::to(next)).into_response())
}

/// `POST /register`.
pub async fn register(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    headers: axum::http::HeaderMap,
    PageForm(form): PageForm<CredentialsForm>,
) -> PageResult {
    check_form_cookie(&headers, &form.csrf_token)?;
    let checked = (Email::parse(&form.email), Password::parse(&form.password));
    let (email, password) = match checked {
        (Ok(e), Ok(p)) => (e, p),
        (Err(e), _) | (_, Err(e)) => {
            let e = ApiError::from(e);
            return Ok(credentials_page(true, &form.email, &e.message, e.status));
        }
    };
    if let Err(limited) = state.throttle.mail(ip, email.as_str()) {
        return Ok(limited_page(true, &form.email, limited));
    }
    if let Err(e) = crate::accounts::register(&state, &email, &password).await {
        let e = ApiError::from(e);
        return Ok(credentials_page(true, &form.email, &e.message, e.status));
    }
    let nav = Nav { user: None, csrf: String::new() };
    Ok(message(nav, "Check your mail", format!("We sent a confirmation link to {}.", email.as_str())))
}

/// The log-in page's "send the link again" button.
#[derive(Deserialize)]
pub struct AddressForm {
    csrf_token: String,
    email: String,
}

/// `POST /accounts/verification`: mails the verification link again; the
/// same answer whether or not the address has an account waiting.
pub async fn resend_verification(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    headers: axum::http::HeaderMap,
    PageForm(form): PageForm<AddressForm>,
) -> PageResult {
    check_form_cookie(&headers, &form.csrf_token)?;
    let email = match Email::parse(&form.email) {
        Ok(email) => email,
        Err(e) => {
            let e = ApiError::from(e);
            return Ok(credentials_page(false, &form.email, &e.message, e.status));
        }
    };
    if let Err(limited) = state.throttle.mail(ip, email.as_str()) {
        return Ok(limited_page(false, &form.email, limited));
    }
    accounts::resend_verification(&state, &email).await?;
    let nav = Nav { user: None, csrf: String::new() };
    let text = format!("If {} has an account waiting for confirmation, a new link is on its way.", email.as_str());
    Ok(message(nav, "Check your mail", text))
}

/// `POST /logout`.
pub async fn logout(State(state): State<AppState>, headers: axum::http::HeaderMap, _: Button) -> PageResult {
    if let Some(token) = cookie(&headers, SESSION_COOKIE) {
        accounts::close_session(&state.pool, token).await?;
    }
    Ok(([(header::SET_COOKIE, crate::routes::ENDED_SESSION_COOKIE)], Redirect::to("/results/")).into_response())
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
    /// Why the password was not changed, when it was not.
    password_error: String,
}

async fn settings_page(state: &AppState, nav: Nav, new_token: String, password_error: String) -> PageResult {
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
    Ok(render(&SettingsPage { nav, tokens, new_token, password_error }))
}

/// `GET /settings`.
pub async fn settings(State(state): State<AppState>, Visitor(nav): Visitor) -> PageResult {
    settings_page(&state, nav, String::new(), String::new()).await
}

/// The password form.
#[derive(Deserialize)]
pub struct PasswordForm {
    csrf_token: String,
    current_password: String,
    new_password: String,
}

/// `POST /settings/password`: every session ends (this one too), as with
/// the API's `PATCH /api/v1/me`; the visitor logs in again.
pub async fn change_password(
    State(state): State<AppState>,
    visitor: Visitor,
    PageForm(form): PageForm<PasswordForm>,
) -> PageResult {
    let user = visitor.check(&form.csrf_token)?.clone();
    let changed = accounts::change_password(&state.pool, &user.id, &form.current_password, &form.new_password).await;
    if let Err(e) = changed {
        return settings_page(&state, visitor.0, String::new(), ApiError::from(e).message).await;
    }
    let nav = Nav { user: None, csrf: String::new() };
    let page = message(nav, "Password changed", "Your sessions have ended: log in again with your new password.");
    Ok(([(header::SET_COOKIE, crate::routes::ENDED_SESSION_COOKIE)], page).into_response())
}

/// A new token's name.
#[derive(Deserialize)]
pub struct TokenForm {
    csrf_token: String,
    name: String,
}

/// `POST /settings/tokens`.
pub async fn create_token(
    State(state): State<AppState>,
    visitor: Visitor,
    PageForm(form): PageForm<TokenForm>,
) -> PageResult {
    let user = visitor.check(&form.csrf_token)?;
    let (_, token) = accounts::create_access_token(&state.pool, &user.id, &form.name).await?;
    settings_page(&state, visitor.0, token, String::new()).await
}

/// `POST /settings/tokens/{id}/revoke`.
pub async fn revoke_token(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Button { user, .. }: Button,
) -> PageResult {
    accounts::revoke_access_token(&state.pool, &user.id, &id).await?;
    Ok(Redirect::to("/settings").into_response())
}
