//! References built once for the whole service.
//!
//! A reference is named by its key ([`fbksd_exchange::scenes::reference_key`]:
//! the renderer's version, the samples per pixel and the scene files'
//! digest), so every reference of one key is the same image. A runner that
//! lacks one asks for it ([`request`]): the first ask queues a `reference`
//! job in the same queue as benchmarks, owned by the service account
//! [`ACCOUNT`] in its private project [`PROJECT`]; runners that have the
//! scene claim such jobs before any other ([`crate::jobs::claim_reference`]),
//! make the reference and upload its files; when the job succeeds they are
//! kept under the data directory ([`store`]) and every runner downloads and
//! checks them instead of rendering. A failed job is retried by the next
//! ask.

use crate::accounts::{Email, User};
use crate::error::ServiceError;
use crate::jobs::{JobKind, JobState};
use crate::projects::Project;
use crate::{now_ms, AppState};
use fbksd_exchange::runner_api::{
    is_reference_file, is_sha256, ReferenceRequest, ReferenceState, ReferenceStatus, REFERENCE_IMAGE, REFERENCE_NOTE,
};
use sha2::{Digest, Sha256};
use sqlx::{AnyPool, Row};
use std::path::{Path, PathBuf};

/// The service account that owns reference jobs.
pub const ACCOUNT: &str = "references@localhost.localdomain";

/// The private project reference jobs belong to (a name users cannot take).
pub const PROJECT: &str = "scene-references";

/// Where the reference of `key` (`sha256:<64 hex digits>`) is kept, or
/// `None` when `key` is not such a key.
pub fn store_dir(data_dir: &Path, key: &str) -> Option<PathBuf> {
    let hex = key.strip_prefix("sha256:").filter(|_| is_sha256(key))?;
    Some(data_dir.join("scene-references").join(hex))
}

fn check_key(data_dir: &Path, key: &str) -> Result<PathBuf, ServiceError> {
    store_dir(data_dir, key).ok_or_else(|| {
        ServiceError::invalid("invalid_reference", format!("{key:?} is not a reference key (sha256:<64 hex digits>)"))
    })
}

/// Where the reference of `key` is on the service, if it was ever asked for.
pub async fn status(pool: &AnyPool, data_dir: &Path, key: &str) -> Result<Option<ReferenceStatus>, ServiceError> {
    let dir = check_key(data_dir, key)?;
    let row = sqlx::query(
        "SELECT sr.scene, sr.job_id, sr.reference_hash, j.state, j.message FROM scene_references sr \
         LEFT JOIN jobs j ON j.id = sr.job_id WHERE sr.key = $1",
    )
    .bind(key)
    .fetch_optional(pool)
    .await?;
    let Some(row) = row else { return Ok(None) };
    let reference_hash: Option<String> = row.try_get("reference_hash")?;
    let job_state: Option<String> = row.try_get("state")?;
    let state = match (&reference_hash, job_state.as_deref().and_then(JobState::parse)) {
        (Some(_), _) => ReferenceState::Ready,
        (None, Some(s)) if s.is_live() => ReferenceState::Building,
        _ => ReferenceState::Failed,
    };
    let files = match state {
        ReferenceState::Ready => stored_files(&dir).await,
        _ => Vec::new(),
    };
    Ok(Some(ReferenceStatus {
        key: key.to_string(),
        scene: row.try_get("scene")?,
        state,
        reference_hash,
        files,
        job_id: row.try_get("job_id")?,
        message: row.try_get::<Option<String>, _>("message")?.unwrap_or_default(),
    }))
}

async fn stored_files(dir: &Path) -> Vec<String> {
    let mut files = Vec::new();
    if let Ok(mut entries) = tokio::fs::read_dir(dir).await {
        while let Ok(Some(entry)) = entries.next_entry().await {
            let name = entry.file_name().to_string_lossy().into_owned();
            if is_reference_file(&name) {
                files.push(name);
            }
        }
    }
    files.sort();
    files
}

/// A runner's ask for the reference `request.key`: its status, after
/// queuing a reference job when none was ever queued or the last failed.
/// Safe when many runners ask at once: one job per key is queued.
pub async fn request(state: &AppState, request: &ReferenceRequest) -> Result<ReferenceStatus, ServiceError> {
    let data = &state.config.data_dir;
    check_key(data, &request.key)?;
    let scene = request.scene.trim();
    if scene.is_empty() || scene.len() > 200 || scene.chars().any(char::is_control) {
        return Err(ServiceError::invalid(
            "invalid_scene",
            format!("scene {:?} must be its directory under the scene root, 1 to 200 characters", request.scene),
        ));
    }
    let name = request.name.as_str();
    let max = fbksd_exchange::runner_api::limits::SCENE_NAME;
    if !fbksd_exchange::runner_api::is_plain_name(name, max) {
        return Err(ServiceError::invalid(
            "invalid_scene",
            format!(
                "scene name {name:?} must be 1 to {max} letters, digits, . - or _, as result sets name scenes \
                 (a runner that sends none is older than this server: upgrade it)"
            ),
        ));
    }
    name_scene(&state.pool, &request.key, name).await?;
    // Twice at most: a race lost to another ask finds that ask's job.
    for _ in 0..2 {
        let failed_job = match status(&state.pool, data, &request.key).await? {
            Some(s) if s.state != ReferenceState::Failed => return Ok(s),
            Some(s) => Some(s.job_id),
            None => None,
        };
        queue_job(state, &request.key, scene, failed_job.as_deref()).await?;
    }
    status(&state.pool, data, &request.key).await?.ok_or_else(|| ServiceError::internal("reference vanished"))
}

