//! Whole scenes with known answers: the white furnace, features on simple
//! geometry, INPUT parameters, replaying a sample, and finite samples at
//! the numerical extremes.

mod common;

use common::{header, layout, pixel_means, samples, scene};
use fbksd_core::{ElementIo, Feature, SampleLayout};

#[test]
fn white_furnace_every_pixel_equals_the_environment() {
    // A white diffuse sphere and a smooth glass sphere under a constant
    // environment: a lossless scene, so every pixel is the environment.
    let text = header(24, 16, 60.0, 200)
        + "LightSource \"infinite\" \"rgb L\" [0.5 0.5 0.5]\n\
           AttributeBegin\n Material \"diffuse\" \"rgb reflectance\" [1 1 1]\n Translate -0.8 0 4\n Shape \"sphere\" \"float radius\" 0.7\nAttributeEnd\n\
           AttributeBegin\n Material \"dielectric\" \"float eta\" 1.5\n Translate 0.8 0 4\n Shape \"sphere\" \"float radius\" 0.7\nAttributeEnd\n";
    let scene = scene(&text, &[]).unwrap();
    let l = layout(&["COLOR_R", "COLOR_G", "COLOR_B"]);
    let spp = 256;
    let (data, repairs) = samples(&scene, &l, spp, 0);
    assert_eq!(repairs, 0);
    for c in 0..3 {
        for (p, v) in pixel_means(&scene, &data, &l, spp, c).iter().enumerate() {
            assert!((v - 0.5).abs() < 0.03, "pixel {p} channel {c}: {v}, the environment is 0.5");
        }
    }
}

#[test]
fn depth_of_a_plane_is_its_distance_along_each_ray() {
    let text = header(9, 9, 60.0, 1) + "Shape \"trianglemesh\" \"point3 P\" [-100 -100 5  100 -100 5  100 100 5  -100 100 5] \"integer indices\" [0 1 2 0 2 3]\n";
    let scene = scene(&text, &[]).unwrap();
    let l = layout(&["IMAGE_X", "IMAGE_Y", "DEPTH", "NORMAL_Z", "WORLD_Z"]);
    let (data, _) = samples(&scene, &l, 4, 0);
    let tan = (30f64).to_radians().tan();
    for s in data.chunks_exact(5) {
        // The camera ray through raster (x, y): direction (sx·tan, sy·tan, 1).
        let sx = (s[0] as f64 / 9.0) * 2.0 - 1.0;
        let sy = 1.0 - (s[1] as f64 / 9.0) * 2.0;
        let expected = 5.0 * (1.0 + (sx * tan).powi(2) + (sy * tan).powi(2)).sqrt();
        assert!((s[2] as f64 - expected).abs() < 1e-3 * expected, "depth {} vs {expected}", s[2]);
        assert_eq!(s[3], -1.0, "the normal faces the camera");
        assert!((s[4] - 5.0).abs() < 1e-4);
    }
}

#[test]
fn a_feature_buffer_is_each_pixel_mean_of_the_feature_its_samples_give() {
    // The buffers made with a reference: the same samples as the protocol's
    // (request and stratification), averaged per pixel.
    let text = header(9, 7, 60.0, 1)
        + "Material \"diffuse\" \"rgb reflectance\" [0.2 0.4 0.6]\n\
           Shape \"trianglemesh\" \"point3 P\" [-100 -100 5  100 -100 5  100 100 5  -100 100 5] \"integer indices\" [0 1 2 0 2 3]\n";
    let scene = scene(&text, &[]).unwrap();
    let l = layout(&["DEPTH", "TEXTURE_COLOR_G", "NORMAL_Z"]);
    let (data, _) = samples(&scene, &l, 16, 7);
    let depth = fbksd_embree::render::render_features(&scene, 16, 7, [(Feature::Depth, 0); 3]);
    let albedo = fbksd_embree::render::render_features(
        &scene,
        16,
        7,
        [(Feature::TextureColorR, 0), (Feature::TextureColorG, 0), (Feature::TextureColorB, 0)],
    );
    let normal = fbksd_embree::render::render_features(
        &scene,
        16,
        7,
        [(Feature::NormalX, 0), (Feature::NormalY, 0), (Feature::NormalZ, 0)],
    );
    for (p, mean) in pixel_means(&scene, &data, &l, 16, 0).iter().enumerate() {
        assert!((depth[p * 3] as f64 - mean).abs() < 1e-5 * mean, "pixel {p}: {} vs {mean}", depth[p * 3]);
        assert_eq!((depth[p * 3], depth[p * 3]), (depth[p * 3 + 1], depth[p * 3 + 2]), "depth is grey");
        assert_eq!(&albedo[p * 3..p * 3 + 3], &[0.2, 0.4, 0.6], "pixel {p}: the reflectance");
        assert_eq!(&normal[p * 3..p * 3 + 3], &[0.0, 0.0, -1.0], "pixel {p}: towards the camera");
    }
}

