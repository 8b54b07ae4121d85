//! The reference cache follows the one rule every renderer shares
//! (`fbksd_exchange::scenes::current_reference_note`).
//!
//! Regression: a procedural reference was kept after its `.expr` changed
//! (the Embree renderer rebuilt its own): a technique would have been
//! scored against an image of another scene.

use fbksd_procedural::reference::{build, SceneMeta};

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
