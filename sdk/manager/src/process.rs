//! Child processes under supervision: each in its own process group (so a
//! kill reaches everything it started), killed if the manager dies, and
//! reaped with `wait4` so that its CPU time and peak memory are measured by
//! the kernel, not reported by itself.
//!
//! Note: the parent-death signal fires when the *thread* that started the
//! child exits, so children are started from threads that outlive them
//! (the caller of `SceneRunner::run`).

use std::fs::File;
use std::io;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::Path;
use std::process::{Command, ExitStatus, Stdio};
use std::sync::mpsc::Sender;
use std::time::{Duration, Instant};

/// How a supervised process ended, as measured by the kernel.
#[derive(Debug, Clone, PartialEq)]
pub struct ExitInfo {
    /// Exit status.
    pub status: ExitStatus,
    /// User + system CPU time.
    pub cpu_time: Duration,
    /// Peak resident set size in bytes.
    pub peak_rss: u64,
    /// When the process was reaped.
    pub at: Instant,
}

impl ExitInfo {
    /// "exit code 3", "killed by signal 9 (SIGKILL)", ….
    pub fn describe(&self) -> String {
        describe_status(self.status)
    }
}

/// A human description of an exit status.
pub fn describe_status(status: ExitStatus) -> String {
    if let Some(code) = status.code() {
        return format!("exit code {code}");
    }
    match status.signal() {
        Some(sig) => format!("killed by signal {sig} ({})", signal_name(sig)),
        None => "unknown exit status".into(),
    }
}

fn signal_name(sig: i32) -> &'static str {
    match sig {
        libc::SIGSEGV => "SIGSEGV",
        libc::SIGABRT => "SIGABRT",
        libc::SIGKILL => "SIGKILL",
        libc::SIGTERM => "SIGTERM",
        libc::SIGBUS => "SIGBUS",
        libc::SIGFPE => "SIGFPE",
        libc::SIGILL => "SIGILL",
        libc::SIGINT => "SIGINT",
        _ => "other",
    }
}

/// A running child process.
#[derive(Debug)]
pub struct Supervised {
    pid: i32,
    /// When it was started.
    pub started: Instant,
}

impl Supervised {
    /// Starts `argv` with `env` added, output appended to `log` (or
    /// inherited when `None`), and reports its end to `on_exit` (from a
    /// waiter thread).
    pub fn spawn(
        argv: &[String],
        env: &[(&str, &std::ffi::OsStr)],
        log: Option<&Path>,
        on_exit: impl FnOnce(ExitInfo) + Send + 'static,
    ) -> io::Result<Self> {
        let (program, args) =
            argv.split_first().ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "empty command"))?;
        let mut command = Command::new(program);
        command.args(args).stdin(Stdio::null()).process_group(0);
        // Its own process group keeps a terminal's Ctrl-C from reaching it, so
        // tie its life to the manager's instead: killed if the manager dies.
        // SAFETY: prctl is async-signal-safe; nothing else runs between fork and exec.
        unsafe {
            command.pre_exec(|| {
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL) != 0 {
                    return Err(io::Error::last_os_error());
                }
                Ok(())
            });
        }
        if let Some(log) = log {
            let log_file = File::options().create(true).append(true).open(log)?;
            command.stdout(log_file.try_clone()?).stderr(log_file);
        }
        for (k, v) in env {
            command.env(k, v);
        }
        let started = Instant::now();
        let child = command.spawn().map_err(|e| io::Error::new(e.kind(), format!("cannot start {program:?}: {e}")))?;
        let pid = child.id() as i32;
        // The waiter reaps with wait4; std's Child is dropped unreaped on purpose.
        drop(child);
        std::thread::Builder::new().name(format!("wait-{pid}")).spawn(move || on_exit(wait4(pid)))?;
        Ok(Supervised { pid, started })
    }

    /// The process id.
    pub fn pid(&self) -> i32 {
        self.pid
    }

    /// Kills the whole process group (idempotent).
    pub fn kill(&self) {
        // SAFETY: plain syscall; a negative pid names the group this child leads.
        unsafe {
            libc::kill(-self.pid, libc::SIGKILL);
        }
    }
}

fn wait4(pid: i32) -> ExitInfo {
    let mut status = 0;
    // SAFETY: rusage is plain data, written by the kernel.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    loop {
        // SAFETY: valid pointers to locals.
        let r = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
        if r == pid {
            break;
        }
        if r < 0 && io::Error::last_os_error().kind() != io::ErrorKind::Interrupted {
            // Someone else reaped it: report a failure without numbers.
            return ExitInfo {
                status: ExitStatus::from_raw(255 << 8),
                cpu_time: Duration::ZERO,
                peak_rss: 0,
                at: Instant::now(),
            };
        }
    }
    let tv = |t: libc::timeval| Duration::new(t.tv_sec as u64, t.tv_usec as u32 * 1000);
    ExitInfo {
        status: ExitStatus::from_raw(status),
        cpu_time: tv(usage.ru_utime) + tv(usage.ru_stime),
        peak_rss: usage.ru_maxrss as u64 * 1024,
        at: Instant::now(),
    }
}

/// The last `max_lines` lines of a log file, for error messages.
pub fn log_tail(path: &Path, max_lines: usize) -> String {
    let text = std::fs::read(path).unwrap_or_default();
    let text = String::from_utf8_lossy(&text);
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(max_lines)..].join("\n")
}

/// A channel-friendly `on_exit` that tags the exit with `tag`.
pub fn report_to<T: Send + 'static>(
    tx: Sender<T>,
    tag: impl FnOnce(ExitInfo) -> T + Send + 'static,
) -> impl FnOnce(ExitInfo) + Send + 'static {
    move |info| {
        let _ = tx.send(tag(info));
    }
}

/// This process's peak resident set size in bytes (Linux `VmHWM`).
pub fn self_peak_rss() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        .map_or(0, |kb| kb * 1024)
}
