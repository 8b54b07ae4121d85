//! The shapes made of triangles (disk, cylinder, bilinear patches, Loop
//! subdivision surfaces) in whole scenes: a disk light's irradiance in
//! closed form, and each shape where pbrt puts it.

mod common;

use common::{header, layout, samples, scene};
use fbksd_embree::scene::shape::Geometry;
use std::f64::consts::PI;

/// Irradiance from a uniform disk of radiance `l` and radius `r`, on a
/// parallel plane at distance `h`, at horizontal distance `rho` from its axis.
fn disk_irradiance(l: f64, r: f64, h: f64, rho: f64) -> f64 {
    let (h2, r2, p2) = (h * h, r * r, rho * rho);
    PI * l / 2.0 * (1.0 - (h2 + p2 - r2) / ((h2 + p2 + r2).powi(2) - 4.0 * r2 * p2).sqrt())
}

#[test]
fn a_disk_light_gives_the_closed_form_irradiance() {
    // A disk of radius 0.6 at z = 4, facing +z, lights the wall at z = 5.
    let text = header(12, 12, 70.0, 1)
        + "AttributeBegin\n AreaLightSource \"diffuse\" \"rgb L\" [3 3 3]\n Translate 0.5 0 4\n Shape \"disk\" \"float radius\" 0.6\nAttributeEnd\n\
           Shape \"trianglemesh\" \"point3 P\" [-50 -50 5  50 -50 5  50 50 5  -50 50 5] \"integer indices\" [0 1 2 0 2 3]\n";
    let scene = scene(&text, &[]).unwrap();
    let l = layout(&["WORLD_X", "WORLD_Y", "WORLD_Z", "DIRECT_LIGHT_R"]);
    let (data, repairs) = samples(&scene, &l, 256, 0);
    assert_eq!(repairs, 0);
    let (mut got, mut want, mut n) = (0f64, 0f64, 0);
    for s in data.chunks_exact(4).filter(|s| s[2] > 4.99) {
        let rho = ((s[0] as f64 - 0.5).powi(2) + (s[1] as f64).powi(2)).sqrt();
        got += s[3] as f64;
        want += disk_irradiance(3.0, 0.6, 1.0, rho) / PI;
        n += 1;
    }
    assert!(n > 10_000, "{n} samples on the wall");
    assert!((got - want).abs() < 0.01 * want, "E/π: {} vs {}", got / n as f64, want / n as f64);
}

#[test]
fn each_tessellated_shape_is_where_pbrt_puts_it() {
    let text = header(16, 16, 30.0, 1)
        + "AttributeBegin\nTranslate 0 0 4\nShape \"cylinder\" \"float radius\" 0.5 \"float zmin\" -2 \"float zmax\" 2\nAttributeEnd\n\
           Shape \"bilinearmesh\" \"point3 P\" [-1 -1 8  1 -1 8  -1 1 8  1 1 9]\n\
           AttributeBegin\nTranslate 0 0 20\nShape \"loopsubdiv\" \"integer levels\" 2 \"point3 P\" [1 0 0  -1 0 0  0 1 0  0 -1 0  0 0 1  0 0 -1] \"integer indices\" [0 2 4 2 1 4 1 3 4 3 0 4 2 0 5 1 2 5 3 1 5 0 3 5]\nAttributeEnd\n\
           Shape \"disk\" \"float radius\" 2 \"float innerradius\" 1 \"float height\" 30 \"float phimax\" 180\n";
    let scene = scene(&text, &[]).unwrap();
    let triangles: Vec<usize> = scene
        .shapes
        .iter()
        .map(|s| match &s.geometry {
            Geometry::Mesh { indices, .. } => indices.len(),
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(triangles[2], 8 * 16, "two levels of Loop subdivision quadruple the octahedron twice");
    assert_eq!(triangles[1], 2 * 16 * 16, "a curved bilinear patch on a grid");
    // The camera looks down +z through the cylinder's axis: the first hits
    // at the centre are the cylinder's inside at radius 0.5.
    let l = layout(&["IMAGE_X", "IMAGE_Y", "WORLD_X", "WORLD_Y", "WORLD_Z", "NORMAL_X", "NORMAL_Y"]);
    let (data, _) = samples(&scene, &l, 4, 0);
    let mut on_cylinder = 0;
    for s in data.chunks_exact(7) {
        let (x, y, z) = (s[2], s[3], s[4]);
        if (2.0..6.0).contains(&z) {
            on_cylinder += 1;
            assert!(((x * x + y * y).sqrt() - 0.5).abs() < 1e-3, "on the cylinder: {x} {y} {z}");
            // The normal faces the viewer, inwards: against the radial direction.
            assert!(s[5] * x + s[6] * y < 0.0);
        }
    }
    assert!(on_cylinder > 100);
}
