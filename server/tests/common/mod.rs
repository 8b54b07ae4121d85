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
/// The password tests give the first administrator in place of its
/// one-time password ([`TestServer::admin`]).
pub const ADMIN_PASSWORD: &str = "the administrator's own password";

pub struct TestServer {
    pub url: String,
    /// Where `/metrics` is served, when `metrics_bind` is set.
    pub metrics_url: Option<String>,
    pub outbox: PathBuf,
    pub admin: Option<(String, String)>,
    config: Config,
    _data: Option<std::sync::Arc<tempfile::TempDir>>,
}

fn postgres_admin_url() -> String {
    std::env::var("FBKSD_TEST_POSTGRES_URL").unwrap_or_else(|_| "postgres://postgres@127.0.0.1:54329/postgres".into())
}

/// A fresh, empty PostgreSQL database; its URL.
pub async fn fresh_postgres() -> String {
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
    spawn_with(db, |_| {}).await
}

/// The runner registration token test servers are configured with.
pub const REGISTRATION_TOKEN: &str = "test-registration-token";

/// Starts a server over a fresh database of kind `db`, with `adjust`
/// applied to its configuration.
pub async fn spawn_with(db: Db, adjust: impl FnOnce(&mut Config)) -> TestServer {
    let data = tempfile::tempdir().unwrap();
    let database_url = match db {
        Db::Sqlite => String::new(),
        Db::Postgres => fresh_postgres().await,
    };
    let config = Config {
        bind: "127.0.0.1:0".into(),
        data_dir: data.path().to_path_buf(),
        database_url: Secret(database_url),
        runner_registration_token: Secret(REGISTRATION_TOKEN.into()),
        ..Config::default()
    };
    let mut config = config;
    adjust(&mut config);
    let outbox = config.outbox_dir();
    let app = fbksd_server::Application::build(config.clone()).await.expect("server starts");
    let url = format!("http://127.0.0.1:{}", app.port());
    let metrics_url = app.metrics_address().map(|a| format!("http://{a}"));
    let admin = app.admin_credentials().cloned();
    tokio::spawn(app.run());
    TestServer { url, metrics_url, outbox, admin, config, _data: Some(std::sync::Arc::new(data)) }
}

impl TestServer {
    /// A server started elsewhere (another process) at `url`, writing its mail to `outbox`.
    pub fn at(url: String, outbox: PathBuf) -> TestServer {
        TestServer { url, metrics_url: None, outbox, admin: None, config: Config::default(), _data: None }
    }

    /// A second server instance on the same database and data directory,
    /// as in a deployment with several instances behind a load balancer.
    pub async fn another_instance(&self) -> TestServer {
        let app = fbksd_server::Application::build(self.config.clone()).await.expect("second instance starts");
        let url = format!("http://127.0.0.1:{}", app.port());
        let metrics_url = app.metrics_address().map(|a| format!("http://{a}"));
        tokio::spawn(app.run());
        TestServer {
            url,
            metrics_url,
            outbox: self.outbox.clone(),
            admin: None,
            config: self.config.clone(),
            _data: self._data.clone(),
        }
    }

    /// The configuration the server was started with.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// A client with its own cookie jar (one browser).
    pub fn browser(&self) -> reqwest::Client {
        reqwest::Client::builder().cookie_store(true).build().unwrap()
    }

    /// The mails in the outbox sent to `to`, oldest first (RFC 5322 text,
    /// quoted-printable bodies decoded; 7-bit ones are as the file holds them).
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
        mails
            .into_iter()
            .map(|(_, m)| {
                if m.contains("Content-Transfer-Encoding: quoted-printable") {
                    decode_quoted_printable(&m)
                } else {
                    m
                }
            })
            .collect()
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

/// A verified, logged-in user: a browser with its session, the session's
/// CSRF token, and a personal access token for scripts and git.
pub struct TestUser {
    pub email: String,
    pub browser: reqwest::Client,
    pub csrf: String,
    pub token: String,
}

impl TestServer {
    /// Registers `email`, verifies it through the outbox, logs in and
    /// creates an access token.
    pub async fn user(&self, email: &str) -> TestUser {
        let browser = self.browser();
        let password = "a long enough password";
        let created = browser
            .post(format!("{}/api/v1/accounts", self.url))
            .json(&serde_json::json!({ "email": email, "password": password }))
            .send()
            .await
            .unwrap();
        assert_eq!(created.status(), 201);
        let link = self.link_in_mail(email, "/accounts/verify?token=");
        assert_eq!(browser.get(&link).send().await.unwrap().status(), 200);
        self.log_in(email, password, browser).await
    }

