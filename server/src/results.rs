//! Result sets: what a successful benchmark job uploaded, stored under a
//! random UUID and changed only by the repeats a seeds job adds
//! ([`crate::seeds`], which changes the board version). Publishing puts a set on its
//! season's leaderboard (one published set per project and season);
//! unpublishing takes it off; discarding deletes it; an administrator can
//! hide a set that breaks the rules.
//!
//! What a runner uploads ([`Upload`]) is a type of the runner API in
//! `fbksd_exchange`, which the runner serialises too.

use crate::error::ServiceError;
use crate::now_ms;
use fbksd_exchange::results::{IndexEntry, Repeat};
use fbksd_exchange::MetricInfo;
use serde::Serialize;
use sqlx::{AnyPool, Row};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;
use std::time::Instant;

pub use fbksd_exchange::runner_api::{SceneProvenance, Upload};

/// The name of an uploaded file: letters, digits, `.`, `-`, `_` and `/`
/// between non-empty parts, no `..`.
pub fn check_file_name(name: &str) -> Result<(), ServiceError> {
    if fbksd_exchange::runner_api::is_upload_file_name(name) {
        Ok(())
    } else {
        Err(ServiceError::invalid("invalid_file_name", format!("file name {name:?}: use letters, digits, . - _ and /")))
    }
}

/// The set `id` if `user` may see it: its owner and administrators always;
/// everyone once it is published and not hidden. Otherwise not found, so
/// private sets do not reveal that they exist.
pub async fn visible(
    pool: &AnyPool,
    id: &str,
    user: Option<&crate::accounts::User>,
) -> Result<ResultSet, ServiceError> {
    if uuid::Uuid::parse_str(id).is_err() {
        return Err(ServiceError::invalid("invalid_uuid", format!("{id:?} is not a result UUID")));
    }
    let not_found = || ServiceError::not_found(format!("no result set {id} that you can see"));
    let set = get(pool, id).await?.ok_or_else(not_found)?;
    let owner = user.is_some_and(|u| set.user_id.as_deref() == Some(u.id.as_str()) || u.is_admin);
    if owner || set.is_public() {
        Ok(set)
    } else {
        Err(not_found())
    }
}

/// The id of the result set `job` produced if `viewer` may not see it: a
/// set is its owner's (and administrators') until it is published and not
/// hidden, and the job's message and log name it, so readers of a public
/// project's jobs get them without it ([`crate::jobs::Job::without_result`],
/// [`crate::jobs::hide_result`]).
pub async fn private_result_of(
    pool: &AnyPool,
    job: &crate::jobs::Job,
    viewer: Option<&crate::accounts::User>,
) -> Result<Option<String>, sqlx::Error> {
    let Some(id) = &job.result_id else { return Ok(None) };
    if viewer.is_some_and(|u| u.id == job.user_id || u.is_admin) {
        return Ok(None);
    }
    let public = get(pool, id).await?.is_some_and(|set| set.is_public());
    Ok((!public).then(|| id.clone()))
}

/// A stored result set's summary.
#[derive(Debug, Clone, Serialize)]
pub struct ResultSet {
    /// The UUID in `/results/<uuid>`.
    pub id: String,
    /// The technique's short name (the project's name).
    pub technique: String,
    /// Its project's name, if the project still exists.
    pub project: Option<String>,
    /// Its project's id, while the project exists: what the set belongs to
    /// (a deleted project's name may be taken again by someone else).
    #[serde(skip)]
    pub project_id: Option<String>,
    /// Owner, while the account exists.
    pub user_id: Option<String>,
    /// The technique's info.json at the commit.
    pub info: serde_json::Value,
    /// The commit benchmarked.
    pub commit_sha: String,
    /// Leaderboard season.
    pub season: i64,
    /// Provenance.
    pub provenance: serde_json::Value,
    /// Metric descriptions.
    pub metrics: Vec<MetricInfo>,
    /// Creation time.
    pub created_at: i64,
    /// Publication time, while published.
    pub published_at: Option<i64>,
    /// Why an administrator hid it.
    pub hidden_reason: Option<String>,
}

