//! The sandbox every container that runs user code (a build or a
//! technique) gets, and the renderer's too:
//!
//! - no network (`network_mode: none`), no capabilities, `no-new-privileges`,
//!   Docker's default seccomp profile (never overridden);
//! - a read-only root filesystem, a size-capped `/tmp` tmpfs, a non-root user;
//! - memory limit equal to memory + swap, a pids limit, pinned cores;
//! - `fsize` and `core` ulimits, a wall-time limit enforced here;
//! - Docker's copy of the output in a bounded ring (`local` log driver);
//! - only the mounts named in the [`ContainerSpec`]: never the Docker
//!   socket, the runner's work directory, the references or any token.
//!
//! Every container carries the labels [`RUNNER_LABEL`] and [`JOB_LABEL`],
//! so a runner removes what a job left behind when the job ends, and what
//! a killed runner left behind when it starts again.

use bollard::container::{
    Config, CreateContainerOptions, KillContainerOptions, ListContainersOptions, LogOutput, LogsOptions,
    RemoveContainerOptions, WaitContainerOptions,
};
use bollard::models::{HostConfig, HostConfigLogConfig, ResourcesUlimits};
use bollard::Docker;
use futures_util::StreamExt;
use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Label naming the runner that created a container.
pub const RUNNER_LABEL: &str = "org.fbksd.ci.runner";
/// Label naming the job a container belongs to.
pub const JOB_LABEL: &str = "org.fbksd.ci.job";

/// Largest file a container may write (RLIMIT_FSIZE): room for an 8K
/// result image and a full sample ring, not for filling a disk.
const MAX_FILE_BYTES: i64 = 4 << 30;

/// A host directory mounted into a container.
#[derive(Debug, Clone)]
pub struct Mount {
    /// Path on the host.
    pub host: PathBuf,
    /// Path in the container.
    pub container: String,
    /// Read-write (otherwise read-only).
    pub writable: bool,
}

/// One container to run.
#[derive(Debug, Clone)]
pub struct ContainerSpec {
    /// Image tag.
    pub image: String,
    /// Command and arguments.
    pub cmd: Vec<String>,
    /// `KEY=value` pairs (the only environment besides the image's own).
    pub env: Vec<String>,
    /// Mounts.
    pub mounts: Vec<Mount>,
    /// Working directory.
    pub working_dir: Option<String>,
    /// Memory (and memory + swap) limit in MiB.
    pub memory_mib: u64,
    /// The job it belongs to.
    pub job_id: String,
    /// Cores it is pinned to, when not all of the sandbox's.
    pub cpuset: Option<String>,
    /// Largest file it may write, when less than the sandbox's 4 GiB.
    pub max_file_bytes: Option<i64>,
}

/// How a container ended.
#[derive(Debug, Clone, PartialEq)]
pub struct ContainerEnd {
    /// Exit code (128 + n when killed by signal n).
    pub exit_code: i64,
    /// Killed by the kernel for going over its memory limit.
    pub out_of_memory: bool,
    /// Killed here for going over its wall-time limit.
    pub timed_out: bool,
}

/// Creates, runs and removes sandboxed containers for one runner.
#[derive(Debug, Clone)]
pub struct Sandbox {
    /// The Docker engine.
    pub docker: Docker,
    runner_id: String,
    cpuset: String,
    pids: i64,
    tmpfs_mib: u64,
    cpu_quota: Option<f64>,
}

impl Sandbox {
    /// A sandbox for the runner `runner_id`, its containers pinned to `cpuset` (`0-3`).
    pub fn new(docker: Docker, runner_id: &str, cpuset: String, pids: i64, tmpfs_mib: u64) -> Sandbox {
        Sandbox { docker, runner_id: runner_id.to_string(), cpuset, pids, tmpfs_mib, cpu_quota: None }
    }

    /// The same sandbox with every container under a quota of `cores` CPUs.
    pub fn with_cpu_quota(mut self, cores: Option<f64>) -> Sandbox {
        self.cpu_quota = cores;
        self
    }

    /// The user containers run as: `nobody`, whoever runs the runner. Never
    /// the runner's own user: a technique running as the owner of the
    /// rendezvous directory could write in it (stash samples between the
    /// budgets of a scene, swap the ring file for a link before it is
    /// made), and a build could touch the runner's files.
    pub fn user() -> (u32, u32) {
        (65534, 65534)
    }