    /// Logs `email` in with `browser` and creates an access token.
    pub async fn log_in(&self, email: &str, password: &str, browser: reqwest::Client) -> TestUser {
        let login = browser.post(format!("{}/api/v1/sessions", self.url));
        let (_, session) =
            json_of(login.json(&serde_json::json!({ "email": email, "password": password })).send().await.unwrap())
                .await;
        let csrf = session["csrf_token"].as_str().expect("logged in").to_string();
        let create = browser.post(format!("{}/api/v1/tokens", self.url)).header("X-CSRF-Token", &csrf);
        let (_, token) = json_of(create.json(&serde_json::json!({ "name": "tests" })).send().await.unwrap()).await;
        TestUser { email: email.into(), browser, csrf, token: token["token"].as_str().unwrap().to_string() }
    }

    /// The administrator created at start, logged in, having replaced the
    /// one-time password first (as the server requires) with
    /// [`ADMIN_PASSWORD`].
    pub async fn admin(&self) -> TestUser {
        let (email, one_time) = self.admin.clone().expect("first start creates an administrator");
        let browser = self.browser();
        let log_in = |password: &str| {
            browser
                .post(format!("{}/api/v1/sessions", self.url))
                .json(&serde_json::json!({ "email": email, "password": password }))
                .send()
        };
        if log_in(ADMIN_PASSWORD).await.unwrap().status() != 200 {
            let (_, session) = json_of(log_in(&one_time).await.unwrap()).await;
            assert_eq!(session["user"]["must_change_password"], true, "{session}");
            let csrf = session["csrf_token"].as_str().expect("logged in with the one-time password");
            let change = browser
                .patch(format!("{}/api/v1/me", self.url))
                .header("X-CSRF-Token", csrf)
                .json(&serde_json::json!({ "current_password": one_time, "new_password": ADMIN_PASSWORD }));
            assert_eq!(change.send().await.unwrap().status(), 200, "the one-time password is replaced");
        }
        self.log_in(&email, ADMIN_PASSWORD, browser).await
    }

