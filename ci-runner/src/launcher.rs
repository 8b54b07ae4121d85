//! The manager's processes as sandboxed containers.
//!
//! The manager (trusted, in the runner) keeps its clock, budget and
//! protocol checks; [`DockerLauncher`] only changes where the renderer and
//! the technique run: each in its own container under the [`sandbox`]
//! limits, the renderer from the trusted renderer image (scene files baked
//! in), the technique from its environment image with its own files mounted
//! read-only. The two share only the run's rendezvous directory, mounted at
//! [`RENDEZVOUS_MOUNT`].
//!
//! [`sandbox`]: crate::sandbox

use crate::sandbox::{ContainerSpec, Mount, Sandbox, Usage};
use fbksd_core::rendezvous;
use fbksd_manager::process::{CpuClock, ExitInfo};
use fbksd_manager::{LaunchSpec, Launcher, ProcessRole, Running};
use std::io::{self, Write};
use std::os::unix::process::ExitStatusExt;
use std::process::ExitStatus;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::runtime::Handle;

/// Where a container sees its run's rendezvous directory.
pub const RENDEZVOUS_MOUNT: &str = "/run/fbksd";

/// How one of the two roles' containers is made.
#[derive(Debug, Clone)]
pub struct RoleContainer {
    /// Image tag.
    pub image: String,
    /// Mounts besides the rendezvous directory.
    pub mounts: Vec<Mount>,
    /// Working directory.
    pub working_dir: Option<String>,
    /// Memory limit in MiB.
    pub memory_mib: u64,
    /// Cores, when not all of the sandbox's.
    pub cpuset: Option<String>,
}

/// Starts renderers and techniques in sandboxed containers.
#[derive(Debug)]
pub struct DockerLauncher {
    /// The sandbox.
    pub sandbox: Sandbox,
    /// The runtime that drives Docker (the manager calls from plain threads).
    pub handle: Handle,
    /// The job the containers belong to.
    pub job_id: String,
    /// The technique's container.
    pub technique: RoleContainer,
    /// The renderer's container.
    pub renderer: RoleContainer,
    /// Set when the job is no longer this runner's: nothing new starts.
    pub cancelled: Arc<AtomicBool>,
    /// Most output of one container kept in its log file: a technique
    /// printing without pause is cut there, with a line saying so, and
    /// runs on.
    pub max_output_bytes: usize,
}

