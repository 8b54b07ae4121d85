//! Test helpers: a server on port 0 over a fresh database — SQLite in a
//! temporary directory, or a new database on the PostgreSQL server that
//! `deploy/setup.sh` starts (127.0.0.1:54329, or `FBKSD_TEST_POSTGRES_URL`).

#![allow(dead_code)]

use fbksd_server::config::{Config, Secret};
use std::path::PathBuf;

/// Which database a test runs against.
#[derive(Debug, Clone, Copy)]
pub enum Db {
    Sqlite,
    Postgres,
}

/// A running server and what a test needs to drive it.
pub struct TestServer {
    pub url: String,
    pub outbox: PathBuf,
    pub admin: Option<(String, String)>,
    _data: tempfile::TempDir,
}

fn postgres_admin_url() -> String {
    std::env::var("FBKSD_TEST_POSTGRES_URL").unwrap_or_else(|_| "postgres://postgres@127.0.0.1:54329/postgres".into())
}

/// A fresh, empty PostgreSQL database; its URL.
async fn fresh_postgres() -> String {
    use sqlx::Connection;
    let admin = postgres_admin_url();
    let mut conn = sqlx::PgConnection::connect(&admin).await.unwrap_or_else(|e| {
        panic!("PostgreSQL at {admin}: {e} (deploy/setup.sh starts it; or set FBKSD_TEST_POSTGRES_URL)")
    });
    let name = format!("fbksd_test_{}", uuid::Uuid::new_v4().simple());
    sqlx::query(&format!("CREATE DATABASE {name}")).execute(&mut conn).await.unwrap();
    let (base, _) = admin.rsplit_once('/').unwrap();
    format!("{base}/{name}")
}

/// Starts a server over a fresh database of kind `db`.
pub async fn spawn(db: Db) -> TestServer {
    let data = tempfile::tempdir().unwrap();
    let database_url = match db {
        Db::Sqlite => String::new(),
        Db::Postgres => fresh_postgres().await,
    };
    let config = Config {
        bind: "127.0.0.1:0".into(),
        data_dir: data.path().to_path_buf(),
        database_url: Secret(database_url),
        ..Config::default()
    };
    let outbox = config.outbox_dir();
    let app = fbksd_server::Application::build(config).await.expect("server starts");
    let url = format!("http://127.0.0.1:{}", app.port());
    let admin = app.admin_credentials().cloned();
    tokio::spawn(app.run());
    TestServer { url, outbox, admin, _data: data }
}

impl TestServer {
    /// A client with its own cookie jar (one browser).
    pub fn browser(&self) -> reqwest::Client {
        reqwest::Client::builder().cookie_store(true).build().unwrap()
    }

    /// The mails in the outbox sent to `to`, oldest first (RFC 5322 text,
    /// quoted-printable bodies decoded).
    pub fn mails_to(&self, to: &str) -> Vec<String> {
        let mut mails: Vec<(std::time::SystemTime, String)> = std::fs::read_dir(&self.outbox)
            .map(|d| d.filter_map(|e| e.ok()).map(|e| e.path()).collect::<Vec<_>>())
            .unwrap_or_default()
            .into_iter()
            .filter(|p| p.extension().is_some_and(|e| e == "eml"))
            .filter_map(|p| Some((std::fs::metadata(&p).ok()?.modified().ok()?, std::fs::read_to_string(&p).ok()?)))
            .filter(|(_, text)| text.lines().any(|l| l.starts_with("To:") && l.contains(to)))
            .collect();
        mails.sort_by_key(|(t, _)| *t);
        mails.into_iter().map(|(_, m)| decode_quoted_printable(&m)).collect()
    }

    /// The first URL in the latest mail to `to` that contains `path`.
    pub fn link_in_mail(&self, to: &str, path: &str) -> String {
        let mails = self.mails_to(to);
        let mail = mails.last().unwrap_or_else(|| panic!("no mail to {to} in {}", self.outbox.display()));
        mail.split_whitespace()
            .find(|w| w.starts_with("http") && w.contains(path))
            .unwrap_or_else(|| panic!("no {path} link in:\n{mail}"))
            .to_string()
    }
}

/// One test body, run once on SQLite and once on PostgreSQL.
#[macro_export]
macro_rules! on_both_databases {
    ($name:ident, $body:expr) => {
        mod $name {
            use super::*;
            #[tokio::test]
            async fn sqlite() {
                ($body)(common::Db::Sqlite).await
            }
            #[tokio::test]
            async fn postgres() {
                ($body)(common::Db::Postgres).await
            }
        }
    };
}

/// Undoes quoted-printable: soft line breaks and `=XX` escapes (enough for
/// the ASCII mails the server sends; headers pass through unchanged).
fn decode_quoted_printable(text: &str) -> String {
    let joined = text.replace("=\r\n", "").replace("=\n", "");
    let bytes = joined.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = bytes.get(i + 1..i + 3).and_then(|h| u8::from_str_radix(std::str::from_utf8(h).ok()?, 16).ok());
        match (bytes[i], hex) {
            (b'=', Some(b)) => {
                out.push(b);
                i += 3;
            }
            (b, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}
