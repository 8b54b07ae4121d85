//! The attack suite: each repository tries one thing a hostile technique
//! might. Every attack that "wins" sends a result, so its job would succeed
//! and the test would fail; a contained attack ends with a typed failure
//! reason and leaves the server and the next job unaffected.

mod common;

use common::*;
use std::time::Duration;

/// What every attack script starts with: `send()` delivers a flat grey
/// image, which is how an attack that got through makes its job succeed.
const PRELUDE: &str = r#"#!/usr/bin/env python3
import os, sys, time
import fbksd.client as fc

def send(value=0.5):
    client = fc.BenchmarkClient()
    client.set_sample_layout(["COLOR_R", "COLOR_G", "COLOR_B"])
    result = client.get_result_buffer()
    result[...] = value
    client.send_result()

def escaped(what):
    print("ESCAPED:", what, flush=True)
    send()
    sys.exit(0)

def walk(top="/"):
    for root, dirs, files in os.walk(top):
        dirs[:] = [d for d in dirs if os.path.join(root, d) not in ("/proc", "/sys", "/dev")]
        for f in files:
            yield os.path.join(root, f)
"#;

const INFO: &str = r#"{"short_name": "NAME", "technique_type": "denoiser", "versions": [{"name": "default", "executable": "attack.py"}]}"#;

/// Stash a file between the budgets of a scene, or put a link where the
/// manager will create the next ring: both need a writable rendezvous
/// directory.
const RENDEZVOUS_TAMPERING: &str = r#"
rendezvous = os.environ["FBKSD_RENDEZVOUS"]
for name in ["stash.bin", "ring-2.f32", "result-2.f32"]:
    try:
        with open(os.path.join(rendezvous, name), "wb") as f:
            f.write(b"x")
        escaped(f"wrote {name} in the rendezvous directory")
    except OSError as e:
        print(f"{name}: {e}", flush=True)
try:
    os.symlink("/etc/passwd", os.path.join(rendezvous, "ring-3.f32"))
    escaped("made a link in the rendezvous directory")
except OSError as e:
    print(f"link: {e}", flush=True)
print("the rendezvous directory is not writable", flush=True)
sys.exit(3)
"#;

struct Attack {
    name: &'static str,
    script: String,
    state: &'static str,
    reason: Option<&'static str>,
    log_says: &'static str,
}

/// An attack whose repository is made apart from its script.
fn failed(name: &'static str, reason: &'static str, log_says: &'static str) -> Attack {
    Attack { name, script: String::new(), state: "failed", reason: Some(reason), log_says }
}

fn attack(name: &'static str, body: &str, reason: &'static str, log_says: &'static str) -> Attack {
    Attack { name, script: format!("{PRELUDE}\n{body}"), state: "failed", reason: Some(reason), log_says }
}