#[test]
fn normals_of_a_sphere_point_from_its_centre_to_the_hit() {
    let text = header(16, 16, 40.0, 1) + "Translate 0 0 6\nShape \"sphere\" \"float radius\" 1.5\n";
    let scene = scene(&text, &[]).unwrap();
    let names = ["WORLD_X", "WORLD_Y", "WORLD_Z", "NORMAL_X", "NORMAL_Y", "NORMAL_Z", "DEPTH"];
    let l = layout(&names);
    let (data, _) = samples(&scene, &l, 2, 0);
    let mut hits = 0;
    for s in data.chunks_exact(names.len()) {
        if s[6] == 0.0 {
            continue; // missed the sphere
        }
        hits += 1;
        let r = ((s[0] as f64).powi(2) + (s[1] as f64).powi(2) + (s[2] as f64 - 6.0).powi(2)).sqrt();
        assert!((r - 1.5).abs() < 1e-4, "hit at radius {r}");
        for (n, p) in [(s[3], s[0]), (s[4], s[1]), (s[5], s[2] - 6.0)] {
            assert!((n as f64 - p as f64 / 1.5).abs() < 1e-4, "normal {n} vs {}", p / 1.5);
        }
    }
    assert!(hits > 100, "{hits}");
}

#[test]
fn albedo_of_a_textured_quad_is_the_texture_at_the_hit() {
    // A checkerboard of 4 × 4 squares on a quad filling the view.
    let text = header(32, 32, 90.0, 2)
        + "Texture \"checks\" \"spectrum\" \"checkerboard\" \"float uscale\" 4 \"float vscale\" 4 \"rgb tex1\" [0.9 0.1 0.1] \"rgb tex2\" [0.1 0.2 0.9]\n\
           Material \"coateddiffuse\" \"texture reflectance\" \"checks\" \"float roughness\" 0.1\n\
           Shape \"trianglemesh\" \"point3 P\" [-1 -1 1  1 -1 1  1 1 1  -1 1 1] \"point2 uv\" [0 0 1 0 1 1 0 1] \"integer indices\" [0 1 2 0 2 3]\n";
    let scene = scene(&text, &[]).unwrap();
    let l = layout(&["WORLD_X", "WORLD_Y", "TEXTURE_COLOR_R", "TEXTURE_COLOR_B", "TEXTURE_COLOR_R_NS"]);
    let (data, _) = samples(&scene, &l, 2, 0);
    for s in data.chunks_exact(5) {
        let (u, v) = ((s[0] + 1.0) / 2.0, (s[1] + 1.0) / 2.0);
        let even = ((u * 4.0).floor() as i64 + (v * 4.0).floor() as i64) % 2 == 0;
        let (r, b) = if even { (0.9, 0.1) } else { (0.1, 0.9) };
        // Far from a square's edge, the texture is unambiguous.
        let edge = |t: f32| ((t * 4.0) - (t * 4.0).round()).abs() < 1e-3;
        if edge(u) || edge(v) {
            continue;
        }
        assert_eq!((s[2], s[3], s[4]), (r, b, r), "at uv ({u}, {v})");
    }
}

