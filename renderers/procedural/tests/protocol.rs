//! The procedural renderer behind a real manager, driven by the Rust client.

use fbksd_client::{BenchmarkClient, ElementIo, SampleLayout, Spp};
use fbksd_manager::{Limits, RunOutcome, RunStatus, SceneRunner, TechniqueLaunch};
use fbksd_procedural::reference::closed_form;
use fbksd_procedural::Scene;
use std::path::{Path, PathBuf};

const RENDERER: &str = env!("CARGO_BIN_EXE_fbksd-procedural");

/// Listing C.1 of the thesis, character for character.
const LISTING_C1: &str = "width := 500;
height := 500;
spp := 64;

#

var c[3] := { 0.5, 0.5, 0.5 };
var r_sq := 0.5^2;
var d := ((IMAGE_X/width) - c[0])^2 + ((IMAGE_Y/height) - c[1])^2 + (TIME - c[2])^2;

COLOR_R := d <= r_sq ? 1.0 : 0.0;
COLOR_G := COLOR_R;
COLOR_B := COLOR_R;
";

/// A technique run in-process: gets a connected client, returns what it saw.
type Technique<T> = Box<dyn FnOnce(BenchmarkClient) -> T + Send>;

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Runs `techniques` one after another against `scene_file`, each in its own session.
fn sessions<T: Send + 'static>(scene_file: &Path, log: &Path, runs: Vec<(u64, Technique<T>)>) -> Vec<(RunOutcome, T)> {
    let argv = vec![RENDERER.to_string(), scene_file.to_string_lossy().into_owned()];
    let mut runner = SceneRunner::new(argv, Some(log.to_path_buf()), Limits::default()).unwrap();
    let mut out = Vec::new();
    for (spp, technique) in runs {
        let dir = runner.dir().to_path_buf();
        let client = std::thread::spawn(move || technique(BenchmarkClient::connect_to(&dir).unwrap()));
        let outcome = runner.run(spp, &TechniqueLaunch::External, &log.with_extension("technique"));
        out.push((outcome, client.join().unwrap()));
    }
    out
}

/// A box filter as a closure technique.
fn box_filter(mut client: BenchmarkClient) -> Vec<f32> {
    let info = client.scene_info().clone();
    let (w, spp) = (info.get::<i64>("width").unwrap() as usize, info.get::<i64>("max_spp").unwrap() as u64);
    client.set_sample_layout(&SampleLayout::new().with("COLOR_R").with("COLOR_G").with("COLOR_B")).unwrap();
    let mut sums = vec![0f64; client.result_buffer().len()];
    client
        .evaluate_samples(Spp(spp), |tile| {
            for y in tile.begin_y()..tile.end_y() {
                for x in tile.begin_x()..tile.end_x() {
                    for s in 0..tile.spp() {
                        for c in 0..3 {
                            sums[(y as usize * w + x as usize) * 3 + c] += tile.sample(x, y, s)[c] as f64;
                        }
                    }
                }
            }
        })
        .unwrap();
    let image: Vec<f32> = sums.iter().map(|s| (s / spp as f64) as f32).collect();
    client.result_buffer().copy_from_slice(&image);
    client.send_result().unwrap();
    image
}