/// Names per reference key at most: two scenes may render the same files,
/// and no runner can grow the table without bound.
const NAMES_PER_KEY: i64 = 16;

/// Records that result sets may name the reference of `key` for scenes
/// called `name`.
async fn name_scene(pool: &AnyPool, key: &str, name: &str) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO scene_reference_names (key, name) \
         SELECT $1, $2 WHERE (SELECT COUNT(*) FROM scene_reference_names WHERE key = $1) < $3 \
         ON CONFLICT (key, name) DO NOTHING",
    )
    .bind(key)
    .bind(name)
    .bind(NAMES_PER_KEY)
    .execute(pool)
    .await?;
    Ok(())
}

/// Checks that every scene of a runner's upload names a reference the
/// service stores, asked for under that scene's name: a result set is
/// scored against the references every runner downloads, so an upload
/// cannot name an image no reference job made, or another scene's (the
/// leaderboard ranks each scene against the newest set's reference, so
/// either would take the scene's board from the other sets).
pub async fn check_upload(pool: &AnyPool, upload: &fbksd_exchange::runner_api::Upload) -> Result<(), ServiceError> {
    for (i, scene) in upload.scenes.iter().enumerate() {
        let at = format!("results: scenes[{i}] ({})", scene.name);
        let rows = sqlx::query(
            "SELECT sr.scene, (SELECT COUNT(*) FROM scene_reference_names n WHERE n.key = sr.key AND n.name = $2) \
             AS named FROM scene_references sr WHERE sr.reference_hash = $1",
        )
        .bind(&scene.reference_hash)
        .bind(&scene.name)
        .fetch_all(pool)
        .await?;
        if rows.is_empty() {
            return Err(ServiceError::invalid(
                "unknown_reference",
                format!(
                    "{at}: reference {} is not one the service stores: score runs against the references \
                     the service hands out (POST /api/v1/runners/references)",
                    scene.reference_hash
                ),
            ));
        }
        let (mut fits, mut made_for) = (false, Vec::new());
        for row in &rows {
            fits |= row.try_get::<i64, _>("named")? > 0;
            made_for.push(row.try_get::<String, _>("scene")?);
        }
        if !fits {
            return Err(ServiceError::invalid(
                "unknown_reference",
                format!(
                    "{at}: reference {} was made for {}, and no runner asked for it under the name {:?}",
                    scene.reference_hash,
                    made_for.join(", "),
                    scene.name
                ),
            ));
        }
    }
    Ok(())
}

/// Queues a reference job for `key`: a new row, or (`failed_job`) the
/// row's next job. Does nothing when another ask did it first.
async fn queue_job(state: &AppState, key: &str, scene: &str, failed_job: Option<&str>) -> Result<(), ServiceError> {
    let (user, project) = service_project(state).await?;
    let season = crate::results::current_season(&state.pool).await?;
    let (pipeline_id, job_id) = (uuid::Uuid::new_v4().to_string(), uuid::Uuid::new_v4().to_string());
    let message = format!("the reference of {scene}");
    let mut tx = state.pool.begin().await?;
    crate::pipelines::insert_pipeline(&mut tx, &pipeline_id, (&project.id, &user.id), (key, scene), "{}", "reference")
        .await?;
    let job = crate::jobs::NewJob {
        id: &job_id,
        pipeline_id: &pipeline_id,
        project_id: &project.id,
        user_id: &user.id,
        kind: JobKind::Reference,
        state: JobState::Queued,
        failure_reason: None,
        message: &message,
        max_attempts: state.config.max_attempts as i64,
        season,
        publish_on_success: false,
        counts_for_quota: false,
        finished_at: None,
        reference_key: Some(key),
        more_seeds: None,
        measures_again: None,
    };
    crate::jobs::insert(&mut tx, &job).await?;
    let claimed = match failed_job {
        None => sqlx::query(
            "INSERT INTO scene_references (key, scene, job_id, created_at) VALUES ($1, $2, $3, $4) \
             ON CONFLICT (key) DO NOTHING",
        )
        .bind(key)
        .bind(scene)
        .bind(&job_id)
        .bind(now_ms())
        .execute(&mut *tx)
        .await?
        .rows_affected(),
        Some(failed) => sqlx::query(
            "UPDATE scene_references SET job_id = $1 WHERE key = $2 AND job_id = $3 AND reference_hash IS NULL",
        )
        .bind(&job_id)
        .bind(key)
        .bind(failed)
        .execute(&mut *tx)
        .await?
        .rows_affected(),
    };
    if claimed == 0 {
        tx.rollback().await?;
        return Ok(());
    }
    tx.commit().await?;
    let again = if failed_job.is_some() { " (the last one failed)" } else { "" };
    crate::jobs::append_log(
        &state.pool,
        &job_id,
        0,
        &format!("[fbksd] reference {key} of {scene} queued{again}\n"),
        i64::MAX,
    )
    .await?;
    state.job_queued.notify_waiters();
    Ok(())
}