#[test]
fn the_first_non_specular_hit_is_seen_through_a_mirror() {
    // A mirror facing the camera at z = 3 (tilted 45°) reflects a diffuse wall.
    let text = header(8, 8, 10.0, 4)
        + "LightSource \"infinite\" \"rgb L\" [1 1 1]\n\
           AttributeBegin\n Material \"conductor\" \"float roughness\" 0 \"rgb reflectance\" [0.9 0.9 0.9]\n Translate 0 0 3\n Rotate 45 0 1 0\n\
           Shape \"trianglemesh\" \"point3 P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0] \"integer indices\" [0 1 2 0 2 3]\nAttributeEnd\n\
           Material \"diffuse\" \"rgb reflectance\" [0.25 0.5 0.75]\n\
           Shape \"trianglemesh\" \"point3 P\" [-10 -5 -5  -10 5 -5  -10 5 10  -10 -5 10] \"integer indices\" [0 1 2 0 2 3]\n";
    let scene = scene(&text, &[]).unwrap();
    let l = layout(&["WORLD_Z", "WORLD_X_NS", "TEXTURE_COLOR_G_NS", "TEXTURE_COLOR_G", "NORMAL_X_NS"]);
    let (data, _) = samples(&scene, &l, 2, 0);
    for s in data.chunks_exact(5) {
        assert!((s[0] - 3.0).abs() < 0.5, "first hit on the mirror: z {}", s[0]);
        assert!((s[1] + 10.0).abs() < 1e-3, "first non-specular hit on the wall: x {}", s[1]);
        assert_eq!(s[2], 0.5);
        assert!(
            (s[3]
                - fbksd_embree::bsdf::fresnel::conductor(
                    1.0,
                    fbksd_embree::math::Vec3::ONE,
                    fbksd_embree::bsdf::fresnel::k_from_reflectance(fbksd_embree::math::Vec3::splat(0.9))
                )
                .y)
                .abs()
                < 1e-4
        );
        assert_eq!(s[4], 1.0, "the wall's normal faces the reflected ray");
    }
}

/// A small lit scene with everything in it: glossy, diffuse, glass, a light.
fn lit_scene() -> fbksd_embree::scene::Scene {
    let text = header(12, 10, 50.0, 5)
        + "LightSource \"infinite\" \"rgb L\" [0.2 0.3 0.4]\n\
           AttributeBegin\n AreaLightSource \"diffuse\" \"rgb L\" [8 8 8]\n Translate 0 3 4\n Shape \"sphere\" \"float radius\" 0.5\nAttributeEnd\n\
           Material \"coateddiffuse\" \"rgb reflectance\" [0.6 0.3 0.2] \"float roughness\" 0.05\n\
           Shape \"trianglemesh\" \"point3 P\" [-5 -1 0  5 -1 0  5 -1 10  -5 -1 10] \"integer indices\" [0 1 2 0 2 3]\n\
           AttributeBegin\n Material \"dielectric\" \"float roughness\" 0.01\n Translate 0.5 0 4\n Shape \"sphere\" \"float radius\" 0.6\nAttributeEnd\n";
    scene(&text, &[]).unwrap()
}

#[test]
fn input_parameters_are_honoured() {
    let scene = lit_scene();
    let mut l = SampleLayout::new();
    for p in ["IMAGE_X", "IMAGE_Y", "LENS_U", "LENS_V", "TIME", "LIGHT_X", "LIGHT_Y"] {
        l = l.with_io(p, ElementIo::Input);
    }
    let l = l.with("COLOR_R").with("DEPTH").compile().unwrap();
    // Every sample at the same position: pixel (6.25, 4.5), same light sample.
    let mut data = vec![0f32; 64 * 9];
    for s in data.chunks_exact_mut(9) {
        s[..7].copy_from_slice(&[6.25, 4.5, 0.3, 0.3, 0.5, 0.25, 0.75]);
    }
    let places = (0..64).map(|s| fbksd_embree::render::Place::Pixel {
        x: (s % 12) as u32,
        y: (s / 12) as u32,
        s: s as u64,
        spp: 1,
    });
    let repairs = fbksd_embree::render::Repairs::default();
    let bindings = fbksd_embree::render::Bindings::new(&l);
    fbksd_embree::render::fill(
        &scene,
        &bindings,
        &l,
        &fbksd_renderer::sampler::Sampler::new(12, 10, 3),
        &mut data,
        places,
        &repairs,
    );
    let depths: Vec<f32> = data.chunks_exact(9).map(|s| s[8]).collect();
    assert!(depths.iter().all(|d| *d == depths[0] && *d > 0.0), "the same camera ray for every sample: {depths:?}");
    // The inputs are left as the technique wrote them.
    assert!(data.chunks_exact(9).all(|s| s[..7] == [6.25, 4.5, 0.3, 0.3, 0.5, 0.25, 0.75]));
}

