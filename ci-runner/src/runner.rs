//! A runner's life: identity, the claim loop, heartbeats and clean-up.
//!
//! - **Identity.** The runner registers once with the server's
//!   registration token and keeps its id and token in
//!   `<work dir>/runner.json` (mode 0600).
//! - **Docker first.** No job is claimed while Docker does not answer, so
//!   a runner without Docker never takes a job it cannot do; a job whose
//!   containers fail to start ends `infrastructure_error`, which the server
//!   queues again.
//! - **One job at a time** on pinned cores, so timings are comparable.
//! - **Heartbeats** every third of the lease. A 410 means the job is no
//!   longer this runner's: its containers are removed and nothing new starts.
//! - **Clean-up.** After every job, its containers and files are removed;
//!   at start, whatever a killed predecessor left (containers with this
//!   runner's label, job directories, rendezvous directories). A runner
//!   stopped mid-job (Ctrl-C, TERM) cancels the job, so its benchmark
//!   starts no new run, removes its containers, and waits for the
//!   benchmark's thread to end before a last removal, so none is left.

use crate::api::{Api, ApiError};
use crate::calibration::Calibration;
use crate::images::Images;
use crate::job::{self, Failure, JobContext, JobLog};
use crate::machine::Machine;
use crate::sandbox::Sandbox;
use crate::RunnerConfig;
use bollard::Docker;
use fbksd_exchange::runner_api::{Claim, ClaimRequest, JobKind, Outcome, RunnerCredentials};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// A registered runner, ready to claim jobs.
#[derive(Debug)]
pub struct Runner {
    ctx: JobContext,
    credentials: RunnerCredentials,
    /// The scenes' reference keys: this runner makes (or uploads) those references for the service.
    references: Vec<crate::references::SceneReference>,
}

/// Connects to Docker (as `DOCKER_HOST` says, or the local socket) and
/// checks that it answers.
pub async fn connect_docker() -> Result<Docker, String> {
    let docker = Docker::connect_with_local_defaults().map_err(|e| e.to_string())?;
    let docker = docker.negotiate_version().await.map_err(|e| e.to_string())?;
    docker.ping().await.map_err(|e| e.to_string())?;
    Ok(docker)
}

/// Waits until Docker answers, saying so (here and to the server) every 5 seconds.
async fn wait_for_docker(api: &Api, runner_token: &str) -> Docker {
    loop {
        match connect_docker().await {
            Ok(docker) => return docker,
            Err(e) => {
                let host = std::env::var("DOCKER_HOST").unwrap_or_else(|_| "unix:///var/run/docker.sock".into());
                tracing::error!(
                    "Docker is unavailable at {host} ({e}); this runner claims no job until it answers (retrying every 5 s)"
                );
                let _ = api.status(runner_token, Some(&format!("waiting for Docker at {host}"))).await;
                tokio::time::sleep(Duration::from_secs(5)).await;
            }
        }
    }
}

