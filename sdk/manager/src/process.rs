//! Child processes under supervision: each in its own process group (so a
//! kill reaches everything it started), killed if the manager dies, and
//! reaped with `wait4` so that its CPU time and peak memory are measured by
//! the kernel, not reported by itself.
//!
//! How a run's processes come to be is a [`Launcher`]'s business: the
//! [`LocalLauncher`] starts them here as [`Supervised`] children; the CI
//! runner starts each in its own sandboxed container, sharing only the
//! rendezvous directory.
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
    /// Whether it was killed for going over its memory limit (a container's
    /// limit; a local process is never marked).
    pub out_of_memory: bool,
}

impl ExitInfo {
    /// "exit code 3", "killed by signal 9 (SIGKILL)", ….
    pub fn describe(&self) -> String {
        if self.out_of_memory {
            return "killed by the kernel: out of memory".into();
        }
        describe_status(self.status)
    }
}

/// Which process of a run is to be started.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProcessRole {
    /// The scene's renderer (trusted).
    Renderer,
    /// The technique under test (untrusted).
    Technique,
}

/// What a [`Launcher`] is asked to start.
#[derive(Debug, Clone, Copy)]
pub struct LaunchSpec<'a> {
    /// Renderer or technique.
    pub role: ProcessRole,
    /// The command.
    pub argv: &'a [String],
    /// The run's rendezvous directory, to be named by `FBKSD_RENDEZVOUS`.
    pub rendezvous: &'a Path,
    /// The technique's session token, to be passed as `FBKSD_SESSION`.
    pub session_token: Option<&'a str>,
    /// Where its output goes (inherited when `None`).
    pub log: Option<&'a Path>,
}

/// A started process: the manager only ever kills it; its end arrives
/// through the `on_exit` callback given to [`Launcher::launch`].
pub trait Running: Send {
    /// Kills it and everything it started (idempotent).
    fn kill(&self);

    /// When its program started: the technique's clock starts here, so a
    /// container's creation is not counted as the technique's time.
    fn started_at(&self) -> Instant;

    /// A clock of the CPU time it has used so far (all its threads), read
    /// while it runs; `None` where it cannot be read. The manager charges
    /// the technique the CPU it burns while it waits for the renderer.
    fn cpu_clock(&self) -> Option<CpuClock> {
        None
    }

    /// A clock of the CPU time used so far by every thread of every process
    /// it started (its process group here, its container's cgroup in a
    /// sandbox): the run's cost is read off it, so work handed to a helper
    /// thread or a child process is charged. It may take a few milliseconds
    /// to read; the manager reads it twice a run.
    fn tree_cpu_clock(&self) -> Option<CpuClock> {
        self.cpu_clock()
    }
}

/// Reads a running process's CPU time so far (`None` once it is gone).
pub type CpuClock = Box<dyn Fn() -> Option<std::time::Duration> + Send>;

/// Starts a run's processes.
pub trait Launcher: std::fmt::Debug + Send + Sync {
    /// Starts `spec` and reports its end to `on_exit`, exactly once.
    fn launch(&self, spec: &LaunchSpec<'_>, on_exit: Box<dyn FnOnce(ExitInfo) + Send>) -> io::Result<Box<dyn Running>>;

    /// Whether the processes run as another user (in containers), so the
    /// rendezvous directory's files must be open to them.
    fn shares_files_with_other_users(&self) -> bool {
        false
    }
}

/// Starts processes on this machine, as children of the manager.
#[derive(Debug, Clone, Copy, Default)]
pub struct LocalLauncher;

impl Launcher for LocalLauncher {
    fn launch(&self, spec: &LaunchSpec<'_>, on_exit: Box<dyn FnOnce(ExitInfo) + Send>) -> io::Result<Box<dyn Running>> {
        let mut env = vec![(fbksd_core::rendezvous::ENV_VAR, spec.rendezvous.as_os_str())];
        if let Some(token) = spec.session_token {
            env.push((fbksd_core::rendezvous::SESSION_ENV_VAR, std::ffi::OsStr::new(token)));
        }
        Ok(Box::new(Supervised::spawn(spec.argv, &env, spec.log, on_exit)?))
    }
}

impl Running for Supervised {
    fn kill(&self) {
        Supervised::kill(self)
    }

    fn started_at(&self) -> Instant {
        self.started
    }

    fn cpu_clock(&self) -> Option<CpuClock> {
        let pid = self.pid;
        process_cpu(pid)?;
        Some(Box::new(move || process_cpu(pid)))
    }

