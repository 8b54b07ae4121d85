//! Runners: machines that claim jobs. A runner registers once with the
//! server's registration token and gets its own runner token (`fbksdr_…`),
//! which can claim jobs and nothing else; each claim hands out a job token
//! (`fbksdj_…`) that can only report on that job.

use crate::accounts::{digest, random_token};
use crate::error::ServiceError;
use crate::now_ms;
use sqlx::{AnyPool, Row};

/// Prefix of runner tokens.
pub const RUNNER_TOKEN_PREFIX: &str = "fbksdr_";

const REGISTRATION_KEY: &str = "runner_registration_token_hash";

/// A registered runner as administrators see it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Runner {
    /// Random id.
    pub id: String,
    /// Its name.
    pub name: String,
    /// What it said about its machine.
    pub machine: serde_json::Value,
    /// Registration time, Unix ms.
    pub registered_at: i64,
    /// Last claim or report, Unix ms.
    pub last_seen_at: i64,
    /// Jobs it holds now.
    pub running_jobs: i64,
    /// What it is preparing before it takes jobs (None: ready).
    pub preparing: Option<String>,
    /// Since when it has been preparing that, Unix ms.
    pub preparing_since: Option<i64>,
}

impl Runner {
    /// Whether the runner reported lately: a runner not heard of for two
    /// leases (or two long polls, if longer) is presumed gone.
    pub fn healthy(&self, config: &crate::config::Config, now_ms: i64) -> bool {
        let silent_after_ms = 2 * config.lease_seconds.max(config.long_poll_seconds) as i64 * 1000;
        now_ms - self.last_seen_at <= silent_after_ms
    }
}

/// Sets the registration token: `configured` if given, else a new random
/// one if none exists yet. Returns the token when it was generated now
/// (to print once).
pub async fn ensure_registration_token(pool: &AnyPool, configured: &str) -> Result<Option<String>, sqlx::Error> {
    if !configured.is_empty() {
        set_setting(pool, REGISTRATION_KEY, &digest(configured)).await?;
        return Ok(None);
    }
    let exists =
        sqlx::query("SELECT value FROM settings WHERE key = $1").bind(REGISTRATION_KEY).fetch_optional(pool).await?;
    if exists.is_some() {
        return Ok(None);
    }
    let token = format!("fbksdreg_{}", random_token());
    set_setting(pool, REGISTRATION_KEY, &digest(&token)).await?;
    Ok(Some(token))
}

/// Replaces the registration token (administration); returns the new one.
pub async fn rotate_registration_token(pool: &AnyPool) -> Result<String, sqlx::Error> {
    let token = format!("fbksdreg_{}", random_token());
    set_setting(pool, REGISTRATION_KEY, &digest(&token)).await?;
    Ok(token)
}

async fn set_setting(pool: &AnyPool, key: &str, value: &str) -> Result<(), sqlx::Error> {
    let mut tx = pool.begin().await?;
    sqlx::query("DELETE FROM settings WHERE key = $1").bind(key).execute(&mut *tx).await?;
    sqlx::query("INSERT INTO settings (key, value) VALUES ($1, $2)").bind(key).bind(value).execute(&mut *tx).await?;
    tx.commit().await
}

/// Registers a runner; returns (id, runner token).
pub async fn register(
    pool: &AnyPool,
    registration_token: &str,
    name: &str,
    machine: &serde_json::Value,
) -> Result<(String, String), ServiceError> {
    let stored =
        sqlx::query("SELECT value FROM settings WHERE key = $1").bind(REGISTRATION_KEY).fetch_optional(pool).await?;
    let valid =
        stored.map(|r| r.try_get::<String, _>("value")).transpose()?.is_some_and(|h| h == digest(registration_token));
    if !valid {
        return Err(ServiceError::unauthenticated("wrong runner registration token: ask the server's administrator"));
    }
    let name = name.trim();
    if name.is_empty() || name.len() > 100 {
        return Err(ServiceError::invalid("invalid_name", "a runner needs a name of 1 to 100 characters"));
    }
    let (id, token) = (uuid::Uuid::new_v4().to_string(), format!("{RUNNER_TOKEN_PREFIX}{}", random_token()));
    let now = now_ms();
    sqlx::query("INSERT INTO runners (id, name, token_hash, machine, registered_at, last_seen_at) VALUES ($1, $2, $3, $4, $5, $5)")
        .bind(&id)
        .bind(name)
        .bind(digest(&token))
        .bind(machine.to_string())
        .bind(now)
        .execute(pool)
        .await?;
    Ok((id, token))
}