impl ResultSet {
    /// The technique's full name (its info.json's `full_name`, else its project's name).
    pub fn full_name(&self) -> &str {
        self.info["full_name"].as_str().filter(|n| !n.trim().is_empty()).unwrap_or(&self.technique)
    }

    /// Whether everyone may see it: published and not hidden.
    pub fn is_public(&self) -> bool {
        self.published_at.is_some() && self.hidden_reason.is_none()
    }
}

/// One stored run.
#[derive(Debug, Clone, Serialize)]
pub struct StoredRun {
    /// The result set.
    pub result_id: String,
    /// Scene.
    pub scene: String,
    /// Budget.
    pub spp: i64,
    /// Typed status.
    pub status: String,
    /// Why, if not ok.
    pub message: String,
    /// Technique time.
    pub technique_ms: f64,
    /// Render time.
    pub render_ms: f64,
    /// Wall time (0 if not recorded).
    pub wall_ms: f64,
    /// CPU time (0 if not recorded).
    pub cpu_ms: f64,
    /// Peak memory (0 if not recorded).
    pub peak_memory_bytes: i64,
    /// Samples used.
    pub used_samples: i64,
    /// Metric values.
    pub metrics: BTreeMap<String, f64>,
    /// Uploaded image file, if any.
    pub image: Option<String>,
    /// The run's record among the set's files (not stored before the viewer).
    pub log: Option<String>,
    /// Its repeats, one per sample seed (empty for runs stored before repeats).
    pub repeats: Vec<Repeat>,
    /// The reference it was scored against (`sha256:<hex>` of its image).
    pub reference_hash: String,
}

const SET_COLUMNS: &str = "r.id, r.technique, p.name AS project_name, p.id AS project_id, r.user_id, r.info, \
     r.commit_sha, r.season, r.provenance, r.metrics, r.created_at, r.published_at, r.hidden_reason";

fn set_of(row: &sqlx::any::AnyRow) -> Result<ResultSet, sqlx::Error> {
    let json = |column: &str| -> Result<serde_json::Value, sqlx::Error> {
        let text: String = row.try_get(column)?;
        serde_json::from_str(&text).map_err(|e| sqlx::Error::Decode(Box::new(e)))
    };
    Ok(ResultSet {
        id: row.try_get("id")?,
        technique: row.try_get("technique")?,
        project: row.try_get("project_name")?,
        project_id: row.try_get("project_id")?,
        user_id: row.try_get("user_id")?,
        info: json("info")?,
        commit_sha: row.try_get("commit_sha")?,
        season: row.try_get("season")?,
        provenance: json("provenance")?,
        metrics: serde_json::from_value(json("metrics")?).map_err(|e| sqlx::Error::Decode(Box::new(e)))?,
        created_at: row.try_get("created_at")?,
        published_at: row.try_get("published_at")?,
        hidden_reason: row.try_get("hidden_reason")?,
    })
}

/// The result set `id` (any string: invalid UUIDs are simply not found).
pub async fn get(pool: &AnyPool, id: &str) -> Result<Option<ResultSet>, sqlx::Error> {
    let row = sqlx::query(&format!(
        "SELECT {SET_COLUMNS} FROM result_sets r LEFT JOIN projects p ON p.id = r.project_id WHERE r.id = $1"
    ))
    .bind(id)
    .fetch_optional(pool)
    .await?;
    row.as_ref().map(set_of).transpose()
}

/// Result sets of a project, newest first.
pub async fn of_project(pool: &AnyPool, project_id: &str) -> Result<Vec<ResultSet>, sqlx::Error> {
    let rows = sqlx::query(&format!(
        "SELECT {SET_COLUMNS} FROM result_sets r LEFT JOIN projects p ON p.id = r.project_id \
         WHERE r.project_id = $1 ORDER BY r.created_at DESC"
    ))
    .bind(project_id)
    .fetch_all(pool)
    .await?;
    rows.iter().map(set_of).collect()
}

/// Published, visible result sets of a season, by technique.
pub async fn published(pool: &AnyPool, season: i64) -> Result<Vec<ResultSet>, sqlx::Error> {
    let rows = sqlx::query(&format!(
        "SELECT {SET_COLUMNS} FROM result_sets r LEFT JOIN projects p ON p.id = r.project_id \
         WHERE r.season = $1 AND r.published_at IS NOT NULL AND r.hidden_reason IS NULL ORDER BY r.technique"
    ))
    .bind(season)
    .fetch_all(pool)
    .await?;
    rows.iter().map(set_of).collect()
}