impl Runner {
    /// Registers (or reloads its identity), waits for Docker, checks the
    /// images and the scene pool, and removes what a previous run left.
    pub async fn start(mut config: RunnerConfig) -> anyhow::Result<Runner> {
        std::fs::create_dir_all(&config.work_dir)?;
        // Docker mounts need absolute paths.
        config.work_dir = std::fs::canonicalize(&config.work_dir)?;
        config.scene_root = std::fs::canonicalize(&config.scene_root)
            .map_err(|e| anyhow::anyhow!("scene root {}: {e}", config.scene_root.display()))?;
        let api = Api::new(&config.server);
        let machine = Machine::probe(config.cpus.as_deref(), config.cpu_quota);
        let calibration = calibrate(&machine).await;
        // Registered first, so the server can show what is being prepared.
        let credentials = identity(&config, &api, &machine.record(&calibration)).await?;
        let scene_dirs = config.scene_dirs()?;
        let prepared = async {
            let references = crate::references::keys(&config.scene_root, &scene_dirs).await?;
            crate::references::prepare(&config.scene_root, &references, &api, &credentials.token).await?;
            Ok::<_, anyhow::Error>((crate::pool::load(&config.scene_root, &scene_dirs)?, references))
        };
        let (scenes, references) = match prepared.await {
            Ok(prepared) => prepared,
            Err(e) => {
                let _ = api.status(&credentials.token, Some(&format!("stopped: {e}"))).await;
                return Err(e);
            }
        };
        let rendezvous_parent = rendezvous_parent(&credentials.id);
        if let Err(e) = check_socket_room(&fbksd_core::rendezvous::default_parent(), &credentials.id) {
            let _ = api.status(&credentials.token, Some(&format!("stopped: {e}"))).await;
            anyhow::bail!(e);
        }
        let docker = wait_for_docker(&api, &credentials.token).await;
        let images = Images::resolve(&config.images, &docker).await?;
        // Pinned even when no cores are named: to all of them, as recorded in every result.
        let sandbox = Sandbox::new(docker, &credentials.id, machine.cpuset.clone(), config.pids, config.tmpfs_mib)
            .with_cpu_quota(config.cpu_quota);
        let left = sandbox.remove_runner_containers().await;
        if left > 0 {
            tracing::warn!("removed {left} containers a previous run of this runner left behind");
        }
        if let Ok(left) = std::fs::read_dir(config.work_dir.join("jobs")) {
            for job in left.flatten() {
                remove_job_dir(&sandbox, &images, &job.path()).await;
            }
        }
        for dir in [config.work_dir.join("jobs"), rendezvous_parent.clone()] {
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir)?;
        }
        std::fs::set_permissions(&rendezvous_parent, std::fs::Permissions::from_mode(0o700))?;
        tracing::info!(
            "runner {} ({}) ready: {} scenes, images {} / {} / {}, class {} on cores {}, calibration {:.1} ms CPU",
            config.runner_name(),
            credentials.id,
            scenes.len(),
            images.cpp.tag,
            images.python.tag,
            images.renderer.tag,
            machine.class,
            machine.cpuset,
            calibration.cpu_ms
        );
        if let Err(e) = api.ready(&credentials.token, &machine.record(&calibration)).await {
            tracing::warn!("telling the server this runner is ready: {e}");
        }
        let runner = (credentials.id.clone(), config.runner_name());
        Ok(Runner {
            ctx: JobContext {
                config,
                api,
                sandbox,
                images,
                machine,
                calibration: Arc::new(Mutex::new(calibration)),
                scenes,
                runner,
                rendezvous_parent,
                benchmark_thread: Arc::new(tokio::sync::Semaphore::new(1)),
            },
            credentials,
            references,
        })
    }

    /// This runner's id on the server.
    pub fn id(&self) -> &str {
        &self.credentials.id
    }

    /// Claims and runs jobs, one at a time, until `shutdown` resolves.
    pub async fn run(self, shutdown: impl std::future::Future<Output = ()>) {
        tokio::pin!(shutdown);
        loop {
            if let Err(e) = self.ctx.sandbox.docker.ping().await {
                tracing::error!("Docker stopped answering ({e}); no job is claimed until it is back");
                tokio::select! {
                    _ = &mut shutdown => break,
                    _ = tokio::time::sleep(Duration::from_secs(5)) => continue,
                }
            }
            let request = ClaimRequest {
                wait_seconds: self.ctx.config.poll_seconds,
                reference_keys: self.references.iter().map(|s| s.key.clone()).collect(),
                references_only: false,
                runner_class: Some(self.ctx.machine.class.clone()),
                more_seeds: true,
            };
            let claimed = tokio::select! {
                _ = &mut shutdown => break,
                c = self.ctx.api.claim(&self.credentials.token, &request) => c,
            };
            match claimed {
                Ok(Some(claim)) => {
                    tokio::select! {
                        _ = &mut shutdown => break,
                        () = self.handle(&claim) => {}
                    }
                }
                Ok(None) => {
                    // Idle: calibrate now and then, so that a runner held
                    // back for a drifted calibration takes benchmarks again
                    // once it is back (the server decides, from the record).
                    let measured_at = self.ctx.calibration.lock().map_or(0, |c| c.measured_at);
                    if crate::calibration::age_seconds(measured_at) >= IDLE_CALIBRATION_SECONDS {
                        tokio::select! {
                            _ = &mut shutdown => break,
                            () = self.recalibrate() => {}
                        }
                    }
                }
                Err(e) => {
                    tracing::error!("claiming a job: {e}");
                    tokio::select! {
                        _ = &mut shutdown => break,
                        _ = tokio::time::sleep(Duration::from_secs(5)) => {}
                    }
                }
            }
        }
        // Stopped mid-job, the job's benchmark thread still runs: removing
        // the containers ends its run, the next finds the job cancelled and
        // starts nothing, and the thread ends. One that started a container
        // in between removes it itself, or the second pass does.
        let mut removed = self.ctx.sandbox.remove_runner_containers().await;
        let ended = tokio::time::timeout(Duration::from_secs(60), self.ctx.benchmark_thread.acquire()).await;
        if ended.is_err() {
            tracing::warn!("the benchmark's thread did not end within 60 s of the stop");
        }
        removed += self.ctx.sandbox.remove_runner_containers().await;
        tracing::info!("runner stopped ({removed} containers removed)");
    }

    /// Runs one claimed job ([`drive`]) and cleans up after it.
    async fn handle(&self, claim: &Claim) {
        let ctx = &self.ctx;
        let log = JobLog::default();
        let cancelled = Arc::new(AtomicBool::new(false));
        // Also when this future is dropped (the runner stops mid-job): the
        // benchmark's thread outlives it, and must not start another
        // container after the runner has removed its own.
        let _cancel_on_drop = CancelOnDrop(cancelled.clone());
        let dir = ctx.config.work_dir.join("jobs").join(&claim.job.id);
        tracing::info!("job {} ({} of {}) claimed", claim.job.id, claim.job.kind, claim.job.project);
        let work = async {
            match claim.job.kind {
                JobKind::Reference => {
                    let root = &ctx.config.scene_root;
                    crate::references::make_and_upload(&ctx.api, claim, root, &self.references, &log, None).await
                }
                _ => job::run(ctx, claim, &dir, &log, &cancelled).await,
            }
        };
        if !drive(&ctx.api, claim, &log, work).await {
            cancelled.store(true, Ordering::SeqCst);
        }
        let left = ctx.sandbox.remove_job_containers(&claim.job.id).await;
        if left > 0 {
            tracing::warn!("job {}: removed {left} containers it left behind", claim.job.id);
        }
        remove_job_dir(&ctx.sandbox, &ctx.images, &dir).await;
        // Between jobs, so the next result says how fast this runner is now.
        self.recalibrate().await;
    }

    /// Measures the calibration again, keeps it for the next result, and
    /// tells the server, which holds the runner back from its season's
    /// benchmarks while it lies too far from its class's.
    async fn recalibrate(&self) {
        let ctx = &self.ctx;
        let calibration = calibrate(&ctx.machine).await;
        let record = ctx.machine.record(&calibration);
        if let Ok(mut kept) = ctx.calibration.lock() {
            *kept = calibration;
        }
        if let Err(e) = ctx.api.ready(&self.credentials.token, &record).await {
            tracing::warn!("could not report the new calibration: {e}");
        }
    }
}