impl Launcher for DockerLauncher {
    fn launch(&self, spec: &LaunchSpec<'_>, on_exit: Box<dyn FnOnce(ExitInfo) + Send>) -> io::Result<Box<dyn Running>> {
        if self.cancelled.load(Ordering::SeqCst) {
            return Err(io::Error::other("the job was cancelled"));
        }
        let role = match spec.role {
            ProcessRole::Technique => &self.technique,
            ProcessRole::Renderer => &self.renderer,
        };
        let mut mounts = role.mounts.clone();
        mounts.push(Mount { host: spec.rendezvous.to_path_buf(), container: RENDEZVOUS_MOUNT.into(), writable: true });
        let mut env = vec![
            format!("{}={RENDEZVOUS_MOUNT}", rendezvous::ENV_VAR),
            "HOME=/tmp".to_string(),
            "PYTHONDONTWRITEBYTECODE=1".to_string(),
        ];
        if let Some(token) = spec.session_token {
            env.push(format!("{}={token}", rendezvous::SESSION_ENV_VAR));
        }
        let container = ContainerSpec {
            image: role.image.clone(),
            cmd: spec.argv.to_vec(),
            env,
            mounts,
            working_dir: role.working_dir.clone(),
            memory_mib: role.memory_mib,
            job_id: self.job_id.clone(),
            cpuset: role.cpuset.clone(),
            max_file_bytes: None,
        };
        let sandbox = self.sandbox.clone();
        let id = self
            .handle
            .block_on(sandbox.start(&container))
            .map_err(|e| io::Error::other(format!("cannot start a container of {}: {e}", role.image)))?;
        // Cancelled while it started: the runner's clean-up may have listed
        // the job's containers before this one existed.
        if self.cancelled.load(Ordering::SeqCst) {
            self.handle.block_on(sandbox.remove(&id));
            return Err(io::Error::other("the job was cancelled"));
        }
        let started = Instant::now();
        let (log, max_output) = (spec.log.map(|p| p.to_path_buf()), self.max_output_bytes);
        let running =
            RunningContainer { id: id.clone(), sandbox: sandbox.clone(), handle: self.handle.clone(), started };
        self.handle.spawn(async move {
            let usage = Arc::new(Mutex::new(Usage::default()));
            // The cgroup disappears with the container: sample it while it runs.
            let poll = {
                let usage = usage.clone();
                let id = id.clone();
                async move {
                    loop {
                        if let Some(u) = Usage::read(&id) {
                            *usage.lock().unwrap() = u;
                        }
                        tokio::time::sleep(Duration::from_millis(50)).await;
                    }
                }
            };
            let output = async {
                let Some(log) = &log else { return };
                let Ok(mut file) = std::fs::File::options().create(true).append(true).open(log) else { return };
                let mut room = max_output;
                sandbox
                    .follow_output(&id, |bytes| {
                        if room == 0 {
                            return;
                        }
                        let kept = bytes.len().min(room);
                        let _ = file.write_all(&bytes[..kept]);
                        room -= kept;
                        if room == 0 {
                            let _ = writeln!(
                                file,
                                "\n[fbksd-ci] the output passed {} MiB: the rest of it is left out",
                                max_output >> 20
                            );
                        }
                    })
                    .await;
            };
            let end = tokio::select! {
                (end, ()) = async { tokio::join!(sandbox.wait(&id, None), output) } => end,
                () = poll => unreachable!("the poll never ends"),
            };
            let usage = *usage.lock().unwrap();
            let info = match end {
                Ok(end) => ExitInfo {
                    status: exit_status(end.exit_code),
                    cpu_time: usage.cpu,
                    peak_rss: usage.peak_memory,
                    at: Instant::now(),
                    out_of_memory: end.out_of_memory,
                },
                Err(e) => {
                    tracing::error!("container {id}: {e}");
                    ExitInfo {
                        status: ExitStatus::from_raw(255 << 8),
                        cpu_time: usage.cpu,
                        peak_rss: usage.peak_memory,
                        at: Instant::now(),
                        out_of_memory: false,
                    }
                }
            };
            sandbox.remove(&id).await;
            on_exit(info);
        });
        Ok(Box::new(running))
    }

    fn shares_files_with_other_users(&self) -> bool {
        true
    }
}

/// A container's exit code as a process status: Docker reports a death by
/// signal n as 128 + n.
fn exit_status(code: i64) -> ExitStatus {
    if (129..=128 + 64).contains(&code) {
        ExitStatus::from_raw((code - 128) as i32)
    } else {
        ExitStatus::from_raw(((code & 0xff) as i32) << 8)
    }
}

struct RunningContainer {
    id: String,
    sandbox: Sandbox,
    handle: Handle,
    started: Instant,
}

impl Running for RunningContainer {
    fn kill(&self) {
        let (sandbox, id) = (self.sandbox.clone(), self.id.clone());
        // Called from the manager's threads and from drops: never block on the runtime here.
        self.handle.spawn(async move { sandbox.kill(&id).await });
    }

    fn started_at(&self) -> Instant {
        self.started
    }

    fn cpu_clock(&self) -> Option<CpuClock> {
        let id = self.id.clone();
        Usage::read(&id)?;
        Some(Box::new(move || Usage::read(&id).map(|u| u.cpu)))
    }
}

#[cfg(test)]
mod tests {
    use super::exit_status;
    use std::os::unix::process::ExitStatusExt;

    #[test]
    fn docker_exit_codes_become_statuses() {
        assert_eq!(exit_status(0).code(), Some(0));
        assert_eq!(exit_status(3).code(), Some(3));
        assert_eq!(exit_status(137).signal(), Some(9));
        assert_eq!(exit_status(139).signal(), Some(11));
    }
}
