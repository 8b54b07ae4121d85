//! One job, from clone to finish.
//!
//! 1. **Clone** the repository at the job's pinned commit, with the job's
//!    token in an HTTP header passed through git's environment (never in a
//!    URL, a file or the command line).
//! 2. **Check** `info.json` (the same rules as the server's).
//! 3. **Build** in a sandboxed container of the environment image: CMake
//!    for `cpp`; a syntax check and an `import fbksd` for `python`.
//! 4. **Benchmark** (benchmark jobs): every scene of the pool at each
//!    budget, one run after another, through the manager with the
//!    [`DockerLauncher`]; then the metrics, here, against the references.
//!    A seeds job makes only the runs it names, with the seeds it names,
//!    and uploads their values alone (the server adds them to the
//!    published set a tie on the board rests on). A scene at which the
//!    renderer ran markedly slower than its usual on this runner was
//!    measured while the machine was slow, and is measured again
//!    ([`crate::renderer_rates`]).
//! 5. **Upload** the files and the results, and report the end.
//!
//! Every failure is a [`Failure`] with a typed [`FailureReason`] and a message the
//! author can act on.

use crate::api::{Api, ApiError};
use crate::calibration::Calibration;
use crate::images::Images;
use crate::launcher::{DockerLauncher, RoleContainer};
use crate::machine::Machine;
use crate::pool::PoolScene;
use crate::renderer_rates::{self, RateHistory};
use crate::sandbox::{ContainerEnd, ContainerSpec, Mount, Sandbox};
use crate::RunnerConfig;
use fbksd_exchange::ranking::RunKey;
use fbksd_exchange::record::RunRecord;
use fbksd_exchange::results::{path_safe_name, ResultsDir};
use fbksd_exchange::runner_api::Claim;
use fbksd_exchange::runner_api::{ImageRef, JobKind, Provenance, SandboxLimits, SceneProvenance, Upload};
use fbksd_exchange::technique::{Environment, TechniqueInfo};
use fbksd_iqa::Metric;
use fbksd_manager::evaluation::{compute, AnyMetric};
use fbksd_manager::{Benchmark, FailureReason, Limits, Progress, RunStatus, SceneSpec, TechniqueSpec};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A failed job.
#[derive(Debug, Clone, PartialEq)]
pub struct Failure {
    /// The typed reason.
    pub reason: FailureReason,
    /// What happened, for the author.
    pub message: String,
}

impl Failure {
    pub(crate) fn new(reason: FailureReason, message: impl Into<String>) -> Failure {
        Failure { reason, message: message.into() }
    }

    pub(crate) fn infrastructure(message: impl Into<String>) -> Failure {
        Failure::new(FailureReason::InfrastructureError, message)
    }
}

impl From<ApiError> for Failure {
    /// A 413 is the job's own doing (its files or results are larger than
    /// the server takes): charged to the author, not retried.
    fn from(e: ApiError) -> Failure {
        match e {
            ApiError::Refused { status: 413, body, what } => {
                Failure::new(FailureReason::OverLimit, format!("the server refused {what}: {body}"))
            }
            e => Failure::infrastructure(e.to_string()),
        }
    }
}

/// How often a build directory's size is checked.
const DISK_POLL: Duration = Duration::from_millis(250);

/// Most output held between two sends: a build printing without pause
/// (`yes`) fills this in a blink, and the rest waits as a count, not in
/// memory.
const MAX_PENDING_LOG: usize = 1 << 20;

/// Most bytes per request (the server refuses batches over 2 MB).
const MAX_LOG_BATCH: usize = 512 << 10;

/// A job's log, sent to the server in batches (see [`JobLog::flush`]).
/// Bounded: output beyond [`MAX_PENDING_LOG`] is counted and left out with
/// a line saying how much, and once the server says the log is full (its
/// `max_log_bytes`) nothing more is sent.
#[derive(Debug, Clone, Default)]
pub struct JobLog {
    buffer: Arc<Mutex<LogBuffer>>,
}

#[derive(Debug, Default)]
struct LogBuffer {
    pending: String,
    /// Output bytes left out since the last line that was kept.
    left_out: u64,
    /// The server's log is full.
    full: bool,
}

impl LogBuffer {
    /// Adds `text`; output (`own` false) only while there is room, the
    /// runner's own lines always (they are few, and say what happened).
    fn add(&mut self, text: &str, own: bool) {
        if self.full {
            return;
        }
        if !own && self.pending.len() + text.len() > MAX_PENDING_LOG {
            self.left_out += text.len() as u64;
            return;
        }
        if self.left_out > 0 {
            let line = format!(
                "\n[fbksd-ci] {} bytes of output left out here: it came faster than the log is sent\n",
                self.left_out
            );
            self.pending.push_str(&line);
            self.left_out = 0;
        }
        self.pending.push_str(text);
    }
}

impl JobLog {
    /// Adds a line.
    pub fn line(&self, text: impl AsRef<str>) {
        let text = text.as_ref();
        tracing::info!("{text}");
        self.buffer.lock().unwrap().add(&format!("{text}\n"), true);
    }

    /// Adds raw output (a container's).
    pub fn raw(&self, bytes: &[u8]) {
        self.buffer.lock().unwrap().add(&String::from_utf8_lossy(bytes), false);
    }

