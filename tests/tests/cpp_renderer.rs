//! The C++ renderer API (`fbksd/renderer/RenderingServer.h`, `samples.h`)
//! through the whole protocol: the thesis's example A.4 (a renderer of
//! blue images whose evaluate callback returns at once and renders on its
//! own thread) compiles with its evident typos fixed, and serves the Rust
//! box filter, per-pixel and count requests alike.

use fbksd_tests::{bin, compile_cpp_with, sdk};
use std::process::Command;

#[test]
fn the_thesis_renderer_a4_serves_the_rust_box_filter() {
    let dir = tempfile::tempdir().unwrap();
    // A.4 leaves setLayout's and main's parameters unused.
    let a4 = compile_cpp_with(
        &[&sdk("cpp/examples/a4_blue_renderer.cpp")],
        &dir.path().join("a4"),
        &["-Wno-unused-parameter"],
    );
    // A.4 renders a fixed 1000×1000 image whatever the scene file says.
    let scene = dir.path().join("blue.scene");
    std::fs::write(&scene, "the blue renderer reads no scene\n").unwrap();
    let results = dir.path().join("results");
    let dumps = dir.path().join("dumps");
    std::fs::create_dir(&dumps).unwrap();
    let output = Command::new(bin("fbksd"))
        .args(["run", "-t", &format!("box={}", bin("box-filter"))])
        .args(["-t", &format!("count={}", bin("fbksd-conformance-technique"))])
        .args(["-r", a4.to_str().unwrap(), "-s", scene.to_str().unwrap()])
        .args(["--spp", "1,3", "--results", results.to_str().unwrap()])
        .env("FBKSD_CONFORMANCE", "count")
        .env("FBKSD_CONFORMANCE_OUT", dumps.join("count.bin"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    // At 1 spp the count scenario cannot split its budget in two; the box filter must still be fine.
    for spp in [1, 3] {
        let (w, h, rgb) =
            fbksd_iqa::image::read_exr(&results.join(format!("box/blue/{spp}_0.exr"))).unwrap_or_else(|e| {
                panic!("box filter at {spp} spp: {e}\n{stdout}{}", String::from_utf8_lossy(&output.stderr))
            });
        assert_eq!((w, h), (1000, 1000));
        assert!(rgb.chunks(3).all(|p| p == [0.0, 0.0, 1.0]), "every pixel is blue at {spp} spp");
    }
    let log: serde_json::Value =
        serde_json::from_slice(&std::fs::read(results.join("count/blue/3_0_log.json")).unwrap()).unwrap();
    assert_eq!(log["status"], "ok", "count requests through A.4's pixel-free pipes: {log}");
    assert_eq!(log["used_samples"], 3_000_000);
    let renderer_log = std::fs::read_to_string(results.join("renderer-logs/blue.log")).unwrap();
    assert!(renderer_log.contains("Done."), "A.4's finish callback ran: {renderer_log}");
}
