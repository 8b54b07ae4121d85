//! Helpers of the runner's tests: the real server (in this process, or as
//! its own process), the real `fbksd-ci` binary, real Docker and real git.
//!
//! The images are built once per machine (`deploy/build-images.sh` from the
//! workspace's debug binaries; content-tagged, so later calls only check
//! them), and so are the references of the scenes used here.

#![allow(dead_code)]

#[path = "../../../server/tests/common/mod.rs"]
pub mod server;

pub use server::*;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The CI scene set: every renderer (procedural, Embree, Mitsuba 3),
/// closed-form and rendered references.
pub const CI_SCENES: &[&str] =
    &["experimental/sphere", "experimental/fireflies", "production-small/cornell-box", "experimental/spheres-sky"];

/// The renderers of this build as `deploy/serve.sh` gives them to its
/// runner: this build's binaries and fbksd-mitsuba on PATH, and the Python
/// SDK of this build on PYTHONPATH.
pub fn renderer_env() -> Vec<(&'static str, String)> {
    let path = std::env::var("PATH").unwrap_or_default();
    vec![
        ("PATH", format!("{}:{}:{path}", bin_dir().display(), workspace().join("renderers/mitsuba").display())),
        ("PYTHONPATH", fbksd_tests::python_path().display().to_string()),
    ]
}

/// The workspace root.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// Where cargo put the binaries (the debug build of the workspace).
pub fn bin_dir() -> PathBuf {
    Path::new(env!("CARGO_BIN_EXE_fbksd-ci")).parent().unwrap().to_path_buf()
}

fn locked(lock: &str, command: &mut Command) {
    let lock_file = bin_dir().join(lock);
    let program = command.get_program().to_owned();
    let args: Vec<_> = command.get_args().map(|a| a.to_owned()).collect();
    let envs: Vec<_> = command.get_envs().filter_map(|(k, v)| Some((k.to_owned(), v?.to_owned()))).collect();
    let out = Command::new("flock")
        .arg(&lock_file)
        .arg(&program)
        .args(&args)
        .envs(envs)
        .current_dir(workspace())
        .output()
        .expect("flock runs");
    assert!(
        out.status.success(),
        "{program:?} {args:?} failed:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Builds (or checks) the images from this build's binaries; the manifest.
pub fn images() -> PathBuf {
    let manifest = bin_dir().join("fbksd-test-images.json");
    let mut build = Command::new("bash");
    build.arg("deploy/build-images.sh").arg("--bin-dir").arg(bin_dir()).arg("--manifest").arg(&manifest);
    locked("fbksd-images.lock", &mut build);
    manifest
}

/// Makes the references of `scenes` that are missing.
pub fn references(scenes: &[&str]) {
    for scene in scenes {
        // Always asked: a current reference is kept, and only its missing
        // feature buffers are made.
        let dir = workspace().join("scenes").join(scene);
        let meta = fbksd_exchange::scenes::SceneMeta::load(&dir).unwrap();
        let mut make = Command::new(format!("fbksd-{}", meta.renderer));
        make.arg("reference").arg(&dir).envs(renderer_env());
        locked("fbksd-references.lock", &mut make);
    }
}

/// How a test runner is configured.
pub struct RunnerOptions<'a> {
    pub scenes: &'a [&'a str],
    pub spp: &'a str,
    pub run_timeout: &'a str,
    pub build_timeout: &'a str,
    pub memory_mib: u64,
    pub env: Vec<(&'a str, String)>,
    /// Run the runner as this (uid, gid) instead of the test's user.
    pub user: Option<(u32, u32)>,
    /// Its scene root (default: the workspace's scenes).
    pub scene_root: Option<PathBuf>,
}

impl Default for RunnerOptions<'_> {
    fn default() -> Self {
        RunnerOptions {
            scenes: &["experimental/fireflies"],
            spp: "1",
            run_timeout: "30s",
            build_timeout: "120s",
            memory_mib: 512,
            env: Vec::new(),
            user: None,
            scene_root: None,
        }
    }
}

/// An `fbksd-ci` process.
pub struct RunnerProcess {
    child: Option<Child>,
    pub work: PathBuf,
    log: PathBuf,
}

impl RunnerProcess {
    /// Starts `fbksd-ci` against `server_url`, keeping its state in `work`.
    pub fn start(server_url: &str, work: &Path, options: &RunnerOptions<'_>) -> RunnerProcess {
        std::fs::create_dir_all(work).unwrap();
        let log = work.with_extension("log");
        let mut command = Command::new(env!("CARGO_BIN_EXE_fbksd-ci"));
        command
            .arg("--server")
            .arg(server_url)
            .args(["--registration-token", REGISTRATION_TOKEN, "--name", "test-runner"])
            .arg("--work-dir")
            .arg(work)
            .arg("--images")
            .arg(bin_dir().join("fbksd-test-images.json"))
            .arg("--scene-root")
            .arg(options.scene_root.clone().unwrap_or_else(|| workspace().join("scenes")))
            .args(["--scene", &options.scenes.join(","), "--spp", options.spp])
            .args(["--run-timeout", options.run_timeout, "--build-timeout", options.build_timeout])
            .args(["--memory-mib", &options.memory_mib.to_string(), "--renderer-memory-mib", "2048"])
            .args(["--tmpfs-mib", "64", "--pids", "64", "--poll-seconds", "1"])
            .env("RUST_LOG", "info")
            .envs(renderer_env())
            .stdin(Stdio::null())
            .stdout(std::fs::File::create(&log).unwrap())
            .stderr(std::fs::File::options().append(true).open(&log).unwrap());
        for (k, v) in &options.env {
            command.env(k, v);
        }
        if let Some((uid, gid)) = options.user {
            use std::os::unix::process::CommandExt;
            std::os::unix::fs::chown(work, Some(uid), Some(gid)).unwrap();
            command.uid(uid).gid(gid).env("HOME", work);
        }
        RunnerProcess { child: Some(command.spawn().expect("fbksd-ci starts")), work: work.to_path_buf(), log }
    }