    /// The URL of a project's repository with `token` as the password.
    pub fn clone_url(&self, project: &str, token: &str) -> String {
        let host = self.url.trim_start_matches("http://");
        format!("http://git:{token}@{host}/git/{project}.git")
    }
}

impl TestServer {
    /// Creates a project as `user`; its JSON.
    pub async fn create_project(&self, user: &TestUser, name: &str, visibility: &str) -> serde_json::Value {
        let response = user
            .api(reqwest::Method::POST, format!("{}/api/v1/projects", self.url))
            .json(&serde_json::json!({ "name": name, "visibility": visibility }))
            .send()
            .await
            .unwrap();
        let (status, body) = json_of(response).await;
        assert_eq!(status, 201, "{body}");
        body
    }
}

/// An answer's status and JSON body (null if it has none).
pub async fn json_of(response: reqwest::Response) -> (u16, serde_json::Value) {
    let status = response.status().as_u16();
    (status, response.json().await.unwrap_or_default())
}

/// The jobs of a project, as its owner sees them in the API.
pub async fn project_jobs(server: &TestServer, user: &TestUser, name: &str) -> Vec<serde_json::Value> {
    let response = user.api(reqwest::Method::GET, format!("{}/api/v1/projects/{name}", server.url)).send().await;
    let (status, body) = json_of(response.unwrap()).await;
    assert_eq!(status, 200, "{body}");
    body["jobs"].as_array().unwrap().clone()
}

/// A job's whole log.
pub async fn log_text(server: &TestServer, user: &TestUser, job: &str) -> String {
    let response = user.api(reqwest::Method::GET, format!("{}/api/v1/jobs/{job}/log", server.url)).send().await;
    let (status, body) = json_of(response.unwrap()).await;
    assert_eq!(status, 200, "{body}");
    body["chunks"].as_array().unwrap().iter().map(|c| c["text"].as_str().unwrap()).collect()
}

impl TestUser {
    /// An API request with the user's access token.
    pub fn api(&self, method: reqwest::Method, url: String) -> reqwest::RequestBuilder {
        reqwest::Client::new().request(method, url).bearer_auth(&self.token)
    }
}

/// Runs git in `dir` without prompts or user configuration; its output.
pub fn git(dir: &std::path::Path, args: &[&str]) -> std::process::Output {
    std::process::Command::new("git")
        .current_dir(dir)
        .args(["-c", "user.name=Test", "-c", "user.email=test@example.org", "-c", "credential.helper="])
        .args(args)
        .env("GIT_TERMINAL_PROMPT", "0")
        .env("GIT_CONFIG_NOSYSTEM", "1")
        .env("HOME", dir)
        .output()
        .expect("git runs")
}

/// A local repository holding the SDK's example technique `name`
/// (`sdk/techniques/<name>`), committed on `main`.
pub fn technique_repository(name: &str) -> tempfile::TempDir {
    sdk_repository(&format!("techniques/{name}"))
}

/// A git repository holding a copy of the SDK folder `sdk/<path>` (one
/// level of files), committed on `main`.
pub fn sdk_repository(path: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let source = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../sdk").join(path);
    for entry in std::fs::read_dir(&source).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), dir.path().join(entry.file_name())).unwrap();
    }
    assert!(git(dir.path(), &["init", "-q", "-b", "main"]).status.success());
    commit_all(dir.path(), "first");
    dir
}