/// Which result sets a query reads.
#[derive(Debug, Clone, Copy)]
pub enum Selection<'a> {
    /// The published, visible sets of a season.
    Published(i64),
    /// One set.
    One(&'a str),
}

impl Selection<'_> {
    /// The condition on `result_id`, with `$1` bound by [`Selection::bind`].
    fn condition(self) -> &'static str {
        match self {
            Selection::Published(_) => {
                "result_id IN (SELECT id FROM result_sets WHERE season = $1 AND published_at IS NOT NULL \
                 AND hidden_reason IS NULL)"
            }
            Selection::One(_) => "result_id = $1",
        }
    }

    fn bind<'q>(
        self,
        query: sqlx::query::Query<'q, sqlx::Any, sqlx::any::AnyArguments<'q>>,
    ) -> sqlx::query::Query<'q, sqlx::Any, sqlx::any::AnyArguments<'q>>
    where
        Self: 'q,
    {
        match self {
            Selection::Published(season) => query.bind(season),
            Selection::One(id) => query.bind(id.to_string()),
        }
    }
}

/// The runs of the selected result sets (one query).
pub async fn runs(pool: &AnyPool, which: Selection<'_>) -> Result<Vec<StoredRun>, sqlx::Error> {
    let sql = format!(
        "SELECT result_id, scene, spp, status, message, technique_ms, render_ms, wall_ms, cpu_ms, peak_memory_bytes, \
         used_samples, metric_values, image, log, repeats, \
         COALESCE((SELECT s.reference_hash FROM result_scenes s \
         WHERE s.result_id = result_runs.result_id AND s.scene = result_runs.scene), '') AS reference_hash \
         FROM result_runs WHERE {} ORDER BY result_id, scene, spp",
        which.condition()
    );
    let rows = which.bind(sqlx::query(&sql)).fetch_all(pool).await?;
    rows.iter()
        .map(|r| {
            let values: String = r.try_get("metric_values")?;
            Ok(StoredRun {
                result_id: r.try_get("result_id")?,
                scene: r.try_get("scene")?,
                spp: r.try_get("spp")?,
                status: r.try_get("status")?,
                message: r.try_get("message")?,
                technique_ms: r.try_get("technique_ms")?,
                render_ms: r.try_get("render_ms")?,
                wall_ms: r.try_get("wall_ms")?,
                cpu_ms: r.try_get("cpu_ms")?,
                peak_memory_bytes: r.try_get("peak_memory_bytes")?,
                used_samples: r.try_get("used_samples")?,
                metrics: serde_json::from_str(&values).unwrap_or_default(),
                image: r.try_get("image")?,
                log: r.try_get("log")?,
                repeats: r
                    .try_get::<Option<String>, _>("repeats")?
                    .and_then(|json| serde_json::from_str(&json).ok())
                    .unwrap_or_default(),
                reference_hash: r.try_get("reference_hash")?,
            })
        })
        .collect()
}

impl StoredRun {
    /// The run as a results-index entry of `technique`, with its repeats
    /// summed up (intervals, spreads, time to the result), for ranking.
    pub fn index_entry(&self, technique: &str) -> IndexEntry {
        let mut entry = IndexEntry {
            status: serde_json::from_value(serde_json::Value::String(self.status.clone()))
                .unwrap_or(fbksd_exchange::RunStatus::InvalidOutput),
            message: self.message.clone(),
            log: self.log.clone().unwrap_or_default(),
            image: self.image.clone(),
            technique_ms: self.technique_ms,
            render_ms: self.render_ms,
            wall_ms: self.wall_ms,
            cpu_ms: self.cpu_ms,
            peak_memory_bytes: self.peak_memory_bytes as u64,
            used_samples: self.used_samples as u64,
            metrics: self.metrics.clone(),
            repeats: self.repeats.clone(),
            ..IndexEntry::new(technique, &self.scene, self.spp as u64)
        };
        if entry.repeats.is_empty() {
            entry.upgrade();
        } else {
            entry.summarize();
        }
        entry
    }
}

