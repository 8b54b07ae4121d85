//! The C++ metric API (`fbksd/iqa/iqa.h`: `IQA`, `Img`): the thesis's
//! example A.3 (MSE with OpenCV) compiles as printed and agrees with the
//! built-in MSE; its `--info` is an IQA `info.json` that the results
//! pipeline runs as an external metric; error maps, value files and bad
//! input behave as documented.

use fbksd_iqa::external::ExternalMetric;
use fbksd_iqa::image::{write_exr, Image};
use fbksd_tests::{compile_cpp_with, sdk};
use std::path::Path;
use std::process::Command;

/// A reference and a test image that differ everywhere, a little.
fn images(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let (w, h) = (37u32, 21u32);
    let reference: Vec<f32> = (0..w * h * 3).map(|i| (i % 17) as f32 / 8.0).collect();
    let test: Vec<f32> = reference.iter().enumerate().map(|(i, v)| v + ((i % 5) as f32 - 2.0) / 16.0).collect();
    let (r, t) = (dir.join("reference.exr"), dir.join("test.exr"));
    write_exr(&r, w, h, &reference).unwrap();
    write_exr(&t, w, h, &test).unwrap();
    (r, t)
}

#[test]
fn the_thesis_metric_a3_matches_the_builtin_mse_and_runs_as_an_external_metric() {
    let dir = tempfile::tempdir().unwrap();
    let metric_dir = dir.path().join("my-mse");
    std::fs::create_dir(&metric_dir).unwrap();
    // OpenCV's headers live under opencv4/ on Debian; A.3 uses only its core module.
    let exe = compile_cpp_with(
        &[&sdk("cpp/examples/a3_mse_metric.cpp")],
        &metric_dir.join("my-mse"),
        &["-I/usr/include/opencv4", "-lopencv_core"],
    );
    let (reference, test) = images(dir.path());

    let output = Command::new(&exe).arg(&reference).arg(&test).output().unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let printed: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let value = printed["My-MSE"].as_f64().unwrap_or_else(|| panic!("{printed}"));
    let builtin =
        fbksd_iqa::evaluate(fbksd_iqa::Metric::Mse, &Image::read(&reference).unwrap(), &Image::read(&test).unwrap())
            .unwrap()
            .value;
    assert!((value - builtin).abs() <= 1e-6 * builtin, "A.3 says {value}, the built-in MSE {builtin}");

    // --info is the IQA info.json the results pipeline loads.
    let info = Command::new(&exe).arg("--info").output().unwrap();
    assert!(info.status.success());
    std::fs::write(metric_dir.join("info.json"), &info.stdout).unwrap();
    let external = ExternalMetric::load(&metric_dir).unwrap();
    assert_eq!(external.info.acronym, "My-MSE");
    assert!(external.info.lower_is_better && !external.info.has_error_map);
    let through_pipeline = external.run(&reference, &test, None).unwrap();
    assert!((through_pipeline - value).abs() <= 1e-9 * value.abs());

    // A missing image is an error that names it.
    let missing = Command::new(&exe).arg(dir.path().join("nope.exr")).arg(&test).output().unwrap();
    assert!(!missing.status.success());
    assert!(String::from_utf8_lossy(&missing.stderr).contains("nope.exr"));
}

#[test]
fn a_cpp_metric_writes_its_error_map_and_value_file_and_refuses_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let source = dir.path().join("abs_diff.cpp");
    std::fs::write(
        &source,
        r#"#include <fbksd/iqa/iqa.h>
#include <cmath>
#include <cstdio>
#include <cstring>
int main(int argc, char* argv[]) {
    try {
        fbksd::IQA iqa(argc, argv, "ABS", "Mean absolute difference", "", true, true);
        fbksd::Img ref, test;
        iqa.loadInputImages(ref, test);
        fbksd::Img map(ref.width(), ref.height(), 0.f);
        double sum = 0;
        for (int y = 0; y < ref.height(); ++y)
            for (int x = 0; x < ref.width(); ++x)
                for (int c = 0; c < 3; ++c) {
                    float d = std::fabs(ref(x, y, c) - test(x, y, c));
                    sum += d;
                    map(x, y, c) = d;
                }
        float value = (float)(sum / (3.0 * ref.width() * ref.height()));
        if (std::getenv("REPORT_NAN"))
            value = NAN;
        iqa.report(value, map);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "abs: %s\n", e.what());
        return 1;
    }
    return 0;
}
"#,
    )
    .unwrap();
    let exe = compile_cpp_with(&[&source], &dir.path().join("abs"), &[]);
    let (reference, test) = images(dir.path());
    let (map, value) = (dir.path().join("map.png"), dir.path().join("value.json"));
    let run = |extra: &[&Path], env: Option<&str>| {
        let mut c = Command::new(&exe);
        c.arg("--map-file").arg(&map).arg("--value-file").arg(&value).args(extra);
        if let Some(e) = env {
            c.env(e, "1");
        }
        c.output().unwrap()
    };
    let ok = run(&[&reference, &test], None);
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    assert!(ok.stdout.is_empty(), "the value goes to the value file");
    let written: serde_json::Value = serde_json::from_slice(&std::fs::read(&value).unwrap()).unwrap();
    let v = written["ABS"].as_f64().unwrap();
    assert!((v - 0.0750).abs() < 1e-3, "{written}");
    let png = image::open(&map).unwrap();
    assert_eq!((png.width(), png.height()), (37, 21));

    let nan = run(&[&reference, &test], Some("REPORT_NAN"));
    assert!(!nan.status.success());
    assert!(String::from_utf8_lossy(&nan.stderr).contains("finite"), "{}", String::from_utf8_lossy(&nan.stderr));

    let small = dir.path().join("small.exr");
    write_exr(&small, 2, 2, &[0.0; 12]).unwrap();
    let sizes = run(&[&reference, &small], None);
    assert!(String::from_utf8_lossy(&sizes.stderr).contains("differ in size"));

    let usage = run(&[&reference], None);
    assert!(String::from_utf8_lossy(&usage.stderr).contains("usage:"));
}
