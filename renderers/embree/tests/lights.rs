//! Point, spot and distant lights against their closed forms: a
//! Lambertian plane at z = 5 facing the camera, lit by one delta light.
//! Light from a delta light is exact per sample (there is one direction to
//! sample), so each sample is checked against the formula at its hit.

mod common;

use common::{header, layout, samples, scene};
use std::f64::consts::PI;

const ALBEDO: f64 = 0.5;

/// Per sample of the plane scene under `light`: its hit point, COLOR_R and
/// DIRECT_LIGHT_R. One bounce, so the colour is the light's direct light alone.
fn plane_under(light: &str, spp: u64) -> Vec<([f64; 3], f64, f64)> {
    let text = header(12, 12, 70.0, 1)
        + light
        + "\nMaterial \"diffuse\" \"rgb reflectance\" [0.5 0.5 0.5]\n\
           Shape \"trianglemesh\" \"point3 P\" [-50 -50 5  50 -50 5  50 50 5  -50 50 5] \"integer indices\" [0 1 2 0 2 3]\n";
    let scene = scene(&text, &[]).unwrap();
    let l = layout(&["WORLD_X", "WORLD_Y", "WORLD_Z", "COLOR_R", "DIRECT_LIGHT_R"]);
    let (data, repairs) = samples(&scene, &l, spp, 0);
    assert_eq!(repairs, 0);
    data.chunks_exact(5).map(|s| ([s[0] as f64, s[1] as f64, s[2] as f64], s[3] as f64, s[4] as f64)).collect()
}

fn close(a: f64, b: f64, what: &str) {
    assert!((a - b).abs() <= 1e-4 * b.abs().max(1e-3), "{what}: {a} vs {b}");
}

#[test]
fn a_point_light_gives_the_inverse_square_irradiance() {
    // Intensity 3 at (1, 0.5, 2): E = I cos θ / d² on the plane z = 5.
    let light = [1.0, 0.5, 2.0];
    for (p, color, direct) in plane_under("LightSource \"point\" \"rgb I\" [3 3 3] \"point3 from\" [1 0.5 2]", 2) {
        let d = [p[0] - light[0], p[1] - light[1], p[2] - light[2]];
        let d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        let e = 3.0 * (d[2] / d2.sqrt()) / d2;
        close(direct, e / PI, "DIRECT_LIGHT is E/π");
        close(color, ALBEDO / PI * e, "COLOR is ρ/π E");
    }
}

#[test]
fn a_point_light_is_placed_by_the_transform_and_scaled_by_its_power() {
    // "power" 4π makes a white light of intensity 1; Translate moves it.
    let a = plane_under("LightSource \"point\" \"float power\" 12.566370614359172", 1);
    let b = plane_under("AttributeBegin\nTranslate 0 0 1\nLightSource \"point\" \"rgb I\" [2 2 2]\nAttributeEnd", 1);
    for ((p, color, _), (q, color_b, _)) in a.iter().zip(&b) {
        assert_eq!(p, q, "the same samples");
        let e = |h: f64, i: f64| {
            let d2 = p[0] * p[0] + p[1] * p[1] + (p[2] - h) * (p[2] - h);
            i * ((p[2] - h) / d2.sqrt()) / d2
        };
        close(*color, ALBEDO / PI * e(0.0, 1.0), "power 4π: intensity 1 at the origin");
        close(*color_b, ALBEDO / PI * e(1.0, 2.0), "intensity 2, translated to z = 1");
    }
}

