//! Object instancing (`ObjectBegin`/`ObjectInstance`, Embree instances):
//! an instanced object renders like copies of it written out in place.

mod common;

use common::{header, layout, samples, scene};

const LIGHTS: &str = "LightSource \"infinite\" \"rgb L\" [0.3 0.35 0.4]\nLightSource \"distant\" \"point3 to\" [0.3 -1 0.6] \"rgb L\" [2 2 2]\n";

/// An object: a glossy sphere on a diffuse slab, in its own frame.
const OBJECT: &str = "AttributeBegin\n Material \"coateddiffuse\" \"rgb reflectance\" [0.7 0.2 0.1] \"float roughness\" 0.1\n Translate 0 0.5 0\n Shape \"sphere\" \"float radius\" 0.5\nAttributeEnd\n\
Material \"diffuse\" \"rgb reflectance\" [0.2 0.6 0.3]\n\
Shape \"trianglemesh\" \"point3 P\" [-0.8 0 -0.8  0.8 0 -0.8  0.8 0 0.8  -0.8 0 0.8] \"integer indices\" [0 2 1 0 3 2]\n";

/// Where the copies go.
const PLACES: [&str; 3] = [
    "Translate -1.5 -0.8 5",
    "Translate 1.4 -0.5 6 Rotate 30 0 1 0 Scale 1.3 1.3 1.3",
    "Translate 0 0.9 7 Rotate -40 1 0 0 Scale 0.7 0.7 0.7",
];

fn instanced() -> String {
    let mut text = header(24, 18, 60.0, 3) + LIGHTS + "ObjectBegin \"thing\"\n" + OBJECT + "ObjectEnd\n";
    for place in PLACES {
        text += &format!("AttributeBegin\n{place}\nObjectInstance \"thing\"\nAttributeEnd\n");
    }
    text
}

fn copies() -> String {
    let mut text = header(24, 18, 60.0, 3) + LIGHTS;
    for place in PLACES {
        text += &format!("AttributeBegin\n{place}\n{OBJECT}AttributeEnd\n");
    }
    text
}

#[test]
fn an_instanced_object_renders_like_its_copies() {
    let (a, b) = (scene(&instanced(), &[]).unwrap(), scene(&copies(), &[]).unwrap());
    assert!(a.has_instances() && !b.has_instances());
    // Sample for sample, the first hit's features agree; a few samples may
    // differ where rounding picks another triangle at an edge.
    let l = layout(&[
        "DEPTH",
        "NORMAL_X",
        "NORMAL_Y",
        "NORMAL_Z",
        "WORLD_X",
        "TEXTURE_COLOR_R",
        "COLOR_R",
        "COLOR_G",
        "COLOR_B",
    ]);
    let ((da, _), (db, _)) = (samples(&a, &l, 8, 0), samples(&b, &l, 8, 0));
    let (mut hits, mut differ) = (0, 0);
    for (x, y) in da.chunks_exact(9).zip(db.chunks_exact(9)) {
        if x[0] > 0.0 {
            hits += 1;
        }
        if x[..6].iter().zip(&y[..6]).any(|(p, q)| (p - q).abs() > 1e-3 * (1.0 + q.abs())) {
            differ += 1;
        }
    }
    assert!(hits > 150, "the objects are in view: {hits}");
    assert!(differ * 200 < da.len() / 9, "{differ} of {} samples differ", da.len() / 9);
    // And the images agree.
    let (ia, ib) = (fbksd_embree::render::render_image(&a, 32, 0), fbksd_embree::render::render_image(&b, 32, 0));
    let mean = |v: &[f32]| v.iter().map(|x| *x as f64).sum::<f64>() / v.len() as f64;
    let diff = ia.rgb.iter().zip(&ib.rgb).map(|(p, q)| (p - q).abs() as f64).sum::<f64>() / ia.rgb.len() as f64;
    assert!(diff < 0.002 * mean(&ib.rgb), "mean difference {diff} against a mean of {}", mean(&ib.rgb));
}

#[test]
fn instancing_errors_name_the_line() {
    let err = |body: &str| scene(&(header(4, 4, 60.0, 1) + body), &[]).err().unwrap();
    let e = err("ObjectInstance \"nope\"\n");
    assert!(e.contains("scene.pbrt:6:") && e.contains("no object named \"nope\""), "{e}");
    let e = err("ObjectBegin \"a\"\nAreaLightSource \"diffuse\"\nShape \"sphere\"\nObjectEnd\n");
    assert!(e.contains("scene.pbrt:8:") && e.contains("area light in object \"a\""), "{e}");
    let e = err("ObjectBegin \"a\"\nObjectBegin \"b\"\n");
    assert!(e.contains("scene.pbrt:7:") && e.contains("ObjectBegin inside object \"a\""), "{e}");
    let e = err("ObjectBegin \"a\"\nShape \"sphere\"\n");
    assert!(e.contains("scene.pbrt:6:") && e.contains("ObjectBegin without a matching ObjectEnd"), "{e}");
    let e = err("ObjectBegin \"a\"\nObjectEnd\nObjectBegin \"a\"\n");
    assert!(e.contains("scene.pbrt:8:") && e.contains("defined twice"), "{e}");
}
