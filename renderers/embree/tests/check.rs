//! `fbksd-embree check`: what a scene uses, every construct it would need
//! (file and line, past the first), and its conversions.

use std::process::Command;

const SCENE: &str = r#"LookAt 0 0 -5  0 0 0  0 1 0
Camera "perspective" "float fov" 45
Film "rgb" "integer xresolution" 16 "integer yresolution" 12
WorldBegin
Material "matte" "color Kd" [0.5 0.5 0.5]
Shape "frobnicated" "float radius" 1
MakeNamedMaterial "fur" "string type" "hair"
Shape "frobnicated"
Shape "sphere"
"#;

/// `fbksd-embree check` of `text` as a scene file, not yet started.
fn check_command(text: &str) -> (tempfile::TempDir, Command) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.pbrt");
    std::fs::write(&path, text).unwrap();
    let mut command = Command::new(env!("CARGO_BIN_EXE_fbksd-embree"));
    command.arg("check").arg(&path);
    (dir, command)
}

fn check(text: &str) -> (bool, String) {
    let (_dir, mut command) = check_command(text);
    let out = command.output().unwrap();
    (out.status.success(), String::from_utf8(out.stdout).unwrap())
}

#[test]
fn check_lists_what_a_scene_uses_and_every_construct_it_would_need() {
    let (ok, out) = check(SCENE);
    assert!(!ok, "the scene does not load: {out}");
    for line in [
        "2 × Shape \"frobnicated\"",
        "1 × MakeNamedMaterial \"hair\"",
        "1 × Material \"matte\"",
        "1 × Shape \"sphere\"",
    ] {
        assert!(out.contains(line), "no {line:?} in {out}");
    }
    // Every problem, not just the first: both kinds, with their lines.
    assert!(out.contains("It does not load. It would need (3 problems)"), "{out}");
    assert!(
        out.contains("scene.pbrt:6: unsupported shape \"frobnicated\"") && out.contains("(and 1 more like it)"),
        "{out}"
    );
    assert!(out.contains("scene.pbrt:7: unsupported material \"hair\""), "{out}");
    assert!(out.contains("scene.pbrt:5: pbrt-v3 material \"matte\" read as \"diffuse\""), "{out}");
}

#[test]
fn check_of_a_scene_that_loads_prints_its_info() {
    let text =
        SCENE.lines().filter(|l| !l.contains("frobnicated") && !l.contains("hair")).collect::<Vec<_>>().join("\n");
    let (ok, out) = check(&text);
    assert!(ok, "{out}");
    assert!(out.contains("It loads:") && out.contains("width = 16") && out.contains("height = 12"), "{out}");
    assert!(!out.contains("would need"), "{out}");
}

#[test]
fn check_piped_into_a_reader_that_stops_ends_quietly() {
    use std::os::unix::process::ExitStatusExt;
    use std::process::Stdio;
    let (_dir, mut command) = check_command(SCENE);
    // As `fbksd-embree check scene.pbrt | head -0`: the reader is gone before the first line.
    // The reader end is closed before the child starts; closing it after spawning raced
    // with a child fast enough to write everything into the pipe's buffer first.
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let out = command.stdout(writer).stderr(Stdio::piped()).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    const SIGPIPE: i32 = 13;
    assert_eq!(out.status.signal(), Some(SIGPIPE), "ended by the closed pipe, as `head` expects: {stderr}");
}