fn attacks(server_port: u16, scene_root: &str) -> Vec<Attack> {
    vec![
        attack(
            "network",
            &format!(
                r#"
import socket
for host, port in [("127.0.0.1", {server_port}), ("172.17.0.1", {server_port}), ("1.1.1.1", 53)]:
    try:
        socket.create_connection((host, port), timeout=3)
        escaped(f"connected to {{host}}:{{port}}")
    except OSError as e:
        print(f"no connection to {{host}}:{{port}}: {{e}}", flush=True)
sys.exit(3)
"#
            ),
            "crashed",
            "no connection to 1.1.1.1:53",
        ),
        attack(
            "fork-bomb",
            r#"
children = 0
try:
    while True:
        if os.fork() == 0:
            time.sleep(3600)
            os._exit(0)
        children += 1
except OSError as e:
    print(f"fork refused after {children} children: {e}", flush=True)
sys.exit(3)
"#,
            "crashed",
            "fork refused after",
        ),
        attack(
            "memory-bomb",
            r#"
hoard = []
while True:
    hoard.append(b"x" * (32 << 20))
"#,
            "out_of_memory",
            "memory limit",
        ),
        attack(
            "disk-fill",
            r#"
written = 0
try:
    with open("/tmp/fill", "wb") as f:
        while True:
            f.write(b"\0" * (1 << 20))
            f.flush()
            written += 1
except OSError as e:
    print(f"/tmp is full after {written} MiB: {e}", flush=True)
for path in ["/fill", "/technique/fill", "/run/fbksd/fill", "/var/tmp/fill", "/usr/fill"]:
    try:
        with open(path, "wb") as f:
            f.write(b"x")
        escaped(f"wrote {path}")
    except OSError as e:
        print(f"{path}: {e}", flush=True)
sys.exit(3)
"#,
            "crashed",
            "No space left on device",
        ),
        attack("infinite-loop", "\nwhile True:\n    pass\n", "timeout", "time"),
        attack(
            "read-reference",
            &format!(
                r#"
candidates = [p for p in walk() if p.endswith(".exr")]
candidates += ["{scene_root}/experimental/fireflies/reference.exr", "/scenes/experimental/fireflies/reference.exr"]
for p in candidates:
    try:
        open(p, "rb").read(16)
        escaped(f"read {{p}}")
    except OSError as e:
        print(f"{{p}}: {{e}}", flush=True)
print("no reference visible", flush=True)
sys.exit(3)
"#
            ),
            "crashed",
            "no reference visible",
        ),
        attack(
            "steal-tokens",
            &format!(
                r#"
# Spelled in pieces, so this script does not find itself.
needles = [b"fbksd" + s for s in (b"r_", b"j_", b"reg_")] + [b"{token_head}" + b"{token_tail}"]
if os.path.exists("/var/run/docker.sock") or os.path.exists("/run/docker.sock"):
    escaped("the Docker socket is here")
print("environment:", sorted(os.environ), flush=True)
for k, v in os.environ.items():
    if any(n in v.encode() for n in needles):
        escaped(f"token in ${{k}}")
paths = list(walk()) + [f"/proc/{{p}}/environ" for p in os.listdir("/proc") if p.isdigit()]
for p in paths:
    try:
        data = open(p, "rb").read(1 << 20)
    except OSError:
        continue
    if any(n in data for n in needles):
        escaped(f"token in {{p}}")
print(f"no token in {{len(paths)}} files", flush=True)
sys.exit(3)
"#,
                token_head = &REGISTRATION_TOKEN[..5],
                token_tail = &REGISTRATION_TOKEN[5..],
            ),
            "crashed",
            "no token in",
        ),
        attack(
            "write-scenes",
            &format!(
                r#"
candidates = [p for p in walk() if p.endswith((".pbrt", ".expr", "fbksd-scene.json"))]
candidates += ["{scene_root}/experimental/fireflies/fireflies.expr", "/scenes/experimental/fireflies/fireflies.expr"]
for p in candidates:
    try:
        with open(p, "a") as f:
            f.write(" defaced")
        escaped(f"wrote {{p}}")
    except OSError as e:
        print(f"{{p}}: {{e}}", flush=True)
print("no scene file writable", flush=True)
sys.exit(3)
"#
            ),
            "crashed",
            "no scene file writable",
        ),
        Attack {
            name: "linger",
            script: format!(
                "{PRELUDE}\nif os.fork() == 0:\n    os.setsid()\n    if os.fork() == 0:\n        os.execv(\"/bin/sleep\", [\"sleep\", \"31337\"])\n    os._exit(0)\nsend()\n"
            ),
            state: "succeeded",
            reason: None,
            log_says: "fireflies at 1 spp",
        },
        attack("rendezvous-tampering", RENDEZVOUS_TAMPERING, "crashed", "the rendezvous directory is not writable"),
        attack("nan-result", "\nsend(float('nan'))\n", "invalid_output", "NaN"),
        attack(
            "wrong-size",
            r#"
client = fc.BenchmarkClient()
client.set_sample_layout(["COLOR_R", "COLOR_G", "COLOR_B"])
os.truncate(os.path.join(os.environ["FBKSD_RENDEZVOUS"], "result-1.f32"), 12)
client.send_result()
"#,
            "invalid_output",
            "invalid_output",
        ),
    ]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_attack_is_contained_with_a_typed_reason() {
    images();
    references(&["experimental/fireflies"]);
    // One user pushes every attack: lift the daily run quota.
    let server = spawn_with(Db::Sqlite, |c| c.max_runs_per_day = 100).await;
    let port: u16 = server.url.rsplit(':').next().unwrap().parse().unwrap();
    let scene_root = workspace().join("scenes").display().to_string();
    let work = tempfile::tempdir().unwrap();
    // 15 s per run: steal-tokens reads every file of its container, which
    // took over 8 s on two loaded cores (it then ended `timeout`, not `crashed`).
    // Disk caps small enough to reach in a second.
    let env = vec![
        ("FBKSD_CI_MAX_BUILD_MIB", "64".to_string()),
        ("FBKSD_CI_MAX_OUTPUT_MIB", "1".to_string()),
        ("FBKSD_CI_MAX_CHECKOUT_MIB", "8".to_string()),
    ];
    let options =
        RunnerOptions { run_timeout: "15s", build_timeout: "15s", memory_mib: 256, env, ..Default::default() };
    let runner = RunnerProcess::start(&server.url, &work.path().join("runner"), &options);
    let mallory = server.user("mallory@example.org").await;

    let mut repositories: Vec<(Attack, tempfile::TempDir)> = attacks(port, &scene_root)
        .into_iter()
        .map(|a| {
            let info = INFO.replace("NAME", a.name);
            let repo = repository_with(&[("info.json", &info), ("attack.py", &a.script)]);
            (a, repo)
        })
        .collect();
    // A build that never ends.
    let never = repository_with(&[
        ("info.json", &INFO.replace("NAME", "endless-build").replace("attack.py", "never")),
        (
            "CMakeLists.txt",
            "cmake_minimum_required(VERSION 3.16)\nproject(never CXX)\nexecute_process(COMMAND sh -c \"while :; do :; done\")\n",
        ),
    ]);
    repositories.push((
        Attack {
            name: "endless-build",
            script: String::new(),
            state: "failed",
            reason: Some("timeout"),
            log_says: "the build did not end",
        },
        never,
    ));

    // A build printing without pause: the runner's log buffer stays
    // bounded and says what it left out.
    let cmake = |name: &str, body: &str| {
        repository_with(&[
            ("info.json", &INFO.replace("NAME", name).replace("attack.py", "never")),
            ("CMakeLists.txt", &format!("cmake_minimum_required(VERSION 3.16)\nproject(attack CXX)\n{body}\n")),
        ])
    };
    repositories.push((
        failed("loud-build", "build_failed", "left out"),
        cmake(
            "loud-build",
            // Long lines: Docker passes each line as a message, and short ones crawl.
            "execute_process(COMMAND sh -c \"yes $(head -c 4000 /dev/zero | tr '\\\\0' y) | head -c 100000000\")\n\
             message(FATAL_ERROR \"loud\")",
        ),
    ));
    // A build filling its build directory, file after file.
    repositories.push((
        failed("fill-build-dir", "over_limit", "the build directory passed 64 MiB"),
        cmake(
            "fill-build-dir",
            "execute_process(COMMAND sh -c \"i=0; while head -c 8000000 /dev/zero > /build/fill$i; do i=$((i+1)); done\")",
        ),
    ));
    // A technique printing without pause, then dying: its log file on the
    // runner's disk is cut at the cap, with a line saying so.
    repositories.push((
        failed("stdout-flood", "crashed", "the rest of it is left out"),
        repository_with(&[
            ("info.json", &INFO.replace("NAME", "stdout-flood")),
            (
                "attack.py",
                &format!("{PRELUDE}\nfor _ in range(100):\n    sys.stdout.write('y' * (1 << 20))\nsys.exit(3)\n"),
            ),
        ]),
    ));
    // A checkout larger than the runner takes (the server allows it: its
    // cap is for what it reads itself).
    let big = repository_with(&[("info.json", &INFO.replace("NAME", "big-clone")), ("attack.py", PRELUDE)]);
    let noise: Vec<u8> = (0..12u32 << 20).map(|i| (i.wrapping_mul(2654435761) >> 13) as u8).collect();
    std::fs::write(big.path().join("noise.bin"), noise).unwrap();
    commit_all(big.path(), "noise");
    repositories.push((failed("big-clone", "over_limit", "the checkout takes more than 8 MiB"), big));

    // FBKSD_ATTACKS=name,… runs only those (while working on one).
    if let Ok(only) = std::env::var("FBKSD_ATTACKS") {
        repositories.retain(|(a, _)| only.split(',').any(|n| n == a.name));
    }
    let mut report = Vec::new();
    for (attack, repo) in &repositories {
        report.push(expect_contained(&server, &mallory, attack, repo, &runner).await);
    }
    let lingering = std::process::Command::new("pgrep").args(["-f", "sleep 31337"]).output().unwrap();
    assert!(lingering.stdout.is_empty(), "a technique's process outlived its job: {:?}", lingering);

    // The server and another user's job are unaffected.
    let bea = server.user("bea@example.org").await;
    server.create_project(&bea, "box-filter-python", "private").await;
    let repo = technique_repository("box-filter-python");
    let (pushed, output) = push(repo.path(), &server.clone_url("box-filter-python", &bea.token), &["FBKSD_RUN"]);
    assert!(pushed, "{output}");
    let id = newest_job(&server, &bea, "box-filter-python", "benchmark").await;
    let job = finished_job(&server, &bea, &id, Duration::from_secs(300)).await;
    assert_eq!(job["state"], "succeeded", "{job}\n{}", log_text(&server, &bea, &id).await);
    eprintln!("attacks:\n{}", report.join("\n"));
}

/// Pushes `attack`'s repository for `user` and checks that its job ended as
/// expected, said so in its log and left no container; one report line.
async fn expect_contained(
    server: &TestServer,
    user: &TestUser,
    attack: &Attack,
    repo: &tempfile::TempDir,
    runner: &RunnerProcess,
) -> String {
    server.create_project(user, attack.name, "private").await;
    let (pushed, output) = push(repo.path(), &server.clone_url(attack.name, &user.token), &["FBKSD_RUN"]);
    assert!(pushed, "{output}");
    let id = newest_job(server, user, attack.name, "benchmark").await;
    let job = finished_job(server, user, &id, Duration::from_secs(300)).await;
    let log = log_text(server, user, &id).await;
    let context = format!("attack {}: {job}\n--- log:\n{log}\n--- runner:\n{}", attack.name, runner.output());
    assert!(!log.contains("ESCAPED"), "{context}");
    assert_eq!(job["state"], attack.state, "{context}");
    assert_eq!(job["failure_reason"].as_str(), attack.reason, "{context}");
    assert!(log.contains(attack.log_says), "expected {:?} in the log; {context}", attack.log_says);
    // The job's containers are gone, and nothing it started runs on.
    assert_eq!(containers_labelled("org.fbksd.ci.job", &id), Vec::<String>::new(), "{context}");
    format!("{}: {} {}", attack.name, job["state"], job["failure_reason"])
}

/// A runner that is not root (its own user, in the docker group): the
/// containers still run as `nobody`, so the technique cannot write the
/// rendezvous directory its runner owns, and the runner still cleans up
/// what a C++ build wrote as that user.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_runner_that_is_not_root_holds_too() {
    images();
    references(&["experimental/fireflies"]);
    let server = spawn_with(Db::Sqlite, |c| c.max_runs_per_day = 100).await;
    let work = tempfile::tempdir().unwrap();
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(work.path(), std::fs::Permissions::from_mode(0o711)).unwrap();
    }
    use std::os::unix::fs::MetadataExt;
    let docker_gid = std::fs::metadata("/var/run/docker.sock").unwrap().gid();
    let options =
        RunnerOptions { run_timeout: "15s", memory_mib: 256, user: Some((4242, docker_gid)), ..Default::default() };
    let runner = RunnerProcess::start(&server.url, &work.path().join("runner"), &options);
    let mallory = server.user("mallory@example.org").await;
    let tampering =
        attack("rendezvous-tampering", RENDEZVOUS_TAMPERING, "crashed", "the rendezvous directory is not writable");
    let repo =
        repository_with(&[("info.json", &INFO.replace("NAME", tampering.name)), ("attack.py", &tampering.script)]);
    expect_contained(&server, &mallory, &tampering, &repo, &runner).await;

    // Another user's C++ technique builds, runs and is cleaned up after.
    let bea = server.user("bea@example.org").await;
    server.create_project(&bea, "box-filter-cpp", "private").await;
    let repo = technique_repository("box-filter-cpp");
    let (pushed, output) = push(repo.path(), &server.clone_url("box-filter-cpp", &bea.token), &["FBKSD_RUN"]);
    assert!(pushed, "{output}");
    let id = newest_job(&server, &bea, "box-filter-cpp", "benchmark").await;
    let job = finished_job(&server, &bea, &id, Duration::from_secs(600)).await;
    assert_eq!(job["state"], "succeeded", "{job}\n{}\n{}", log_text(&server, &bea, &id).await, runner.output());
    let jobs = work.path().join("runner/jobs");
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    while std::fs::read_dir(&jobs).map(|d| d.count()).unwrap_or(0) > 0 {
        assert!(std::time::Instant::now() < deadline, "the job's directory is left:\n{}", runner.output());
        std::thread::sleep(Duration::from_millis(200));
    }
}
