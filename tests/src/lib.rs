//! Helpers for the end-to-end tests: finding the workspace's binaries and
//! writing analytic scenes. The tests themselves are in `tests/tests/`.
//!
//! The tests start real processes (the `fbksd` CLI, the analytic renderer,
//! techniques), so the workspace's binaries must be built first:
//! `cargo build --workspace` (README's test command does it; it also builds `libfbksd.so`).

use std::path::{Path, PathBuf};
use std::process::Command;

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

/// A path inside the repository's `sdk/` directory.
pub fn sdk(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../sdk").join(path)
}

/// Compiles a C program against the committed header and the built library.
pub fn compile_c(sources: &[&Path], out: &Path) -> PathBuf {
    compile("cc", &["-std=c99"], sources, out)
}

/// Compiles C++ sources against the C++ headers and the built library.
pub fn compile_cpp(sources: &[&Path], out: &Path) -> PathBuf {
    compile_cpp_with(sources, out, &[])
}

/// [`compile_cpp`] with extra compiler flags.
pub fn compile_cpp_with(sources: &[&Path], out: &Path, extra: &[&str]) -> PathBuf {
    let include = sdk("cpp/include");
    let mut flags = vec!["-std=c++14", "-I", include.to_str().unwrap()];
    flags.extend_from_slice(extra);
    compile("c++", &flags, sources, out)
}

fn compile(compiler: &str, flags: &[&str], sources: &[&Path], out: &Path) -> PathBuf {
    let lib = bin_dir();
    assert!(lib.join("libfbksd.so").is_file(), "libfbksd.so is missing: run `cargo build --workspace` first");
    // Libraries must follow the sources that use them.
    let (libs, flags): (Vec<&str>, Vec<&str>) = flags.iter().partition(|f| f.starts_with("-l"));
    let status = Command::new(compiler)
        .args(&flags)
        .args(["-Wall", "-Wextra", "-Werror", "-O2", "-pthread"])
        .arg("-I")
        .arg(sdk("capi/include"))
        .args(sources)
        .arg("-o")
        .arg(out)
        .arg(format!("-L{}", lib.display()))
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .arg("-lfbksd")
        .args(&libs)
        .status()
        .unwrap_or_else(|e| panic!("{compiler}: {e}"));
    assert!(status.success(), "compiling {sources:?} failed");
    out.to_path_buf()
}

/// A `PYTHONPATH` directory holding the `fbksd` package of this checkout:
/// its Python sources and the native module just built by cargo
/// (`lib_native.so`), linked, so tests never run a stale `pip install`.
pub fn python_path() -> PathBuf {
    let native = bin_dir().join("lib_native.so");
    assert!(native.is_file(), "{} is missing: run `cargo build --workspace` first", native.display());
    let package = bin_dir().join("python-sdk/fbksd");
    std::fs::create_dir_all(&package).unwrap();
    let sources = sdk("python/python/fbksd");
    let mut links: Vec<(PathBuf, PathBuf)> = std::fs::read_dir(&sources)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .map(|p| (p.clone(), package.join(p.file_name().unwrap())))
        .collect();
    links.push((native, package.join("_native.so")));
    for (target, link) in links {
        // Tests run in parallel processes: whoever links first wins, the links are identical.
        match std::os::unix::fs::symlink(&target, &link) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => panic!("linking {}: {e}", link.display()),
        }
    }
    package.parent().unwrap().to_path_buf()
}

/// Installs the SDK as a user would (`deploy/install-sdk.sh`, once per
/// `dir`) and builds the CMake project at `source` against it; returns the
/// build directory.
pub fn build_with_cmake(source: &Path, dir: &Path) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let prefix = dir.join("sdk");
    if !prefix.join("lib/cmake/fbksd").is_dir() {
        run(Command::new("bash").arg(root.join("deploy/install-sdk.sh")).arg(&prefix).arg(bin_dir()));
    }
    let name = source.file_name().unwrap().to_string_lossy();
    let build = dir.join(format!("build-{name}"));
    run(Command::new("cmake")
        .arg("-S")
        .arg(source)
        .arg("-B")
        .arg(&build)
        .arg(format!("-DCMAKE_PREFIX_PATH={}", prefix.display())));
    run(Command::new("cmake").arg("--build").arg(&build));
    build
}

/// Writes an executable script (a technique, a renderer, a wrapper) at `path`.
pub fn write_script(path: &Path, text: &str) {
    std::fs::write(path, text).unwrap();
    std::fs::set_permissions(path, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
}

/// Runs a command; panics with its output unless it succeeds.
pub fn run(cmd: &mut Command) -> std::process::Output {
    let out = cmd.output().unwrap_or_else(|e| panic!("{cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{cmd:?}: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}