fn rmse(a: &[f32], b: &[f32]) -> f64 {
    (a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
}

#[test]
fn listing_c1_unchanged_renders_and_converges_to_its_closed_form() {
    let file = repo_root().join("scenes/experimental/sphere/sphere.expr");
    assert_eq!(std::fs::read_to_string(&file).unwrap(), LISTING_C1, "the scene file is listing C.1 unchanged");
    let reference = closed_form("sphere_time", &Scene::load(&file).unwrap(), 64).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let runs: Vec<(u64, Technique<Vec<f32>>)> =
        [1, 4, 16, 64].into_iter().map(|spp| (spp, Box::new(box_filter) as Box<_>)).collect();
    let results = sessions(&file, &dir.path().join("log"), runs);
    let errors: Vec<f64> = results
        .iter()
        .map(|(outcome, image)| {
            assert_eq!(outcome.status, RunStatus::Ok, "{}", outcome.message);
            rmse(image, &reference)
        })
        .collect();
    // Stratified, the error falls about as 1/spp: each step of 4× at least halves it.
    for pair in errors.windows(2) {
        assert!(pair[1] < pair[0] / 2.0, "errors {errors:?}");
    }
    assert!(errors[3] < 0.012, "errors {errors:?}"); // seen: 0.36, 0.13, 0.032, 0.0081
}

#[test]
fn input_parameters_are_used_as_given() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("echo.expr");
    std::fs::write(&file, "width := 8;\nheight := 4;\n#\nCOLOR_R := IMAGE_X; COLOR_G := IMAGE_Y; COLOR_B := TIME;\nDEPTH := LENS_U + 10 * LENS_V; NORMAL_X := LIGHT_X; NORMAL_Y := LIGHT_Y;\n").unwrap();
    let mine = |i: usize, x: u32, y: u32| -> [f32; 7] {
        let u = |k: usize| ((i * 7 + k * 3) % 11) as f32 / 11.0;
        [x as f32 + u(0), y as f32 + u(1), u(2), u(3), u(4), u(5), u(6)]
    };
    let technique = move |mut client: BenchmarkClient| -> usize {
        let mut layout = SampleLayout::new();
        for p in ["IMAGE_X", "IMAGE_Y", "LENS_U", "LENS_V", "TIME", "LIGHT_X", "LIGHT_Y"] {
            layout = layout.with_io(p, ElementIo::Input);
        }
        let layout =
            layout.with("COLOR_R").with("COLOR_G").with("COLOR_B").with("DEPTH").with("NORMAL_X").with("NORMAL_Y");
        client.set_sample_layout(&layout).unwrap();
        let check = |s: &[f32]| {
            // The program computes in f64 and delivers f32.
            let depth = (s[2] as f64 + 10.0 * s[3] as f64) as f32;
            assert_eq!(&s[7..], &[s[0], s[1], s[4], depth, s[5], s[6]], "features follow the given inputs");
        };
        let mut checked = 0;
        client
            .evaluate_input_samples(
                Spp(2),
                |tile| {
                    for y in tile.begin_y()..tile.end_y() {
                        for x in tile.begin_x()..tile.end_x() {
                            for s in 0..tile.spp() {
                                tile.sample_mut(x, y, s)[..7].copy_from_slice(&mine(s as usize, x, y));
                            }
                        }
                    }
                },
                |tile| {
                    for y in tile.begin_y()..tile.end_y() {
                        for x in tile.begin_x()..tile.end_x() {
                            for s in 0..tile.spp() {
                                let sample = tile.sample(x, y, s);
                                assert_eq!(&sample[..7], &mine(s as usize, x, y));
                                check(sample);
                                checked += 1;
                            }
                        }
                    }
                },
            )
            .unwrap();
        // Count requests: the technique places every sample, even outside pixel order.
        let mut i = 0;
        client
            .evaluate_input_sample_count(
                30,
                |data| {
                    for s in data.chunks_exact_mut(13) {
                        s[..7].copy_from_slice(&mine(i, 7, 3));
                        i += 1;
                    }
                },
                |data| {
                    for s in data.chunks_exact(13) {
                        check(s);
                        assert!(s[0] >= 7.0 && s[1] >= 3.0);
                        checked += 1;
                    }
                },
            )
            .unwrap();
        client.send_result().unwrap();
        checked
    };
    let results = sessions(&file, &dir.path().join("log"), vec![(3, Box::new(technique))]);
    assert_eq!(results[0].0.status, RunStatus::Ok, "{}", results[0].0.message);
    assert_eq!(results[0].1, 2 * 32 + 30);
}

#[test]
fn the_same_requests_give_the_same_samples() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("noise.expr");
    std::fs::write(
        &file,
        "width := 9;\nheight := 7;\n#\nCOLOR_R := sin(IMAGE_X * 3) * LENS_U + TIME * LIGHT_Y;\nDEPTH := LENS_V;\n",
    )
    .unwrap();
    let collect = |mut client: BenchmarkClient| -> Vec<u32> {
        client
            .set_sample_layout(&SampleLayout::new().with("IMAGE_X").with("IMAGE_Y").with("COLOR_R").with("DEPTH"))
            .unwrap();
        let mut bits = Vec::new();
        client.evaluate_samples(Spp(3), |t| bits.extend(t.data().iter().map(|v| v.to_bits()))).unwrap();
        client.evaluate_sample_count(100, |d| bits.extend(d.iter().map(|v| v.to_bits()))).unwrap();
        client.send_result().unwrap();
        bits
    };
    let runs: Vec<(u64, Technique<Vec<u32>>)> = vec![(5, Box::new(collect)), (5, Box::new(collect))];
    let results = sessions(&file, &dir.path().join("log"), runs);
    assert_eq!(results[0].1.len(), (3 * 63 + 100) * 4);
    // Tiles may arrive in any order; the multiset of samples is what must repeat.
    let sorted = |v: &Vec<u32>| {
        let mut s: Vec<&[u32]> = v.chunks(4).collect();
        s.sort();
        s.concat()
    };
    assert_eq!(sorted(&results[0].1), sorted(&results[1].1));
}