/// Marks a job cancelled when dropped.
struct CancelOnDrop(Arc<AtomicBool>);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::SeqCst);
    }
}

/// How often an idle runner calibrates again, in seconds.
const IDLE_CALIBRATION_SECONDS: i64 = 180;

/// Times the calibration workload off the async threads, on the cores the
/// jobs run on.
async fn calibrate(machine: &Machine) -> Calibration {
    let cpus = crate::machine::cpus_of(&machine.cpuset).unwrap_or_default();
    tokio::task::spawn_blocking(move || crate::calibration::measure_on(&cpus))
        .await
        .unwrap_or_else(|e| std::panic::resume_unwind(e.into_panic()))
}

/// Runs `work` for a claimed job with heartbeats and a streaming log, and
/// reports its end; false when the job stopped being this runner's first
/// (cancelled or requeued: `work` is dropped, and its end not reported).
pub(crate) async fn drive(
    api: &Api,
    claim: &Claim,
    log: &JobLog,
    work: impl std::future::Future<Output = Result<String, Failure>>,
) -> bool {
    let beat = Duration::from_secs((claim.lease_seconds / 3).max(1));
    let keepalive = async {
        let mut tick = tokio::time::interval(beat.min(Duration::from_secs(1)));
        let mut since_beat = Duration::ZERO;
        loop {
            tick.tick().await;
            since_beat += beat.min(Duration::from_secs(1));
            let _ = log.flush(api, claim).await;
            if since_beat >= beat {
                since_beat = Duration::ZERO;
                if let Err(crate::api::ApiError::JobGone) = api.heartbeat(claim).await {
                    return;
                }
            }
        }
    };
    let outcome = tokio::select! {
        outcome = work => Some(outcome),
        () = keepalive => None,
    };
    let Some(outcome) = outcome else {
        tracing::warn!("job {} is no longer this runner's: stopped", claim.job.id);
        return false;
    };
    let body = match &outcome {
        Ok(message) => {
            log.line(format!("[fbksd-ci] succeeded: {message}"));
            Outcome::succeeded(message.clone())
        }
        Err(Failure { reason, message }) => {
            log.line(format!("[fbksd-ci] failed ({}): {message}", reason.as_str()));
            Outcome::failed(*reason, message.clone())
        }
    };
    // Reporting may wait out a server restart (JOB_PATIENCE): the lease
    // is kept meanwhile, or the job would be requeued and run again.
    let report = async {
        if let Err(e) = log.flush(api, claim).await {
            tracing::warn!("job {}: the log's end was not sent: {e}", claim.job.id);
        }
        api.finish(claim, &body).await
    };
    let heartbeats = async {
        loop {
            tokio::time::sleep(beat).await;
            if let Err(crate::api::ApiError::JobGone) = api.heartbeat(claim).await {
                return;
            }
        }
    };
    let finished = tokio::select! {
        finished = report => finished,
        () = heartbeats => Err(crate::api::ApiError::JobGone),
    };
    match finished {
        Ok(url) => tracing::info!("job {} finished{}", claim.job.id, url.map(|u| format!(": {u}")).unwrap_or_default()),
        // Cancelled (or requeued) while it ran: the server already ended it.
        Err(crate::api::ApiError::JobGone) => {
            tracing::info!(
                "job {} ended on the server first (cancelled or requeued): {body:?} not recorded",
                claim.job.id
            )
        }
        Err(e) => tracing::error!("job {}: reporting its end failed: {e}", claim.job.id),
    }
    true
}

