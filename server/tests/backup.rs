//! `fbksd-server backup DIR`, taken while the service runs, restored with
//! `fbksd-server restore DIR` into an empty data directory (and database):
//! the restored service shows the same board, projects, private results,
//! repositories and scene references, to the same users and runners with
//! the same tokens; the backup is its owner's alone.

mod common;

use common::{json_of, push, spawn, technique_repository, Db, FakeRunner, TestServer};
use reqwest::Method;
use serde_json::json;
use std::process::Command;

/// `fbksd-server <args>` over `data` (and `database`, for PostgreSQL).
fn server_command(data: &std::path::Path, database: &str, args: &[&str]) -> String {
    let mut command = Command::new(env!("CARGO_BIN_EXE_fbksd-server"));
    for (key, _) in std::env::vars() {
        if key.starts_with("FBKSD_SERVER_") {
            command.env_remove(key);
        }
    }
    command.env("FBKSD_SERVER_DATA_DIR", data).env("FBKSD_SERVER_DATABASE_URL", database).args(args);
    let out = command.output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "fbksd-server {args:?}: {text}");
    text
}

on_both_databases!(a_backup_restored_into_an_empty_directory_serves_the_same_service, |db: Db| async move {
    let server = spawn(db).await;
    let ada = server.user("ada@example.org").await;
    let runner = FakeRunner::register(&server, "runner-1").await;
    let mut results = Vec::new();
    for (name, quality) in [("published", 1.0), ("private", 2.0)] {
        server.create_project(&ada, name, "private").await;
        let repo = technique_repository("box-filter-cpp");
        assert!(push(repo.path(), &server.clone_url(name, &ada.token), &["FBKSD_RUN"]).0);
        let job = runner.claim(5).await.expect("a benchmark");
        common::upload_results(&runner, &job, quality).await;
        let (status, done) = job.finish(&runner, json!({ "state": "succeeded" })).await;
        assert_eq!(status, 200, "{done}");
        results.push(done["result_id"].as_str().unwrap().to_string());
    }
    let publish = format!("{}/api/v1/results/{}/publish", server.url, results[0]);
    assert_eq!(ada.api(Method::POST, publish).send().await.unwrap().status(), 200);
    let board = |s: &TestServer| {
        let url = format!("{}/api/v1/leaderboard", s.url);
        async move { reqwest::get(url).await.unwrap().json::<serde_json::Value>().await.unwrap() }
    };
    let before = board(&server).await;
    assert_eq!(before["standings"].as_array().unwrap().len(), 1, "{before}");

    // Taken while the service runs; restored where nothing is.
    let backups = tempfile::tempdir().unwrap();
    let backup = backups.path().join("nightly");
    let data = &server.config().data_dir;
    server_command(data, &server.config().database_url.0, &["backup", &backup.to_string_lossy()]);
    let mode = |p: &std::path::Path| std::os::unix::fs::PermissionsExt::mode(&p.metadata().unwrap().permissions());
    assert_eq!(mode(&backup) & 0o777, 0o700, "password hashes and private repositories are the owner's alone");
    let restored = tempfile::tempdir().unwrap();
    let database = match db {
        Db::Sqlite => String::new(),
        Db::Postgres => common::fresh_postgres().await,
    };
    server_command(restored.path(), &database, &["restore", &backup.to_string_lossy()]);
    // A second restore into the same place is refused: it would mix two services.
    let mut again = Command::new(env!("CARGO_BIN_EXE_fbksd-server"));
    again.env("FBKSD_SERVER_DATA_DIR", restored.path()).env("FBKSD_SERVER_DATABASE_URL", &database);
    let again = again.args(["restore", &backup.to_string_lossy()]).output().unwrap();
    assert!(!again.status.success());
    assert!(String::from_utf8_lossy(&again.stderr).contains("restore into an empty one"));

    let mut config = server.config().clone();
    config.data_dir = restored.path().to_path_buf();
    config.database_url = fbksd_server::config::Secret(database);
    config.bind = "127.0.0.1:0".into();
    config.public_url = String::new();
    let app = fbksd_server::Application::build(config).await.expect("the restored service starts");
    let url = format!("http://127.0.0.1:{}", app.port());
    tokio::spawn(app.run());
    let copy = TestServer::at(url.clone(), restored.path().join("outbox"));

    assert_eq!(board(&copy).await, before, "the same board");
    // Ada's token, her private result and its files, her repository.
    let bearer = |path: String| reqwest::Client::new().get(format!("{url}{path}")).bearer_auth(&ada.token).send();
    let (status, set) = json_of(bearer(format!("/api/v1/results/{}", results[1])).await.unwrap()).await;
    assert_eq!((status, set["runs"].as_array().map(Vec::len)), (200, Some(4)), "{set}");
    let file = bearer(format!("/results/{}/files/sin-bands/4_0.png", results[1])).await.unwrap();
    assert_eq!(file.status(), 200);
    assert_eq!(&file.bytes().await.unwrap()[..], b"\x89PNG fake");
    let (status, projects) = json_of(bearer("/api/v1/projects".into()).await.unwrap()).await;
    assert_eq!((status, projects.as_array().map(Vec::len)), (200, Some(2)), "{projects}");
    let clone = tempfile::tempdir().unwrap();
    let cloned = common::git(clone.path(), &["clone", "-q", &copy.clone_url("private", &ada.token), "src"]);
    assert!(cloned.status.success(), "{}", String::from_utf8_lossy(&cloned.stderr));
    assert!(clone.path().join("src/CMakeLists.txt").is_file());
    // The scenes' references, which runners download before any job.
    let key = common::fake_reference_key("sin-bands");
    let reference = reqwest::Client::new()
        .get(format!("{url}/api/v1/runners/references/{key}/files/reference.exr"))
        .bearer_auth(&runner.token)
        .send()
        .await
        .unwrap();
    assert_eq!(reference.status(), 200, "a restored service hands out its stored references");
    assert_eq!(reference.bytes().await.unwrap().to_vec(), common::fake_reference("sin-bands").0);
});
