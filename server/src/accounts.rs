//! Accounts (thesis §5.2): e-mail addresses and passwords parsed at the
//! boundary, argon2 password hashes, one-time e-mail tokens, and browser
//! sessions with their CSRF token. Only SHA-256 digests of tokens are
//! stored, so a leaked database opens no session.
//!
//! Argon2 is slow on purpose; it runs on blocking threads, at most one per
//! core, so a flood of log-ins queues for the CPU instead of stalling the
//! async workers that answer heartbeats and pages. A log-in for an unknown
//! address verifies against a dummy hash, so its answer and its time are
//! those of a wrong password.

use crate::error::ServiceError;
use crate::now_ms;
use argon2::password_hash::{rand_core::OsRng, PasswordHash, PasswordHasher, PasswordVerifier, SaltString};
use argon2::Argon2;
use rand::RngCore;
use sha2::{Digest, Sha256};
use sqlx::{AnyPool, Row};
use std::sync::{Arc, LazyLock};
use tokio::sync::Semaphore;

/// A valid, normalised (trimmed, lower-case) e-mail address.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Email(String);

impl Email {
    /// Parses an address: one `@`, a dot in the domain, no spaces, at most 254 bytes.
    pub fn parse(text: &str) -> Result<Email, ServiceError> {
        let email = text.trim().to_lowercase();
        let bad =
            |why: &str| ServiceError::invalid("invalid_email", format!("{email:?} is not an e-mail address: {why}"));
        if email.len() > 254 {
            return Err(bad("longer than 254 characters"));
        }
        if email.chars().any(|c| c.is_whitespace() || c.is_control()) {
            return Err(bad("it contains spaces"));
        }
        let Some((local, domain)) = email.split_once('@') else { return Err(bad("no @")) };
        if local.is_empty()
            || domain.contains('@')
            || !domain.contains('.')
            || domain.starts_with('.')
            || domain.ends_with('.')
        {
            return Err(bad("expected name@domain.tld"));
        }
        Ok(Email(email))
    }
    /// The address.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Whether the address is in [`SERVICE_DOMAIN`] (addresses are lower-case).
    pub fn is_reserved(&self) -> bool {
        self.0.rsplit_once('@').is_some_and(|(_, domain)| domain == SERVICE_DOMAIN)
    }
}

/// The domain of the service's own accounts (the bootstrap administrator,
/// the references' and the baselines' publishers): no user registers an
/// address there. Were it open, whoever registered a service address first
/// would hold it for ever (the service refuses to take over an ordinary
/// account), and every runner that lacks a reference would stop.
pub const SERVICE_DOMAIN: &str = "localhost.localdomain";

/// A password good enough to accept: 10 to 1024 characters.
pub struct Password(String);

impl Password {
    /// Checks the length rules.
    pub fn parse(text: &str) -> Result<Password, ServiceError> {
        let n = text.chars().count();
        if n < 10 {
            return Err(ServiceError::invalid("weak_password", "the password needs at least 10 characters"));
        }
        if n > 1024 {
            return Err(ServiceError::invalid("invalid_password", "the password is longer than 1024 characters"));
        }
        Ok(Password(text.to_string()))
    }

    async fn hash(&self) -> Result<String, ServiceError> {
        let password = self.0.clone();
        off_workers(move || hash_password(&password)).await?
    }
}

fn hash_password(password: &str) -> Result<String, ServiceError> {
    let salt = SaltString::generate(&mut OsRng);
    Argon2::default().hash_password(password.as_bytes(), &salt).map(|h| h.to_string()).map_err(ServiceError::internal)
}

/// Whether `password` matches the stored argon2 `hash`.
fn password_matches(password: &str, hash: &str) -> bool {
    PasswordHash::new(hash).is_ok_and(|h| Argon2::default().verify_password(password.as_bytes(), &h).is_ok())
}