/// The id of the runner a runner token belongs to (recording that it was seen).
pub async fn token_runner(pool: &AnyPool, token: &str) -> Result<Option<String>, sqlx::Error> {
    if !token.starts_with(RUNNER_TOKEN_PREFIX) {
        return Ok(None);
    }
    let row =
        sqlx::query("SELECT id FROM runners WHERE token_hash = $1").bind(digest(token)).fetch_optional(pool).await?;
    let Some(row) = row else { return Ok(None) };
    let id: String = row.try_get("id")?;
    seen(pool, &id).await?;
    Ok(Some(id))
}

/// Records that a runner reported.
pub async fn seen(pool: &AnyPool, runner_id: &str) -> Result<(), sqlx::Error> {
    sqlx::query("UPDATE runners SET last_seen_at = $1 WHERE id = $2")
        .bind(now_ms())
        .bind(runner_id)
        .execute(pool)
        .await?;
    Ok(())
}

/// Records what a runner is preparing (`None`: it is ready for jobs); the
/// time is kept while the status stays the same.
pub async fn set_status(pool: &AnyPool, runner_id: &str, preparing: Option<&str>) -> Result<(), sqlx::Error> {
    sqlx::query(
        "UPDATE runners SET status_since = CASE WHEN status IS NOT NULL AND status = $1 THEN status_since ELSE $2 END, \
         status = $1, last_seen_at = $2 WHERE id = $3",
    )
    .bind(preparing)
    .bind(now_ms())
    .bind(runner_id)
    .execute(pool)
    .await?;
    Ok(())
}

/// Records what a runner says its machine is now (its class and
/// calibration change with its hardware and its settings).
pub async fn set_machine(pool: &AnyPool, runner_id: &str, machine: &serde_json::Value) -> Result<(), sqlx::Error> {
    // Bounded as a registration's is: by the API's body limit.
    sqlx::query("UPDATE runners SET machine = $1 WHERE id = $2")
        .bind(machine.to_string())
        .bind(runner_id)
        .execute(pool)
        .await?;
    Ok(())
}

/// The season whose benchmarks `runner_id` is not handed now, if any: the
/// current one, while the runner's latest calibration (its machine record,
/// sent after each calibration) lies beyond the drift limit from its
/// class's there. Its times would not compare with the board's; it still
/// builds and makes references, and takes the benchmarks again once a
/// calibration is back within the limit, or those that have waited longer
/// than `max_drift_hold_minutes` (the claim route's bound).
pub async fn held_season(
    pool: &AnyPool,
    boards: &crate::leaderboard::BoardCache,
    runner_id: &str,
) -> Result<Option<i64>, sqlx::Error> {
    let machine: Option<String> =
        sqlx::query_scalar("SELECT machine FROM runners WHERE id = $1").bind(runner_id).fetch_optional(pool).await?;
    let machine: serde_json::Value = machine.and_then(|m| serde_json::from_str(&m).ok()).unwrap_or_default();
    if crate::results::runner_class(&machine).is_none() {
        return Ok(None);
    }
    let season = crate::results::current_season(pool).await?;
    Ok(boards.season(pool, season).await?.drift_of(&machine).map(|_| season))
}

/// Every runner, most recently seen first.
pub async fn all(pool: &AnyPool) -> Result<Vec<Runner>, sqlx::Error> {
    let rows = sqlx::query(
        "SELECT r.id, r.name, r.machine, r.registered_at, r.last_seen_at, r.status, r.status_since, \
         (SELECT COUNT(*) FROM jobs j WHERE j.runner_id = r.id AND j.state = 'running') AS running_jobs \
         FROM runners r ORDER BY r.last_seen_at DESC",
    )
    .fetch_all(pool)
    .await?;
    rows.iter()
        .map(|r| {
            let machine: String = r.try_get("machine")?;
            Ok(Runner {
                id: r.try_get("id")?,
                name: r.try_get("name")?,
                machine: serde_json::from_str(&machine).unwrap_or_default(),
                registered_at: r.try_get("registered_at")?,
                last_seen_at: r.try_get("last_seen_at")?,
                running_jobs: r.try_get("running_jobs")?,
                preparing: r.try_get("status")?,
                preparing_since: r.try_get("status_since")?,
            })
        })
        .collect()
}

/// Removes a runner (administration); its running jobs lose their lease at once.
pub async fn remove(pool: &AnyPool, runner_id: &str) -> Result<bool, sqlx::Error> {
    crate::jobs::drop_leases_of(pool, runner_id).await?;
    let done = sqlx::query("DELETE FROM runners WHERE id = $1").bind(runner_id).execute(pool).await?;
    Ok(done.rows_affected() > 0)
}