    /// Empties `dir` from inside a container running as [`Sandbox::user`]:
    /// a runner that is not root cannot remove what a build wrote as that
    /// user. `image` is any image with `find`.
    pub async fn empty_as_container_user(&self, image: &str, dir: &std::path::Path) -> bool {
        let spec = ContainerSpec {
            image: image.to_string(),
            cmd: ["find", "/empty", "-mindepth", "1", "-delete"].map(String::from).to_vec(),
            env: Vec::new(),
            mounts: vec![Mount { host: dir.to_path_buf(), container: "/empty".into(), writable: true }],
            working_dir: None,
            memory_mib: 256,
            job_id: "cleanup".into(),
            cpuset: None,
            max_file_bytes: None,
        };
        matches!(self.run_to_end(&spec, Duration::from_secs(120), |_| {}).await, Ok((end, _)) if end.exit_code == 0)
    }

    /// The Docker host configuration of the sandbox.
    pub fn host_config(&self, spec: &ContainerSpec) -> HostConfig {
        let memory = (spec.memory_mib * 1024 * 1024) as i64;
        let ulimit =
            |name: &str, limit: i64| ResourcesUlimits { name: Some(name.into()), soft: Some(limit), hard: Some(limit) };
        HostConfig {
            network_mode: Some("none".into()),
            cap_drop: Some(vec!["ALL".into()]),
            security_opt: Some(vec!["no-new-privileges".into()]),
            readonly_rootfs: Some(true),
            tmpfs: Some(HashMap::from([(
                "/tmp".to_string(),
                format!("rw,nosuid,nodev,size={}m,mode=1777", self.tmpfs_mib),
            )])),
            memory: Some(memory),
            memory_swap: Some(memory),
            pids_limit: Some(self.pids),
            cpuset_cpus: Some(spec.cpuset.clone().unwrap_or_else(|| self.cpuset.clone())),
            nano_cpus: self.cpu_quota.map(|cores| (cores * 1e9) as i64),
            ulimits: Some(vec![
                ulimit("fsize", spec.max_file_bytes.unwrap_or(MAX_FILE_BYTES).min(MAX_FILE_BYTES)),
                ulimit("core", 0),
                ulimit("nofile", 4096),
            ]),
            ipc_mode: Some("private".into()),
            // Docker keeps a container's output on its own disk too: a
            // bounded ring, read live by `follow_output`, so a container
            // printing without pause costs at most this much of it.
            log_config: Some(HostConfigLogConfig {
                typ: Some("local".into()),
                config: Some(HashMap::from([
                    ("max-size".to_string(), "8m".to_string()),
                    ("max-file".to_string(), "2".to_string()),
                ])),
            }),
            binds: Some(
                spec.mounts
                    .iter()
                    .map(|m| format!("{}:{}:{}", m.host.display(), m.container, if m.writable { "rw" } else { "ro" }))
                    .collect(),
            ),
            ..Default::default()
        }
    }

    /// Creates and starts a container; returns its id. A container that
    /// cannot start is removed.
    pub async fn start(&self, spec: &ContainerSpec) -> Result<String, bollard::errors::Error> {
        let (uid, gid) = Sandbox::user();
        let labels = HashMap::from([
            (RUNNER_LABEL.to_string(), self.runner_id.clone()),
            (JOB_LABEL.to_string(), spec.job_id.clone()),
        ]);
        let config = Config {
            image: Some(spec.image.clone()),
            cmd: Some(spec.cmd.clone()),
            env: Some(spec.env.clone()),
            user: Some(format!("{uid}:{gid}")),
            working_dir: spec.working_dir.clone(),
            labels: Some(labels),
            network_disabled: Some(true),
            attach_stdout: Some(true),
            attach_stderr: Some(true),
            host_config: Some(self.host_config(spec)),
            ..Default::default()
        };
        let created = self.docker.create_container(None::<CreateContainerOptions<String>>, config).await?;
        if let Err(e) = self.docker.start_container::<String>(&created.id, None).await {
            self.remove(&created.id).await;
            return Err(e);
        }
        Ok(created.id)
    }

    /// Waits for a container to end, killing it after `limit`.
    pub async fn wait(&self, id: &str, limit: Option<Duration>) -> Result<ContainerEnd, bollard::errors::Error> {
        let waited = match limit {
            Some(limit) => tokio::time::timeout(limit, self.wait_exit(id)).await.ok(),
            None => Some(self.wait_exit(id).await),
        };
        let (exit_code, timed_out) = match waited {
            Some(code) => (code?, false),
            None => {
                self.kill(id).await;
                (self.wait_exit(id).await?, true)
            }
        };
        let state = self.docker.inspect_container(id, None).await?.state.unwrap_or_default();
        Ok(ContainerEnd { exit_code, out_of_memory: state.oom_killed.unwrap_or(false), timed_out })
    }

