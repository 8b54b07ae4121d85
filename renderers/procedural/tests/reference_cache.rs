//! The reference cache follows the one rule every renderer shares
//! (`fbksd_exchange::scenes::current_reference_note`).
//!
//! Regression: a procedural reference was kept after its `.expr` changed
//! (the Embree renderer rebuilt its own): a technique would have been
//! scored against an image of another scene.
//!
//! The feature buffers the results viewer shows are made with the
//! reference, from the features the scene's program assigns.

use fbksd_procedural::reference::{build, key, SceneMeta};

/// A copy of the sin-bands scene with a small image, without a reference.
fn scene_copy() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let source = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/experimental/sin-bands");
    for name in ["fbksd-scene.json", "sin-bands.expr"] {
        let text = std::fs::read_to_string(source.join(name)).unwrap();
        // 32×16 pixels: the reference renders in a moment.
        let text = text.replace("\"width\": 512", "\"width\": 32").replace("\"height\": 512", "\"height\": 16");
        let text = text.replace("width := 512;", "width := 32;").replace("height := 512;", "height := 16;");
        std::fs::write(dir.path().join(name), text).unwrap();
    }
    dir
}

fn reference_bytes(meta: &SceneMeta) -> Vec<u8> {
    std::fs::read(meta.reference_file()).unwrap()
}

#[test]
fn a_changed_scene_file_or_budget_rebuilds_the_reference() {
    let dir = scene_copy();
    let meta = SceneMeta::load(dir.path()).unwrap();
    let first = build(&meta, false, Some(8)).unwrap();
    let image = reference_bytes(&meta);
    assert!(first.scene_digest.starts_with("sha256:"), "{first:?}");

    // Nothing changed: the cached reference is kept (the note is read back as written).
    let kept = build(&meta, false, Some(8)).unwrap();
    assert_eq!((kept.seconds, &kept.scene_digest), (first.seconds, &first.scene_digest));

    // The scene file changes: the reference is made again, of the new scene.
    let expr = dir.path().join("sin-bands.expr");
    let text = std::fs::read_to_string(&expr).unwrap();
    let changed = text.replace("COLOR_R :=", "COLOR_R := 0.5 * ");
    assert_ne!(text, changed, "the edit must change the scene");
    std::fs::write(&expr, changed).unwrap();
    let rebuilt = build(&meta, false, Some(8)).unwrap();
    assert_ne!(rebuilt.scene_digest, first.scene_digest);
    assert_ne!(reference_bytes(&meta), image, "the new scene's image");
    assert!(rebuilt.mean_value < first.mean_value, "{} vs {}", rebuilt.mean_value, first.mean_value);

    // Another budget: made again too.
    assert_eq!(build(&meta, false, Some(16)).unwrap().samples_per_pixel, 16);
}

#[test]
fn the_features_a_scene_assigns_become_buffers_beside_its_reference() {
    let dir = scene_copy();
    let expr = dir.path().join("sin-bands.expr");
    // Depth grows with x across each pixel's footprint: the buffer is its mean.
    let text = std::fs::read_to_string(&expr).unwrap().replace("DEPTH := 1;", "DEPTH := 2 + IMAGE_X;");
    std::fs::write(&expr, text).unwrap();
    let meta = SceneMeta::load(dir.path()).unwrap();
    build(&meta, false, Some(8)).unwrap();
    let read = |name: &str| fbksd_iqa::image::Image::read(&meta.feature_buffer_file(name)).unwrap();

    let albedo = read("albedo");
    assert_eq!((albedo.width, albedo.height), (32, 16));
    assert!(albedo.rgb.iter().all(|v| *v == 1.0), "TEXTURE_COLOR_* := 1 everywhere");
    let normal = read("normal");
    assert!(normal.rgb.chunks(3).all(|n| n == [0.0, 0.0, 1.0]), "NORMAL_Z := 1, x and y unassigned");
    let depth = read("depth");
    for x in 0..32usize {
        let seen = depth.rgb[(5 * 32 + x) * 3];
        // The mean of 2 + IMAGE_X over the pixel is 2.5 + x, within the stratification's error.
        assert!((seen - (2.5 + x as f32)).abs() < 0.1, "depth at x = {x}: {seen}");
    }
    assert!(meta.feature_buffer_file("albedo").starts_with(dir.path()));
    let digest = fbksd_exchange::scenes::scene_digest(&meta.scene_file()).unwrap();
    assert_eq!(build(&meta, false, Some(8)).unwrap().scene_digest, digest, "the buffers are not part of the scene");

    // A scene without features has no buffers, and loses those of its earlier version.
    let plain: String = std::fs::read_to_string(&expr)
        .unwrap()
        .lines()
        .filter(|l| !["TEXTURE_COLOR", "DEPTH", "NORMAL"].iter().any(|f| l.starts_with(f)))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&expr, plain).unwrap();
    build(&meta, false, Some(8)).unwrap();
    for name in fbksd_exchange::scenes::FEATURE_BUFFERS {
        assert!(!meta.feature_buffer_file(name).exists(), "{name} left behind");
    }
}

#[test]
fn a_reference_key_is_known_before_the_reference_and_names_what_was_built() {
    let dir = scene_copy();
    let meta = SceneMeta::load(dir.path()).unwrap();
    let before = key(&meta, Some(8)).unwrap();
    assert!(!meta.reference_file().exists(), "asking for the key builds nothing");
    let note = build(&meta, false, Some(8)).unwrap();
    let built = fbksd_exchange::scenes::reference_key(&note.generator, note.samples_per_pixel, &note.scene_digest);
    assert_eq!(before, built, "the key is the one of the reference made");
    assert_ne!(key(&meta, Some(16)).unwrap(), before, "another budget, another key");

    // The program prints it too, one line per scene.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_fbksd-procedural"))
        .args(["reference", "--key", "--spp", "8"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(String::from_utf8(out.stdout).unwrap(), format!("{before} {}\n", dir.path().display()));
}