/// Hashes running at once: one per core.
static HASHING: LazyLock<Arc<Semaphore>> =
    LazyLock::new(|| Arc::new(Semaphore::new(std::thread::available_parallelism().map_or(2, |n| n.get()))));

/// The hash an unknown address's log-in is checked against: the same
/// parameters, so the same work, as a real one; matched by no password.
static DUMMY_HASH: LazyLock<String> =
    LazyLock::new(|| hash_password(&random_token()).expect("argon2 hashes a random password"));

/// Runs argon2 `work` on a blocking thread once a core is free. The permit
/// goes with the work, so a client that hangs up does not free its core
/// while the hash still runs.
async fn off_workers<T: Send + 'static>(work: impl FnOnce() -> T + Send + 'static) -> Result<T, ServiceError> {
    let permit = HASHING.clone().acquire_owned().await.map_err(ServiceError::internal)?;
    tokio::task::spawn_blocking(move || {
        let _permit = permit;
        work()
    })
    .await
    .map_err(ServiceError::internal)
}

/// Whether `password` matches `hash`, off the async workers; no hash (an
/// unknown address) costs the same and never matches.
async fn verify_password(password: &str, hash: Option<String>) -> Result<bool, ServiceError> {
    let password = password.to_string();
    off_workers(move || match hash {
        Some(hash) => password_matches(&password, &hash),
        None => {
            password_matches(&password, &DUMMY_HASH);
            false
        }
    })
    .await
}

/// A random token (256 bits, hex).
pub fn random_token() -> String {
    let mut bytes = [0u8; 32];
    rand::rng().fill_bytes(&mut bytes);
    hex(&bytes)
}