/// Removes a job's directory. A runner that is not root cannot remove what
/// a build wrote as the containers' user: a container empties the build
/// directory first.
async fn remove_job_dir(sandbox: &Sandbox, images: &Images, dir: &Path) {
    if std::fs::remove_dir_all(dir).is_ok() || !dir.exists() {
        return;
    }
    let build = dir.join("build");
    if build.exists() && !sandbox.empty_as_container_user(&images.renderer.tag, &build).await {
        tracing::warn!("{}: a container could not empty it", build.display());
    }
    if let Err(e) = std::fs::remove_dir_all(dir) {
        tracing::warn!("{}: {e}", dir.display());
    }
}

/// The runner's identity: kept in the work directory, or bought with the
/// registration token. A kept identity the server no longer knows (its data
/// directory was started afresh) is replaced when the runner has the
/// registration token, instead of being refused on every claim.
async fn identity(config: &RunnerConfig, api: &Api, machine: &serde_json::Value) -> anyhow::Result<RunnerCredentials> {
    let path = config.work_dir.join("runner.json");
    if let Ok(text) = std::fs::read_to_string(&path) {
        let kept: RunnerCredentials =
            serde_json::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        match api.status(&kept.token, Some("starting")).await {
            Err(ApiError::Refused { status: 401, .. }) if config.registration_token.is_some() => {
                tracing::warn!(
                    "the server does not know the runner {} kept in {} (a new data directory?): registering again",
                    kept.id,
                    path.display()
                );
            }
            _ => return Ok(kept),
        }
    }
    let Some(token) = &config.registration_token else {
        anyhow::bail!(
            "{} does not exist: give the server's runner registration token (--registration-token or \
             FBKSD_REGISTRATION_TOKEN) to register this runner",
            path.display()
        );
    };
    let credentials = api.register(token, &config.runner_name(), machine).await?;
    write_private(&path, &serde_json::to_vec_pretty(&credentials)?)?;
    tracing::info!("registered as runner {}", credentials.id);
    Ok(credentials)
}

fn write_private(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let tmp = path.with_extension("tmp");
    let mut f = std::fs::File::options().write(true).create(true).truncate(true).mode(0o600).open(&tmp)?;
    f.write_all(bytes)?;
    f.sync_all()?;
    std::fs::rename(tmp, path)
}

/// Refuses a runtime directory so long that a run's control socket
/// (`<runtime>/fbksd-ci-<runner id>/fbksd-run-XXXXXX/control.sock`) could
/// not be bound: a Unix socket's path holds at most 107 bytes, and every
/// run would fail late.
fn check_socket_room(runtime: &Path, runner_id: &str) -> Result<(), String> {
    let parent = runtime.join(format!("fbksd-ci-{runner_id}"));
    let socket = fbksd_core::rendezvous::control_socket(&parent.join("fbksd-run-XXXXXX"));
    let length = socket.as_os_str().len();
    if length > 107 {
        let room = 107usize.saturating_sub(length - runtime.as_os_str().len());
        return Err(format!(
            "a run's control socket would be {} ({length} bytes; a Unix socket's path holds at most 107): \
             set FBKSD_RUNTIME_DIR to a directory of at most {room} characters",
            socket.display()
        ));
    }
    Ok(())
}

/// This runner's own directory for rendezvous directories, wiped at start:
/// under the manager's usual parent (`/dev/shm` when writable, memory-backed).
fn rendezvous_parent(runner_id: &str) -> PathBuf {
    fbksd_core::rendezvous::default_parent().join(format!("fbksd-ci-{runner_id}"))
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    #[test]
    fn a_runtime_directory_too_long_for_the_control_socket_is_refused_with_the_room_left() {
        let id = "0123abcd-0123-4567-89ab-0123456789ab";
        assert!(super::check_socket_room(Path::new("/dev/shm"), id).is_ok());
        assert!(super::check_socket_room(Path::new(&format!("/{}", "r".repeat(30))), id).is_ok());
        let long = format!("/{}", "r".repeat(31));
        let refused = super::check_socket_room(Path::new(&long), id).unwrap_err();
        assert!(refused.contains("108 bytes") && refused.contains("at most 31 characters"), "{refused}");
    }
}