    /// Sends what is pending, in batches the server accepts. Text leaves
    /// the buffer only once the server has it, so a flush cut short (server
    /// down, job ending) loses nothing; once the server answers that the
    /// log is full (413), the buffer is dropped and stays empty.
    pub async fn flush(&self, api: &Api, claim: &Claim) -> Result<(), ApiError> {
        loop {
            let batch = {
                let buffer = self.buffer.lock().unwrap();
                let mut end = buffer.pending.len().min(MAX_LOG_BATCH);
                while !buffer.pending.is_char_boundary(end) {
                    end -= 1;
                }
                buffer.pending[..end].to_string()
            };
            if batch.is_empty() {
                return Ok(());
            }
            match api.log(claim, &batch).await {
                Ok(()) => drop(self.buffer.lock().unwrap().pending.drain(..batch.len())),
                Err(ApiError::Refused { status: 413, body, .. }) => {
                    tracing::warn!("job {}: {body}", claim.job.id);
                    let mut buffer = self.buffer.lock().unwrap();
                    (buffer.full, buffer.pending) = (true, String::new());
                    return Ok(());
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// Bytes held for sending (for tests of the bound).
    pub fn pending_bytes(&self) -> usize {
        self.buffer.lock().unwrap().pending.len()
    }
}

/// What a job works with.
#[derive(Debug, Clone)]
pub struct JobContext {
    /// Settings.
    pub config: RunnerConfig,
    /// The server.
    pub api: Api,
    /// The containers.
    pub sandbox: Sandbox,
    /// The images.
    pub images: Images,
    /// The machine.
    pub machine: Machine,
    /// Its latest calibration (at start, then after every job).
    pub calibration: Arc<Mutex<Calibration>>,
    /// The scene pool.
    pub scenes: Vec<PoolScene>,
    /// This runner's id and name.
    pub runner: (String, String),
    /// Where rendezvous directories go.
    pub rendezvous_parent: PathBuf,
    /// Held by a benchmark's thread while it runs. The thread outlives a
    /// job whose work was dropped (the runner stopped mid-job): the runner
    /// waits for this before its last clean-up, so that no container the
    /// thread started in the meantime is left.
    pub benchmark_thread: Arc<tokio::sync::Semaphore>,
}

/// Set when the job is no longer this runner's: no new container starts.
pub type Cancelled = Arc<AtomicBool>;

/// Runs a claimed job in `dir` (created, and left for the caller to remove);
/// returns the success message for the server.
pub async fn run(
    ctx: &JobContext,
    claim: &Claim,
    dir: &Path,
    log: &JobLog,
    cancelled: &Cancelled,
) -> Result<String, Failure> {
    let started = Instant::now();
    std::fs::create_dir_all(dir)
        .and_then(|()| {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700))
        })
        .map_err(|e| Failure::infrastructure(format!("{}: {e}", dir.display())))?;
    let src = dir.join("src");
    log.line(format!(
        "[fbksd-ci] job {} ({}, attempt {}) on runner {} (class {}, cores pinned: {})",
        claim.job.id, claim.job.kind, claim.job.attempts, ctx.runner.1, ctx.machine.class, ctx.machine.cpuset
    ));
    clone(claim, &src, ctx.config.max_checkout_mib << 20).await?;
    log.line(format!("[fbksd-ci] checked out {} at {}", claim.job.project, claim.commit));

    let info = check(&src)?;
    let image = ctx.images.for_environment(info.environment);
    log.line(format!(
        "[fbksd-ci] {} ({}): environment {} (image {}, {})",
        info.full_name,
        info.short_name,
        info.environment.as_str(),
        image.tag,
        image.id
    ));
    let install = build(ctx, claim, &info, &src, dir, log).await?;
    if !matches!(claim.job.kind, JobKind::Benchmark | JobKind::Seeds) {
        return Ok(format!("built in {:.1} s", started.elapsed().as_secs_f64()));
    }
    if cancelled.load(Ordering::SeqCst) {
        return Err(Failure::infrastructure("the job was cancelled"));
    }

    let results = dir.join("results");
    let benchmark_started = Instant::now();
    let runs_time = benchmark(ctx, claim, &info, &install, &results, log, cancelled).await?;
    let benchmark_time = benchmark_started.elapsed();
    let metrics_started = Instant::now();
    let (upload, files, message) = collect(ctx, claim, &info, &results).await?;
    let metrics_time = metrics_started.elapsed();
    let upload_started = Instant::now();
    let mut bytes_sent = 0;
    for (name, path) in &files {
        let bytes = std::fs::read(path).map_err(|e| Failure::infrastructure(format!("{}: {e}", path.display())))?;
        bytes_sent += bytes.len();
        ctx.api.put_file(claim, name, bytes).await?;
    }
    ctx.api.put_results(claim, &upload).await?;
    // The runner's own cost, for its operators: everything but the runs themselves.
    log.line(format!(
        "[fbksd-ci] times: job {:.1} s; benchmark {:.1} s, of which the runs themselves {:.1} s; metrics {:.1} s; \
         upload of {} files ({:.1} MB) {:.1} s",
        started.elapsed().as_secs_f64(),
        benchmark_time.as_secs_f64(),
        runs_time.as_secs_f64(),
        metrics_time.as_secs_f64(),
        files.len(),
        bytes_sent as f64 / 1e6,
        upload_started.elapsed().as_secs_f64(),
    ));
    Ok(message)
}

/// Clones the repository at the pinned commit into `src`.
async fn clone(claim: &Claim, src: &Path, max_bytes: u64) -> Result<(), Failure> {
    use base64::Engine;
    let credentials = base64::engine::general_purpose::STANDARD.encode(format!("fbksd-ci:{}", claim.token));
    let git = |args: &[&str]| {
        let mut command = tokio::process::Command::new("git");
        command
            .args(args)
            .env("GIT_TERMINAL_PROMPT", "0")
            .env("GIT_CONFIG_NOSYSTEM", "1")
            .env("GIT_CONFIG_COUNT", "1")
            .env("GIT_CONFIG_KEY_0", "http.extraHeader")
            .env("GIT_CONFIG_VALUE_0", format!("Authorization: Basic {credentials}"))
            .kill_on_drop(true);
        command
    };
    let src_arg = src.to_string_lossy().into_owned();
    // Blobs come with the checkout, for the pinned commit only: a history
    // of large pushes is never downloaded whole.
    let steps: [Vec<&str>; 2] = [
        vec!["clone", "--quiet", "--no-checkout", "--filter=blob:none", &claim.repository, &src_arg],
        vec!["-C", &src_arg, "-c", "advice.detachedHead=false", "checkout", "--quiet", "--detach", &claim.commit],
    ];
    for args in steps {
        let output = tokio::time::timeout(Duration::from_secs(300), git(&args).output())
            .await
            .map_err(|_| Failure::infrastructure("git did not finish within 5 minutes"))?
            .map_err(|e| Failure::infrastructure(format!("cannot run git: {e}")))?;
        if !output.status.success() {
            return Err(Failure::infrastructure(format!(
                "git {} failed: {}",
                args[0],
                String::from_utf8_lossy(&output.stderr).trim()
            )));
        }
    }
    if fbksd_exchange::disk::disk_usage(src, max_bytes) > max_bytes {
        return Err(Failure::new(
            FailureReason::OverLimit,
            format!("the checkout takes more than {} MiB: keep data sets out of the repository", max_bytes >> 20),
        ));
    }
    Ok(())
}

/// Reads and checks `info.json`.
fn check(src: &Path) -> Result<TechniqueInfo, Failure> {
    // Never follow a link from a user's repository on the host: it could
    // name any file of the runner's machine.
    let path = src.join("info.json");
    if path.symlink_metadata().is_ok_and(|m| !m.is_file()) {
        return Err(Failure::new(
            FailureReason::BuildFailed,
            "info.json is a symbolic link or not a file: commit the file itself",
        ));
    }
    let text = std::fs::read_to_string(&path).map_err(|e| {
        Failure::new(FailureReason::BuildFailed, format!("info.json: {e}: add it at the repository's root"))
    })?;
    let mut files = Vec::new();
    files_under(src, src, &mut files);
    let files: Vec<String> = files.into_iter().map(|(name, _)| name).collect();
    TechniqueInfo::parse(&text, &files).map_err(|e| Failure::new(FailureReason::BuildFailed, e))
}

/// Where a built technique's files are, and how its container sees them.
struct Install {
    host: PathBuf,
}

/// Where a technique's files are mounted in its container.
const TECHNIQUE_MOUNT: &str = "/technique";

/// The python environment's build: each script's syntax, and that every
/// module it imports at its top level is there (so a missing one fails the
/// build, with the environment's hint, instead of every run).
const PYTHON_CHECK: &str = "\
import ast, importlib.util, os, sys
def present(module):
    try:
        return importlib.util.find_spec(module) is not None
    except Exception:
        return True
for path in sys.argv[1:]:
    tree = ast.parse(open(path, 'rb').read(), path)
    sys.path.insert(0, os.path.dirname(os.path.abspath(path)))  # as when the script runs
    for node in tree.body:
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else \\
            [node.module] if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module else []
        for top in {name.split('.')[0] for name in names}:
            if not present(top):
                sys.exit(f\"{path}:{node.lineno}: ModuleNotFoundError: No module named '{top}'\")
    sys.path.pop(0)
import fbksd.client
print('syntax and imports of', ', '.join(sys.argv[1:]), 'checked')";

/// Builds the technique in a sandbox; returns the directory its executables are in.
async fn build(
    ctx: &JobContext,
    claim: &Claim,
    info: &TechniqueInfo,
    src: &Path,
    dir: &Path,
    log: &JobLog,
) -> Result<Install, Failure> {
    let image = ctx.images.for_environment(info.environment).tag.clone();
    let (spec, install) = match info.environment {
        Environment::Cpp => {
            let build = dir.join("build");
            std::fs::create_dir_all(&build).map_err(|e| Failure::infrastructure(e.to_string()))?;
            // The build's user writes it: given to that user by a root
            // runner, opened to all by another (the job's directory, 0700,
            // keeps the machine's other users out).
            let (uid, gid) = Sandbox::user();
            std::os::unix::fs::chown(&build, Some(uid), Some(gid))
                .or_else(|_| {
                    use std::os::unix::fs::PermissionsExt;
                    std::fs::set_permissions(&build, std::fs::Permissions::from_mode(0o777))
                })
                .map_err(|e| Failure::infrastructure(format!("{}: {e}", build.display())))?;
            let script = format!(
                "cmake -S /src -B /build -DCMAKE_BUILD_TYPE=Release && cmake --build /build --parallel {}",
                ctx.machine.cores
            );
            let spec = ContainerSpec {
                image,
                cmd: vec!["sh".into(), "-c".into(), script],
                env: Vec::new(), // HOME=/tmp is set by the image
                mounts: vec![
                    Mount { host: src.to_path_buf(), container: "/src".into(), writable: false },
                    Mount { host: build.clone(), container: "/build".into(), writable: true },
                ],
                working_dir: Some("/build".into()),
                memory_mib: ctx.config.memory_mib,
                job_id: claim.job.id.clone(),
                cpuset: None,
                // One file cannot pass the directory's cap between two checks.
                max_file_bytes: Some((ctx.config.max_build_mib << 20) as i64),
            };
            (spec, Install { host: build })
        }
        Environment::Python => {
            let mut cmd = vec!["python3".to_string(), "-c".to_string(), PYTHON_CHECK.to_string()];
            cmd.extend(info.versions.iter().map(|v| v.executable.clone()));
            let spec = ContainerSpec {
                image,
                cmd,
                env: Vec::new(), // HOME and PYTHONDONTWRITEBYTECODE are set by the image
                mounts: vec![Mount { host: src.to_path_buf(), container: TECHNIQUE_MOUNT.into(), writable: false }],
                working_dir: Some(TECHNIQUE_MOUNT.into()),
                memory_mib: ctx.config.memory_mib,
                job_id: claim.job.id.clone(),
                cpuset: None,
                max_file_bytes: None,
            };
            (spec, Install { host: src.to_path_buf() })
        }
    };
    log.line(format!(
        "[fbksd-ci] environment {} ({}): {}",
        info.environment.as_str(),
        spec.image,
        info.environment.summary()
    ));
    log.line(format!("[fbksd-ci] build: {}", spec.cmd.join(" ").lines().next().unwrap_or("")));
    // The start of the output (where the first compiler error usually is) and its end.
    let (head, tail) = (Arc::new(Mutex::new(Vec::<u8>::new())), Arc::new(Mutex::new(Vec::<u8>::new())));
    let sink = {
        let (head, tail) = (head.clone(), tail.clone());
        let log = log.clone();
        move |bytes: &[u8]| {
            log.raw(bytes);
            let mut h = head.lock().unwrap();
            let room = (64usize << 10).saturating_sub(h.len());
            h.extend_from_slice(&bytes[..bytes.len().min(room)]);
            let mut t = tail.lock().unwrap();
            t.extend_from_slice(bytes);
            let excess = t.len().saturating_sub(4000);
            t.drain(..excess);
        }
    };
    // A build directory on the host grows only this far: past it, the
    // build's containers are removed and the job fails `over_limit`.
    let max_bytes = ctx.config.max_build_mib << 20;
    let over = AtomicBool::new(false);
    let watch = async {
        loop {
            tokio::time::sleep(DISK_POLL).await;
            let dir = install.host.clone();
            let used = tokio::task::spawn_blocking(move || fbksd_exchange::disk::disk_usage(&dir, max_bytes))
                .await
                .unwrap_or(0);
            if used > max_bytes {
                over.store(true, Ordering::SeqCst);
                ctx.sandbox.remove_job_containers(&claim.job.id).await;
                return;
            }
        }
    };
    let writes_host = info.environment == Environment::Cpp;
    let ran = tokio::select! {
        ran = ctx.sandbox.run_to_end(&spec, ctx.config.build_timeout, sink) => Some(ran),
        () = watch, if writes_host => None,
    };
    // The build may end (killed) before the watch has removed it: the flag says why.
    let ran = match ran {
        Some(ran) if !over.load(Ordering::SeqCst) => ran,
        _ => {
            return Err(Failure::new(
                FailureReason::OverLimit,
                format!("the build directory passed {} MiB: the build was stopped", ctx.config.max_build_mib),
            ))
        }
    };
    let (end, took) =
        ran.map_err(|e| Failure::infrastructure(format!("Docker: cannot run the build container: {e}")))?;
    let tail = String::from_utf8_lossy(&tail.lock().unwrap()).trim().to_string();
    let head = String::from_utf8_lossy(&head.lock().unwrap()).into_owned();
    let first_error = first_error_line(&head).or_else(|| first_error_line(&tail));
    match end {
        ContainerEnd { timed_out: true, .. } => {
            return Err(Failure::new(
                FailureReason::Timeout,
                format!("the build did not end within {}", humantime::format_duration(ctx.config.build_timeout)),
            ))
        }
        ContainerEnd { out_of_memory: true, .. } => {
            return Err(Failure::new(
                FailureReason::OutOfMemory,
                format!("the build went over its memory limit ({} MiB)", ctx.config.memory_mib),
            ))
        }
        ContainerEnd { exit_code: 0, .. } => {}
        ContainerEnd { exit_code, .. } => {
            let first = first_error.map(|line| format!(" {line}")).unwrap_or_default();
            let hint = info
                .environment
                .explain_missing(&head)
                .or_else(|| info.environment.explain_missing(&tail))
                .map(|h| format!("\n\n{h}"))
                .unwrap_or_default();
            return Err(Failure::new(
                FailureReason::BuildFailed,
                format!(
                    "the build failed in the {} environment (exit code {exit_code}):{first}{hint}\n\n\
                     last lines of the build:\n{tail}",
                    info.environment.as_str()
                ),
            ));
        }
    }
    for v in &info.versions {
        let exe = install.host.join(&v.executable);
        if !exe.is_file() {
            return Err(Failure::new(
                FailureReason::BuildFailed,
                format!(
                    "version {:?}: its executable {:?} is not there after the build (for cpp it is looked for in \
                     the CMake build directory, for python in the repository)",
                    v.name, v.executable
                ),
            ));
        }
    }
    log.line(format!("[fbksd-ci] build succeeded in {:.1} s", took.as_secs_f64()));
    Ok(install)
}

/// Runs the first version of the technique on every scene of the pool;
/// returns the runs' own time (technique start to result, summed).
async fn benchmark(
    ctx: &JobContext,
    claim: &Claim,
    info: &TechniqueInfo,
    install: &Install,
    results: &Path,
    log: &JobLog,
    cancelled: &Cancelled,
) -> Result<Duration, Failure> {
    let version = &info.versions[0];
    if info.versions.len() > 1 {
        log.line(format!("[fbksd-ci] benchmarking version {:?} (the first one in info.json)", version.name));
    }
    let exe = format!("{TECHNIQUE_MOUNT}/{}", version.executable);
    let argv = match info.environment {
        Environment::Cpp => vec![exe],
        Environment::Python => vec!["python3".into(), exe],
    };
    let seeds = more_seeds(ctx, claim, info)?;
    if !seeds.is_empty() {
        log.line(format!("[fbksd-ci] more seeds for {} runs a tie on the board rests on", seeds.len()));
    }
    let scenes = ctx
        .scenes
        .iter()
        .map(|s| SceneSpec {
            name: s.meta.name.clone(),
            renderer_argv: s.renderer_argv(),
            spps: if !seeds.is_empty() {
                let scene = path_safe_name(&s.meta.name);
                seeds.keys().filter(|k| k.scene == scene).map(|k| k.spp).collect()
            } else if ctx.config.spp.is_empty() {
                s.meta.spp.clone()
            } else {
                ctx.config.spp.clone()
            },
        })
        .collect();
    // With four cores or more, the renderer and the technique get disjoint
    // halves: neither's clock then pays for the other's threads.
    let cores = crate::machine::split_cpus(&ctx.machine.cpuset);
    if let Some(c) = &cores {
        log.line(format!("[fbksd-ci] renderer on cores {}, technique on cores {}", c.renderer, c.technique));
    }
    let launcher = DockerLauncher {
        sandbox: ctx.sandbox.clone(),
        handle: tokio::runtime::Handle::current(),
        job_id: claim.job.id.clone(),
        technique: RoleContainer {
            image: ctx.images.for_environment(info.environment).tag.clone(),
            mounts: vec![Mount { host: install.host.clone(), container: TECHNIQUE_MOUNT.into(), writable: false }],
            working_dir: Some(TECHNIQUE_MOUNT.into()),
            memory_mib: ctx.config.memory_mib,
            cpuset: cores.as_ref().map(|c| c.technique.clone()),
        },
        renderer: RoleContainer {
            image: ctx.images.renderer.tag.clone(),
            mounts: Vec::new(),
            working_dir: None,
            memory_mib: ctx.config.renderer_memory_mib,
            cpuset: cores.as_ref().map(|c| c.renderer.clone()),
        },
        cancelled: cancelled.clone(),
        max_output_bytes: (ctx.config.max_output_mib << 20) as usize,
    };
    let bench = Benchmark {
        techniques: vec![TechniqueSpec { name: info.short_name.clone(), argv }],
        scenes,
        results: results.to_path_buf(),
        limits: Limits {
            time_limit: Some(ctx.config.run_timeout),
            rendezvous_parent: Some(ctx.rendezvous_parent.clone()),
            ..Limits::default()
        },
        launcher: Arc::new(launcher),
        repeats: ctx.config.repeats,
    };
    let (records, runs_time) = measure(ctx, &bench, &seeds, log, "").await?;
    if cancelled.load(Ordering::SeqCst) {
        return Err(Failure::infrastructure("the job was cancelled"));
    }
    let (records, again_time) = measure_slow_scenes_again(ctx, &bench, &seeds, records, log, cancelled).await?;
    if let Some(first) = records.iter().find(|r| r.status != RunStatus::Ok) {
        if records.iter().all(|r| r.status != RunStatus::Ok) {
            let tail = fbksd_manager::process::log_tail(
                &results.join(path_safe_name(&first.technique)).join(&first.scene).join(&first.technique_log),
                20,
            );
            let output = if tail.is_empty() { String::new() } else { format!("\ntechnique output:\n{tail}") };
            return Err(Failure::new(
                first.status.failure_reason(),
                format!(
                    "no run succeeded; the first, {} at {} spp, ended {}: {}{output}",
                    first.scene, first.spp_budget, first.status, first.message
                ),
            ));
        }
    }
    Ok(runs_time + again_time)
}

/// Seeds jobs' runs by their names in the results, with their seeds (empty
/// for a benchmark job: every run with the configured repeats).
type SeedsOf = std::collections::BTreeMap<RunKey, std::ops::Range<u32>>;

/// Makes `bench`'s runs (those `seeds` names, if any) on a blocking thread,
/// logging each as it ends (`label` says which measurement); returns the
/// records and the runs' own time (technique start to result, summed).
async fn measure(
    ctx: &JobContext,
    bench: &Benchmark,
    seeds: &SeedsOf,
    log: &JobLog,
    label: &'static str,
) -> Result<(Vec<RunRecord>, Duration), Failure> {
    let (bench, seeds, log) = (bench.clone(), seeds.clone(), log.clone());
    let running = ctx
        .benchmark_thread
        .clone()
        .acquire_owned()
        .await
        .map_err(|_| Failure::infrastructure("the runner is stopping"))?;
    let records = tokio::task::spawn_blocking(move || {
        let _running = running;
        let progress = |p: Progress<'_>| {
            if let Progress::RunFinished(r) = p {
                let how = if r.status == RunStatus::Ok {
                    format!("technique {:.1} ms, render {:.1} ms", r.times.technique_ms, r.times.render_ms)
                } else {
                    format!("{}: {}", r.status, r.message)
                };
                let seed = if r.repeat > 0 { format!(" (seed {})", r.seed) } else { String::new() };
                log.line(format!("[fbksd-ci] {label}{} at {} spp{seed}: {}", r.scene, r.spp_budget, how));
            }
        };
        if seeds.is_empty() {
            bench.run(progress)
        } else {
            bench.run_more_seeds(&seeds, progress)
        }
    })
    .await
    .map_err(|e| Failure::infrastructure(format!("the benchmark panicked: {e}")))?
    .map_err(|e| Failure::infrastructure(format!("the benchmark could not write its results: {e}")))?;
    let time = records.iter().map(|r| Duration::from_secs_f64(r.times.wall_ms / 1e3)).sum();
    Ok((records, time))
}

/// Measures again each scene at which the renderer ran markedly slower
/// than its usual on this runner (the machine was slow, and the
/// technique's times with it; see [`crate::renderer_rates`]), up to the
/// configured number of times, keeping the calmest measurement; then adds
/// the rates kept to the runner's history. Returns the records kept and the
/// time the new runs took.
async fn measure_slow_scenes_again(
    ctx: &JobContext,
    bench: &Benchmark,
    seeds: &SeedsOf,
    mut records: Vec<RunRecord>,
    log: &JobLog,
    cancelled: &Cancelled,
) -> Result<(Vec<RunRecord>, Duration), Failure> {
    let history_path = ctx.config.work_dir.join(renderer_rates::FILE);
    let mut history = RateHistory::load(&history_path, &ctx.images.renderer.tag);
    let results = ResultsDir::create(&bench.results).map_err(|e| Failure::infrastructure(e.to_string()))?;
    let mut time = Duration::ZERO;
    for spec in &bench.scenes {
        let scene = path_safe_name(&spec.name);
        let of_scene = |records: &[RunRecord]| renderer_rates::rates_of(records.iter().filter(|r| r.scene == scene));
        let Some(slow) = history.slowest(&of_scene(&records)) else { continue };
        if slow.ratio() <= ctx.config.remeasure_above || ctx.config.max_remeasures == 0 {
            continue;
        }
        log.line(format!(
            "[fbksd-ci] {scene}: the renderer ran at {slow}: the machine was slow during these runs, and the \
             technique's times with it; measuring {scene} again (at most {} times, keeping the calmest)",
            ctx.config.max_remeasures
        ));
        let ok =
            |records: &[RunRecord]| records.iter().filter(|r| r.scene == scene && r.status == RunStatus::Ok).count();
        let mut kept = (slow.ratio(), ok(&records));
        for attempt in 1..=ctx.config.max_remeasures {
            let again = bench.results.with_file_name(format!("again-{scene}-{attempt}"));
            let single = Benchmark { scenes: vec![spec.clone()], results: again.clone(), ..bench.clone() };
            let (new, took) = measure(ctx, &single, seeds, log, "again: ").await?;
            time += took;
            if cancelled.load(Ordering::SeqCst) {
                return Err(Failure::infrastructure("the job was cancelled"));
            }
            let ratio = history.slowest(&of_scene(&new)).map_or(f64::INFINITY, |s| s.ratio());
            let calmer = ratio < kept.0 && ok(&new) >= kept.1;
            if calmer {
                let from = ResultsDir::create(&again).map_err(|e| Failure::infrastructure(e.to_string()))?;
                results.take_scene(&from, &scene).map_err(|e| {
                    Failure::infrastructure(format!("cannot keep the second measurement of {scene}: {e}"))
                })?;
                records.retain(|r| r.scene != scene);
                records.extend(new);
                kept = (ratio, ok(&records));
            }
            let _ = std::fs::remove_dir_all(&again);
            log.line(format!(
                "[fbksd-ci] {scene} measured again ({attempt} of {}): the renderer at {ratio:.2}× its usual; {}",
                ctx.config.max_remeasures,
                if calmer { "this measurement is kept" } else { "the earlier one is kept" }
            ));
            if kept.0 <= ctx.config.remeasure_above {
                break;
            }
        }
        if kept.0 > ctx.config.remeasure_above {
            log.line(format!(
                "[fbksd-ci] {scene}: still slow after {} measurements; kept the calmest (the renderer at {:.2}× its usual)",
                ctx.config.max_remeasures + 1,
                kept.0
            ));
        }
    }
    history.add(&renderer_rates::rates_of(&records));
    if let Err(e) = history.save(&history_path) {
        tracing::warn!("{}: {e}; this job's renderer rates are not kept", history_path.display());
    }
    Ok((records, time))
}

/// A seeds job's runs, by their names in this benchmark's results (empty
/// for a benchmark job). A scene this runner lacks fails the attempt as
/// the infrastructure's: a runner with the season's pool takes it again.
fn more_seeds(ctx: &JobContext, claim: &Claim, info: &TechniqueInfo) -> Result<SeedsOf, Failure> {
    let mut runs = std::collections::BTreeMap::new();
    for run in &claim.more_seeds {
        let Some(scene) = ctx.scenes.iter().find(|s| path_safe_name(&s.meta.name) == run.scene) else {
            return Err(Failure::infrastructure(format!("this runner's scene pool lacks {}", run.scene)));
        };
        let key = RunKey {
            technique: path_safe_name(&info.short_name),
            scene: path_safe_name(&scene.meta.name),
            spp: run.spp,
        };
        runs.insert(key, run.seeds());
    }
    Ok(runs)
}

/// The upload, the files to send with it, and the success message.
type Collected = (Upload, Vec<(String, PathBuf)>, String);

/// Computes the metrics and gathers what is uploaded.
async fn collect(ctx: &JobContext, claim: &Claim, info: &TechniqueInfo, results: &Path) -> Result<Collected, Failure> {
    let scenes: std::collections::BTreeMap<_, _> =
        ctx.scenes.iter().map(|s| (path_safe_name(&s.meta.name), s.meta.clone())).collect();
    let metrics: Vec<AnyMetric> = Metric::ALL.iter().map(|m| AnyMetric::Builtin(*m)).collect();
    let results_dir = ResultsDir::create(results).map_err(|e| Failure::infrastructure(e.to_string()))?;
    let index = {
        let metrics = metrics.clone();
        tokio::task::spawn_blocking(move || {
            compute(&results_dir, &scenes, &metrics, |_, _| {})?;
            results_dir.read_index()
        })
        .await
        .map_err(|e| Failure::infrastructure(format!("the metrics panicked: {e}")))?
        .map_err(|e| Failure::infrastructure(format!("the metrics: {e}")))?
    };
    // Repeats beyond the first are scored here and their images dropped:
    // the viewer shows a run's first repeat, the values carry all of them.
    let mut index = index;
    let seeds = claim.job.kind == JobKind::Seeds;
    for run in &mut index.runs {
        for repeat in run.repeats.iter_mut().skip(if seeds { 0 } else { 1 }) {
            if let Some(image) = repeat.image.take() {
                let _ = std::fs::remove_file(results.join(image));
            }
            if seeds {
                repeat.log.clear();
            }
        }
        if seeds {
            (run.image, run.log) = (None, String::new());
        }
    }
    // A seeds job adds values to a set that has its images and logs.
    let mut files = Vec::new();
    if !seeds {
        files_under(results, &results.join(path_safe_name(&info.short_name)), &mut files);
        files_under(results, &results.join("renderer-logs"), &mut files);
        files.extend(references_to_upload(ctx, claim, results).await?);
    }
    let failed = index.runs.iter().filter(|r| r.status != RunStatus::Ok).count();
    let repeats: usize = index.runs.iter().map(|r| r.repeats.len()).sum();
    let message = if seeds {
        format!("{repeats} more seeds of {} runs ({failed} of the runs failed)", index.runs.len())
    } else if failed == 0 {
        format!("{} runs on {} scenes", index.runs.len(), ctx.scenes.len())
    } else {
        format!("{} runs on {} scenes, {failed} of them failed (they rank last)", index.runs.len(), ctx.scenes.len())
    };
    let ran: std::collections::BTreeSet<String> = index.runs.iter().map(|r| r.scene.clone()).collect();
    let environment_image = ctx.images.for_environment(info.environment);
    let upload = Upload {
        runs: index.runs,
        metrics: metrics.iter().map(AnyMetric::info).collect(),
        scenes: ctx
            .scenes
            .iter()
            .filter(|s| !seeds || ran.contains(&path_safe_name(&s.meta.name)))
            .map(|s| SceneProvenance {
                name: path_safe_name(&s.meta.name),
                tags: s.meta.tags.clone(),
                scene_hash: s.scene_hash.clone(),
                reference_hash: s.reference_hash.clone(),
            })
            .collect(),
        provenance: Provenance {
            image_digest: Some(environment_image.id.clone()),
            images: [
                (
                    info.environment.as_str().to_string(),
                    ImageRef { tag: environment_image.tag.clone(), id: environment_image.id.clone() },
                ),
                (
                    "renderer".to_string(),
                    ImageRef { tag: ctx.images.renderer.tag.clone(), id: ctx.images.renderer.id.clone() },
                ),
            ]
            .into(),
            commit: Some(claim.commit.clone()),
            version: Some(info.versions[0].name.clone()),
            runner: Some(ctx.runner.1.clone()),
            runner_id: Some(ctx.runner.0.clone()),
            machine: ctx
                .machine
                .record(&ctx.calibration.lock().map(|c| c.clone()).unwrap_or_else(|e| e.into_inner().clone())),
            limits: Some(SandboxLimits {
                run_timeout_s: ctx.config.run_timeout.as_secs_f64(),
                memory_mib: ctx.config.memory_mib,
                pids: ctx.config.pids,
            }),
            fbksd_ci: Some(env!("CARGO_PKG_VERSION").to_string()),
        },
    };
    Ok((upload, files, message))
}

/// The viewer's pixel files of the references the server lacks (it keeps
/// one per reference digest) and of the feature buffers made with them,
/// written under `results/references/`.
async fn references_to_upload(
    ctx: &JobContext,
    claim: &Claim,
    results: &Path,
) -> Result<Vec<(String, PathBuf)>, Failure> {
    let mut out = Vec::new();
    for scene in ctx.scenes.iter() {
        let hash = &scene.reference_hash;
        let buffers = fbksd_exchange::scenes::FEATURE_BUFFERS.iter().map(|b| Some(*b));
        for buffer in std::iter::once(None).chain(buffers) {
            let Some(name) = fbksd_exchange::pixels::uploaded_reference_name(hash, buffer) else { continue };
            let source = buffer.map_or_else(|| scene.meta.reference_file(), |b| scene.meta.feature_buffer_file(b));
            if (buffer.is_some() && !source.is_file()) || ctx.api.has_reference(claim, hash, buffer).await? {
                continue;
            }
            let path = results.join(&name);
            let bytes =
                tokio::task::spawn_blocking(move || fbksd_iqa::image::Image::read(&source).map(|i| i.pixels_file()))
                    .await
                    .map_err(|e| Failure::infrastructure(format!("encoding a reference panicked: {e}")))?
                    .map_err(|e| Failure::infrastructure(format!("the reference of {}: {e}", scene.meta.name)))?;
            std::fs::create_dir_all(results.join("references"))
                .and_then(|()| std::fs::write(&path, bytes))
                .map_err(|e| Failure::infrastructure(format!("{}: {e}", path.display())))?;
            out.push((name, path));
        }
    }
    Ok(out)
}

/// Every file under `dir` (sorted, `.git` left out), named relative to
/// `root`. Symbolic links are listed, never followed: the directory may be
/// a user's repository.
fn files_under(root: &Path, dir: &Path, out: &mut Vec<(String, PathBuf)>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    let mut entries: Vec<_> = entries.flatten().filter(|e| e.file_name() != ".git").collect();
    entries.sort_by_key(|e| e.file_name());
    for entry in entries {
        let path = entry.path();
        match entry.file_type() {
            Ok(t) if t.is_dir() => files_under(root, &path, out),
            Ok(_) => out.push((path.strip_prefix(root).unwrap_or(&path).to_string_lossy().into_owned(), path)),
            Err(_) => {}
        }
    }
}

/// The first line of build output that reports an error (a compiler's
/// `file:line:col: error: …`, `CMake Error …`, a Python `…Error: …`), which
/// leads a failed build's message.
fn first_error_line(output: &str) -> Option<String> {
    output
        .lines()
        .map(str::trim)
        .find(|line| {
            let lower = line.to_ascii_lowercase();
            lower.contains("error:") || lower.starts_with("cmake error") || lower.contains("fatal error")
        })
        .map(|line| line.chars().take(500).collect())
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_loud_build_is_held_to_the_log_bound_and_says_what_it_left_out() {
        let log = super::JobLog::default();
        let chunk = vec![b'y'; 64 << 10];
        // 64 MiB of `yes`, as fast as it comes, with no send in between.
        for _ in 0..1024 {
            log.raw(&chunk);
        }
        assert!(log.pending_bytes() <= super::MAX_PENDING_LOG, "{} bytes held", log.pending_bytes());
        log.line("[fbksd-ci] build failed");
        let text = log.buffer.lock().unwrap().pending.clone();
        assert!(text.contains(&format!("{} bytes of output left out", 1024 * 65536 - super::MAX_PENDING_LOG)));
        assert!(text.ends_with("[fbksd-ci] build failed\n"), "the runner's own line is kept");
    }

    #[test]
    fn a_symlinked_info_json_is_never_followed_on_the_host() {
        let src = tempfile::tempdir().unwrap();
        let secret = src.path().join("secret.json");
        std::fs::write(&secret, r#"{"short_name": "x", "technique_type": "denoiser"}"#).unwrap();
        std::os::unix::fs::symlink(&secret, src.path().join("info.json")).unwrap();
        let failure = super::check(src.path()).unwrap_err();
        assert_eq!(failure.reason, fbksd_manager::FailureReason::BuildFailed);
        assert!(failure.message.contains("info.json is a symbolic link"), "{}", failure.message);
    }

    #[test]
    fn a_failed_build_leads_with_its_first_error() {
        let output = "-- Configuring done\n[ 50%] Building CXX object main.cpp.o\n\
                      /technique/main.cpp:7:5: error: 'foo' was not declared in this scope\n\
                      /technique/main.cpp:9:1: error: expected ';'\nmake: *** [all] Error 2\n";
        assert_eq!(
            super::first_error_line(output).as_deref(),
            Some("/technique/main.cpp:7:5: error: 'foo' was not declared in this scope")
        );
        assert_eq!(
            super::first_error_line("CMake Error at CMakeLists.txt:3 (find_package):\n").as_deref(),
            Some("CMake Error at CMakeLists.txt:3 (find_package):")
        );
        assert_eq!(super::first_error_line("all good\n"), None);
    }
}
