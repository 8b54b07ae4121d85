//! Stability at the extremes, through the whole local pipeline (`fbksd
//! run`, `results compute`, `results show`, `results page`): a 1×1 image
//! at 1 and 4096 spp, a 3840×2160 image, a renderer that emits NaN, ±Inf,
//! negative and 1e30 samples into a reference with NaN, infinite and black
//! pixels, and a technique that returns denormals and negatives. Nothing
//! crashes; every value, interval and rank written is finite; a bad value
//! is reported where it came from (the run's status, the renderer's log,
//! the metric's note), never averaged in.

use fbksd_tests::{bin, scene_meta};
use std::path::Path;
use std::process::Command;

fn fbksd(args: &[&str]) -> (i32, String, String) {
    let o = Command::new(bin("fbksd")).args(args).output().unwrap();
    let (out, err) = (String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned());
    assert!(!err.contains("panicked"), "fbksd {args:?} panicked: {err}");
    (o.status.code().unwrap_or(-1), out, err)
}

/// A procedural scene `name` with its reference (of `reference_spp`).
fn scene(
    root: &Path,
    name: &str,
    program: &str,
    spp: &[u64],
    (width, height): (u32, u32),
    reference_spp: u64,
) -> String {
    let dir = root.join(name);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("scene.expr"), format!("width := {width};\nheight := {height};\n#\n{program}\n")).unwrap();
    scene_meta(&dir, name, "scene.expr", "procedural", spp, width, height);
    let meta = dir.join("fbksd-scene.json");
    let text = std::fs::read_to_string(&meta).unwrap().replace("4096", &reference_spp.to_string());
    std::fs::write(&meta, text).unwrap();
    let out = Command::new(bin("fbksd-procedural")).arg("reference").arg(&dir).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    dir.to_string_lossy().into_owned()
}

/// Every number under `value` (JSON) is finite: JSON has no NaN, so a
/// non-finite value would have become `null` where a number belongs.
fn assert_numbers_finite(value: &serde_json::Value, at: &str, keys: &[&str]) {
    match value {
        serde_json::Value::Object(map) => {
            for (k, v) in map {
                if keys.contains(&k.as_str()) && !v.is_object() {
                    assert!(v.as_f64().is_some_and(f64::is_finite), "{at}.{k} = {v}");
                }
                assert_numbers_finite(v, &format!("{at}.{k}"), keys);
            }
        }
        serde_json::Value::Array(items) => {
            for (i, v) in items.iter().enumerate() {
                assert_numbers_finite(v, &format!("{at}[{i}]"), keys);
            }
        }
        _ => {}
    }
}

const NUMBERS: &[&str] =
    &["mean", "low", "high", "median", "min", "max", "cv", "place", "mean_rank", "ms", "technique_ms", "time_ms"];