/// Commits every change in `dir`.
pub fn commit_all(dir: &std::path::Path, message: &str) {
    assert!(git(dir, &["add", "-A"]).status.success());
    let out = git(dir, &["commit", "-q", "--allow-empty", "-m", message]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// Pushes `main` of `dir` to `url` with push options; (success, stderr).
pub fn push(dir: &std::path::Path, url: &str, options: &[&str]) -> (bool, String) {
    let mut args = vec!["push", "--porcelain"];
    for option in options {
        args.extend(["-o", option]);
    }
    args.extend([url, "main"]);
    let out = git(dir, &args);
    (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned() + &String::from_utf8_lossy(&out.stdout))
}

/// A runner driven by the test through the real runner API.
pub struct FakeRunner {
    pub url: String,
    pub token: String,
    client: reqwest::Client,
}

/// A job a fake runner holds.
pub struct HeldJob {
    pub id: String,
    pub token: String,
    pub body: serde_json::Value,
}

impl FakeRunner {
    /// Registers a runner named `name`.
    pub async fn register(server: &TestServer, name: &str) -> FakeRunner {
        FakeRunner::register_with(server, name, REGISTRATION_TOKEN).await
    }

    /// Registers a runner named `name` with the server's registration token `token`.
    pub async fn register_with(server: &TestServer, name: &str, token: &str) -> FakeRunner {
        let client = reqwest::Client::new();
        let response = client
            .post(format!("{}/api/v1/runners", server.url))
            .json(&serde_json::json!({
                "registration_token": token,
                "name": name,
                "machine": { "cpu_model": "test CPU", "cores": 2 }
            }))
            .send()
            .await
            .unwrap();
        assert_eq!(response.status(), 201);
        let body: serde_json::Value = response.json().await.unwrap();
        FakeRunner { url: server.url.clone(), token: body["token"].as_str().unwrap().into(), client }
    }

    /// Claims a job, waiting up to `wait_seconds`.
    pub async fn claim(&self, wait_seconds: u64) -> Option<HeldJob> {
        self.claim_with(serde_json::json!({ "wait_seconds": wait_seconds })).await
    }

    /// Claims a job as the claim request `request` says (reference keys, …).
    pub async fn claim_with(&self, request: serde_json::Value) -> Option<HeldJob> {
        let response = self
            .client
            .post(format!("{}/api/v1/runners/jobs", self.url))
            .bearer_auth(&self.token)
            .json(&request)
            .send()
            .await
            .unwrap();
        match response.status().as_u16() {
            204 => None,
            200 => {
                let body: serde_json::Value = response.json().await.unwrap();
                Some(HeldJob {
                    id: body["job"]["id"].as_str().unwrap().into(),
                    token: body["token"].as_str().unwrap().into(),
                    body,
                })
            }
            other => panic!("claim answered {other}: {}", response.text().await.unwrap()),
        }
    }

    /// POSTs `body` to the runner API's `path` with the runner token; the answer.
    pub async fn post(&self, path: &str, body: serde_json::Value) -> (u16, serde_json::Value) {
        let response =
            self.client.post(format!("{}/api/v1/{path}", self.url)).bearer_auth(&self.token).json(&body).send().await;
        json_of(response.unwrap()).await
    }

    /// GETs the runner API's `path` with the runner token; the status and body.
    pub async fn get(&self, path: &str) -> (u16, Vec<u8>) {
        let response =
            self.client.get(format!("{}/api/v1/{path}", self.url)).bearer_auth(&self.token).send().await.unwrap();
        (response.status().as_u16(), response.bytes().await.unwrap().to_vec())
    }

    /// A request about `job` with `token` (usually the job's own).
    pub fn job_request(&self, method: reqwest::Method, job: &str, token: &str, tail: &str) -> reqwest::RequestBuilder {
        self.client.request(method, format!("{}/api/v1/jobs/{job}/{tail}", self.url)).bearer_auth(token)
    }
}

impl HeldJob {
    /// POSTs or PUTs `tail` of this job with its token; the status.
    pub async fn send(&self, runner: &FakeRunner, method: reqwest::Method, tail: &str, body: reqwest::Body) -> u16 {
        runner.job_request(method, &self.id, &self.token, tail).body(body).send().await.unwrap().status().as_u16()
    }

    /// Reports the end of the job; the answer's status and body.
    pub async fn finish(&self, runner: &FakeRunner, outcome: serde_json::Value) -> (u16, serde_json::Value) {
        let response = runner
            .job_request(reqwest::Method::POST, &self.id, &self.token, "finish")
            .json(&outcome)
            .send()
            .await
            .unwrap();
        (response.status().as_u16(), response.json().await.unwrap_or_default())
    }
}

/// The reference image a fake renderer makes of `scene` (bytes no one
/// reads as an EXR: the service only hashes and keeps them) and its hash.
pub fn fake_reference(scene: &str) -> (Vec<u8>, String) {
    let bytes = format!("the reference of {scene}").into_bytes();
    let hash = format!("sha256:{:x}", <sha2::Sha256 as sha2::Digest>::digest(&bytes));
    (bytes, hash)
}

/// A `sha256:<hex>` that stands for the files of `scene`.
pub fn fake_scene_hash(scene: &str) -> String {
    format!("sha256:{:x}", <sha2::Sha256 as sha2::Digest>::digest(format!("the files of {scene}")))
}

/// The key of [`fake_reference`] of `scene` (the recipe its note names).
pub fn fake_reference_key(scene: &str) -> String {
    fbksd_exchange::scenes::reference_key(FAKE_RENDERER, FAKE_SPP, &fake_scene_hash(scene))
}

const FAKE_RENDERER: &str = "fake-renderer 1";
const FAKE_SPP: u64 = 16;

/// Has the service store [`fake_reference`] of `scene` as a runner would
/// (asks for it, then makes it as the reference job it queues, unless it
/// is stored already), so result sets may be scored against it; its hash.
pub async fn stored_reference(runner: &FakeRunner, scene: &str) -> String {
    let (bytes, hash) = fake_reference(scene);
    let (generator, spp, digest) = (FAKE_RENDERER, FAKE_SPP, fake_scene_hash(scene));
    let key = fake_reference_key(scene);
    let ask = serde_json::json!({ "key": key, "scene": format!("fake/{scene}"), "name": scene });
    let (status, body) = runner.post("runners/references", ask).await;
    assert_eq!(status, 200, "{body}");
    if body["state"] == "ready" {
        assert_eq!(body["reference_hash"], hash.as_str(), "{body}");
        return hash;
    }
    let claim = serde_json::json!({ "wait_seconds": 5, "reference_keys": [key], "references_only": true });
    let job = runner.claim_with(claim).await.expect("the reference job just queued");
    let note = serde_json::json!({ "generator": generator, "samples_per_pixel": spp, "scene_digest": digest });
    for (name, file) in [("reference.exr", bytes), ("reference.json", note.to_string().into_bytes())] {
        assert_eq!(job.send(runner, reqwest::Method::PUT, &format!("files/{name}"), file.into()).await, 204, "{name}");
    }
    let (status, body) = job.finish(runner, serde_json::json!({ "state": "succeeded" })).await;
    assert_eq!(status, 200, "{body}");
    hash
}

/// Results a runner could upload: two scenes at 4 and 16 spp, metric
/// values scaled by `quality` (smaller is better), images named like the
/// SDK's results directory, scored against the scenes' [`fake_reference`]s
/// (which [`upload_results`] has the service store first).
pub fn results_upload(quality: f64) -> serde_json::Value {
    let mut runs = Vec::new();
    for (scene, base) in [("sin-bands", 0.01), ("defocus-checkerboard", 0.1)] {
        for spp in [4u64, 16] {
            runs.push(serde_json::json!({
                "technique": "t", "scene": scene, "spp": spp, "status": "ok", "message": "",
                "log": format!("{scene}/{spp}_0_log.json"), "image": format!("{scene}/{spp}_0.png"),
                "technique_ms": 12.5, "render_ms": 100.0, "used_samples": spp * 64 * 64,
                "metrics": { "MSE": base * quality / spp as f64, "SSIM": 1.0 - base * quality / spp as f64 }
            }));
        }
    }
    let scenes: Vec<serde_json::Value> = [
        ("sin-bands", vec!["procedural"]),
        ("defocus-checkerboard", vec!["procedural", "dof"]),
    ]
    .into_iter()
    .map(|(name, tags)| {
        let (scene_hash, reference_hash) = (fake_scene_hash(name), fake_reference(name).1);
        serde_json::json!({ "name": name, "tags": tags, "scene_hash": scene_hash, "reference_hash": reference_hash })
    })
    .collect();
    serde_json::json!({
        "runs": runs,
        "metrics": [
            { "acronym": "MSE", "name": "Mean squared error", "reference": "", "lower_is_better": true, "has_error_map": true },
            { "acronym": "SSIM", "name": "Structural similarity", "reference": "", "lower_is_better": false, "has_error_map": true }
        ],
        "scenes": scenes,
        "provenance": { "image_digest": "sha256:0123", "runner": "fake", "machine": { "cpu_model": "test CPU", "cores": 2 } }
    })
}

/// Uploads the files and results of [`results_upload`] for `job`.
pub async fn upload_results(runner: &FakeRunner, job: &HeldJob, quality: f64) {
    upload_results_on(runner, job, quality, serde_json::json!({ "cpu_model": "test CPU", "cores": 2 })).await;
}

/// [`upload_results`], measured on `machine` (its provenance's record of the runner's machine).
pub async fn upload_results_on(runner: &FakeRunner, job: &HeldJob, quality: f64, machine: serde_json::Value) {
    let mut upload = results_upload(quality);
    upload["provenance"]["machine"] = machine;
    for scene in upload["scenes"].as_array().unwrap() {
        stored_reference(runner, scene["name"].as_str().unwrap()).await;
    }
    for run in upload["runs"].as_array().unwrap() {
        let name = run["image"].as_str().unwrap();
        let status =
            job.send(runner, reqwest::Method::PUT, &format!("files/{name}"), b"\x89PNG fake".to_vec().into()).await;
        assert_eq!(status, 204, "upload of {name}");
    }
    let status = job.send(runner, reqwest::Method::PUT, "results", upload.to_string().into()).await;
    assert_eq!(status, 204);
}

/// A scene of [`Pictured`] results (scored against its [`stored_reference`]).
pub struct PicturedScene<'a> {
    pub name: &'a str,
    pub tags: &'a [&'a str],
}