#[test]
fn a_spot_light_is_full_inside_its_cone_dark_outside_and_smooth_between() {
    // Axis +z from the origin; cone 20°, fall-off over the last 10°.
    let spot = "LightSource \"spot\" \"rgb I\" [5 5 5] \"point3 from\" [0 0 0] \"point3 to\" [0 0 1] \"float coneangle\" 20 \"float conedeltaangle\" 10";
    let (mut inside, mut outside, mut between) = (0, 0, 0);
    for (p, color, _) in plane_under(spot, 2) {
        let d2 = p[0] * p[0] + p[1] * p[1] + p[2] * p[2];
        let cos = p[2] / d2.sqrt();
        let full = 5.0 * cos / d2 * ALBEDO / PI;
        let angle = cos.acos().to_degrees();
        if angle < 9.99 {
            inside += 1;
            close(color, full, "inside the inner cone");
        } else if angle > 20.01 {
            outside += 1;
            assert_eq!(color, 0.0, "outside the cone at {angle}°");
        } else if (10.01..19.99).contains(&angle) {
            between += 1;
            // pbrt's smooth step between the cosines of 20° and 10°.
            let (a, b) = (20f64.to_radians().cos(), 10f64.to_radians().cos());
            let t = ((cos - a) / (b - a)).clamp(0.0, 1.0);
            let falloff = t * t * (3.0 - 2.0 * t);
            assert!(color < full && color > 0.0, "between at {angle}°");
            assert!(
                (color - full * falloff).abs() < 1e-3 * full,
                "fall-off at {angle}°: {color} vs {}",
                full * falloff
            );
        }
    }
    assert!(inside > 10 && outside > 10 && between > 10, "{inside} {outside} {between}");
}

#[test]
fn a_distant_light_lights_the_plane_evenly_at_its_cosine() {
    // From (0, 0, 0) towards (0, 1, 1): 45° to the plane's normal.
    for (_, color, direct) in
        plane_under("LightSource \"distant\" \"rgb L\" [2 2 2] \"point3 from\" [0 0 0] \"point3 to\" [0 1 1]", 1)
    {
        let e = 2.0 * std::f64::consts::FRAC_1_SQRT_2;
        close(direct, e / PI, "DIRECT_LIGHT");
        close(color, ALBEDO / PI * e, "COLOR");
    }
}

#[test]
fn a_point_light_beside_a_sky_adds_to_it() {
    // Light choice and multiple importance sampling with a delta light and
    // an environment: the mean is the sum of the two lights' answers.
    let samples =
        plane_under("LightSource \"infinite\" \"rgb L\" [0.4 0.4 0.4]\nLightSource \"point\" \"rgb I\" [3 3 3]", 64);
    let (mut sum, mut expected) = (0.0, 0.0);
    for (p, color, _) in &samples {
        let d2 = p[0] * p[0] + p[1] * p[1] + p[2] * p[2];
        expected += ALBEDO * 0.4 + ALBEDO / PI * 3.0 * (p[2] / d2.sqrt()) / d2;
        sum += color;
    }
    let (mean, want) = (sum / samples.len() as f64, expected / samples.len() as f64);
    assert!((mean - want).abs() < 0.01 * want, "{mean} vs {want}");
}

#[test]
fn a_light_with_a_bad_cone_is_an_error_naming_the_line() {
    let text = header(4, 4, 60.0, 1) + "LightSource \"spot\" \"float coneangle\" 10 \"float conedeltaangle\" 20\n";
    let err = scene(&text, &[]).err().unwrap();
    assert!(err.contains("scene.pbrt:6:") && err.contains("conedeltaangle"), "{err}");
}