/// Scenes of the selected result sets: name → tags (the union over the sets).
pub async fn scene_tags(
    pool: &AnyPool,
    which: Selection<'_>,
    out: &mut BTreeMap<String, BTreeSet<String>>,
) -> Result<(), sqlx::Error> {
    let sql = format!("SELECT scene, tags FROM result_scenes WHERE {}", which.condition());
    for r in which.bind(sqlx::query(&sql)).fetch_all(pool).await? {
        let tags: String = r.try_get("tags")?;
        let tags: Vec<String> = serde_json::from_str(&tags).unwrap_or_default();
        out.entry(r.try_get("scene")?).or_default().extend(tags);
    }
    Ok(())
}

/// Everything needed to store a result set, decided before the transaction.
pub struct NewResultSet<'a> {
    /// Its id (a random UUID: the private page's key), chosen before its
    /// files are moved under it.
    pub id: &'a str,
    /// The job that produced it.
    pub job_id: &'a str,
    /// Its project.
    pub project_id: &'a str,
    /// Its owner.
    pub user_id: &'a str,
    /// Technique name.
    pub technique: &'a str,
    /// info.json at the commit.
    pub info: &'a serde_json::Value,
    /// Commit.
    pub commit_sha: &'a str,
    /// Season.
    pub season: i64,
    /// Publish at once (season re-runs).
    pub publish: bool,
    /// The checked upload.
    pub upload: &'a Upload,
}

/// Inserts a result set and its runs and scenes inside `tx`; returns its UUID.
pub async fn insert(tx: &mut sqlx::Transaction<'_, sqlx::Any>, new: &NewResultSet<'_>) -> Result<String, sqlx::Error> {
    let id = new.id.to_string();
    let now = now_ms();
    if new.publish {
        unpublish_others(tx, Some(new.project_id), new.season).await?;
        boards_changed(&mut **tx).await?;
    }
    sqlx::query(
        "INSERT INTO result_sets (id, job_id, project_id, user_id, technique, info, commit_sha, season, provenance, \
         metrics, created_at, published_at) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12)",
    )
    .bind(&id)
    .bind(new.job_id)
    .bind(new.project_id)
    .bind(new.user_id)
    .bind(new.technique)
    .bind(new.info.to_string())
    .bind(new.commit_sha)
    .bind(new.season)
    .bind(serde_json::to_string(&new.upload.provenance).unwrap_or_default())
    .bind(serde_json::to_string(&new.upload.metrics).unwrap_or_default())
    .bind(now)
    .bind(if new.publish { Some(now) } else { None })
    .execute(&mut **tx)
    .await?;
    // The season's first result measured on a named class names the season's.
    if let Some(class) = runner_class(&new.upload.provenance.machine) {
        let named = sqlx::query("UPDATE seasons SET runner_class = $1 WHERE number = $2 AND runner_class IS NULL")
            .bind(class)
            .bind(new.season)
            .execute(&mut **tx)
            .await?;
        if named.rows_affected() > 0 {
            boards_changed(&mut **tx).await?;
        }
    }
    for run in &new.upload.runs {
        let query = sqlx::query(
            "INSERT INTO result_runs (result_id, scene, spp, status, message, technique_ms, render_ms, wall_ms, cpu_ms, \
             peak_memory_bytes, used_samples, metric_values, image, log, repeats) \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15)",
        )
        .bind(&id)
        .bind(&run.scene)
        .bind(run.spp as i64);
        bind_summary(query, run)
            .bind(run.image.as_deref())
            .bind(Some(run.log.as_str()).filter(|l| !l.is_empty()))
            .bind((!run.repeats.is_empty()).then(|| serde_json::to_string(&run.repeats).unwrap_or_default()))
            .execute(&mut **tx)
            .await?;
    }
    for scene in &new.upload.scenes {
        sqlx::query(
            "INSERT INTO result_scenes (result_id, scene, tags, scene_hash, reference_hash) VALUES ($1, $2, $3, $4, $5)",
        )
        .bind(&id)
        .bind(&scene.name)
        .bind(serde_json::to_string(&scene.tags).unwrap_or_default())
        .bind(&scene.scene_hash)
        .bind(&scene.reference_hash)
        .execute(&mut **tx)
        .await?;
    }
    Ok(id)
}

