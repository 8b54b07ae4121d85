//! `fbksd-server backup DIR` and `fbksd-server restore DIR`: the database
//! and the files the service cannot make again (git repositories, result
//! files, the shared reference pixels), taken while the service runs.
//!
//! The database is copied first, consistently: SQLite by `VACUUM INTO`
//! (an online, transactional copy), PostgreSQL by `pg_dump`. The files are
//! copied after it, so every row of the copy finds its files (a set stored
//! meanwhile only leaves files no row names). Mail, uploads in progress and
//! the git hooks are left out: the outbox is the users', uploads belong to
//! jobs that a restored service runs again, and the hooks are written at
//! start. A restore goes into an empty data directory (and, for
//! PostgreSQL, an empty database) only: it never mixes two services.

use crate::config::Config;
use anyhow::{bail, Context};
use std::path::Path;

/// The folders of the data directory a backup holds.
const KEPT: [&str; 3] = ["git", "results", "references"];

/// What a backup directory says about itself.
#[derive(serde::Serialize, serde::Deserialize)]
struct Manifest {
    /// `sqlite` or `postgres`.
    database: String,
    /// When it was taken, Unix ms.
    taken_at: i64,
    /// The server that took it.
    fbksd_server: String,
}

const MANIFEST: &str = "fbksd-backup.json";
const SQLITE_FILE: &str = "fbksd.sqlite3";
const PG_FILE: &str = "fbksd.pgdump";

fn is_postgres(config: &Config) -> bool {
    config.database_url().starts_with("postgres")
}

/// Writes a backup of the service configured by `config` into `dir` (new, or empty).
pub async fn backup(config: &Config, dir: &Path) -> anyhow::Result<()> {
    if !config.data_dir.is_dir() {
        bail!(
            "there is no data directory at {}: give the service's own (FBKSD_SERVER_DATA_DIR)",
            config.data_dir.display()
        );
    }
    ensure_empty(dir).with_context(|| format!("backup directory {}", dir.display()))?;
    let url = config.database_url();
    let database = if is_postgres(config) {
        run("pg_dump", &["--format=custom", "--no-owner", "--file", &dir.join(PG_FILE).to_string_lossy(), &url])?;
        "postgres"
    } else {
        let pool = crate::db::connect(&url).await.context("the database")?;
        let target = dir.join(SQLITE_FILE).to_string_lossy().replace('\'', "''");
        sqlx::query(&format!("VACUUM INTO '{target}'")).execute(&pool).await.context("copying the database")?;
        "sqlite"
    };
    for name in KEPT {
        let from = config.data_dir.join(name);
        if from.exists() {
            copy_tree(&from, &dir.join("files").join(name))?;
        }
    }
    let manifest = Manifest {
        database: database.into(),
        taken_at: crate::now_ms(),
        fbksd_server: env!("CARGO_PKG_VERSION").into(),
    };
    std::fs::write(dir.join(MANIFEST), serde_json::to_vec_pretty(&manifest)?)?;
    Ok(())
}

/// Restores the backup in `dir` into the (empty) data directory and
/// database `config` names.
pub async fn restore(config: &Config, dir: &Path) -> anyhow::Result<()> {
    let manifest: Manifest = serde_json::from_slice(
        &std::fs::read(dir.join(MANIFEST)).with_context(|| format!("{} is not a backup", dir.display()))?,
    )
    .with_context(|| format!("{}", dir.join(MANIFEST).display()))?;
    let to_postgres = is_postgres(config);
    if manifest.database != if to_postgres { "postgres" } else { "sqlite" } {
        bail!("the backup holds a {} database; the configured one is not", manifest.database);
    }
    ensure_empty(&config.data_dir).with_context(|| {
        format!("data directory {}: restore into an empty one (or a new path)", config.data_dir.display())
    })?;
    let url = config.database_url();
    if to_postgres {
        let pool = crate::db::connect(&url).await.context("the database")?;
        let users: i64 = sqlx::Row::try_get(&sqlx::query("SELECT COUNT(*) FROM users").fetch_one(&pool).await?, 0)?;
        if users > 0 {
            bail!("the configured database already holds {users} users: restore into an empty one");
        }
        pool.close().await;
        run(
            "pg_restore",
            &["--clean", "--if-exists", "--no-owner", "--dbname", &url, &dir.join(PG_FILE).to_string_lossy()],
        )?;
    } else {
        std::fs::copy(dir.join(SQLITE_FILE), config.data_dir.join(SQLITE_FILE)).context("copying the database")?;
    }
    for name in KEPT {
        let from = dir.join("files").join(name);
        if from.exists() {
            copy_tree(&from, &config.data_dir.join(name))?;
        }
    }
    Ok(())
}

/// Creates `dir`, or checks that it holds nothing.
fn ensure_empty(dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    if std::fs::read_dir(dir)?.next().is_some() {
        bail!("it is not empty");
    }
    Ok(())
}

/// Copies a tree: directories, files, and links as links (never followed).
fn copy_tree(from: &Path, to: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(to).with_context(|| to.display().to_string())?;
    for entry in std::fs::read_dir(from).with_context(|| from.display().to_string())? {
        let entry = entry?;
        let (source, target) = (entry.path(), to.join(entry.file_name()));
        let kind = entry.file_type()?;
        if kind.is_dir() {
            copy_tree(&source, &target)?;
        } else if kind.is_symlink() {
            std::os::unix::fs::symlink(std::fs::read_link(&source)?, &target)?;
        } else {
            std::fs::copy(&source, &target).with_context(|| source.display().to_string())?;
        }
    }
    Ok(())
}

/// Runs a PostgreSQL tool; its error output names what failed.
fn run(program: &str, args: &[&str]) -> anyhow::Result<()> {
    let output = std::process::Command::new(program)
        .args(args)
        .output()
        .with_context(|| format!("cannot run {program} (PostgreSQL's client tools)"))?;
    if !output.status.success() {
        bail!("{program} failed: {}", String::from_utf8_lossy(&output.stderr).trim());
    }
    Ok(())
}
