//! Techniques written for FBKSD 2.x build and run unchanged: the corpus in
//! `sdk/cpp/compat/` (2.x build files, 2.x idioms) is built with CMake
//! against the installed SDK, run through `fbksd run` on the analytic
//! renderer, and each image is the one its technique must make. And the
//! client header leaves the renderer's names (DEPTH, COLOR_R, ...) to the
//! technique.

use fbksd_tests::{analytic_scene, bin, build_with_cmake, run, sdk};
use std::path::Path;
use std::process::Command;

const WIDTH: u32 = 37;
const HEIGHT: u32 = 21;

#[test]
fn the_2x_corpus_builds_unchanged_and_each_technique_makes_its_expected_image() {
    let dir = tempfile::tempdir().unwrap();
    let corpus = ["iterating-box", "centre-sampler", "openexr-omp-box"];
    let mut fbksd = Command::new(bin("fbksd"));
    fbksd.args(["run", "-t", &format!("rust-box={}", bin("box-filter"))]);
    for name in corpus {
        let build = build_with_cmake(&sdk(&format!("cpp/compat/{name}")), dir.path());
        fbksd.args(["-t", &format!("{name}={}", build.join(name).display())]);
    }
    let scene = analytic_scene(dir.path(), "compat", WIDTH, HEIGHT);
    let results = dir.path().join("results");
    let out = run(fbksd.args(["-r", &bin("fbksd-analytic-renderer"), "-s", scene.to_str().unwrap()]).args([
        "--spp",
        "4,9",
        "--results",
        results.to_str().unwrap(),
    ]));
    let printed = String::from_utf8_lossy(&out.stderr);

    for spp in [4u32, 9] {
        let read = |t: &str| {
            fbksd_iqa::image::read_exr(&results.join(format!("{t}/compat/{spp}_0.exr")))
                .unwrap_or_else(|e| panic!("{t} at {spp} spp: {e}\n{printed}"))
                .2
        };
        let box_filter = read("rust-box");
        close(&read("iterating-box"), &box_filter, 1e-6, &format!("iterating-box at {spp} spp"));
        // Through a half-float EXR: the box filter's image to half precision.
        close(&read("openexr-omp-box"), &box_filter, 1.0 / 1024.0, &format!("openexr-omp-box at {spp} spp"));
        // Every sample at its pixel's centre: red and green are the pixel's
        // position, blue (the analytic scene's TIME) the mean of the strata, ½.
        let centre: Vec<f32> = (0..HEIGHT)
            .flat_map(|y| {
                (0..WIDTH).flat_map(move |x| [(x as f32 + 0.5) / WIDTH as f32, (y as f32 + 0.5) / HEIGHT as f32, 0.5])
            })
            .collect();
        close(&read("centre-sampler"), &centre, 1e-5, &format!("centre-sampler at {spp} spp"));
    }
}

/// Equal within a relative tolerance, value by value.
fn close(got: &[f32], want: &[f32], tolerance: f32, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: size");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!((g - w).abs() <= tolerance * w.abs().max(1e-3), "{what}: value {i} is {g}, expected {w}");
    }
}

/// Compiles C++ against the SDK's headers only; the compiler's messages on failure.
fn compiles(dir: &Path, name: &str, source: &str) -> Result<(), String> {
    let file = dir.join(format!("{name}.cpp"));
    std::fs::write(&file, source).unwrap();
    let out = Command::new("c++")
        .args(["-std=c++14", "-fsyntax-only", "-Wall", "-Werror"])
        .arg("-I")
        .arg(sdk("cpp/include"))
        .arg("-I")
        .arg(sdk("capi/include"))
        .arg(&file)
        .output()
        .unwrap();
    out.status.success().then_some(()).ok_or_else(|| String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn a_technique_declares_its_own_depth_under_using_namespace_fbksd() {
    let dir = tempfile::tempdir().unwrap();
    let own_names = r#"#include <fbksd/client/BenchmarkClient.h>
using namespace fbksd;
enum { COLOR_R, COLOR_G, COLOR_B, DEPTH, IMAGE_X, NORMAL_X };
enum Feature { ALBEDO };
int main() { return COLOR_R + DEPTH + IMAGE_X + NORMAL_X + ALBEDO + int(std::numeric_limits<int>::digits > 0); }
"#;
    compiles(dir.path(), "own_names", own_names).unwrap();
    // The renderer's header still has them, so a renderer written for 2.x compiles too.
    let renderer = r#"#include <fbksd/renderer/SamplesPipe.h>
#include <fbksd/renderer/RenderingServer.h>
using namespace fbksd;
int main() { return int(DEPTH) + int(IMAGE_X) + int(NUM_FEATURES) - 34; }
"#;
    compiles(dir.path(), "renderer", renderer).unwrap();
    // And the client header alone really does not declare them.
    let qualified = "#include <fbksd/client/BenchmarkClient.h>\nint main() { return fbksd::DEPTH; }\n";
    let refused = compiles(dir.path(), "qualified", qualified).unwrap_err();
    assert!(refused.contains("DEPTH"), "{refused}");
}