#[test]
fn a_sample_replayed_from_its_seed_gives_identical_values() {
    let scene = lit_scene();
    let names = [
        "IMAGE_X",
        "IMAGE_Y",
        "COLOR_R",
        "COLOR_G",
        "DIRECT_LIGHT_R",
        "DIFFUSE_COLOR_B",
        "WORLD_X_NS",
        "TEXTURE_COLOR_R_1",
    ];
    let l = {
        let mut l = SampleLayout::new();
        for n in &names[..7] {
            l = l.with(n);
        }
        l.with_number("TEXTURE_COLOR_R", 1).compile().unwrap()
    };
    let (all, _) = samples(&scene, &l, 4, 9);
    let (again, _) = samples(&scene, &l, 4, 9);
    assert_eq!(all, again, "the same request replays bit for bit");
    // One sample alone (pixel (7, 3), sample 2 of 4), replayed from its place.
    let size = l.sample_size();
    let index = ((3 * 12 + 7) * 4 + 2) as usize;
    let mut one = vec![0f32; size];
    let repairs = fbksd_embree::render::Repairs::default();
    fbksd_embree::render::fill(
        &scene,
        &fbksd_embree::render::Bindings::new(&l),
        &l,
        &fbksd_renderer::sampler::Sampler::new(12, 10, 9),
        &mut one,
        std::iter::once(fbksd_embree::render::Place::Pixel { x: 7, y: 3, s: 2, spp: 4 }),
        &repairs,
    );
    assert_eq!(one, all[index * size..][..size]);
    // Another request draws other samples.
    let (other, _) = samples(&scene, &l, 4, 10);
    assert_ne!(all, other);
}

#[test]
fn diffuse_color_splits_colour_at_the_roughness_threshold() {
    let scene = lit_scene();
    let names =
        ["COLOR_R", "COLOR_G", "COLOR_B", "DIFFUSE_COLOR_R", "DIFFUSE_COLOR_G", "DIFFUSE_COLOR_B", "DEPTH", "WORLD_Y"];
    let run = |t: f32| {
        let mut l = SampleLayout::new();
        for n in names {
            l = l.with(n);
        }
        samples(&scene, &l.with_roughness_threshold(t).compile().unwrap(), 16, 0).0
    };
    let diffuse_sum = |data: &[f32]| data.chunks_exact(8).map(|s| (s[3] + s[4] + s[5]) as f64).sum::<f64>();
    // Threshold 0: every scattering counts as diffuse, so on a surface that
    // does not emit, the diffuse colour is the whole colour.
    let all = run(0.0);
    let mut checked = 0;
    for s in all.chunks_exact(8) {
        if s[6] > 0.0 && s[7] < 2.0 {
            for c in 0..3 {
                assert!((s[c] - s[3 + c]).abs() <= 1e-5 * s[c].abs() + 1e-7, "colour {} vs diffuse {}", s[c], s[3 + c]);
            }
            checked += 1;
        } else if s[6] == 0.0 {
            assert_eq!(&s[3..6], &[0.0; 3], "light seen directly is not diffuse");
        }
    }
    assert!(checked > 100, "{checked}");
    // Above the glossy lobes' α (0.22 coating, 0.1 glass): only the diffuse base remains.
    let some = diffuse_sum(&run(0.5));
    assert!(some < 0.9 * diffuse_sum(&all) && some > 0.05 * diffuse_sum(&all), "{some}");
    // A huge threshold keeps exactly the Lambertian base (roughness ∞).
    let base_only = diffuse_sum(&run(1e30));
    assert!((base_only - some).abs() <= 1e-6 * some, "{base_only} vs {some}");
}

