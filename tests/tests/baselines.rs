//! The baselines of `sdk/techniques/baselines.txt`, as the service builds
//! and runs them: each repository built as it says (CMake, or its Python
//! scripts as they are), every version run through `fbksd run` against the
//! real renderers. Every one spends exactly its budget and returns a finite
//! image on every small production scene; the filters give back a constant
//! scene exactly; NFOR and OIDN beat the box filter by a wide margin; OIDN
//! through FBKSD is `pyoidn` applied to the same samples; and the samplers'
//! positions keep their stratification properties.

use fbksd_exchange::results::{IndexEntry, ResultsDir};
use fbksd_exchange::technique::TechniqueInfo;
use fbksd_exchange::RunStatus;
use fbksd_tests::{bin, build_with_cmake, python_path, run, sdk};
use std::path::{Path, PathBuf};
use std::process::Command;

/// One version of one baseline: its name in results and its command.
struct Technique {
    name: String,
    command: String,
}

/// Every version of every listed baseline, built in `dir`.
fn baselines(dir: &Path) -> Vec<Technique> {
    let list = sdk("techniques/baselines.txt");
    let mut techniques = Vec::new();
    for entry in std::fs::read_to_string(&list).unwrap().lines() {
        let entry = entry.split('#').next().unwrap().trim();
        if entry.is_empty() {
            continue;
        }
        let repo = sdk(&format!("techniques/{entry}"));
        let files: Vec<String> = std::fs::read_dir(&repo)
            .unwrap_or_else(|e| panic!("{}: {e}", repo.display()))
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        let text = std::fs::read_to_string(repo.join("info.json")).unwrap();
        let info = TechniqueInfo::parse(&text, &files).unwrap_or_else(|e| panic!("{entry}: {e}"));
        let built = repo.join("CMakeLists.txt").is_file().then(|| build_with_cmake(&repo, dir));
        for version in &info.versions {
            let command = match &built {
                Some(build) => build.join(&version.executable),
                None => repo.join(&version.executable),
            };
            assert!(command.is_file(), "{entry}: {} is missing", command.display());
            let name = if info.versions.len() == 1 { entry.to_string() } else { format!("{entry}-{}", version.name) };
            techniques.push(Technique { name, command: command.display().to_string() });
        }
    }
    techniques
}

/// `fbksd run` of `techniques` on `scenes` at `spp`; the results' index.
fn fbksd_run(techniques: &[&Technique], scenes: &[PathBuf], spp: &str, results: &Path) -> Vec<IndexEntry> {
    let mut command = Command::new(bin("fbksd"));
    command.env("PYTHONPATH", python_path()).args(["run", "--spp", spp, "--results", results.to_str().unwrap()]);
    command.args(["-t", &format!("box={}", bin("box-filter"))]);
    for technique in techniques {
        command.args(["-t", &format!("{}={}", technique.name, technique.command)]);
    }
    for scene in scenes {
        command.arg("-s").arg(scene);
    }
    run(&mut command);
    ResultsDir::create(results).unwrap().read_index().unwrap().runs
}

fn image(results: &Path, run: &IndexEntry) -> Vec<f32> {
    let file = run.image.as_ref().unwrap_or_else(|| panic!("{} on {}: no image", run.technique, run.scene));
    fbksd_iqa::image::read_exr(&results.join(file)).unwrap().2
}

fn small_production_scenes() -> Vec<PathBuf> {
    let mut scenes: Vec<_> =
        std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/production-small"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
    scenes.sort();
    scenes
}

/// The framework's relative MSE of `test` against `reference` (robust to
/// the light sources' HDR values, which a plain MSE would be all about).
fn rel_mse(width: u32, height: u32, reference: &[f32], test: &[f32]) -> f64 {
    let image = |rgb: &[f32]| fbksd_iqa::image::Image::new(width, height, rgb.to_vec());
    fbksd_iqa::evaluate(fbksd_iqa::Metric::RelMse, &image(reference), &image(test)).unwrap().value
}