/// The albedo buffer [`upload_pictured`] sends with scene `scene`'s
/// reference: x / width in red, y / height in green, the scene's number
/// over 4 in blue.
pub fn albedo((w, h): (u32, u32), scene: usize) -> Vec<f32> {
    (0..w * h).flat_map(|p| [(p % w) as f32 / w as f32, (p / w) as f32 / h as f32, scene as f32 / 4.0]).collect()
}

/// One technique's results with real pixel files, as the runner uploads
/// them: per scene and spp the viewer's pixel file, the image, its record,
/// the technique's log and an MSE error map; MSE and PSNR values.
pub struct Pictured<'a> {
    pub technique: &'a str,
    pub scenes: &'a [PicturedScene<'a>],
    pub spps: &'a [u64],
    pub size: (u32, u32),
    /// A scene's reference (interleaved RGB).
    pub reference: &'a dyn Fn(usize) -> Vec<f32>,
    /// The technique's image of a scene at an spp.
    pub image: &'a dyn Fn(usize, u64) -> Vec<f32>,
    pub mse: &'a dyn Fn(usize, u64) -> f64,
    pub technique_ms: &'a dyn Fn(usize, u64) -> f64,
    /// The bytes uploaded as the run's EXR.
    pub exr: &'a dyn Fn(&[f32]) -> Vec<u8>,
}

