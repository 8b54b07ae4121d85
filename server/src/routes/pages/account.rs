//! Pages of one's account: log-in, registration, log-out and access tokens.

use super::*;

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
        Err(e) => {
            let e = ApiError::from(e);
            return Ok(credentials_page(false, &form.email, &e.message, e.status));
        }
    };
    let session = accounts::open_session(&state.pool, &user.id, state.config.session_hours).await?;
    let cookie = crate::routes::session_cookie(&state, &session.token);
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
        (Err(e), _) | (_, Err(e)) => {
            let e = ApiError::from(e);
            return Ok(credentials_page(true, &form.email, &e.message, e.status));
        }
    };
    if let Err(e) = crate::accounts::register(&state, &email, &password).await {
        let e = ApiError::from(e);
        return Ok(credentials_page(true, &form.email, &e.message, e.status));
    }
    let nav = Nav { user: None, csrf: String::new() };
    Ok(message(nav, "Check your mail", format!("We sent a confirmation link to {}.", email.as_str())))
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
    Path(id): Path<String>,
    Button { user, .. }: Button,
) -> PageResult {
    accounts::revoke_access_token(&state.pool, &user.id, &id).await?;
    Ok(Redirect::to("/settings").into_response())
}