/// `query` with a run's summary bound next: status, message, technique,
/// render, wall and CPU times, peak memory, samples used and values.
fn bind_summary<'q>(
    query: sqlx::query::Query<'q, sqlx::Any, sqlx::any::AnyArguments<'q>>,
    run: &'q IndexEntry,
) -> sqlx::query::Query<'q, sqlx::Any, sqlx::any::AnyArguments<'q>> {
    query
        .bind(run.status.as_str())
        .bind(&run.message)
        .bind(run.technique_ms)
        .bind(run.render_ms)
        .bind(run.wall_ms)
        .bind(run.cpu_ms)
        .bind(run.peak_memory_bytes as i64)
        .bind(run.used_samples as i64)
        .bind(serde_json::to_string(&run.metrics).unwrap_or_default())
}

/// Stores `run`'s repeats (more seeds, [`crate::seeds`]) and the summary
/// they make (status, values, times) in place of its row's.
pub async fn replace_repeats(tx: &mut sqlx::Transaction<'_, sqlx::Any>, run: &StoredRun) -> Result<(), sqlx::Error> {
    let entry = run.index_entry(&run.result_id);
    let query = sqlx::query(
        "UPDATE result_runs SET status = $1, message = $2, technique_ms = $3, render_ms = $4, wall_ms = $5, \
         cpu_ms = $6, peak_memory_bytes = $7, used_samples = $8, metric_values = $9, repeats = $10 \
         WHERE result_id = $11 AND scene = $12 AND spp = $13",
    );
    bind_summary(query, &entry)
        .bind(serde_json::to_string(&run.repeats).unwrap_or_default())
        .bind(&run.result_id)
        .bind(&run.scene)
        .bind(run.spp)
        .execute(&mut **tx)
        .await?;
    Ok(())
}

/// Records that what leaderboards show has changed (every server
/// instance reloads its cached boards).
pub async fn boards_changed<'e>(executor: impl sqlx::Executor<'e, Database = sqlx::Any>) -> Result<(), sqlx::Error> {
    sqlx::query("UPDATE board_version SET version = version + 1 WHERE id = 1").execute(executor).await?;
    Ok(())
}

/// The current board version. Read through [`SharedBoardVersion`], the one
/// reader, so that every page view shares it.
async fn board_version(pool: &AnyPool) -> Result<i64, sqlx::Error> {
    sqlx::query("SELECT version FROM board_version WHERE id = 1").fetch_one(pool).await?.try_get("version")
}

/// Reads of the board version shared by the callers asking at the same
/// time. Each caller gets the version from a read that began after it
/// asked, so it sees every change committed before then, on any instance,
/// as a read of its own would; but one query answers every caller that was
/// waiting when it began. Under load the board pages cost a query per
/// batch of readers instead of one each (SQLite has one connection), which
/// took the load benchmark's leaderboard page from 2 300–3 200 to
/// 4 000–4 800 req/s on two cores.
#[derive(Clone, Default)]
pub struct SharedBoardVersion(Arc<tokio::sync::Mutex<Option<(Instant, i64)>>>);

impl SharedBoardVersion {
    /// The board version as of a read that began after this call.
    pub async fn read(&self, pool: &AnyPool) -> Result<i64, sqlx::Error> {
        let asked = Instant::now();
        // Held across the query: callers arriving meanwhile wait for it to
        // end, then the first of them starts the next read for the rest.
        let mut last = self.0.lock().await;
        if let Some((began, version)) = *last {
            if began > asked {
                return Ok(version);
            }
        }
        let began = Instant::now();
        let version = board_version(pool).await?;
        *last = Some((began, version));
        Ok(version)
    }
}

/// One published set per project and season. By project, not by name: a
/// deleted project's published sets stay on the board, and whoever takes
/// its name again publishes beside them, never over them. A set whose
/// project is gone replaces nothing.
async fn unpublish_others(
    tx: &mut sqlx::Transaction<'_, sqlx::Any>,
    project_id: Option<&str>,
    season: i64,
) -> Result<(), sqlx::Error> {
    let Some(project_id) = project_id else { return Ok(()) };
    sqlx::query("UPDATE result_sets SET published_at = NULL WHERE project_id = $1 AND season = $2")
        .bind(project_id)
        .bind(season)
        .execute(&mut **tx)
        .await?;
    Ok(())
}