#[test]
fn every_baseline_spends_its_budget_is_exact_on_constants_and_the_best_beat_the_box_filter() {
    let dir = tempfile::tempdir().unwrap();
    let techniques = baselines(dir.path());
    let all: Vec<&Technique> = techniques.iter().collect();
    assert_eq!(techniques.len(), 14, "every version of the 13 listed baselines");

    // 1. Every small production scene at 2 spp (the least that has two
    // half buffers), and one at 1 spp: the budget spent exactly, images finite.
    let scenes = small_production_scenes();
    let pool = dir.path().join("pool");
    let one_spp = dir.path().join("one-spp");
    let runs: Vec<(&Path, IndexEntry)> =
        (fbksd_run(&all, &scenes, "2", &pool).into_iter().map(|r| (pool.as_path(), r)))
            .chain(fbksd_run(&all, &scenes[..1], "1", &one_spp).into_iter().map(|r| (one_spp.as_path(), r)))
            .collect();
    assert_eq!(runs.len(), (techniques.len() + 1) * (scenes.len() + 1));
    for (results, run) in &runs {
        let what = format!("{} on {} at {} spp", run.technique, run.scene, run.spp);
        assert_eq!(run.status, RunStatus::Ok, "{what}: {}", run.message);
        let file = results.join(run.image.as_ref().unwrap_or_else(|| panic!("{what}: no image")));
        let (width, height, pixels) = fbksd_iqa::image::read_exr(&file).unwrap();
        assert_eq!(run.used_samples, run.spp * u64::from(width * height), "{what} did not spend exactly its budget");
        assert!(pixels.iter().all(|v| v.is_finite()), "{what}: a value is not finite");
    }

    // 2. A constant scene (colour and every feature): each filter, sampler
    // and adaptive technique gives it back exactly. OIDN is a learned
    // filter, not a normalised average, so it is left out.
    let constant = constant_scene(dir.path());
    let exact: Vec<&Technique> = techniques.iter().filter(|t| t.name != "oidn").collect();
    let results = dir.path().join("constant");
    for run in fbksd_run(&exact, std::slice::from_ref(&constant), "4", &results) {
        let pixels = image(&results, &run);
        let worst = pixels
            .chunks(3)
            .flat_map(|p| p.iter().zip([0.25f32, 0.5, 2.0]).map(|(v, c)| (v - c).abs() / c))
            .fold(0f32, f32::max);
        assert!(worst <= 1e-5, "{} is off a constant image by {worst} (relative)", run.technique);
    }

    // 3. Against a converged image of the same scene (other seeds), NFOR and
    // OIDN beat the box filter by a wide margin at 4 and 16 spp: at least 4×
    // lower relative MSE (observed: see the FIGURE lines and the note).
    let best: Vec<&Technique> = techniques.iter().filter(|t| t.name == "nfor" || t.name == "oidn").collect();
    assert_eq!(best.len(), 2);
    let results = dir.path().join("margin");
    let margin_scenes: Vec<PathBuf> = ["cornell-box", "glossy-spheres"]
        .iter()
        .map(|s| scenes.iter().find(|p| p.ends_with(s)).unwrap().clone())
        .collect();
    let runs = fbksd_run(&best, &margin_scenes, "4,16", &results);
    for scene in &margin_scenes {
        let meta = fbksd_exchange::scenes::SceneMeta::load(scene).unwrap();
        let loaded = fbksd_embree::pbrt::load(&meta.scene_file()).unwrap();
        let reference = fbksd_embree::render::render_image(&loaded, 512, 7).rgb;
        for spp in [4, 16] {
            let of = |name: &str| {
                let run = runs.iter().find(|r| r.technique == name && r.scene == meta.name && r.spp == spp).unwrap();
                rel_mse(loaded.width(), loaded.height(), &reference, &image(&results, run))
            };
            let box_filter = of("box");
            for name in ["nfor", "oidn"] {
                let times = box_filter / of(name);
                eprintln!("FIGURE {name} on {} at {spp} spp: rMSE {times:.1}× lower than the box filter's", meta.name);
                assert!(
                    times >= 4.0,
                    "{name} on {} at {spp} spp: rMSE only {times:.1}× below the box filter's",
                    meta.name
                );
            }
        }
    }

    // 4. OIDN through FBKSD is pyoidn applied directly to the per-pixel
    // means of the same samples (the renderer replays them exactly).
    oidn_reproduces_pyoidn(dir.path(), &margin_scenes[0], &results);
}