    fn tree_cpu_clock(&self) -> Option<CpuClock> {
        // Not read here: each read scans /proc, and a group it cannot read reads as `None` later.
        let group = self.pid;
        Some(Box::new(move || process_group_cpu(group)))
    }
}

/// The CPU time so far of every process in the process group `group`: each
/// member's own clock (all its threads, to the nanosecond) plus what the
/// children it reaped used (the kernel keeps those in clock ticks). A member
/// that has exited but is not yet reaped counts by its ticks. `None` when
/// the group has no member left.
///
/// A process that leaves the group (`setsid`) is not seen; the service's
/// runner reads the container's cgroup instead, which nothing escapes.
pub fn process_group_cpu(group: i32) -> Option<Duration> {
    // SAFETY: sysconf has no preconditions.
    let ticks_per_second = unsafe { libc::sysconf(libc::_SC_CLK_TCK) }.max(1) as f64;
    let ticks = |n: u64| Duration::from_secs_f64(n as f64 / ticks_per_second);
    let mut total = Duration::ZERO;
    let mut members = 0;
    for entry in std::fs::read_dir("/proc").ok()?.flatten() {
        let Some(pid) = entry.file_name().to_str().and_then(|n| n.parse::<i32>().ok()) else { continue };
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else { continue };
        let Some(stat) = ProcStat::parse(&stat) else { continue };
        if stat.group != group {
            continue;
        }
        members += 1;
        let own = if stat.zombie { None } else { process_cpu(pid) };
        total += own.unwrap_or_else(|| ticks(stat.ticks)) + ticks(stat.children_ticks);
    }
    (members > 0).then_some(total)
}

/// What `/proc/<pid>/stat` says that [`process_group_cpu`] needs.
#[derive(Debug, PartialEq)]
struct ProcStat {
    group: i32,
    zombie: bool,
    /// User + system time, in clock ticks.
    ticks: u64,
    /// User + system time of the reaped children, in clock ticks.
    children_ticks: u64,
}

impl ProcStat {
    fn parse(stat: &str) -> Option<ProcStat> {
        // The command name may hold spaces and parentheses: fields start after the last ')'.
        let fields: Vec<&str> = stat[stat.rfind(')')? + 1..].split_whitespace().collect();
        let number = |i: usize| fields.get(i)?.parse::<u64>().ok();
        Some(ProcStat {
            zombie: *fields.first()? == "Z",
            group: fields.get(2)?.parse().ok()?,
            ticks: number(11)? + number(12)?,
            children_ticks: number(13)? + number(14)?,
        })
    }
}

/// A process's CPU clock (all its threads), read once; `None` once it is gone.
fn process_cpu(pid: i32) -> Option<Duration> {
    let mut clock: libc::clockid_t = 0;
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: each call writes one plain value; a vanished process fails cleanly.
    let ok = unsafe { libc::clock_getcpuclockid(pid, &mut clock) == 0 && libc::clock_gettime(clock, &mut ts) == 0 };
    ok.then(|| Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32))
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
                out_of_memory: false,
            };
        }
    }
    let tv = |t: libc::timeval| Duration::new(t.tv_sec as u64, t.tv_usec as u32 * 1000);
    ExitInfo {
        status: ExitStatus::from_raw(status),
        cpu_time: tv(usage.ru_utime) + tv(usage.ru_stime),
        peak_rss: usage.ru_maxrss as u64 * 1024,
        at: Instant::now(),
        out_of_memory: false,
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn proc_stat_fields_follow_the_last_parenthesis() {
        let line = "4242 (a (b) c) S 1 4200 4200 0 -1 4194560 100 0 0 0 7 3 20 5 20 0 1 0 100 0 0";
        assert_eq!(ProcStat::parse(line), Some(ProcStat { group: 4200, zombie: false, ticks: 10, children_ticks: 25 }));
        assert_eq!(ProcStat::parse("1 (x) Z 0 9 9 0 -1 0 0 0 0 0 1 1 0 0").map(|s| s.zombie), Some(true));
        assert_eq!(ProcStat::parse("garbage"), None);
    }

    /// A child's burn, and a grandchild's that the child reaped, both count.
    #[test]
    fn a_process_group_is_charged_for_its_children() {
        let dir = tempfile::tempdir().unwrap();
        let done = dir.path().join("done");
        let path = std::ffi::CString::new(done.to_str().unwrap()).unwrap();
        // SAFETY: a valid C string.
        assert_eq!(unsafe { libc::mkfifo(path.as_ptr(), 0o600) }, 0);
        let burn = "i=0; while [ $i -lt 60000 ]; do i=$((i+1)); done";
        let script = format!("sh -c '{burn}'; {burn}; echo done > {}; sleep 30", done.display());
        let (tx, rx) = std::sync::mpsc::channel();
        let child =
            Supervised::spawn(&["sh".into(), "-c".into(), script], &[], None, move |info| tx.send(info).unwrap())
                .unwrap();
        let clock = child.tree_cpu_clock().expect("the group is readable");
        let own = child.cpu_clock().expect("the leader is readable");
        // Opening the FIFO returns once both burns are done.
        std::fs::read_to_string(&done).unwrap();
        let (tree, leader) = (clock().unwrap(), own().unwrap());
        child.kill();
        rx.recv().unwrap();
        // The grandchild's burn is as long as the leader's own.
        assert!(tree.as_secs_f64() > 1.5 * leader.as_secs_f64(), "group {tree:?}, leader alone {leader:?}");
        assert!(leader > Duration::from_millis(20), "the leader burned: {leader:?}");
    }
}
