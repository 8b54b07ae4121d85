//! Helpers for the end-to-end tests: finding the workspace's binaries and
//! writing analytic scenes. The tests themselves are in `tests/tests/`.
//!
//! The tests start real processes (the `fbksd` CLI, the analytic renderer,
//! techniques), so the workspace's binaries must be built first:
//! `cargo build --workspace` (README's test command does it; it also builds `libfbksd.so`).

use std::path::{Path, PathBuf};

/// The directory holding the workspace's binaries (`target/<profile>`).
pub fn bin_dir() -> PathBuf {
    // Test executables live in target/<profile>/deps.
    let exe = std::env::current_exe().expect("current_exe");
    let deps = exe.parent().expect("exe has a parent");
    let dir = if deps.ends_with("deps") { deps.parent().unwrap() } else { deps };
    dir.to_path_buf()
}

/// Path of a workspace binary; panics with the command that builds it.
pub fn bin(name: &str) -> String {
    let path = bin_dir().join(name);
    assert!(path.is_file(), "{} is missing: run `cargo build --workspace` first", path.display());
    path.to_string_lossy().into_owned()
}

/// Writes an analytic scene file and returns its path.
pub fn analytic_scene(dir: &Path, name: &str, width: u32, height: u32) -> PathBuf {
    let path = dir.join(format!("{name}.json"));
    std::fs::write(&path, format!(r#"{{"width": {width}, "height": {height}}}"#)).unwrap();
    path
}

/// The analytic renderer's command for a scene, with optional extra flags.
pub fn renderer_argv(scene: &Path, flags: &[&str]) -> Vec<String> {
    let mut argv = vec![bin("fbksd-analytic-renderer")];
    argv.extend(flags.iter().map(|s| s.to_string()));
    argv.push(scene.to_string_lossy().into_owned());
    argv
}

/// Writes a scene directory's `fbksd-scene.json`.
pub fn scene_meta(dir: &Path, name: &str, file: &str, renderer: &str, spp: &[u64], width: u32, height: u32) {
    let meta = serde_json::json!({
        "name": name, "path": file, "ref-img": "reference.exr", "renderer": renderer,
        "category": "experimental", "tags": [], "spp": spp, "width": width, "height": height,
        "reference": {"method": "render", "spp": 4096}, "description": "a test scene",
    });
    std::fs::write(dir.join("fbksd-scene.json"), serde_json::to_vec_pretty(&meta).unwrap()).unwrap();
}