/// SHA-256 of a token, hex: what the database keeps.
pub fn digest(token: &str) -> String {
    hex(&Sha256::digest(token.as_bytes()))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// A user as the rest of the server sees one.
#[derive(Debug, Clone, serde::Serialize)]
pub struct User {
    /// Random id.
    pub id: String,
    /// Normalised e-mail address.
    pub email: String,
    /// Whether the address was verified.
    pub verified: bool,
    /// Whether the user administers the server.
    pub is_admin: bool,
    /// Whether the user must choose a password before anything else (the
    /// first administrator's one-time password was printed to the log).
    pub must_change_password: bool,
}

fn user_of(row: &sqlx::any::AnyRow) -> Result<User, sqlx::Error> {
    Ok(User {
        id: row.try_get("id")?,
        email: row.try_get("email")?,
        verified: row.try_get::<i64, _>("verified")? != 0,
        is_admin: row.try_get::<i64, _>("is_admin")? != 0,
        must_change_password: row.try_get::<i64, _>("must_change_password")? != 0,
    })
}

/// Requires `user_id` to choose a password before anything else
/// ([`User::must_change_password`]).
pub async fn require_password_change(pool: &AnyPool, user_id: &str) -> Result<(), sqlx::Error> {
    sqlx::query("UPDATE users SET must_change_password = 1 WHERE id = $1").bind(user_id).execute(pool).await?;
    Ok(())
}

/// Registers an unverified account and mails its verification link.
pub async fn register(state: &crate::AppState, email: &Email, password: &Password) -> Result<User, ServiceError> {
    if email.is_reserved() {
        return Err(ServiceError::invalid(
            "reserved_email",
            format!("{} is one of the service's own addresses: register with your own", email.as_str()),
        ));
    }
    let user = create_user(&state.pool, email, password, false, false).await?;
    mail_verification(state, &user.id, email).await?;
    Ok(user)
}

async fn mail_verification(state: &crate::AppState, user_id: &str, email: &Email) -> Result<(), ServiceError> {
    let token = issue_email_token(&state.pool, user_id, "verify").await?;
    let link = format!("{}/accounts/verify?token={token}", state.public_url);
    let body = format!(
        "Welcome to FBKSD.\n\nConfirm your e-mail address to use your account:\n\n{link}\n\n\
         The link works once, for 48 hours. If you did not register, ignore this message.\n"
    );
    state.mailer.send(&state.config.mail_from, email.as_str(), "Confirm your FBKSD account", body).await?;
    Ok(())
}

/// Mails a new verification link if `email` has an account that is not
/// verified yet; does nothing otherwise (callers answer the same either
/// way). Earlier links keep working until they expire.
pub async fn resend_verification(state: &crate::AppState, email: &Email) -> Result<(), ServiceError> {
    let row = sqlx::query("SELECT id FROM users WHERE email = $1 AND verified = 0")
        .bind(email.as_str())
        .fetch_optional(&state.pool)
        .await?;
    let Some(row) = row else { return Ok(()) };
    mail_verification(state, &row.try_get::<String, _>("id")?, email).await
}

/// Mails a password-reset token if `email` has an account; does nothing
/// otherwise (callers answer the same either way, revealing no accounts).
pub async fn mail_password_reset(state: &crate::AppState, email: &Email) -> Result<(), ServiceError> {
    let Some(user_id) = user_id_by_email(&state.pool, email).await? else { return Ok(()) };
    let token = issue_email_token(&state.pool, &user_id, "reset").await?;
    let body = format!(
        "Someone asked to reset the password of your FBKSD account.\n\n\
         Your reset token (valid once, for 48 hours):\n\n{token}\n\n\
         Send it with your new password to {}/api/v1/password-resets/confirm.\n\
         If it was not you, ignore this message: your password is unchanged.\n",
        state.public_url
    );
    state.mailer.send(&state.config.mail_from, email.as_str(), "Reset your FBKSD password", body).await?;
    Ok(())
}

/// Creates an account; `verified` accounts skip the e-mail step (the
/// bootstrap administrator). A taken address is a 409.
pub async fn create_user(
    pool: &AnyPool,
    email: &Email,
    password: &Password,
    verified: bool,
    is_admin: bool,
) -> Result<User, ServiceError> {
    let id = uuid::Uuid::new_v4().to_string();
    let hash = password.hash().await?;
    let inserted = sqlx::query(
        "INSERT INTO users (id, email, password_hash, verified, is_admin, created_at) VALUES ($1, $2, $3, $4, $5, $6)",
    )
    .bind(&id)
    .bind(email.as_str())
    .bind(&hash)
    .bind(verified as i64)
    .bind(is_admin as i64)
    .bind(now_ms())
    .execute(pool)
    .await;
    match inserted {
        Ok(_) => Ok(User { id, email: email.as_str().to_string(), verified, is_admin, must_change_password: false }),
        Err(sqlx::Error::Database(e)) if e.is_unique_violation() => Err(ServiceError::conflict(
            "email_taken",
            format!("an account with {} exists: log in, or reset its password", email.as_str()),
        )),
        Err(e) => Err(e.into()),
    }
}

/// The service account at `email` (the baselines' or the references'
/// publisher), created at the server's start and on first use: verified
/// without mail, with a password nobody knows, exempt from quotas and
/// yielding the runners to users (see `is_service`). An ordinary account at
/// that address (registered before [`SERVICE_DOMAIN`] was reserved) is
/// refused, never taken over.
pub async fn ensure_service_account(pool: &AnyPool, email: &Email) -> Result<User, ServiceError> {
    if let Some(id) = user_id_by_email(pool, email).await? {
        if !is_service(pool, &id).await? {
            return Err(ServiceError::conflict(
                "email_taken",
                format!("{} is an ordinary account, not the service account", email.as_str()),
            ));
        }
        return user_by_id(pool, &id).await?.ok_or_else(|| ServiceError::internal("service account vanished"));
    }
    let password = Password::parse(&random_token())?;
    let user = create_user(pool, email, &password, true, false).await?;
    sqlx::query("UPDATE users SET is_service = 1 WHERE id = $1").bind(&user.id).execute(pool).await?;
    Ok(user)
}

/// Whether `user_id` is a service account (no quotas).
pub async fn is_service(pool: &AnyPool, user_id: &str) -> Result<bool, sqlx::Error> {
    let row = sqlx::query("SELECT is_service FROM users WHERE id = $1").bind(user_id).fetch_optional(pool).await?;
    Ok(row.map(|r| r.try_get::<i64, _>("is_service")).transpose()?.unwrap_or(0) != 0)
}

/// Revokes every access token of `user_id` (a service account's tokens
/// live as long as the command that made them).
pub async fn revoke_all_access_tokens(pool: &AnyPool, user_id: &str) -> Result<(), sqlx::Error> {
    sqlx::query("DELETE FROM access_tokens WHERE user_id = $1").bind(user_id).execute(pool).await?;
    Ok(())
}

/// Whether any administrator exists.
pub async fn has_admin(pool: &AnyPool) -> Result<bool, sqlx::Error> {
    let row = sqlx::query("SELECT COUNT(*) AS n FROM users WHERE is_admin = 1").fetch_one(pool).await?;
    Ok(row.try_get::<i64, _>("n")? > 0)
}

/// How long an e-mail token is valid.
const EMAIL_TOKEN_MS: i64 = 48 * 3600 * 1000;

/// Stores a new one-time token for `purpose` and returns it (to be mailed).
pub async fn issue_email_token(pool: &AnyPool, user_id: &str, purpose: &str) -> Result<String, sqlx::Error> {
    // Expired tokens go as new ones come: the table holds two days' mail.
    sqlx::query("DELETE FROM email_tokens WHERE expires_at < $1").bind(now_ms()).execute(pool).await?;
    let token = random_token();
    sqlx::query("INSERT INTO email_tokens (token_hash, user_id, purpose, expires_at) VALUES ($1, $2, $3, $4)")
        .bind(digest(&token))
        .bind(user_id)
        .bind(purpose)
        .bind(now_ms() + EMAIL_TOKEN_MS)
        .execute(pool)
        .await?;
    Ok(token)
}

/// Uses a one-time token: returns its user, or an error saying it is
/// unknown, used or expired.
pub async fn redeem_email_token(pool: &AnyPool, token: &str, purpose: &str) -> Result<String, ServiceError> {
    let mut conn = pool.acquire().await?;
    redeem(&mut conn, token, purpose).await
}

/// Marks a live token used and returns its user, in one statement, so two
/// requests racing with one token cannot both redeem it.
async fn redeem(conn: &mut sqlx::AnyConnection, token: &str, purpose: &str) -> Result<String, ServiceError> {
    let invalid =
        || ServiceError::invalid("invalid_token", "this link is unknown, already used or expired: ask for a new one");
    let row = sqlx::query(
        "UPDATE email_tokens SET used = 1 \
         WHERE token_hash = $1 AND purpose = $2 AND used = 0 AND expires_at >= $3 RETURNING user_id",
    )
    .bind(digest(token))
    .bind(purpose)
    .bind(now_ms())
    .fetch_optional(&mut *conn)
    .await?
    .ok_or_else(invalid)?;
    Ok(row.try_get("user_id")?)
}

/// Sets a new password with a mailed reset token. Whoever had the account
/// is shut out: every session and access token ends, and every other
/// reset token dies. The address is verified: the mail was read.
pub async fn reset_password(pool: &AnyPool, token: &str, password: &Password) -> Result<(), ServiceError> {
    // Hashed before the transaction, which must not wait for a core.
    let hash = password.hash().await?;
    let mut tx = pool.begin().await?;
    let user_id = redeem(&mut tx, token, "reset").await?;
    sqlx::query("UPDATE users SET password_hash = $1, verified = 1, must_change_password = 0 WHERE id = $2")
        .bind(&hash)
        .bind(&user_id)
        .execute(&mut *tx)
        .await?;
    sqlx::query("DELETE FROM sessions WHERE user_id = $1").bind(&user_id).execute(&mut *tx).await?;
    sqlx::query("DELETE FROM access_tokens WHERE user_id = $1").bind(&user_id).execute(&mut *tx).await?;
    sqlx::query("UPDATE email_tokens SET used = 1 WHERE user_id = $1 AND purpose = 'reset' AND used = 0")
        .bind(&user_id)
        .execute(&mut *tx)
        .await?;
    tx.commit().await?;
    Ok(())
}

/// Marks a user's address verified.
pub async fn mark_verified(pool: &AnyPool, user_id: &str) -> Result<(), sqlx::Error> {
    sqlx::query("UPDATE users SET verified = 1 WHERE id = $1").bind(user_id).execute(pool).await?;
    Ok(())
}

/// The user with these credentials; one message for an unknown address and
/// a wrong password, so it does not tell which addresses exist.
pub async fn authenticate(pool: &AnyPool, email: &str, password: &str) -> Result<User, ServiceError> {
    let wrong = || ServiceError::unauthenticated("wrong e-mail address or password");
    // No account has a malformed address or an over-long password: nothing to time.
    let email = Email::parse(email).map_err(|_| wrong())?;
    if password.chars().count() > 1024 {
        return Err(wrong());
    }
    let row = sqlx::query(
        "SELECT id, email, password_hash, verified, is_admin, must_change_password FROM users WHERE email = $1",
    )
    .bind(email.as_str())
    .fetch_optional(pool)
    .await?;
    let hash = row.as_ref().map(|r| r.try_get::<String, _>("password_hash")).transpose()?;
    let matches = verify_password(password, hash).await?;
    let Some(row) = row.filter(|_| matches) else { return Err(wrong()) };
    let user = user_of(&row)?;
    if !user.verified {
        return Err(ServiceError::forbidden(
            "email_not_verified",
            "verify your e-mail address first: follow the link we sent you",
        ));
    }
    Ok(user)
}

/// A browser session: the cookie's token and the CSRF token to echo.
pub struct NewSession {
    /// Goes into the session cookie.
    pub token: String,
    /// Must accompany every state-changing request of this session.
    pub csrf_token: String,
}

/// Opens a session for `user_id` lasting `hours`.
pub async fn open_session(pool: &AnyPool, user_id: &str, hours: u64) -> Result<NewSession, sqlx::Error> {
    let (token, csrf_token) = (random_token(), random_token());
    let now = now_ms();
    // Expired sessions go as new ones open: the table holds live ones only.
    sqlx::query("DELETE FROM sessions WHERE expires_at < $1").bind(now).execute(pool).await?;
    sqlx::query(
        "INSERT INTO sessions (token_hash, user_id, csrf_token, created_at, expires_at) VALUES ($1, $2, $3, $4, $5)",
    )
    .bind(digest(&token))
    .bind(user_id)
    .bind(&csrf_token)
    .bind(now)
    .bind(now + hours as i64 * 3600 * 1000)
    .execute(pool)
    .await?;
    Ok(NewSession { token, csrf_token })
}

/// The user and CSRF token of a live session.
pub async fn session_user(pool: &AnyPool, token: &str) -> Result<Option<(User, String)>, sqlx::Error> {
    let row = sqlx::query(
        "SELECT u.id, u.email, u.verified, u.is_admin, u.must_change_password, s.csrf_token \
         FROM sessions s JOIN users u ON u.id = s.user_id \
         WHERE s.token_hash = $1 AND s.expires_at > $2",
    )
    .bind(digest(token))
    .bind(now_ms())
    .fetch_optional(pool)
    .await?;
    row.map(|r| Ok((user_of(&r)?, r.try_get("csrf_token")?))).transpose()
}

/// Ends a session.
pub async fn close_session(pool: &AnyPool, token: &str) -> Result<(), sqlx::Error> {
    sqlx::query("DELETE FROM sessions WHERE token_hash = $1").bind(digest(token)).execute(pool).await?;
    Ok(())
}

/// Sets a new password and ends every session of the user.
pub async fn set_password(pool: &AnyPool, user_id: &str, password: &Password) -> Result<(), ServiceError> {
    let hash = password.hash().await?;
    let mut tx = pool.begin().await?;
    sqlx::query("UPDATE users SET password_hash = $1, must_change_password = 0 WHERE id = $2")
        .bind(&hash)
        .bind(user_id)
        .execute(&mut *tx)
        .await?;
    sqlx::query("DELETE FROM sessions WHERE user_id = $1").bind(user_id).execute(&mut *tx).await?;
    tx.commit().await?;
    Ok(())
}

/// Replaces `user_id`'s password, given the current one; every session
/// ends (the caller logs in again), and a pending one-time password is
/// replaced.
pub async fn change_password(pool: &AnyPool, user_id: &str, current: &str, new: &str) -> Result<(), ServiceError> {
    check_password(pool, user_id, current).await?;
    set_password(pool, user_id, &Password::parse(new)?).await
}

/// Checks a user's current password (for changes that need it).
pub async fn check_password(pool: &AnyPool, user_id: &str, password: &str) -> Result<(), ServiceError> {
    let row = sqlx::query("SELECT password_hash FROM users WHERE id = $1").bind(user_id).fetch_one(pool).await?;
    if verify_password(password, Some(row.try_get("password_hash")?)).await? {
        Ok(())
    } else {
        Err(ServiceError::forbidden("wrong_password", "the current password is wrong"))
    }
}

/// The user with id `id`, if any.
pub async fn user_by_id(pool: &AnyPool, id: &str) -> Result<Option<User>, sqlx::Error> {
    let row = sqlx::query("SELECT id, email, verified, is_admin, must_change_password FROM users WHERE id = $1")
        .bind(id)
        .fetch_optional(pool)
        .await?;
    row.as_ref().map(user_of).transpose()
}

/// The id of the user with this address, if any.
pub async fn user_id_by_email(pool: &AnyPool, email: &Email) -> Result<Option<String>, sqlx::Error> {
    let row = sqlx::query("SELECT id FROM users WHERE email = $1").bind(email.as_str()).fetch_optional(pool).await?;
    row.map(|r| r.try_get("id")).transpose()
}

/// Deletes a user and, by cascade, their sessions, tokens (and, as they
/// come, projects and unpublished results).
pub async fn delete_user(pool: &AnyPool, user_id: &str) -> Result<(), sqlx::Error> {
    sqlx::query("DELETE FROM users WHERE id = $1").bind(user_id).execute(pool).await?;
    Ok(())
}

/// Prefix of personal access tokens, so they are recognisable in logs and
/// secret scanners.
pub const ACCESS_TOKEN_PREFIX: &str = "fbksd_";

/// An access token as listed (never the token itself).
#[derive(Debug, serde::Serialize)]
pub struct AccessToken {
    /// Id, for revoking.
    pub id: String,
    /// The user's name for it.
    pub name: String,
    /// Creation time, Unix ms.
    pub created_at: i64,
    /// Last use, Unix ms.
    pub last_used_at: Option<i64>,
}

/// Access tokens one account may hold (each is a row checked at every
/// token's use and listed on the settings page).
pub const MAX_ACCESS_TOKENS: usize = 50;

/// Creates a personal access token named `name`; returns its id and the
/// token, which is shown this once.
pub async fn create_access_token(pool: &AnyPool, user_id: &str, name: &str) -> Result<(String, String), ServiceError> {
    let name = name.trim();
    if name.is_empty() || name.chars().count() > 100 {
        return Err(ServiceError::invalid("invalid_name", "a token needs a name of 1 to 100 characters"));
    }
    let held: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM access_tokens WHERE user_id = $1")
        .bind(user_id)
        .fetch_one(pool)
        .await?;
    if held as usize >= MAX_ACCESS_TOKENS {
        return Err(ServiceError::forbidden(
            "too_many_tokens",
            format!("you have {held} access tokens, the most one account may: revoke one you no longer use first"),
        ));
    }
    let (id, token) = (uuid::Uuid::new_v4().to_string(), format!("{ACCESS_TOKEN_PREFIX}{}", random_token()));
    sqlx::query("INSERT INTO access_tokens (id, user_id, name, token_hash, created_at) VALUES ($1, $2, $3, $4, $5)")
        .bind(&id)
        .bind(user_id)
        .bind(name)
        .bind(digest(&token))
        .bind(now_ms())
        .execute(pool)
        .await?;
    Ok((id, token))
}

/// A user's access tokens, newest first.
pub async fn access_tokens(pool: &AnyPool, user_id: &str) -> Result<Vec<AccessToken>, sqlx::Error> {
    let rows = sqlx::query(
        "SELECT id, name, created_at, last_used_at FROM access_tokens WHERE user_id = $1 ORDER BY created_at DESC",
    )
    .bind(user_id)
    .fetch_all(pool)
    .await?;
    rows.iter()
        .map(|r| {
            Ok(AccessToken {
                id: r.try_get("id")?,
                name: r.try_get("name")?,
                created_at: r.try_get("created_at")?,
                last_used_at: r.try_get("last_used_at")?,
            })
        })
        .collect()
}

/// Revokes one of a user's tokens; false if the user has no such token.
pub async fn revoke_access_token(pool: &AnyPool, user_id: &str, id: &str) -> Result<bool, sqlx::Error> {
    let done = sqlx::query("DELETE FROM access_tokens WHERE id = $1 AND user_id = $2")
        .bind(id)
        .bind(user_id)
        .execute(pool)
        .await?;
    Ok(done.rows_affected() > 0)
}

/// The user a personal access token belongs to (recording its use).
pub async fn token_user(pool: &AnyPool, token: &str) -> Result<Option<User>, sqlx::Error> {
    if !token.starts_with(ACCESS_TOKEN_PREFIX) {
        return Ok(None);
    }
    let row = sqlx::query(
        "SELECT u.id, u.email, u.verified, u.is_admin, u.must_change_password \
         FROM access_tokens t JOIN users u ON u.id = t.user_id \
         WHERE t.token_hash = $1",
    )
    .bind(digest(token))
    .fetch_optional(pool)
    .await?;
    let Some(row) = row else { return Ok(None) };
    sqlx::query("UPDATE access_tokens SET last_used_at = $1 WHERE token_hash = $2")
        .bind(now_ms())
        .bind(digest(token))
        .execute(pool)
        .await?;
    Ok(Some(user_of(&row)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn email_addresses_are_normalised_or_refused() {
        assert_eq!(Email::parse("  Ada@Example.ORG ").unwrap().as_str(), "ada@example.org");
        for bad in ["", "ada", "ada@", "@example.org", "ada@example", "a da@example.org", "a@b@c.org", "ada@.org"] {
            let e = Email::parse(bad).unwrap_err();
            assert_eq!(e.code, "invalid_email", "{bad:?}");
        }
        assert!(Email::parse(&format!("{}@example.org", "a".repeat(250))).is_err());
    }

    #[tokio::test]
    async fn passwords_need_ten_characters_and_hash_with_argon2() {
        assert_eq!(Password::parse("short").err().unwrap().code, "weak_password");
        let p = Password::parse("correct horse battery").unwrap();
        let hash = p.hash().await.unwrap();
        assert!(hash.starts_with("$argon2"));
        assert!(verify_password("correct horse battery", Some(hash.clone())).await.unwrap());
        assert!(!verify_password("correct horse battery!", Some(hash)).await.unwrap());
        assert!(!verify_password("correct horse battery", None).await.unwrap(), "the dummy hash matches nothing");
        assert!(DUMMY_HASH.starts_with("$argon2"));
    }

    #[test]
    fn tokens_are_random_and_stored_as_digests() {
        let (a, b) = (random_token(), random_token());
        assert_ne!(a, b);
        assert_eq!(a.len(), 64);
        assert_ne!(digest(&a), a);
        assert_eq!(digest(&a), digest(&a));
    }
}