/// Uploads `p` for `job` (references only where the server lacks them) and
/// reports success; the result set's UUID and how many references were sent.
pub async fn upload_pictured(runner: &FakeRunner, job: &HeldJob, p: &Pictured<'_>) -> (String, usize) {
    let put = |name: String, bytes: Vec<u8>| async move {
        assert_eq!(job.send(runner, reqwest::Method::PUT, &format!("files/{name}"), bytes.into()).await, 204, "{name}");
    };
    let (w, h) = p.size;
    let mut map = Vec::new();
    image::RgbImage::from_pixel(w, h, image::Rgb([200, 30, 30]))
        .write_to(&mut std::io::Cursor::new(&mut map), image::ImageFormat::Png)
        .unwrap();
    let mut runs = Vec::new();
    for (s, scene) in p.scenes.iter().enumerate() {
        for &spp in p.spps {
            let dir = format!("{}/{}", p.technique, scene.name);
            let image = (p.image)(s, spp);
            put(format!("{dir}/{spp}_0.fbpx"), fbksd_exchange::pixels::encode(w, h, 3, &image)).await;
            put(format!("{dir}/{spp}_0.exr"), (p.exr)(&image)).await;
            put(format!("{dir}/{spp}_0_log.json"), b"{}".to_vec()).await;
            put(format!("{dir}/{spp}_0_technique.log"), format!("{} at {spp} spp\n", p.technique).into_bytes()).await;
            put(format!("{dir}/{spp}_0_MSE_map.png"), map.clone()).await;
            let mse = (p.mse)(s, spp);
            let technique_ms = (p.technique_ms)(s, spp);
            runs.push(serde_json::json!({
                "technique": p.technique, "scene": scene.name, "spp": spp, "status": "ok", "message": "",
                "log": format!("{dir}/{spp}_0_log.json"), "image": format!("{dir}/{spp}_0.exr"),
                "technique_ms": technique_ms, "render_ms": 10.0 * spp as f64,
                "wall_ms": technique_ms + 10.0 * spp as f64, "cpu_ms": 3.0 * spp as f64, "peak_memory_bytes": 12 << 20,
                "used_samples": spp * (w * h) as u64,
                "metrics": { "MSE": mse, "PSNR": -10.0 * mse.log10() }
            }));
        }
    }
    let mut hashes = Vec::new();
    for scene in p.scenes {
        hashes.push(stored_reference(runner, scene.name).await);
    }
    let mut sent = 0;
    for (s, hash) in hashes.iter().enumerate() {
        let held =
            runner.job_request(reqwest::Method::GET, &job.id, &job.token, &format!("references/{hash}")).send().await;
        match held.unwrap().status().as_u16() {
            204 => {}
            404 => {
                let name = format!("references/{}.fbpx", hash.trim_start_matches("sha256:"));
                put(name, fbksd_exchange::pixels::encode(w, h, 3, &(p.reference)(s))).await;
                sent += 1;
            }
            other => panic!("asking for reference {hash}: {other}"),
        }
    }
    // The albedo buffer made with each reference, also once per reference.
    for (s, hash) in hashes.iter().enumerate() {
        let path = format!("references/{hash}?buffer=albedo");
        let held = runner.job_request(reqwest::Method::GET, &job.id, &job.token, &path).send().await;
        match held.unwrap().status().as_u16() {
            204 => {}
            404 => {
                let name = format!("references/{}.albedo.fbpx", hash.trim_start_matches("sha256:"));
                put(name, fbksd_exchange::pixels::encode(w, h, 3, &albedo(p.size, s))).await;
            }
            other => panic!("asking for the albedo buffer of reference {hash}: {other}"),
        }
    }
    let upload = serde_json::json!({
        "runs": runs,
        "metrics": [
            { "acronym": "MSE", "name": "Mean squared error", "reference": "", "lower_is_better": true, "has_error_map": true },
            { "acronym": "PSNR", "name": "Peak signal-to-noise ratio", "reference": "", "lower_is_better": false, "has_error_map": false }
        ],
        "scenes": p.scenes.iter().zip(&hashes).map(|(s, hash)| serde_json::json!({
            "name": s.name, "tags": s.tags, "scene_hash": fake_scene_hash(s.name), "reference_hash": hash
        })).collect::<Vec<_>>(),
        "provenance": { "runner": "fake" }
    });
    assert_eq!(job.send(runner, reqwest::Method::PUT, "results", upload.to_string().into()).await, 204);
    let (status, body) = job.finish(runner, serde_json::json!({ "state": "succeeded" })).await;
    assert_eq!(status, 200, "{body}");
    (body["result_id"].as_str().unwrap().to_string(), sent)
}

