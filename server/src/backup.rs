//! `fbksd-server backup DIR` and `fbksd-server restore DIR`: the database
//! and the files the service cannot make again (git repositories, result
//! files, the shared reference pixels, the scenes' references that runners
//! download), taken while the service runs.
//!
//! The database is copied first, consistently: SQLite by `VACUUM INTO`
//! (an online, transactional copy), PostgreSQL by `pg_dump`. The files are
//! copied after it, so every row of the copy finds its files (a set stored
//! meanwhile only leaves files no row names). Mail, uploads in progress and
//! the git hooks are left out: the outbox is the users', uploads belong to
//! jobs that a restored service runs again, and the hooks are written at
//! start. A restore goes into an empty data directory (and, for
//! PostgreSQL, an empty database) only: it never mixes two services.
//!
//! A backup holds password hashes and private repositories, so its folder
//! (like the data directory) is its owner's alone (`0700`), and the
//! database's password reaches `pg_dump` and `pg_restore` through their
//! environment, never their command line, which other users can read.

use crate::config::Config;
use anyhow::{bail, Context};
use std::path::Path;

/// The folders of the data directory a backup holds.
const KEPT: [&str; 4] = ["git", "results", "references", "scene-references"];

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
        let file = dir.join(PG_FILE).to_string_lossy().into_owned();
        run(postgres_tool("pg_dump", &url, &["--format=custom", "--no-owner", "--file", &file])?)?;
        "postgres"
    } else {
        let pool = crate::db::connect(&url).await.context("the database")?;
        let target = dir.join(SQLITE_FILE).to_string_lossy().replace('\'', "''");
        sqlx::query(&format!("VACUUM INTO '{target}'")).execute(&pool).await.context("copying the database")?;
        // Closed, not dropped: a dropped pool's maintenance task was seen
        // spinning at exit, and the command never ended (once in many runs).
        pool.close().await;
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
        let file = dir.join(PG_FILE).to_string_lossy().into_owned();
        run(postgres_tool("pg_restore", &url, &["--clean", "--if-exists", "--no-owner", &file])?)?;
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

/// Creates `dir`, or checks that it holds nothing, and makes it its
/// owner's alone: nothing copied into it is readable by other users,
/// whatever its own mode.
fn ensure_empty(dir: &Path) -> anyhow::Result<()> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::create_dir_all(dir)?;
    if std::fs::read_dir(dir)?.next().is_some() {
        bail!("it is not empty");
    }
    std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700))?;
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

/// The PostgreSQL client `program` with `args`, connected to the database
/// at `url`: the URL without its password on the command line (which every
/// local user can read), the password in `PGPASSWORD`.
fn postgres_tool(program: &str, url: &str, args: &[&str]) -> anyhow::Result<std::process::Command> {
    let mut command = std::process::Command::new(program);
    let parsed = reqwest::Url::parse(url).ok().filter(|u| u.password().is_some());
    match parsed {
        Some(mut url) => {
            // A URL's password is %-escaped; the tools take it as it is.
            let password = percent_encoding::percent_decode_str(url.password().unwrap_or_default());
            command.env("PGPASSWORD", password.decode_utf8_lossy().as_ref());
            url.set_password(None).map_err(|()| anyhow::anyhow!("database_url: {url} takes no password"))?;
            command.arg("--dbname").arg(url.as_str())
        }
        // No password in it (a socket, or a password file): as it is.
        None => command.arg("--dbname").arg(url),
    };
    command.args(args);
    Ok(command)
}

/// Runs a PostgreSQL tool; its error output names what failed.
fn run(mut command: std::process::Command) -> anyhow::Result<()> {
    let program = command.get_program().to_string_lossy().into_owned();
    let output = command.output().with_context(|| format!("cannot run {program} (PostgreSQL's client tools)"))?;
    if !output.status.success() {
        bail!("{program} failed: {}", String::from_utf8_lossy(&output.stderr).trim());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_database_password_stays_off_the_command_line() {
        let url = "postgres://fbksd:s%40cret%2Fpass@db.internal:5432/fbksd?sslmode=require";
        let command = postgres_tool("pg_dump", url, &["--format=custom"]).unwrap();
        let args: Vec<String> = command.get_args().map(|a| a.to_string_lossy().into_owned()).collect();
        assert!(args.iter().all(|a| !a.contains("cret")), "{args:?}");
        assert_eq!(args[..2], ["--dbname", "postgres://fbksd@db.internal:5432/fbksd?sslmode=require"]);
        let env: Vec<_> = command.get_envs().collect();
        assert_eq!(env, [(std::ffi::OsStr::new("PGPASSWORD"), Some(std::ffi::OsStr::new("s@cret/pass")))]);
        // A URL without a password (a local socket) is passed as it is.
        let socket = "postgres:///fbksd?host=/run/postgresql";
        let command = postgres_tool("pg_dump", socket, &[]).unwrap();
        assert_eq!(command.get_args().collect::<Vec<_>>(), ["--dbname", socket]);
        assert_eq!(command.get_envs().count(), 0);
    }
}
