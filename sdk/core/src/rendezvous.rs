//! The rendezvous directory: where the three processes of one run meet.
//!
//! The manager creates one private directory per run holding the control
//! socket and the shared-memory files. The renderer and the technique find
//! it through the [`ENV_VAR`] environment variable. Nothing else is global:
//! no ports, no fixed shared-memory names, so any number of runs can share a
//! host, and two containers share a run by sharing only this directory.

use std::path::{Path, PathBuf};

/// Environment variable holding the rendezvous directory's path.
pub const ENV_VAR: &str = "FBKSD_RENDEZVOUS";

/// Environment variable holding the session token of a technique the
/// manager started; its hello must carry it back.
pub const SESSION_ENV_VAR: &str = "FBKSD_SESSION";

/// The control socket's file name inside the rendezvous directory.
pub const CONTROL_SOCKET: &str = "control.sock";

/// Path of the control socket of a rendezvous directory.
pub fn control_socket(dir: &Path) -> PathBuf {
    dir.join(CONTROL_SOCKET)
}

/// The rendezvous directory named by the environment, if any.
pub fn from_env() -> Option<PathBuf> {
    std::env::var_os(ENV_VAR).map(PathBuf::from)
}

/// Where new rendezvous directories go: `$FBKSD_RUNTIME_DIR`, else
/// `/dev/shm` when it is a writable directory (memory-backed, so the ring
/// never touches a disk), else the system temporary directory.
pub fn default_parent() -> PathBuf {
    if let Some(dir) = std::env::var_os("FBKSD_RUNTIME_DIR") {
        return PathBuf::from(dir);
    }
    let shm = Path::new("/dev/shm");
    if shm.is_dir() && tempfile_probe(shm) {
        return shm.to_path_buf();
    }
    std::env::temp_dir()
}

fn tempfile_probe(dir: &Path) -> bool {
    let probe = dir.join(format!(".fbksd-probe-{}", std::process::id()));
    let ok = std::fs::write(&probe, b"").is_ok();
    let _ = std::fs::remove_file(&probe);
    ok
}

/// A fresh, unguessable session token (128 bits from the OS, in hex).
pub fn new_session_token() -> std::io::Result<String> {
    use std::io::Read;
    let mut bytes = [0u8; 16];
    std::fs::File::open("/dev/urandom")?.read_exact(&mut bytes)?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}