#[test]
fn direct_light_on_a_lambertian_plane_under_a_uniform_sky_is_the_sky() {
    // E/π under a uniform sky of radiance L over the upper hemisphere is L.
    let text = header(4, 4, 30.0, 1)
        + "LightSource \"infinite\" \"rgb L\" [0.7 0.7 0.7]\nTranslate 0 0 2\nShape \"trianglemesh\" \"point3 P\" [-9 -9 0  -9 9 0  9 9 0  9 -9 0] \"integer indices\" [0 1 2 0 2 3]\n";
    let scene = scene(&text, &[]).unwrap();
    let l = layout(&["DIRECT_LIGHT_R"]);
    let (data, _) = samples(&scene, &l, 1024, 0);
    let mean = data.iter().map(|v| *v as f64).sum::<f64>() / data.len() as f64;
    assert!((mean - 0.7).abs() < 0.02, "{mean}");
}

#[test]
fn every_sample_is_finite_at_the_numerical_extremes() {
    let everything: Vec<String> = Feature::ALL
        .iter()
        .flat_map(|f| {
            if f.is_numbered() {
                vec![f.name().to_string(), format!("{}#1", f.name())]
            } else {
                vec![f.name().to_string()]
            }
        })
        .collect();
    let mut l = SampleLayout::new();
    for n in &everything {
        l = match n.strip_suffix("#1") {
            Some(name) => l.with_number(name, 1),
            None => l.with(n),
        };
    }
    let l = l.with("IMAGE_X").compile().unwrap();
    let quad = |z: f32, s: f32| {
        format!("Shape \"trianglemesh\" \"point3 P\" [{a} {a} {z}  {b} {a} {z}  {b} {b} {z}  {a} {b} {z}] \"integer indices\" [0 1 2 0 2 3]\n", a = -s, b = s)
    };
    let cases: Vec<(&str, String)> = vec![
        ("grazing plane", header(16, 16, 60.0, 5) + "LightSource \"infinite\" \"rgb L\" [1 1 1]\nMaterial \"conductor\" \"float roughness\" 0.01\nShape \"trianglemesh\" \"point3 P\" [-100 -1e-4 0  100 -1e-4 0  100 -1e-4 1000  -100 -1e-4 1000] \"integer indices\" [0 1 2 0 2 3]\n"),
        ("roughness 0 and huge", header(16, 16, 60.0, 5) + "LightSource \"infinite\" \"rgb L\" [1 1 1]\nAttributeBegin\nMaterial \"conductor\" \"float roughness\" 0 \"bool remaproughness\" false\nTranslate -1 0 4\nShape \"sphere\"\nAttributeEnd\nMaterial \"dielectric\" \"float roughness\" 1e8\nTranslate 1 0 4\nShape \"sphere\"\n"),
        ("index of refraction 1", header(16, 16, 60.0, 8) + "LightSource \"infinite\" \"rgb L\" [1 1 1]\nMaterial \"dielectric\" \"float eta\" 1\nTranslate 0 0 3\nShape \"sphere\"\nMaterial \"dielectric\" \"float eta\" 1 \"float roughness\" 0.3\nShape \"sphere\" \"float radius\" 0.5\n"),
        ("degenerate and tiny triangles", header(16, 16, 60.0, 5) + "LightSource \"infinite\" \"rgb L\" [1 1 1]\nShape \"trianglemesh\" \"point3 P\" [0 0 2  0 0 2  0 0 2  -1 -1 2  1 1 2  0 0 2 0 1e-9 2  1e-9 0 2  0 0 2.000000001] \"integer indices\" [0 1 2  3 4 5  6 7 8]\n" + &quad(3.0, 1.0)),
        ("very small scene", header(16, 16, 60.0, 5) + "AttributeBegin\nAreaLightSource \"diffuse\" \"rgb L\" [5 5 5]\nTranslate 0 3e-5 4e-5\nShape \"sphere\" \"float radius\" 1e-5\nAttributeEnd\nMaterial \"coateddiffuse\" \"float roughness\" 0.2\n" + &quad(5e-5, 1e-4) + "Translate 0 0 4e-5\nShape \"sphere\" \"float radius\" 1e-5\n"),
        ("very large scene", header(16, 16, 60.0, 5) + "AttributeBegin\nAreaLightSource \"diffuse\" \"rgb L\" [5 5 5]\nTranslate 0 3e5 4e5\nShape \"sphere\" \"float radius\" 1e5\nAttributeEnd\nMaterial \"coateddiffuse\" \"float roughness\" 0.2\n" + &quad(5e5, 1e6) + "Translate 0 0 4e5\nShape \"sphere\" \"float radius\" 1e5\n"),
        ("lights of extreme power", header(16, 16, 60.0, 5) + "AttributeBegin\nAreaLightSource \"diffuse\" \"rgb L\" [1e12 1e12 1e12]\nTranslate -1 1 4\nShape \"sphere\" \"float radius\" 1e-3\nAttributeEnd\nAttributeBegin\nAreaLightSource \"diffuse\" \"rgb L\" [1e-12 1e-12 1e-12]\nTranslate 1 1 4\nShape \"sphere\" \"float radius\" 0.5\nAttributeEnd\nMaterial \"diffuse\"\n" + &quad(6.0, 10.0)),
    ];
    for (name, text) in cases {
        let scene = scene(&text, &[]).unwrap_or_else(|e| panic!("{name}: {e}"));
        let (data, repairs) = samples(&scene, &l, 8, 0);
        assert_eq!(repairs, 0, "{name}: the renderer produced non-finite values");
        assert!(data.iter().all(|v| v.is_finite()), "{name}: a non-finite sample");
        let color: f64 = data.chunks_exact(l.sample_size()).map(|s| s[0] as f64).sum();
        assert!(color > 0.0, "{name}: the scene rendered black");
    }
}

