//! Bump maps (`"texture displacement"`) and normal maps (`"string
//! normalmap"`) tilt the shading normal as pbrt's do: checked on a plane
//! against the normal the height gradient or the map gives.

mod common;

use common::{header, layout, samples, scene};

/// An EXR of `w × h` pixels, each `f(column)`.
fn exr(w: usize, h: usize, f: impl Fn(usize) -> [f32; 3]) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.exr");
    let rgb: Vec<f32> = (0..w * h).flat_map(|i| f(i % w)).collect();
    fbksd_iqa::image::write_exr(&path, w as u32, h as u32, &rgb).unwrap();
    std::fs::read(path).unwrap()
}

/// A 4 × 4 plane at z = 5 with uv (0, 0)–(1, 1) across it (∂p/∂u = (4, 0, 0)),
/// lit head-on by a distant light; per sample: (world x, normal, DIRECT_LIGHT_R).
fn plane(material: &str, files: &[(&str, &[u8])]) -> Vec<(f32, [f32; 3], f32)> {
    let text = header(16, 16, 60.0, 1)
        + "LightSource \"distant\" \"point3 from\" [0 0 0] \"point3 to\" [0 0 1] \"rgb L\" [2 2 2]\n"
        + material
        + "\nShape \"trianglemesh\" \"point3 P\" [-2 -2 5  2 -2 5  2 2 5  -2 2 5] \"integer indices\" [0 1 2 0 2 3] \"point2 uv\" [0 0 1 0 1 1 0 1]\n";
    let scene = scene(&text, files).unwrap();
    let l = layout(&["WORLD_X", "WORLD_Z", "NORMAL_X", "NORMAL_Y", "NORMAL_Z", "DIRECT_LIGHT_R"]);
    let (data, _) = samples(&scene, &l, 2, 0);
    data.chunks_exact(6).filter(|s| (s[1] - 5.0).abs() < 1e-3).map(|s| (s[0], [s[2], s[3], s[4]], s[5])).collect()
}

#[test]
fn a_bump_map_tilts_the_normal_by_the_height_gradient() {
    // Height 0.4·u: the surface tangent (4, 0, 0.4) tilts the normal by atan(0.1) towards −u.
    let ramp = exr(64, 1, |i| [0.4 * (i as f32 + 0.5) / 64.0; 3]);
    let samples = plane(
        "Texture \"h\" \"float\" \"imagemap\" \"string filename\" \"ramp.exr\"\nMaterial \"diffuse\" \"texture displacement\" \"h\"",
        &[("ramp.exr", &ramp)],
    );
    let tilt = (0.1f32).atan();
    // Facing the viewer (−z): (sin, 0, −cos).
    let want = [tilt.sin(), 0.0, -tilt.cos()];
    let mut checked = 0;
    for (x, n, direct) in samples.iter().filter(|s| s.0.abs() < 1.5) {
        checked += 1;
        for k in 0..3 {
            assert!((n[k] - want[k]).abs() < 2e-3, "at x = {x}: normal {n:?}, want {want:?}");
        }
        // The light arrives along the geometric normal: cos of the tilt.
        let e = 2.0 * tilt.cos() / std::f32::consts::PI;
        assert!((direct - e).abs() < 1e-3 * e, "DIRECT_LIGHT {direct} vs {e}");
    }
    assert!(checked > 100);
    // Without the bump, the normal is the plane's.
    let flat = plane("Material \"diffuse\"", &[]);
    assert!(flat.iter().all(|(_, n, _)| n == &[0.0, 0.0, -1.0]));
}

#[test]
fn a_normal_map_sets_the_normal_in_the_tangent_frame() {
    // The map's normal (0.6, 0, 0.8) in the frame (∂p/∂u, ·, n), n = +z as wound.
    let map = exr(4, 4, |_| [0.8, 0.5, 0.9]);
    let samples = plane("Material \"diffuse\" \"string normalmap\" \"n.exr\"", &[("n.exr", &map)]);
    assert!(samples.len() > 100);
    for (x, n, _) in &samples {
        let want = [-0.6, 0.0, -0.8];
        assert!((0..3).all(|k| (n[k] - want[k]).abs() < 1e-4), "at x = {x}: {n:?} vs {want:?}");
    }
}