#[test]
fn wild_samples_odd_results_and_tiny_images_stay_finite_and_reported() {
    let dir = tempfile::tempdir().unwrap();
    let scenes = dir.path().join("scenes");
    // Columns: NaN, +Inf and −Inf on a tenth of the samples, negative, 1e30;
    // the last row black. The 4096-spp reference has NaN, infinite and black pixels.
    let wild = scene(
        &scenes,
        "wild",
        "var c := IMAGE_X < 1 ? (LIGHT_X < 0.1 ? 0 / 0 : 0.5) : IMAGE_X < 2 ? (LIGHT_X < 0.1 ? 1 / 0 : 0.5) \
         : IMAGE_X < 3 ? (LIGHT_X < 0.1 ? -1 / 0 : 0.5) : IMAGE_X < 4 ? -0.5 * LIGHT_X : IMAGE_X < 5 ? 1e30 * LIGHT_X : LIGHT_X;\n\
         var v := IMAGE_Y >= 7 ? 0 : c;\nCOLOR_R := v; COLOR_G := v; COLOR_B := v;",
        &[1, 16],
        (8, 8),
        4096,
    );
    let tiny = scene(
        &scenes,
        "one-pixel",
        "COLOR_R := LIGHT_X; COLOR_G := LIGHT_Y; COLOR_B := 0.5;",
        &[1, 4096],
        (1, 1),
        4096,
    );
    let results = dir.path().join("results");
    let r = results.to_str().unwrap();
    let (code, _, err) = fbksd(&[
        "run",
        "-t",
        &format!("box={}", bin("box-filter")),
        "-t",
        &format!("odd={} denormals-and-negatives", bin("fbksd-test-technique")),
        "-s",
        &wild,
        "-s",
        &tiny,
        "--repeats",
        "2",
        "--results",
        r,
    ]);
    assert_eq!(code, 2, "some runs fail (NaN results), and the benchmark says so: {err}");
    let s = scenes.to_str().unwrap();
    let (code, _, err) = fbksd(&["results", "compute", "--results", r, "--scenes", s]);
    assert_eq!(code, 0, "{err}");

    let index: serde_json::Value = serde_json::from_slice(&std::fs::read(results.join("index.json")).unwrap()).unwrap();
    assert_numbers_finite(&index, "index", NUMBERS);
    let run = |t: &str, scene: &str, spp: u64| {
        index["runs"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["technique"] == t && r["scene"] == scene && r["spp"] == spp)
            .unwrap()
            .clone()
    };
    // The box filter passes the renderer's NaN through: its run fails, saying so.
    let nan = run("box", "wild", 16);
    assert_eq!(nan["status"], "invalid_output", "{nan}");
    assert!(nan["message"].as_str().unwrap().contains("NaN"), "{nan}");
    assert!(nan["metrics"].as_object().unwrap().is_empty(), "a failed run has no values: {nan}");
    let renderer_log = std::fs::read_to_string(results.join("renderer-logs/wild.log")).unwrap();
    assert!(renderer_log.contains("NaN or infinite values"), "{renderer_log}");
    // Denormals, negatives and huge values are a result like any other, scored against the
    // reference's finite pixels (its NaN and infinite ones are counted, not averaged).
    let odd = run("odd", "wild", 16);
    assert_eq!(odd["status"], "ok", "{odd}");
    assert_eq!(odd["metrics"].as_object().unwrap().len(), 7, "{odd}");
    let mse: serde_json::Value =
        serde_json::from_slice(&std::fs::read(results.join("odd/wild/16_0_MSE.json")).unwrap()).unwrap();
    // The NaN, +Inf and −Inf columns, but for the black row.
    assert_eq!(mse["nonfinite_reference"].as_u64(), Some(3 * 7), "{mse}");
    // 1×1 at 4096 spp: exact budget, every metric finite.
    let tiny_run = run("box", "one-pixel", 4096);
    assert_eq!((tiny_run["status"].as_str(), tiny_run["used_samples"].as_u64()), (Some("ok"), Some(4096)));
    assert_eq!(tiny_run["metrics"].as_object().unwrap().len(), 7, "{tiny_run}");
    // Ranks are finite, and the failed runs rank last.
    let standings = index["rankings"]["equal_spp"]["standings"].as_array().unwrap();
    assert!(standings.iter().any(|s| s["missing"].as_u64().unwrap() > 0), "{standings:?}");

    let (code, table, err) = fbksd(&["results", "show", "--results", r]);
    assert_eq!(code, 0, "{err}");
    assert!(table.contains("invalid_output") && !table.contains("NaN") && !table.contains("inf"), "{table}");
    let page = dir.path().join("page");
    let (code, _, err) = fbksd(&["results", "page", "--results", r, "--scenes", s, "--out", page.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let data = std::fs::read_to_string(page.join("data.js")).unwrap();
    let json = data.trim().strip_prefix("window.FBKSD_DOCUMENT = ").unwrap().trim_end_matches(';');
    let doc: serde_json::Value = serde_json::from_str(json).unwrap();
    assert_numbers_finite(&doc, "viewer", NUMBERS);
    for run in doc["techniques"].as_array().unwrap().iter().flat_map(|t| t["runs"].as_array().unwrap()) {
        for (metric, v) in run["metrics"].as_object().unwrap() {
            assert!(v.as_f64().is_some_and(f64::is_finite), "viewer {metric} = {v}");
        }
    }
}

/// A 3840×2160 image end to end (1 spp): the ring, the result buffer, the
/// EXR, the metrics and the viewer's pixel file all hold.
#[test]
fn an_uhd_image_goes_through_the_pipeline() {
    let dir = tempfile::tempdir().unwrap();
    let scenes = dir.path().join("scenes");
    let uhd = scene(
        &scenes,
        "uhd",
        "COLOR_R := IMAGE_X / width * LIGHT_X; COLOR_G := IMAGE_Y / height; COLOR_B := 0;",
        &[1],
        (3840, 2160),
        2,
    );
    let results = dir.path().join("results");
    let r = results.to_str().unwrap();
    let (code, _, err) = fbksd(&["run", "-t", &bin("box-filter"), "-s", &uhd, "--results", r]);
    assert_eq!(code, 0, "{err}");
    let s = scenes.to_str().unwrap();
    let (code, _, err) =
        fbksd(&["results", "compute", "--results", r, "--scenes", s, "--metrics", "MSE,rMSE,PSNR,SSIM"]);
    assert_eq!(code, 0, "{err}");
    let index: serde_json::Value = serde_json::from_slice(&std::fs::read(results.join("index.json")).unwrap()).unwrap();
    assert_numbers_finite(&index, "index", NUMBERS);
    let run = &index["runs"][0];
    assert_eq!((run["status"].as_str(), run["used_samples"].as_u64()), (Some("ok"), Some(3840 * 2160)));
    assert_eq!(run["metrics"].as_object().unwrap().len(), 4, "{run}");
    assert!(results.join("box-filter/uhd/1_0.fbpx").is_file());
}