/// A procedural scene where every sample is colour (0.25, 0.5, 2) with a
/// constant normal, albedo and depth; its folder.
fn constant_scene(dir: &Path) -> PathBuf {
    let scene = dir.join("constant");
    std::fs::create_dir_all(&scene).unwrap();
    std::fs::write(
        scene.join("constant.expr"),
        "width := 48;\nheight := 40;\n#\nCOLOR_R := 0.25; COLOR_G := 0.5; COLOR_B := 2.0;\n\
         NORMAL_X := 0.0; NORMAL_Y := 0.0; NORMAL_Z := 1.0;\n\
         TEXTURE_COLOR_R := 0.5; TEXTURE_COLOR_G := 0.5; TEXTURE_COLOR_B := 0.5;\n\
         DEPTH := 3.0; WORLD_X := 1.0; WORLD_Y := 2.0; WORLD_Z := 3.0;\n",
    )
    .unwrap();
    let meta = serde_json::json!({
        "name": "constant", "path": "constant.expr", "ref-img": "reference.exr", "renderer": "procedural",
        "category": "experimental", "tags": [], "spp": [4], "width": 48, "height": 40,
        "reference": {"method": "render", "spp": 4}, "description": "A constant image."
    });
    std::fs::write(scene.join("fbksd-scene.json"), meta.to_string()).unwrap();
    scene
}

/// Runs the test technique that saves the per-pixel means OIDN is given,
/// applies pyoidn to them directly, and compares with the oidn baseline's image.
fn oidn_reproduces_pyoidn(dir: &Path, scene: &Path, results: &Path) {
    let means = dir.join("means.npz");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("baselines");
    let mut fbksd = Command::new(bin("fbksd"));
    fbksd.env("PYTHONPATH", python_path()).env("FBKSD_MEANS_OUT", &means);
    fbksd.args(["run", "--spp", "16", "--results", dir.join("means").to_str().unwrap(), "-s"]).arg(scene);
    run(fbksd.arg("-t").arg(script.join("feature_means.py")));
    let direct = dir.join("direct.f32");
    run(Command::new("python3").arg(script.join("pyoidn_direct.py")).arg(&means).arg(&direct));
    let direct: Vec<f32> =
        std::fs::read(&direct).unwrap().chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
    let index = ResultsDir::create(results).unwrap().read_index().unwrap();
    let name = fbksd_exchange::scenes::SceneMeta::load(scene).unwrap().name;
    let run = index.runs.iter().find(|r| r.technique == "oidn" && r.scene == name && r.spp == 16).unwrap();
    let through_fbksd = image(results, run);
    assert_eq!(direct.len(), through_fbksd.len());
    let worst = direct.iter().zip(&through_fbksd).map(|(a, b)| (a - b).abs() / a.abs().max(0.05)).fold(0f32, f32::max);
    assert!(worst < 1e-3, "OIDN through FBKSD differs from pyoidn on the same samples by {worst} (relative)");
}

#[test]
fn each_sampler_keeps_its_stratification_property() {
    let out = run(Command::new("python3")
        .args(["-m", "unittest", "-v", "sdk/techniques/tests/test_samplers.py"])
        .current_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("..")));
    let printed = String::from_utf8_lossy(&out.stderr);
    assert!(printed.contains("OK"), "{printed}");
}