/// A program started by a test, with everything it prints (stdout and
/// stderr, line by line) collected as it goes.
pub struct Captured {
    pub child: std::process::Child,
    output: std::sync::Arc<std::sync::Mutex<String>>,
}

impl Captured {
    /// Starts `command` with its output piped and collected.
    pub fn spawn(mut command: std::process::Command) -> Captured {
        use std::io::BufRead;
        let mut child = command
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("{:?} starts: {e}", command.get_program()));
        let output = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
        for stream in [
            Box::new(child.stdout.take().unwrap()) as Box<dyn std::io::Read + Send>,
            Box::new(child.stderr.take().unwrap()),
        ] {
            let output = output.clone();
            std::thread::spawn(move || {
                for line in std::io::BufReader::new(stream).lines().map_while(Result::ok) {
                    output.lock().unwrap().push_str(&(line + "\n"));
                }
            });
        }
        Captured { child, output }
    }

    /// What it printed so far.
    pub fn output(&self) -> String {
        self.output.lock().unwrap().clone()
    }

    /// The first printed line containing `text`, waiting up to `within` for it.
    pub fn line_with(&self, text: &str, within: std::time::Duration) -> String {
        let deadline = std::time::Instant::now() + within;
        loop {
            if let Some(line) = self.output().lines().find(|l| l.contains(text)) {
                return line.to_string();
            }
            assert!(std::time::Instant::now() < deadline, "never printed {text:?}:\n{}", self.output());
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
    }
}