/// The service account and project reference jobs belong to, made on
/// first use. Asks racing to make them find them on a second try.
async fn service_project(state: &AppState) -> Result<(User, Project), ServiceError> {
    let mut tries = 0;
    loop {
        match try_service_project(state).await {
            Err(e) if e.code.ends_with("_taken") && tries < 5 => tries += 1,
            done => return done,
        }
        tokio::time::sleep(std::time::Duration::from_millis(50 * tries)).await;
    }
}

async fn try_service_project(state: &AppState) -> Result<(User, Project), ServiceError> {
    let user = crate::accounts::ensure_service_account(&state.pool, &Email::parse(ACCOUNT)?).await?;
    if let Some(project) = crate::projects::by_name(&state.pool, PROJECT).await? {
        if project.owner_id != user.id {
            return Err(ServiceError::conflict(
                "name_taken",
                format!("the project {PROJECT:?} belongs to a user, not to {ACCOUNT}: rename it to build references"),
            ));
        }
        return Ok((user, project));
    }
    Ok((user.clone(), crate::projects::create_for_service(state, &user, PROJECT).await?))
}

/// Keeps a succeeding reference job's uploads as the reference of its key,
/// after checking that they are whole and that the note's recipe makes that
/// key. Idempotent: a retry after a crash finds the files already moved.
pub async fn store(state: &AppState, job: &crate::jobs::Job) -> Result<(), ServiceError> {
    let data = &state.config.data_dir;
    let key = job.reference_key.as_deref().ok_or_else(|| ServiceError::internal("a reference job without a key"))?;
    let target = check_key(data, key)?;
    let staging = crate::results::staging_dir(data, &job.id);
    let source = if tokio::fs::try_exists(staging.join(REFERENCE_IMAGE)).await.unwrap_or(false) {
        staging.clone()
    } else {
        target.clone()
    };
    for name in [REFERENCE_IMAGE, REFERENCE_NOTE] {
        if !tokio::fs::try_exists(source.join(name)).await.unwrap_or(false) {
            return Err(ServiceError::conflict(
                "no_reference",
                format!("upload {REFERENCE_IMAGE} and {REFERENCE_NOTE} (PUT …/files/NAME) before reporting success"),
            ));
        }
    }
    let note = tokio::fs::read(source.join(REFERENCE_NOTE)).await.map_err(ServiceError::internal)?;
    let made = fbksd_exchange::scenes::note_reference_key(&note)
        .map_err(|e| ServiceError::invalid("invalid_output", format!("{REFERENCE_NOTE}: {e}")))?;
    if made != key {
        return Err(ServiceError::invalid(
            "invalid_output",
            format!("{REFERENCE_NOTE} describes the reference {made}, but the job makes {key}"),
        ));
    }
    if source == staging {
        if let Some(parent) = target.parent() {
            tokio::fs::create_dir_all(parent).await.map_err(ServiceError::internal)?;
        }
        let _ = tokio::fs::remove_dir_all(&target).await;
        tokio::fs::rename(&staging, &target).await.map_err(ServiceError::internal)?;
    }
    let image = tokio::fs::read(target.join(REFERENCE_IMAGE)).await.map_err(ServiceError::internal)?;
    let hash = format!("sha256:{:x}", Sha256::digest(&image));
    sqlx::query("UPDATE scene_references SET reference_hash = $1, finished_at = $2 WHERE key = $3")
        .bind(&hash)
        .bind(now_ms())
        .bind(key)
        .execute(&state.pool)
        .await?;
    let message = format!("reference {key} stored ({hash})");
    crate::jobs::end(&state.pool, &job.id, JobState::Succeeded, None, &message, false).await?;
    Ok(())
}

/// The stored file `name` of the reference `key`, once it is ready.
pub async fn file(pool: &AnyPool, data_dir: &Path, key: &str, name: &str) -> Result<PathBuf, ServiceError> {
    let dir = check_key(data_dir, key)?;
    if !is_reference_file(name) {
        return Err(ServiceError::invalid(
            "invalid_reference_file",
            format!("{name:?} is not a reference's file ({REFERENCE_IMAGE}, {REFERENCE_NOTE}, reference-<buffer>.exr)"),
        ));
    }
    let ready = status(pool, data_dir, key).await?.is_some_and(|s| s.state == ReferenceState::Ready);
    let path = dir.join(name);
    if !ready || !tokio::fs::try_exists(&path).await.unwrap_or(false) {
        return Err(ServiceError::not_found(format!("no file {name} of a stored reference {key}")));
    }
    Ok(path)
}