/// A square EXR environment map of `size` pixels with a pattern, and its pixels.
fn environment_file(size: usize) -> (Vec<u8>, Vec<[f32; 3]>) {
    let pixels: Vec<[f32; 3]> = (0..size * size)
        .map(|i| {
            let (x, y) = (i % size, i / size);
            let v = 0.2 + ((x * 7 + y * 13) % 10) as f32 / 5.0;
            [v, 0.5 * v, if x < size / 4 { 4.0 } else { 0.1 }]
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sky.exr");
    let flat: Vec<f32> = pixels.iter().flatten().copied().collect();
    fbksd_iqa::image::write_exr(&path, size as u32, size as u32, &flat).unwrap();
    (std::fs::read(&path).unwrap(), pixels)
}

#[test]
fn an_environment_map_lights_a_plane_with_its_cosine_weighted_mean() {
    // The plane's normal is world +y, which `Rotate -90 1 0 0` makes the
    // map's +z. Its irradiance is the sum over pixels of L cos θ times each
    // pixel's solid angle, 4π/N (the mapping is equal-area), summed here
    // over 8 × 8 points per pixel.
    let size = 32;
    let (file, pixels) = environment_file(size);
    let text = header(8, 8, 60.0, 1)
        + "AttributeBegin\nRotate -90 1 0 0\nLightSource \"infinite\" \"string filename\" \"sky.exr\"\nAttributeEnd\n\
           Shape \"trianglemesh\" \"point3 P\" [-50 -1 -50  50 -1 -50  50 -1 50  -50 -1 50] \"integer indices\" [0 2 1 0 3 2]\n";
    let scene = scene(&text, &[("sky.exr", &file)]).unwrap();
    let (sub, mut expected) = (8, [0f64; 3]);
    for (i, p) in pixels.iter().enumerate() {
        for k in 0..sub * sub {
            let u = ((i % size) as f64 + ((k % sub) as f64 + 0.5) / sub as f64) / size as f64;
            let v = ((i / size) as f64 + ((k / sub) as f64 + 0.5) / sub as f64) / size as f64;
            let z = fbksd_embree::scene::environment::square_to_sphere([u as f32, v as f32]).z.max(0.0) as f64;
            for c in 0..3 {
                expected[c] += p[c] as f64 * z * 4.0 * PI / (size * size * sub * sub) as f64;
            }
        }
    }
    // DIRECT_LIGHT (light samples alone) is E/π; COLOR (light and BSDF
    // samples, weighted by MIS) is the default material's ρ/π E.
    let l = layout(&["DEPTH", "DIRECT_LIGHT_R", "DIRECT_LIGHT_G", "DIRECT_LIGHT_B", "COLOR_R", "COLOR_G", "COLOR_B"]);
    let (data, repairs) = samples(&scene, &l, 2048, 0);
    assert_eq!(repairs, 0);
    let hits: Vec<&[f32]> = data.chunks_exact(7).filter(|s| s[0] > 0.0).collect();
    assert!(hits.len() > 1000);
    for (c, e) in expected.iter().enumerate() {
        let mean = |e: usize| hits.iter().map(|s| s[e] as f64).sum::<f64>() / hits.len() as f64;
        let want = e / PI;
        assert!((mean(1 + c) - want).abs() < 0.01 * want, "channel {c}: E/π {} vs {want}", mean(1 + c));
        assert!(
            (mean(4 + c) - ALBEDO * want).abs() < 0.01 * want,
            "channel {c}: colour {} vs {}",
            mean(4 + c),
            ALBEDO * want
        );
    }
}

#[test]
fn a_camera_ray_that_misses_sees_the_map_in_its_direction() {
    let size = 16;
    let (file, pixels) = environment_file(size);
    let text = header(10, 10, 60.0, 1) + "LightSource \"infinite\" \"string filename\" \"sky.exr\" \"float scale\" 2\n";
    let scene = scene(&text, &[("sky.exr", &file)]).unwrap();
    let l = layout(&["IMAGE_X", "IMAGE_Y", "COLOR_R", "COLOR_G", "COLOR_B"]);
    let (data, _) = samples(&scene, &l, 4, 0);
    let tan = 30f64.to_radians().tan();
    for s in data.chunks_exact(5) {
        // Camera at the origin looking down +z, +x to the right, +y up.
        let (sx, sy) = ((s[0] as f64 / 10.0) * 2.0 - 1.0, 1.0 - (s[1] as f64 / 10.0) * 2.0);
        let d = fbksd_embree::math::vec3((sx * tan) as f32, (sy * tan) as f32, 1.0).normalize();
        let [u, v] = fbksd_embree::scene::environment::sphere_to_square(d);
        let p = pixels[((v * size as f32) as usize).min(size - 1) * size + ((u * size as f32) as usize).min(size - 1)];
        // Pixels near a boundary may round either way; most must match exactly.
        let want = [2.0 * p[0], 2.0 * p[1], 2.0 * p[2]];
        if s[2..5] != want {
            let near_edge = [u, v].iter().any(|t| ((t * size as f32) - (t * size as f32).round()).abs() < 1e-3);
            assert!(near_edge, "direction {d:?}: {:?} vs {want:?}", &s[2..5]);
        }
    }
}

#[test]
fn an_environment_map_must_be_square() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("wide.exr");
    fbksd_iqa::image::write_exr(&path, 4, 2, &[1.0; 24]).unwrap();
    let text = header(4, 4, 60.0, 1) + "LightSource \"infinite\" \"string filename\" \"wide.exr\"\n";
    let err = scene(&text, &[("wide.exr", &std::fs::read(&path).unwrap())]).err().unwrap();
    assert!(err.contains("scene.pbrt:6:") && err.contains("4×2") && err.contains("square"), "{err}");
}