/// The result set `id` if `user_id` owns it: 404 for an invalid or unknown
/// UUID or another user's set (which it does not reveal).
pub async fn owned(pool: &AnyPool, id: &str, user_id: &str) -> Result<ResultSet, ServiceError> {
    let not_found = || ServiceError::not_found(format!("no result set {id:?} of yours"));
    if uuid::Uuid::parse_str(id).is_err() {
        return Err(ServiceError::invalid("invalid_uuid", format!("{id:?} is not a result UUID")));
    }
    match get(pool, id).await? {
        Some(set) if set.user_id.as_deref() == Some(user_id) => Ok(set),
        _ => Err(not_found()),
    }
}

/// Puts the set on its season's leaderboard, replacing its project's
/// previously published set there.
pub async fn publish(pool: &AnyPool, set: &ResultSet) -> Result<(), ServiceError> {
    if set.hidden_reason.is_some() {
        return Err(ServiceError::forbidden("hidden", "an administrator hid this result set; it cannot be published"));
    }
    let mut tx = pool.begin().await?;
    unpublish_others(&mut tx, set.project_id.as_deref(), set.season).await?;
    sqlx::query("UPDATE result_sets SET published_at = $1 WHERE id = $2")
        .bind(now_ms())
        .bind(&set.id)
        .execute(&mut *tx)
        .await?;
    boards_changed(&mut *tx).await?;
    tx.commit().await?;
    Ok(())
}

/// Takes the set off the leaderboard.
pub async fn unpublish(pool: &AnyPool, id: &str) -> Result<(), sqlx::Error> {
    sqlx::query("UPDATE result_sets SET published_at = NULL WHERE id = $1").bind(id).execute(pool).await?;
    boards_changed(pool).await
}

/// Deletes the set (rows and files).
pub async fn discard(pool: &AnyPool, data_dir: &std::path::Path, id: &str) -> Result<(), sqlx::Error> {
    sqlx::query("DELETE FROM result_sets WHERE id = $1").bind(id).execute(pool).await?;
    let _ = tokio::fs::remove_dir_all(files_dir(data_dir, id)).await;
    boards_changed(pool).await
}

/// Hides (with a reason) or shows again a set (administration).
pub async fn set_hidden(pool: &AnyPool, id: &str, reason: Option<&str>) -> Result<bool, sqlx::Error> {
    let done = sqlx::query("UPDATE result_sets SET hidden_reason = $1 WHERE id = $2")
        .bind(reason)
        .bind(id)
        .execute(pool)
        .await?;
    boards_changed(pool).await?;
    Ok(done.rows_affected() > 0)
}

/// Deletes a user's unpublished sets (with their account); published ones stay.
pub async fn discard_unpublished_of(
    pool: &AnyPool,
    data_dir: &std::path::Path,
    user_id: &str,
) -> Result<(), sqlx::Error> {
    let rows = sqlx::query("SELECT id FROM result_sets WHERE user_id = $1 AND published_at IS NULL")
        .bind(user_id)
        .fetch_all(pool)
        .await?;
    for row in rows {
        discard(pool, data_dir, &row.try_get::<String, _>("id")?).await?;
    }
    Ok(())
}

/// Where a stored set's files live.
pub fn files_dir(data_dir: &std::path::Path, id: &str) -> std::path::PathBuf {
    data_dir.join("results").join(id)
}

/// Where a job's uploads wait until the job succeeds.
pub fn staging_dir(data_dir: &std::path::Path, job_id: &str) -> std::path::PathBuf {
    data_dir.join("uploads").join(job_id)
}

/// The current (latest) season.
pub async fn current_season(pool: &AnyPool) -> Result<i64, sqlx::Error> {
    sqlx::query("SELECT MAX(number) AS n FROM seasons").fetch_one(pool).await?.try_get("n")
}

/// The runner class `season`'s times come from, once one is named.
pub async fn season_class(pool: &AnyPool, season: i64) -> Result<Option<String>, sqlx::Error> {
    let row =
        sqlx::query("SELECT runner_class FROM seasons WHERE number = $1").bind(season).fetch_optional(pool).await?;
    Ok(row.and_then(|r| r.try_get::<Option<String>, _>("runner_class").ok().flatten()))
}

