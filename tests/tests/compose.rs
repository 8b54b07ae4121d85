//! `deploy/compose.yaml`, brought up and checked by `deploy/compose-check.sh`
//! on this machine's Docker engine: PostgreSQL, the server and two runners,
//! the scene's reference made by one and downloaded by the other; a push
//! per runner, each doing one job; a runner stopped mid-job and its
//! job finished by the other; the board identical afterwards; a third
//! runner added to the running service, which downloads the reference, with
//! the time to its first job.
//! It uses the debug build the tests already made (`cargo build
//! --workspace`), as CI does. Prints the script's timings.

use std::path::{Path, PathBuf};
use std::process::Command;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// The server's settings: the fields of `Config` in server/src/config.rs.
fn server_settings() -> Vec<String> {
    let source = std::fs::read_to_string(workspace().join("server/src/config.rs")).unwrap();
    let body = source.split("pub struct Config {").nth(1).and_then(|rest| rest.split("\n}").next()).unwrap();
    body.lines()
        .filter_map(|l| l.trim().strip_prefix("pub ")?.split_once(':').map(|(name, _)| name.trim().to_string()))
        .collect()
}

/// The server refuses to start on an FBKSD_SERVER_* variable it does not
/// know: every one the compose file and its check name is a setting.
#[test]
fn the_compose_files_name_only_server_settings_the_server_has() {
    let settings = server_settings();
    assert!(settings.contains(&"lease_seconds".to_string()), "{settings:?}");
    let mut named = 0;
    for file in ["deploy/compose.yaml", "deploy/compose-check.sh"] {
        let text = std::fs::read_to_string(workspace().join(file)).unwrap();
        for (at, _) in text.match_indices("FBKSD_SERVER_") {
            let key: String = text[at + "FBKSD_SERVER_".len()..]
                .chars()
                .take_while(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || *c == '_')
                .collect();
            assert!(
                settings.contains(&key.to_lowercase()),
                "{file} names FBKSD_SERVER_{key}, which the server refuses"
            );
            named += 1;
        }
    }
    assert!(named > 5, "the compose files configure the server: {named}");
}

#[test]
fn compose_check_passes() {
    let bin = fbksd_tests::bin_dir();
    for program in ["fbksd-server", "fbksd-ci", "fbksd-procedural", "fbksd-embree", "libfbksd.so", "lib_native.so"] {
        assert!(
            bin.join(program).is_file(),
            "{} is missing: cargo build --workspace first",
            bin.join(program).display()
        );
    }
    // The images first, under the lock the runner's tests build theirs
    // with (same binaries, same content tags): then the check finds them.
    let images = Command::new("flock")
        .arg(bin.join("fbksd-images.lock"))
        .args(["bash", "deploy/build-service-images.sh", "--bin-dir"])
        .arg(&bin)
        .arg("--manifest")
        .arg(bin.join("fbksd-compose-images.json"))
        .current_dir(workspace())
        .output()
        .expect("flock runs");
    assert!(
        images.status.success(),
        "build-service-images.sh failed:\n{}{}",
        String::from_utf8_lossy(&images.stdout),
        String::from_utf8_lossy(&images.stderr)
    );

    let mut check = Command::new("bash");
    check.arg("deploy/compose-check.sh").arg("--bin-dir").arg(&bin).current_dir(workspace());
    for (key, _) in std::env::vars() {
        if key.starts_with("FBKSD_") {
            check.env_remove(key);
        }
    }
    let started = std::time::Instant::now();
    let out = check.output().expect("bash runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && stdout.lines().any(|l| l == "compose-check: passed"),
        "compose-check.sh failed ({}):\n{stdout}\n{stderr}",
        out.status
    );
    for line in stdout.lines().filter(|l| l.starts_with("compose-check: time")) {
        eprintln!("FIGURE {line}");
    }
    eprintln!("FIGURE compose-check.sh: {:.0} s in all", started.elapsed().as_secs_f64());
}