    async fn wait_exit(&self, id: &str) -> Result<i64, bollard::errors::Error> {
        let mut stream = self.docker.wait_container(id, None::<WaitContainerOptions<String>>);
        match stream.next().await {
            Some(Ok(r)) => Ok(r.status_code),
            Some(Err(bollard::errors::Error::DockerContainerWaitError { code, .. })) => Ok(code),
            Some(Err(e)) => Err(e),
            None => Ok(-1),
        }
    }

    /// Follows a container's output, handing each chunk to `sink` until it ends.
    pub async fn follow_output(&self, id: &str, mut sink: impl FnMut(&[u8])) {
        let options = LogsOptions::<String> { follow: true, stdout: true, stderr: true, ..Default::default() };
        let mut stream = self.docker.logs(id, Some(options));
        while let Some(Ok(chunk)) = stream.next().await {
            match chunk {
                LogOutput::StdOut { message } | LogOutput::StdErr { message } | LogOutput::Console { message } => {
                    sink(&message)
                }
                LogOutput::StdIn { .. } => {}
            }
        }
    }

    /// Kills a container (no error if it is gone).
    pub async fn kill(&self, id: &str) {
        let _ = self.docker.kill_container(id, Some(KillContainerOptions { signal: "SIGKILL" })).await;
    }

    /// Removes a container, killing it if it runs (no error if it is gone).
    pub async fn remove(&self, id: &str) {
        let options = RemoveContainerOptions { force: true, v: true, ..Default::default() };
        let _ = self.docker.remove_container(id, Some(options)).await;
    }

    /// Removes every container with `label=value` (a job's, or a runner's); returns how many.
    pub async fn remove_labelled(&self, label: &str, value: &str) -> usize {
        let filters = HashMap::from([("label".to_string(), vec![format!("{label}={value}")])]);
        let options = ListContainersOptions { all: true, filters, ..Default::default() };
        let Ok(containers) = self.docker.list_containers(Some(options)).await else { return 0 };
        for c in &containers {
            if let Some(id) = &c.id {
                self.remove(id).await;
            }
        }
        containers.len()
    }

    /// Removes every container of this runner (left by a runner that was killed).
    pub async fn remove_runner_containers(&self) -> usize {
        self.remove_labelled(RUNNER_LABEL, &self.runner_id).await
    }

    /// Removes every container of a job.
    pub async fn remove_job_containers(&self, job_id: &str) -> usize {
        self.remove_labelled(JOB_LABEL, job_id).await
    }

    /// Runs a container to its end within `limit`, handing its output to
    /// `sink`, and removes it. Returns how it ended and how long it took.
    pub async fn run_to_end(
        &self,
        spec: &ContainerSpec,
        limit: Duration,
        sink: impl FnMut(&[u8]),
    ) -> Result<(ContainerEnd, Duration), bollard::errors::Error> {
        let started = Instant::now();
        let id = self.start(spec).await?;
        let (end, ()) = tokio::join!(self.wait(&id, Some(limit)), self.follow_output(&id, sink));
        self.remove(&id).await;
        Ok((end?, started.elapsed()))
    }
}

/// CPU time and peak memory of a running container, read from its cgroup
/// (v1 with the cgroupfs driver, or v2), as the kernel counts them.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Usage {
    /// User + system CPU time.
    pub cpu: Duration,
    /// Peak memory in bytes.
    pub peak_memory: u64,
}

impl Usage {
    /// The container's usage so far, when its cgroup can be found.
    pub fn read(id: &str) -> Option<Usage> {
        let read = |p: String| std::fs::read_to_string(p).ok().and_then(|s| s.trim().parse::<u64>().ok());
        let v1 = format!("/sys/fs/cgroup/cpuacct/docker/{id}/cpuacct.usage");
        if let Some(ns) = read(v1) {
            let peak = read(format!("/sys/fs/cgroup/memory/docker/{id}/memory.max_usage_in_bytes")).unwrap_or(0);
            return Some(Usage { cpu: Duration::from_nanos(ns), peak_memory: peak });
        }
        for dir in [format!("/sys/fs/cgroup/system.slice/docker-{id}.scope"), format!("/sys/fs/cgroup/docker/{id}")] {
            let Ok(stat) = std::fs::read_to_string(format!("{dir}/cpu.stat")) else { continue };
            let usec = stat.lines().find_map(|l| l.strip_prefix("usage_usec ")).and_then(|v| v.trim().parse().ok());
            let peak = read(format!("{dir}/memory.peak")).unwrap_or(0);
            return Some(Usage { cpu: Duration::from_micros(usec.unwrap_or(0)), peak_memory: peak });
        }
        None
    }
}