/// The runner class a result's machine record names (`machine.class`,
/// written by fbksd-ci), if any.
pub fn runner_class(machine: &serde_json::Value) -> Option<&str> {
    machine["class"].as_str().filter(|c| !c.trim().is_empty())
}

/// Every season: (number, note, start).
pub async fn seasons(pool: &AnyPool) -> Result<Vec<(i64, String, i64)>, sqlx::Error> {
    let rows = sqlx::query("SELECT number, note, started_at FROM seasons ORDER BY number").fetch_all(pool).await?;
    rows.iter().map(|r| Ok((r.try_get("number")?, r.try_get("note")?, r.try_get("started_at")?))).collect()
}

/// Where the pixel files of references (or, with `buffer`, of a feature
/// buffer made with one) live: one per reference digest, shared by every
/// set scored against it, under the name a runner uploads it with
/// ([`fbksd_exchange::pixels::uploaded_reference_name`]).
pub fn reference_pixels(
    data_dir: &std::path::Path,
    reference_hash: &str,
    buffer: Option<&str>,
) -> Option<std::path::PathBuf> {
    fbksd_exchange::pixels::uploaded_reference_name(reference_hash, buffer).map(|name| data_dir.join(name))
}

/// Moves the references (and their feature buffers) a job uploaded among a
/// new set's files to the shared store (keeping a copy already there), and
/// drops the rest of `references/`.
pub async fn keep_references(data_dir: &std::path::Path, set_dir: &std::path::Path, upload: &Upload) {
    // Collected first: an iterator of closures held across the awaits below
    // would make the future not Send.
    let mut files: Vec<(&str, Option<&str>)> = Vec::new();
    for scene in &upload.scenes {
        files.push((&scene.reference_hash, None));
        files.extend(fbksd_exchange::scenes::FEATURE_BUFFERS.iter().map(|b| (scene.reference_hash.as_str(), Some(*b))));
    }
    for (hash, buffer) in files {
        let Some(name) = fbksd_exchange::pixels::uploaded_reference_name(hash, buffer) else {
            continue;
        };
        let (staged, store) = (set_dir.join(&name), data_dir.join(&name));
        if staged.is_file() && !store.is_file() {
            if let Some(parent) = store.parent() {
                let _ = tokio::fs::create_dir_all(parent).await;
            }
            if let Err(e) = tokio::fs::rename(&staged, &store).await {
                tracing::warn!("keeping reference {hash}: {e}");
            }
        }
    }
    let _ = tokio::fs::remove_dir_all(set_dir.join("references")).await;
}

/// The reference digest a set's scene was scored against.
pub async fn reference_hash(pool: &AnyPool, set_id: &str, scene: &str) -> Result<Option<String>, sqlx::Error> {
    let row = sqlx::query("SELECT reference_hash FROM result_scenes WHERE result_id = $1 AND scene = $2")
        .bind(set_id)
        .bind(scene)
        .fetch_optional(pool)
        .await?;
    row.map(|r| r.try_get("reference_hash")).transpose()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_shared_version_read_sees_every_change_committed_before_it_was_asked() {
        let dir = tempfile::tempdir().unwrap();
        let pool = crate::db::connect(&format!("sqlite://{}?mode=rwc", dir.path().join("db").display())).await.unwrap();
        let shared = SharedBoardVersion::default();
        // Other readers keep a read in flight nearly all the time, so a
        // reader that took one already begun would see a stale version.
        let readers: Vec<_> = (0..8)
            .map(|_| {
                let (shared, pool) = (shared.clone(), pool.clone());
                tokio::spawn(async move {
                    for _ in 0..300 {
                        shared.read(&pool).await.unwrap();
                    }
                })
            })
            .collect();
        for _ in 0..100 {
            boards_changed(&pool).await.unwrap();
            let committed = board_version(&pool).await.unwrap();
            assert!(shared.read(&pool).await.unwrap() >= committed, "a read older than version {committed}");
        }
        for reader in readers {
            reader.await.unwrap();
        }
    }
}
