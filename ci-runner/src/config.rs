//! The runner's settings: flags, or `FBKSD_*` environment variables.

use clap::Args;
use std::path::PathBuf;
use std::time::Duration;

/// Everything a runner needs to know.
#[derive(Debug, Clone, Args)]
pub struct RunnerConfig {
    /// The server's base URL, e.g. http://127.0.0.1:8096.
    #[arg(long, env = "FBKSD_SERVER")]
    pub server: String,

    /// The server's runner registration token (needed once: the runner
    /// token it buys is kept in the work directory).
    #[arg(long, env = "FBKSD_REGISTRATION_TOKEN", hide_env_values = true)]
    pub registration_token: Option<String>,

    /// This runner's name on the server (default: the host name).
    #[arg(long, env = "FBKSD_CI_NAME")]
    pub name: Option<String>,

    /// Where the runner keeps its identity and each job's files.
    #[arg(long, env = "FBKSD_CI_WORK_DIR", default_value = "fbksd-ci")]
    pub work_dir: PathBuf,

    /// The image manifest written by `deploy/build-images.sh`.
    #[arg(long, env = "FBKSD_CI_IMAGES")]
    pub images: PathBuf,

    /// The scene pool on this machine: the directory the renderer image
    /// holds at /scenes, with the references beside each scene.
    #[arg(long, env = "FBKSD_CI_SCENE_ROOT", default_value = "scenes")]
    pub scene_root: PathBuf,

    /// Scenes benchmarked, as directories under the scene root (repeatable;
    /// default: every experimental scene).
    #[arg(long = "scene", env = "FBKSD_CI_SCENES", value_delimiter = ',')]
    pub scenes: Vec<String>,

    /// Budgets in samples per pixel (default: each scene's own list).
    #[arg(long, env = "FBKSD_CI_SPP", value_delimiter = ',')]
    pub spp: Vec<u64>,

    /// How many times each run is made, with sample seeds 0, 1, …: metric
    /// values carry confidence intervals and the ranking ties what the
    /// noise cannot separate. 3 keeps a job on the default pool within a
    /// few minutes on two cores.
    #[arg(long, env = "FBKSD_CI_REPEATS", default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub repeats: u32,

    /// Cores every container is pinned to, e.g. "0-1" (default: all of this machine's).
    #[arg(long, env = "FBKSD_CI_CPUS")]
    pub cpus: Option<String>,

    /// A CPU quota for every container, in cores (Docker's `--cpus`, e.g.
    /// 0.5), for a runner that shares its machine. It is recorded with
    /// every result and is part of the runner class: under a quota costs
    /// moved by up to 13 % with the calibration within 2 % (README).
    #[arg(long, env = "FBKSD_CI_CPU_QUOTA", value_parser = parse_quota)]
    pub cpu_quota: Option<f64>,

    /// Memory of a technique's container (build or run), in MiB; swap is not allowed.
    #[arg(long, env = "FBKSD_CI_MEMORY_MIB", default_value_t = 2048)]
    pub memory_mib: u64,

    /// Memory of a renderer's container, in MiB.
    #[arg(long, env = "FBKSD_CI_RENDERER_MEMORY_MIB", default_value_t = 4096)]
    pub renderer_memory_mib: u64,

    /// Size of a container's writable /tmp, in MiB.
    #[arg(long, env = "FBKSD_CI_TMPFS_MIB", default_value_t = 256)]
    pub tmpfs_mib: u64,

    /// Most disk a checkout (with its `.git`) may take, in MiB; over it,
    /// the job fails `over_limit`.
    #[arg(long, env = "FBKSD_CI_MAX_CHECKOUT_MIB", default_value_t = 1024)]
    pub max_checkout_mib: u64,

    /// Most disk a C++ build directory may take, in MiB (checked while the
    /// build runs; no single file may pass it either); over it, the job
    /// fails `over_limit`.
    #[arg(long, env = "FBKSD_CI_MAX_BUILD_MIB", default_value_t = 2048)]
    pub max_build_mib: u64,

    /// Most output of one technique run kept on disk, in MiB: the rest is
    /// left out with a line saying so.
    #[arg(long, env = "FBKSD_CI_MAX_OUTPUT_MIB", default_value_t = 8)]
    pub max_output_mib: u64,

    /// Processes a container may hold at once.
    #[arg(long, env = "FBKSD_CI_PIDS", default_value_t = 256)]
    pub pids: i64,

    /// Wall-time limit of a build.
    #[arg(long, env = "FBKSD_CI_BUILD_TIMEOUT", default_value = "15m", value_parser = humantime::parse_duration)]
    pub build_timeout: Duration,

    /// Wall-time limit of one run (scene × budget).
    #[arg(long, env = "FBKSD_CI_RUN_TIMEOUT", default_value = "10m", value_parser = humantime::parse_duration)]
    pub run_timeout: Duration,

    /// A scene whose renderer ran this many times slower per sample than
    /// its usual on this runner (the median of its last jobs) is measured
    /// again: the machine was slow during those runs, and the technique's
    /// times with it (see `renderer_rates`).
    #[arg(long, env = "FBKSD_CI_REMEASURE_ABOVE", default_value_t = 1.2, value_parser = parse_slowdown)]
    pub remeasure_above: f64,

    /// How many times at most a scene measured while the machine was slow
    /// is measured again (0: never); the calmest measurement is kept.
    #[arg(long, env = "FBKSD_CI_MAX_REMEASURES", default_value_t = 2, value_parser = clap::value_parser!(u32).range(0..=10))]
    pub max_remeasures: u32,

    /// How long a claim waits for a job before asking again.
    #[arg(long, env = "FBKSD_CI_POLL_SECONDS", default_value_t = 20)]
    pub poll_seconds: u64,
}

/// A quota in cores: positive and finite.
fn parse_quota(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(cores) if cores.is_finite() && cores >= 0.01 => Ok(cores),
        _ => Err(format!("a CPU quota is a number of cores, 0.01 or more (e.g. 0.5), not {text:?}")),
    }
}

/// A slowdown ratio: finite and above 1 (1.2 is 20 % slower).
fn parse_slowdown(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(ratio) if ratio.is_finite() && ratio > 1.0 => Ok(ratio),
        _ => Err(format!("a slowdown is a ratio above 1 (1.2 is 20 % slower than usual), not {text:?}")),
    }
}

impl RunnerConfig {
    /// The scenes benchmarked: the configured ones, or every experimental scene.
    pub fn scene_dirs(&self) -> std::io::Result<Vec<String>> {
        if !self.scenes.is_empty() {
            return Ok(self.scenes.clone());
        }
        let mut found = Vec::new();
        for entry in std::fs::read_dir(self.scene_root.join("experimental"))? {
            let entry = entry?;
            if entry.path().join(fbksd_exchange::scenes::META_FILE).is_file() {
                found.push(format!("experimental/{}", entry.file_name().to_string_lossy()));
            }
        }
        found.sort();
        Ok(found)
    }

    /// The runner's name: configured, or the host name.
    pub fn runner_name(&self) -> String {
        self.name.clone().unwrap_or_else(|| {
            std::fs::read_to_string("/proc/sys/kernel/hostname").map_or("runner".into(), |h| h.trim().to_string())
        })
    }
}
