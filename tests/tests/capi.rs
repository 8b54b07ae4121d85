//! The C and C++ APIs through the whole protocol: a box filter written in C
//! against `fbksd.h` and `libfbksd.so` gives the same image, bit for bit,
//! as the Rust box filter; errors reach C as codes with messages; the
//! thesis's C++ examples A.1 and A.2 compile against the C++ headers and
//! run (A.1 unchanged; A.2 declares the sample indices its listing leaves
//! out, as 2.x's samplers did).

use fbksd_tests::{analytic_scene, bin, build_with_cmake, compile_c, compile_cpp, run, sdk};
use std::process::Command;

#[test]
fn a_c_box_filter_matches_the_rust_box_filter_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let source = sdk("capi/tests/c/box_filter.c");
    let exe = compile_c(&[&source], &dir.path().join("box-filter-c"));
    let scene = analytic_scene(dir.path(), "conformance", 40, 24);
    let results = dir.path().join("results");
    let output = Command::new(bin("fbksd"))
        .args(["run", "-t", &format!("rust={}", bin("box-filter")), "-t", &format!("c={}", exe.display())])
        .args(["-r", &bin("fbksd-analytic-renderer"), "-s", scene.to_str().unwrap()])
        .args(["--spp", "1,7,16", "--results", results.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    for spp in [1, 7, 16] {
        let read = |t: &str| fbksd_iqa::image::read_exr(&results.join(format!("{t}/conformance/{spp}_0.exr"))).unwrap();
        let (rust, c) = (read("rust"), read("c"));
        assert_eq!(
            rust.2.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            c.2.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            "{spp} spp"
        );
    }
}

#[test]
fn c_callers_get_error_codes_and_messages() {
    let dir = tempfile::tempdir().unwrap();
    let source = dir.path().join("errors.c");
    std::fs::write(
        &source,
        r#"#include <fbksd/fbksd.h>
#include <stdio.h>
#include <string.h>
int main(void) {
    FbksdClient *client = NULL;
    /* Not started by a manager, no debug arguments. */
    if (fbksd_client_new(0, NULL, &client) != FBKSD_STATUS_CONNECTION) return 1;
    if (strstr(fbksd_last_error(), "fbksd run") == NULL) return 2;
    /* Null handles are refused, not dereferenced. */
    if (fbksd_client_set_layout(NULL, NULL) != FBKSD_STATUS_INVALID_ARGUMENT) return 3;
    if (strstr(fbksd_last_error(), "client is null") == NULL) return 4;
    FbksdLayout *layout = fbksd_layout_new();
    if (fbksd_layout_add(layout, "WORLD_X", true, 1) != FBKSD_STATUS_INVALID_ARGUMENT) return 5;
    fbksd_layout_free(layout);
    fbksd_client_free(NULL);
    puts("ok");
    return 0;
}
"#,
    )
    .unwrap();
    let exe = compile_c(&[&source], &dir.path().join("errors"));
    let output = Command::new(&exe).env_remove("FBKSD_RENDEZVOUS").output().unwrap();
    assert!(output.status.success(), "exit {:?}: {}", output.status.code(), String::from_utf8_lossy(&output.stderr));
    assert_eq!(String::from_utf8_lossy(&output.stdout).trim(), "ok");
}

#[test]
fn the_thesis_cpp_examples_compile_and_run() {
    let dir = tempfile::tempdir().unwrap();
    let a1 = compile_cpp(&[&sdk("cpp/examples/a1_box_filter.cpp")], &dir.path().join("a1"));
    let a2 = compile_cpp(
        &[&sdk("cpp/examples/a2_random_sampler.cpp"), &sdk("cpp/examples/random_float.cpp")],
        &dir.path().join("a2"),
    );
    let scene = analytic_scene(dir.path(), "examples", 40, 24);
    let results = dir.path().join("results");
    let output = Command::new(bin("fbksd"))
        .args(["run", "-t", &format!("rust={}", bin("box-filter"))])
        .args(["-t", &format!("a1={}", a1.display()), "-t", &format!("a2={}", a2.display())])
        .args(["-r", &bin("fbksd-analytic-renderer"), "-s", scene.to_str().unwrap()])
        .args(["--spp", "4,16", "--results", results.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    for spp in [4, 16] {
        let read = |t: &str| fbksd_iqa::image::read_exr(&results.join(format!("{t}/examples/{spp}_0.exr"))).unwrap().2;
        // A.1 sums in single precision; the Rust box filter in double.
        let (rust, a1) = (read("rust"), read("a1"));
        for (r, c) in rust.iter().zip(&a1) {
            assert!((r - c).abs() <= 1e-5 * r.abs().max(1e-3), "A.1 at {spp} spp: {c} vs {r}");
        }
        assert_eq!(read("a2").len(), rust.len(), "A.2 ran and sent an image");
    }
}

#[test]
fn a_cpp_technique_builds_with_find_package_and_matches_the_rust_box_filter() {
    let dir = tempfile::tempdir().unwrap();
    let build = build_with_cmake(&sdk("techniques/box-filter-cpp"), dir.path());
    let scene = analytic_scene(dir.path(), "cmake", 33, 17);
    let results = dir.path().join("results");
    run(Command::new(bin("fbksd"))
        .args(["run", "-t", &format!("rust={}", bin("box-filter"))])
        .args(["-t", &format!("cpp={}", build.join("box-filter-cpp").display())])
        .args(["-r", &bin("fbksd-analytic-renderer"), "-s", scene.to_str().unwrap()])
        .args(["--spp", "5", "--results", results.to_str().unwrap()]));
    let read = |t: &str| fbksd_iqa::image::read_exr(&results.join(format!("{t}/cmake/5_0.exr"))).unwrap().2;
    assert_eq!(read("rust"), read("cpp"));
}

#[test]
fn the_cpp_stratified_sampler_places_every_sample_itself_within_budget() {
    let dir = tempfile::tempdir().unwrap();
    let build = build_with_cmake(&sdk("techniques/stratified-cpp"), dir.path());
    let scene = analytic_scene(dir.path(), "stratified", 29, 13);
    let results = dir.path().join("results");
    run(Command::new(bin("fbksd"))
        .args(["run", "-t", &format!("box={}", bin("box-filter"))])
        .args(["-t", &format!("stratified={}", build.join("stratified").display())])
        .args(["-r", &bin("fbksd-analytic-renderer"), "-s", scene.to_str().unwrap()])
        .args(["--spp", "3,16", "--results", results.to_str().unwrap()]));
    for spp in [3u64, 16] {
        let log: serde_json::Value = serde_json::from_slice(
            &std::fs::read(results.join(format!("stratified/stratified/{spp}_0_log.json"))).unwrap(),
        )
        .unwrap();
        // The sampler checks that every sample came back inside its own pixel (it throws otherwise).
        assert_eq!(log["status"], "ok", "{log}");
        assert_eq!(log["used_samples"], spp * 29 * 13);
        let read =
            |t: &str| fbksd_iqa::image::read_exr(&results.join(format!("{t}/stratified/{spp}_0.exr"))).unwrap().2;
        let (own, renderer) = (read("stratified"), read("box"));
        let mean = |v: &[f32]| v.iter().map(|x| *x as f64).sum::<f64>() / v.len() as f64;
        // Both estimate the same image: their means agree to a few percent.
        assert!((mean(&own) - mean(&renderer)).abs() < 0.05 * mean(&renderer).abs(), "{spp} spp");
    }
}