#[test]
fn features_without_colour_are_the_same_features_at_a_fraction_of_the_rays() {
    let scene = lit_scene();
    let geometry = ["WORLD_X", "NORMAL_Y", "TEXTURE_COLOR_R_NS", "DEPTH", "DIRECT_LIGHT_G"];
    let (alone, _) = samples(&scene, &layout(&geometry), 4, 0);
    let mut with_colour: Vec<&str> = geometry.to_vec();
    with_colour.push("COLOR_R");
    let (full, _) = samples(&scene, &layout(&with_colour), 4, 0);
    let stripped: Vec<f32> = full.chunks_exact(6).flat_map(|s| s[..5].to_vec()).collect();
    assert_eq!(alone, stripped, "the features do not depend on whether colour is asked for");
    // In a closed room every path is long: features alone take two rays per sample.
    let cornell =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/production/cornell-box/small.pbrt");
    let cornell = fbksd_embree::pbrt::load(&cornell).unwrap();
    let features = layout(&["WORLD_X", "NORMAL_Y", "TEXTURE_COLOR_R_NS", "DEPTH"]);
    let few = common::rays(&cornell, &features, 1);
    let many = common::rays(&cornell, &layout(&["WORLD_X", "NORMAL_Y", "TEXTURE_COLOR_R_NS", "DEPTH", "COLOR_R"]), 1);
    assert!(few * 2 < many, "{few} rays for features alone, {many} with colour");
}

#[test]
fn sphere_texture_coordinates_follow_pbrt() {
    // Seen from above (+y, with the sphere's z axis turned to +y), the
    // top of the sphere is its +z pole, where pbrt's v is 1.
    let text = header(8, 8, 10.0, 1).replace("LookAt 0 0 0  0 0 1  0 1 0", "LookAt 0 10 0  0 0 0  0 0 1")
        + "Texture \"halves\" \"spectrum\" \"checkerboard\" \"float uscale\" 1 \"float vscale\" 2 \"rgb tex1\" [0.2 0.2 0.2] \"rgb tex2\" [0.8 0.8 0.8]\n\
           Material \"diffuse\" \"texture reflectance\" \"halves\"\nRotate -90 1 0 0\nScale 2 2 2\nShape \"sphere\"\n";
    let scene = scene(&text, &[]).unwrap();
    let l = layout(&["TEXTURE_COLOR_R", "WORLD_Y"]);
    let (data, _) = samples(&scene, &l, 1, 0);
    for s in data.chunks_exact(2) {
        assert!(s[1] > 1.7, "hits the top of the sphere: y {}", s[1]);
        assert_eq!(s[0], 0.8, "v near 1 is the upper half of the texture");
    }
}