#[test]
fn nan_samples_are_delivered_and_reported_in_the_renderer_log() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("nan.expr");
    std::fs::write(
        &file,
        "width := 6;\nheight := 2;\n#\nCOLOR_R := IMAGE_X < 1 ? 0 / 0 : 1;\nCOLOR_G := 1 / (IMAGE_Y - IMAGE_Y);\n",
    )
    .unwrap();
    let log = dir.path().join("renderer.log");
    let results = sessions(&file, &log, vec![(2, Box::new(box_filter) as Technique<Vec<f32>>)]);
    let (outcome, image) = &results[0];
    assert!(image[0].is_nan() && image[3] == 1.0 && image[1].is_infinite());
    assert_eq!(outcome.status, RunStatus::InvalidOutput, "{}", outcome.message);
    let log = std::fs::read_to_string(&log).unwrap();
    assert!(
        log.contains(
            "nan.expr: warning: 28 NaN or infinite values in request 0; first: COLOR_R = NaN at pixel (0, 0) sample 0"
        ),
        "{log}"
    );
}

#[test]
fn an_endless_loop_fails_the_run_with_the_scene_position() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("loop.expr");
    std::fs::write(&file, "width := 2;\nheight := 2;\n#\nvar i := 0;\nwhile (1) { i += 1 };\nCOLOR_R := i;\n").unwrap();
    let technique = |mut client: BenchmarkClient| {
        client.set_sample_layout(&SampleLayout::new().with("COLOR_R")).unwrap();
        client.evaluate_samples(Spp(1), |_| {}).unwrap_err().to_string()
    };
    let results = sessions(&file, &dir.path().join("log"), vec![(1, Box::new(technique))]);
    assert_eq!(results[0].0.status, RunStatus::RendererFailed);
    assert!(
        results[0].0.message.contains("loop.expr:5:1: loop ran more than 10000000 times"),
        "{}",
        results[0].0.message
    );
    assert!(results[0].1.contains("loop.expr:5:1"), "the technique is told too: {}", results[0].1);
}

#[test]
fn every_experimental_scene_loads_and_matches_its_metadata() {
    let root = repo_root().join("scenes/experimental");
    let mut names = Vec::new();
    for entry in std::fs::read_dir(&root).unwrap() {
        let meta = fbksd_exchange::scenes::SceneMeta::load(&entry.unwrap().path()).unwrap();
        assert_eq!(meta.category, "experimental");
        // The pool's Mitsuba scenes are fbksd-mitsuba's (tests/tests/mitsuba.rs).
        if meta.renderer == "mitsuba" {
            continue;
        }
        assert_eq!(meta.renderer, "procedural");
        let scene = Scene::load(&meta.scene_file()).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((scene.width, scene.height), (meta.width, meta.height), "{}", meta.name);
        let info = scene.info();
        assert_eq!(info.get::<bool>("has_dof").unwrap(), meta.tags.iter().any(|t| t == "dof"), "{}", meta.name);
        assert_eq!(
            info.get::<bool>("has_motion_blur").unwrap(),
            meta.tags.iter().any(|t| t == "motion-blur"),
            "{}",
            meta.name
        );
        names.push(meta.name);
    }
    names.sort();
    assert_eq!(
        names,
        ["black-ring", "defocus-checkerboard", "fireflies", "mandelbrot", "moving-bars", "sin-bands", "sphere"]
    );
}

#[test]
fn the_fireflies_closed_form_is_the_scene_expectation() {
    // Cross-checks the Rust formula against the scene program. At the
    // scene's own resolution the hit probability is nearly constant within
    // a pixel, so 256 spp pin the mean to about ±0.6% (seen over 6 seeds).
    let scene = Scene::load(&repo_root().join("scenes/experimental/fireflies/fireflies.expr")).unwrap();
    let exact = closed_form("fireflies", &scene, 16).unwrap();
    let rendered = fbksd_procedural::render::render_image(&scene, 256, 0).unwrap();
    let mean = |v: &[f32]| v.iter().map(|x| *x as f64).sum::<f64>() / v.len() as f64;
    assert!((mean(&rendered) - mean(&exact)).abs() < 0.025 * mean(&exact), "{} vs {}", mean(&rendered), mean(&exact));
}
