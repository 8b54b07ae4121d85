//! pbrt-v4's `mix` and `interface` materials in whole scenes.

mod common;

use common::{header, layout, samples, scene, scene_with_warnings};

const PLANE: &str =
    "Shape \"trianglemesh\" \"point3 P\" [-50 -50 5  50 -50 5  50 50 5  -50 50 5] \"integer indices\" [0 1 2 0 2 3]\n";

#[test]
fn a_mix_picks_its_second_material_with_probability_amount() {
    let text = header(16, 16, 60.0, 1)
        + "LightSource \"infinite\" \"rgb L\" [1 1 1]\n\
           MakeNamedMaterial \"red\" \"string type\" \"diffuse\" \"rgb reflectance\" [0.8 0 0]\n\
           MakeNamedMaterial \"blue\" \"string type\" \"diffuse\" \"rgb reflectance\" [0 0 0.8]\n\
           Material \"mix\" \"string materials\" [\"red\" \"blue\"] \"float amount\" 0.25\n"
        + PLANE;
    let scene = scene(&text, &[]).unwrap();
    let l = layout(&["TEXTURE_COLOR_R", "TEXTURE_COLOR_B", "COLOR_B"]);
    let (data, _) = samples(&scene, &l, 16, 0);
    let n = data.len() / 3;
    let blue = data.chunks_exact(3).filter(|s| s[1] == 0.8).count();
    let red = data.chunks_exact(3).filter(|s| s[0] == 0.8).count();
    assert_eq!(red + blue, n, "every sample sees one of the two");
    // 4096 samples: the fraction is within 4 standard deviations (0.027) of 0.25.
    let share = blue as f64 / n as f64;
    assert!((share - 0.25).abs() < 0.027, "{share}");
    // The colour is the mixture: 0.25 of the blue material's (0.8 under a white sky).
    let mean_b = data.chunks_exact(3).map(|s| s[2] as f64).sum::<f64>() / n as f64;
    assert!((mean_b - 0.25 * 0.8).abs() < 0.03, "{mean_b}");
    // The pick replays.
    assert_eq!(data, samples(&scene, &l, 16, 0).0);
}

#[test]
fn a_mix_naming_an_unknown_material_is_an_error() {
    let text = header(4, 4, 60.0, 1) + "Material \"mix\" \"string materials\" [\"a\" \"b\"]\n";
    let err = scene(&text, &[]).err().unwrap();
    assert!(err.contains("scene.pbrt:6:") && err.contains("names \"a\", which is not defined"), "{err}");
}

#[test]
fn a_shape_with_an_interface_material_is_left_out_with_a_warning() {
    let text = header(8, 8, 60.0, 1)
        + "AttributeBegin\nMaterial \"interface\"\nTranslate 0 0 3\nShape \"sphere\" \"float radius\" 1\nAttributeEnd\n"
        + PLANE;
    let (scene, warnings) = scene_with_warnings(&text).unwrap();
    assert!(
        warnings.iter().any(|w| w.contains("scene.pbrt:9:") && w.contains("interface material left out")),
        "{warnings:?}"
    );
    let (data, _) = samples(&scene, &layout(&["WORLD_Z"]), 4, 0);
    assert!(data.iter().all(|z| (z - 5.0).abs() < 1e-3), "every ray reaches the plane");
}

#[test]
fn diffuse_transmission_lets_light_through_from_behind() {
    // A sheet lit from behind by a distant light (L = 2, straight on): its
    // visible side shows the transmitted T/π·E, nothing reflected.
    let text = header(8, 8, 60.0, 1)
        + "LightSource \"distant\" \"point3 from\" [0 0 10] \"point3 to\" [0 0 0] \"rgb L\" [2 2 2]\n\
           Material \"diffusetransmission\" \"rgb reflectance\" [0 0 0] \"rgb transmittance\" [0.5 0.3 0.1]\n"
        + PLANE;
    let scene = scene(&text, &[]).unwrap();
    let (data, _) = samples(&scene, &layout(&["COLOR_R", "COLOR_G", "COLOR_B", "TEXTURE_COLOR_R"]), 4, 0);
    for s in data.chunks_exact(4) {
        for (c, t) in [0.5f32, 0.3, 0.1].iter().enumerate() {
            let want = t / std::f32::consts::PI * 2.0;
            assert!((s[c] - want).abs() < 1e-4, "channel {c}: {} vs {want}", s[c]);
        }
        assert_eq!(s[3], 0.0, "the albedo feature is the reflectance");
    }
}

#[test]
fn a_thin_glass_pane_loses_no_light_and_bends_none() {
    // Under a uniform sky the pane's reflection and transmission add up to the sky.
    let pane = "Material \"thindielectric\" \"float eta\" 1.5\n\
                Shape \"trianglemesh\" \"point3 P\" [-50 -50 3  50 -50 3  50 50 3  -50 50 3] \"integer indices\" [0 1 2 0 2 3]\n";
    let sky = header(8, 8, 60.0, 20) + "LightSource \"infinite\" \"rgb L\" [0.5 0.5 0.5]\n" + pane;
    let (data, _) = samples(&scene(&sky, &[]).unwrap(), &layout(&["COLOR_R"]), 256, 0);
    let mean = data.iter().map(|v| *v as f64).sum::<f64>() / data.len() as f64;
    assert!((mean - 0.5).abs() < 0.01, "{mean}");
    // Seen through the pane, the wall behind is where the camera ray meets it: no refraction.
    let wall = header(8, 8, 60.0, 20) + pane + "Material \"diffuse\"\n" + PLANE;
    let l = layout(&["IMAGE_X", "IMAGE_Y", "WORLD_X_NS", "WORLD_Y_NS", "WORLD_Z_NS"]);
    let (data, _) = samples(&scene(&wall, &[]).unwrap(), &l, 16, 0);
    let tan = 30f32.to_radians().tan();
    let mut through = 0;
    for s in data.chunks_exact(5).filter(|s| (s[4] - 5.0).abs() < 1e-3) {
        through += 1;
        let (sx, sy) = ((s[0] / 8.0) * 2.0 - 1.0, 1.0 - (s[1] / 8.0) * 2.0);
        assert!((s[2] - 5.0 * sx * tan).abs() < 1e-3 && (s[3] - 5.0 * sy * tan).abs() < 1e-3, "{s:?}");
    }
    assert!(through > 500, "{through} samples see the wall through the pane");
}