    /// What it printed so far.
    pub fn output(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Waits until its output contains `text`.
    pub fn wait_for_output(&self, text: &str, within: Duration) {
        let deadline = Instant::now() + within;
        while !self.output().contains(text) {
            assert!(Instant::now() < deadline, "the runner never printed {text:?}:\n{}", self.output());
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Kills it at once (SIGKILL: no clean-up).
    pub fn kill(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// Stops it as Ctrl-C does (SIGINT), and waits until it has exited.
    pub fn interrupt(&mut self, within: Duration) -> std::process::ExitStatus {
        let mut child = self.child.take().expect("the runner runs");
        // SAFETY: a signal to our own child, which has not been reaped.
        assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) }, 0);
        let deadline = Instant::now() + within;
        loop {
            if let Some(status) = child.try_wait().unwrap() {
                return status;
            }
            if Instant::now() >= deadline {
                let _ = child.kill();
                let _ = child.wait();
                panic!("the runner did not stop within {within:?} of Ctrl-C:\n{}", self.output());
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Its id on the server, once registered.
    pub fn id(&self) -> Option<String> {
        let text = std::fs::read_to_string(self.work.join("runner.json")).ok()?;
        let v: serde_json::Value = serde_json::from_str(&text).ok()?;
        v["id"].as_str().map(str::to_string)
    }
}

impl Drop for RunnerProcess {
    fn drop(&mut self) {
        self.kill();
        // What a killed runner left behind (its next start would remove it too).
        if let Some(id) = self.id() {
            let _ = Command::new("sh")
                .arg("-c")
                .arg(format!("docker ps -aq --filter label=org.fbksd.ci.runner={id} | xargs -r docker rm -f"))
                .output();
        }
    }
}

/// The containers (any state) carrying `label=value`.
pub fn containers_labelled(label: &str, value: &str) -> Vec<String> {
    let out = Command::new("docker")
        .args(["ps", "-aq", "--filter", &format!("label={label}={value}")])
        .output()
        .expect("docker runs");
    String::from_utf8_lossy(&out.stdout).lines().map(str::to_string).collect()
}

/// Waits until a container of job `id` is running (a benchmark's renderer
/// or technique, once the build has succeeded).
pub fn wait_for_running_container(id: &str, within: Duration) {
    let deadline = Instant::now() + within;
    loop {
        let out = Command::new("docker")
            .args(["ps", "-q", "--filter", &format!("label=org.fbksd.ci.job={id}"), "--filter", "status=running"])
            .output()
            .expect("docker runs");
        if !out.stdout.is_empty() {
            return;
        }
        assert!(Instant::now() < deadline, "no container of job {id} ran within {within:?}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A job as the API shows it.
pub async fn job(server: &TestServer, user: &TestUser, id: &str) -> serde_json::Value {
    let (status, body) =
        json_of(user.api(reqwest::Method::GET, format!("{}/api/v1/jobs/{id}", server.url)).send().await.unwrap()).await;
    assert_eq!(status, 200, "{body}");
    body
}

/// Waits until a job has ended; the job.
pub async fn finished_job(server: &TestServer, user: &TestUser, id: &str, within: Duration) -> serde_json::Value {
    let deadline = Instant::now() + within;
    loop {
        let job = job(server, user, id).await;
        if ["succeeded", "failed", "cancelled"].contains(&job["state"].as_str().unwrap_or("")) {
            return job;
        }
        assert!(Instant::now() < deadline, "job {id} did not end within {within:?}: {job}");
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
}

/// The job a push or pipeline started: the newest of the project's jobs with `kind`.
pub async fn newest_job(server: &TestServer, user: &TestUser, project: &str, kind: &str) -> String {
    let jobs = project_jobs(server, user, project).await;
    jobs.iter()
        .filter(|j| j["kind"] == kind)
        .max_by_key(|j| j["created_at"].as_i64())
        .unwrap_or_else(|| panic!("no {kind} job in {jobs:?}"))["id"]
        .as_str()
        .unwrap()
        .to_string()
}

/// The private results URL a benchmark job's log ends with.
pub fn private_results_url(log: &str) -> String {
    log.lines()
        .find_map(|l| l.split("private results: ").nth(1))
        .unwrap_or_else(|| panic!("no private results URL in the log:\n{log}"))
        .trim()
        .to_string()
}

/// A repository with the files `files` (path, content), committed on `main`.
pub fn repository_with(files: &[(&str, &str)]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for (path, text) in files {
        let path = dir.path().join(path);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }
    assert!(git(dir.path(), &["init", "-q", "-b", "main"]).status.success());
    commit_all(dir.path(), "first");
    dir
}