/// One test body, run once on SQLite and once on PostgreSQL.
#[macro_export]
macro_rules! on_both_databases {
    ($name:ident, $body:expr) => {
        mod $name {
            use super::*;
            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
            async fn sqlite() {
                ($body)(common::Db::Sqlite).await
            }
            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
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

/// Sends `method path` with a body of `length` zero bytes, a megabyte at a
/// time, as a client that never holds it whole; the answer's status (the
/// server may answer and close before the body is all sent).
pub async fn send_zeros(url: &str, method: &str, path: &str, length: u64, headers: &str) -> u16 {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let host = url.trim_start_matches("http://");
    let mut stream = tokio::net::TcpStream::connect(host).await.unwrap();
    let head = format!(
        "{method} {path} HTTP/1.1\r\nHost: {host}\r\nContent-Length: {length}\r\n{headers}Connection: close\r\n\r\n"
    );
    stream.write_all(head.as_bytes()).await.unwrap();
    let zeros = vec![0u8; 1 << 20];
    let mut left = length;
    while left > 0 {
        let n = left.min(zeros.len() as u64) as usize;
        if stream.write_all(&zeros[..n]).await.is_err() {
            break;
        }
        left -= n as u64;
    }
    let mut answer = Vec::new();
    let _ = stream.read_to_end(&mut answer).await;
    let answer = String::from_utf8_lossy(&answer);
    answer.split(' ').nth(1).and_then(|code| code.parse().ok()).unwrap_or_else(|| panic!("no answer: {answer:?}"))
}

/// Sends a v0 `git-upload-pack` request for `commit` as a client that reads
/// the answer's headers and then nothing more (a slow clone); the status
/// and the connection, held open.
pub async fn slow_clone(url: &str, project: &str, commit: &str) -> (u16, tokio::net::TcpStream) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let host = url.trim_start_matches("http://");
    let mut stream = tokio::net::TcpStream::connect(host).await.unwrap();
    let body = format!("0032want {commit}\n00000009done\n");
    let head = format!(
        "POST /git/{project}.git/git-upload-pack HTTP/1.1\r\nHost: {host}\r\n\
         Content-Type: application/x-git-upload-pack-request\r\nContent-Length: {}\r\n\r\n",
        body.len()
    );
    stream.write_all((head + &body).as_bytes()).await.unwrap();
    let mut answer = Vec::new();
    while !answer.ends_with(b"\r\n\r\n") {
        let mut byte = [0u8];
        assert_eq!(stream.read(&mut byte).await.unwrap(), 1, "closed before its headers: {answer:?}");
        answer.push(byte[0]);
    }
    let status = String::from_utf8_lossy(&answer).split(' ').nth(1).unwrap().parse().unwrap();
    (status, stream)
}

/// The SDK's C++ box filter with 32 MiB of random bytes beside it, committed
/// on `main`: a pack larger than every buffer between git and a client
/// that stops reading (pipe, sockets, the server's own), since random
/// bytes do not compress.
pub fn repository_too_big_to_buffer() -> tempfile::TempDir {
    let repo = technique_repository("box-filter-cpp");
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let noise: Vec<u8> = (0..32 << 20)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state as u8
        })
        .collect();
    std::fs::write(repo.path().join("weights.bin"), noise).unwrap();
    commit_all(repo.path(), "weights");
    repo
}

/// The value of the sample `name{labels}` in a scrape.
pub fn sample(metrics: &str, series: &str) -> Option<f64> {
    metrics.lines().find_map(|l| l.strip_prefix(series)?.strip_prefix(' ')?.trim().parse().ok())
}

/// The process's peak resident memory so far, in bytes (`VmHWM`): the
/// server's and the test's together (nextest runs each test in its own process).
pub fn peak_memory() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with("VmHWM:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse::<u64>().unwrap() << 10
}

/// Incompressible bytes: a pack holds them as they are.
pub fn noise(len: usize, mut x: u64) -> Vec<u8> {
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}
