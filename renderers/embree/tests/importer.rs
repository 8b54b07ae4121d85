//! The pbrt-v4 importer: every supported directive does what pbrt does,
//! and every error names the file, the line and what was wrong.

mod common;

use common::{scene, scene_with_warnings};
use fbksd_embree::scene::light::Light;
use fbksd_embree::scene::material::Material;
use fbksd_embree::scene::shape::Geometry;
use fbksd_embree::scene::Scene;

const CAMERA: &str = "LookAt 0 0 -5  0 0 0  0 1 0\nCamera \"perspective\" \"float fov\" 45\nFilm \"rgb\" \"integer xresolution\" 8 \"integer yresolution\" 6\n";
const TRI: &str = "Shape \"trianglemesh\" \"point3 P\" [0 0 0  1 0 0  0 1 0]\n";

fn mesh(scene: &Scene, i: usize) -> &Vec<Vec<[f32; 3]>> {
    match &scene.shapes[i].geometry {
        Geometry::Mesh { positions, .. } => positions,
        other => panic!("shape {i} is not a mesh: {other:?}"),
    }
}

fn close(a: [f32; 3], b: [f32; 3]) -> bool {
    (0..3).all(|i| (a[i] - b[i]).abs() < 1e-5)
}

#[test]
fn transforms_compose_as_in_pbrt() {
    let text = format!(
        "{CAMERA}WorldBegin\n\
         AttributeBegin\n Translate 1 2 3\n {TRI}AttributeEnd\n\
         AttributeBegin\n Scale 2 2 2\n Rotate 90 0 0 1\n {TRI}AttributeEnd\n\
         AttributeBegin\n Transform [1 0 0 0  0 1 0 0  0 0 1 0  5 6 7 1]\n ConcatTransform [2 0 0 0  0 2 0 0  0 0 2 0  0 0 0 1]\n {TRI}AttributeEnd\n\
         AttributeBegin\n Translate 9 9 9\n Identity\n {TRI}AttributeEnd\n\
         Translate 0 0 1\nCoordinateSystem \"lifted\"\nIdentity\nTransformBegin\n Translate 4 0 0\nTransformEnd\nCoordSysTransform \"lifted\"\n{TRI}"
    );
    let s = scene(&text, &[]).unwrap();
    assert!(close(mesh(&s, 0)[0][1], [2.0, 2.0, 3.0]), "Translate");
    assert!(close(mesh(&s, 1)[0][1], [0.0, 2.0, 0.0]), "Scale ∘ Rotate: {:?}", mesh(&s, 1)[0][1]);
    assert!(
        close(mesh(&s, 2)[0][1], [7.0, 6.0, 7.0]),
        "Transform is column-major, then ConcatTransform: {:?}",
        mesh(&s, 2)[0][1]
    );
    assert!(close(mesh(&s, 3)[0][1], [1.0, 0.0, 0.0]), "Identity");
    assert!(close(mesh(&s, 4)[0][1], [1.0, 0.0, 1.0]), "CoordSysTransform restores; TransformEnd pops");
}

#[test]
fn motion_blur_comes_from_transform_times_and_active_transform() {
    let text = format!(
        "TransformTimes 0 1\n{CAMERA}WorldBegin\nActiveTransform EndTime\nTranslate 1 0 0\nActiveTransform All\n{TRI}Shape \"sphere\" \"float radius\" 0.5\n"
    );
    let s = scene(&text, &[]).unwrap();
    assert!(s.has_motion);
    let p = mesh(&s, 0);
    assert_eq!(p.len(), 2);
    assert!(close(p[0][0], [0.0, 0.0, 0.0]) && close(p[1][0], [1.0, 0.0, 0.0]));
    match &s.shapes[1].geometry {
        Geometry::Sphere { steps, .. } => assert_eq!(steps, &vec![[0.0, 0.0, 0.0, 0.5], [1.0, 0.0, 0.0, 0.5]]),
        other => panic!("{other:?}"),
    }
    assert!(s.info().get::<String>("random_parameters").unwrap().contains("TIME"));
    let still = scene(&format!("{CAMERA}WorldBegin\n{TRI}"), &[]).unwrap();
    assert!(!still.has_motion && !still.info().get::<String>("random_parameters").unwrap().contains("TIME"));
}

#[test]
fn reverse_orientation_flips_given_normals_and_world_begin_resets_the_active_transform() {
    let text = format!(
        "{CAMERA}ActiveTransform StartTime\nWorldBegin\nTranslate 0 0 1\nReverseOrientation\n\
         Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0] \"normal N\" [0 0 1 0 0 1 0 0 1]\n"
    );
    let s = scene(&text, &[]).unwrap();
    match &s.shapes[0].geometry {
        Geometry::Mesh { normals: Some(n), positions, .. } => {
            assert_eq!(n[0][0].z, -1.0, "pbrt-v4 negates N under ReverseOrientation");
            assert_eq!(positions.len(), 1, "the Translate applied to both times: not moving");
            assert_eq!(positions[0][0][2], 1.0);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn options_directives_set_the_camera_film_and_integrator() {
    let text = "ColorSpace \"srgb\"\nSampler \"zsobol\" \"integer pixelsamples\" 64\nPixelFilter \"box\"\n\
                Integrator \"path\" \"integer maxdepth\" 9\n\
                LookAt 0 0 -5  0 0 0  0 1 0\n\
                Camera \"perspective\" \"float fov\" 30 \"float lensradius\" 0.1 \"float focaldistance\" 5 \"float shutteropen\" 0.25 \"float shutterclose\" 0.75\n\
                Film \"rgb\" \"integer xresolution\" 20 \"integer yresolution\" 10 \"string filename\" \"x.exr\"\nWorldBegin\nWorldEnd\n";
    let s = scene(text, &[]).unwrap();
    assert_eq!((s.width(), s.height(), s.max_depth), (20, 10, 9));
    assert_eq!(s.camera.lens_radius, 0.1);
    assert_eq!(s.camera.focal_distance, 5.0);
    assert_eq!(s.camera.shutter, [0.25, 0.75]);
    assert!((s.camera.tan_half_fov - 15f32.to_radians().tan()).abs() < 1e-6);
    assert_eq!(s.camera.screen, [-2.0, 2.0, -1.0, 1.0]);
    assert!(s.info().get::<bool>("has_dof").unwrap());
}

#[test]
fn materials_textures_and_lights_are_read_with_their_parameters() {
    // A 2 × 1 PNG and a 1 × 1 EXR texture.
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("t.png");
    image::RgbImage::from_raw(2, 1, vec![255, 0, 0, 0, 0, 255]).unwrap().save(&png).unwrap();
    let exr = dir.path().join("r.exr");
    fbksd_iqa::image::write_exr(&exr, 1, 1, &[0.25, 0.25, 0.25]).unwrap();
    let text = format!(
        "{CAMERA}WorldBegin\n\
         Texture \"img\" \"spectrum\" \"imagemap\" \"string filename\" \"t.png\" \"string wrap\" \"clamp\"\n\
         Texture \"rough\" \"float\" \"imagemap\" \"string filename\" \"r.exr\" \"string encoding\" \"linear\"\n\
         Texture \"scaled\" \"spectrum\" \"scale\" \"texture tex\" \"img\" \"float scale\" 0.5\n\
         Texture \"c\" \"float\" \"constant\" \"float value\" 0.3\n\
         MakeNamedMaterial \"metal\" \"string type\" \"conductor\" \"spectrum eta\" \"metal-Au-eta\" \"spectrum k\" \"metal-Au-k\" \"float uroughness\" 0.1 \"float vroughness\" 0.2 \"bool remaproughness\" false\n\
         MakeNamedMaterial \"glass\" \"string type\" \"dielectric\" \"float eta\" 1.33 \"texture roughness\" \"rough\"\n\
         MakeNamedMaterial \"plastic\" \"string type\" \"coateddiffuse\" \"texture reflectance\" \"scaled\" \"texture roughness\" \"c\"\n\
         Material \"diffuse\" \"texture reflectance\" \"img\"\n{TRI}\
         NamedMaterial \"metal\"\n{TRI}NamedMaterial \"glass\"\n{TRI}NamedMaterial \"plastic\"\n{TRI}\
         AttributeBegin\n AreaLightSource \"diffuse\" \"blackbody L\" 6500 \"float scale\" 2 \"bool twosided\" true\n ReverseOrientation\n Shape \"sphere\" \"float radius\" 0.25\nAttributeEnd\n\
         LightSource \"infinite\" \"rgb L\" [0.1 0.2 0.3] \"float scale\" 10\n"
    );
    std::fs::write(dir.path().join("scene.pbrt"), text).unwrap();
    let s = fbksd_embree::pbrt::load(&dir.path().join("scene.pbrt")).unwrap();
    let albedo = |i: usize, uv: [f32; 2]| s.materials[s.shapes[i].material as usize].albedo(uv);
    assert_eq!(albedo(0, [0.0, 0.5]).to_array(), [1.0, 0.0, 0.0], "PNG, sRGB-decoded, clamped at the left edge");
    assert_eq!(albedo(0, [1.0, 0.5]).to_array(), [0.0, 0.0, 1.0]);
    assert!(matches!(s.materials[s.shapes[1].material as usize], Material::Conductor { .. }));
    match &s.materials[s.shapes[2].material as usize] {
        Material::Dielectric { eta, roughness } => {
            assert_eq!(*eta, 1.33);
            assert_eq!(roughness.u.eval_float([0.5, 0.5]), 0.25);
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(albedo(3, [0.0, 0.5]).to_array(), [0.5, 0.0, 0.0], "scale texture");
    let area = s.lights.iter().find_map(|l| match l {
        Light::Sphere { radiance, two_sided, flip, .. } => Some((*radiance, *two_sided, *flip)),
        _ => None,
    });
    let (radiance, two_sided, flip) = area.unwrap();
    assert!(two_sided && flip && (radiance.max_component() - 2.0).abs() < 1e-5, "{radiance:?}");
    assert!(s.lights.iter().any(|l| matches!(l, Light::Environment { radiance } if (radiance.z - 3.0).abs() < 1e-5)));
    assert!(s.shapes[4].light.is_some());
}

#[test]
fn include_import_plymesh_and_curves_load() {
    let ply = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 0 0 -1\n1 0 0 0 0 -1\n0 1 0 0 0 -1\n3 0 1 2\n";
    let text = "Include \"camera.pbrt\"\nWorldBegin\nImport \"objects.pbrt\"\n\
         Shape \"curve\" \"point3 P\" [0 0 0  0 1 0  0 2 0  0 3 0  0 4 0  0 5 0  0 6 0] \"float width0\" 0.2 \"float width1\" 0.1 \"string type\" \"cylinder\" \"integer splitdepth\" 2\n";
    let camera = CAMERA.as_bytes();
    let objects = b"Shape \"plymesh\" \"string filename\" \"mesh.ply\"\n";
    let s = scene(text, &[("camera.pbrt", camera), ("objects.pbrt", objects), ("mesh.ply", ply)]).unwrap();
    match &s.shapes[0].geometry {
        Geometry::Mesh { normals: Some(n), .. } => assert_eq!(n[0][0].z, -1.0),
        other => panic!("{other:?}"),
    }
    match &s.shapes[1].geometry {
        Geometry::Curves { points, first, round } => {
            assert!(*round);
            assert_eq!(first, &vec![0, 4], "two cubic segments");
            assert!(
                (points[0][0][3] - 0.1).abs() < 1e-6 && (points[0][7][3] - 0.05).abs() < 1e-6,
                "radius is half the width"
            );
        }
        other => panic!("{other:?}"),
    }
}

/// The error for `body` (after a valid header unless `bare`), checked to name the line and say `what`.
fn error_at(body: &str, line: u32, what: &str) {
    let text = format!("{CAMERA}WorldBegin\n{body}");
    let err = scene(&text, &[]).err().unwrap_or_else(|| panic!("no error for {body:?}"));
    let at = format!("scene.pbrt:{}:", line + 4);
    assert!(err.contains(&at) && err.contains(what), "for {body:?}: got {err:?}, wanted {at} … {what}");
}

#[test]
fn every_error_names_the_file_line_and_problem() {
    error_at("Frobnicate 1 2 3\n", 1, "unknown directive \"Frobnicate\"");
    error_at("MakeNamedMedium \"x\"\n", 1, "unsupported directive MakeNamedMedium");
    error_at(
        "\n\nShape \"sphere\" \"float radius\" 1 \"float zmax\" 0.5\n",
        3,
        "unused parameter \"float zmax\" for Shape \"sphere\"",
    );
    error_at("Shape \"sphere\" \"integer radius\" 1\n", 1, "should be float");
    error_at("Shape \"sphere\" \"float radius\" -1\n", 1, "must be positive");
    error_at("Shape \"sphere\" \"float radius\" [1 2]\n", 1, "takes one value");
    error_at("Shape \"sphere\" \"flaot radius\" 1\n", 1, "unknown parameter type \"flaot\"");
    error_at("Shape \"sphere\" \"float radius\" \"one\"\n", 1, "wrong kind");
    error_at("Shape \"sphere\" \"float radius\" [1\n", 1, "unclosed [");
    error_at("Shape \"sphere\n", 1, "newline inside a string");
    error_at("Translate 1 2\nShape \"sphere\"\n", 2, "Translate takes 3 numbers");
    error_at("Translate 1 2 1e\n", 1, "is not a number");
    error_at("Scale 1 0 1\n", 1, "singular transform");
    error_at("Include \"missing.pbrt\"\n", 1, "cannot read");
    error_at("AttributeEnd\n", 1, "AttributeEnd without a matching Begin");
    error_at("TransformBegin\nAttributeEnd\n", 2, "does not match the Begin at line");
    error_at("Camera \"perspective\"\n", 1, "must come before WorldBegin");
    error_at("NamedMaterial \"nope\"\n", 1, "no material named \"nope\"");
    error_at("Material \"diffuse\" \"texture reflectance\" \"nope\"\n", 1, "not defined");
    error_at("Material \"hair\"\n", 1, "unsupported material \"hair\"");
    error_at("Material \"coateddiffuse\" \"float thickness\" 0.1\n", 1, "unused parameter \"float thickness\"");
    error_at("Material \"dielectric\" \"spectrum eta\" [300 1.5 800 1.4]\n", 1, "dispersion is not supported");
    error_at("Material \"conductor\" \"spectrum eta\" [500 1.5 400 1.4]\n", 1, "pairs of increasing wavelength");
    error_at("Material \"conductor\" \"spectrum eta\" \"metal-Xx-eta\"\n", 1, "unknown named spectrum");
    error_at("Texture \"t\" \"spectrum\" \"marble\"\n", 1, "unsupported texture class \"marble\"");
    error_at("Texture \"t\" \"spectrum\" \"imagemap\" \"string filename\" \"none.png\"\n", 1, "none.png");
    error_at("Shape \"hyperboloid\"\n", 1, "unsupported shape \"hyperboloid\"");
    error_at("Shape \"disk\" \"float innerradius\" 2\n", 1, "innerradius");
    error_at("Shape \"bilinearmesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0 1 1 0 2 2 2]\n", 1, "needs \"integer indices\"");
    error_at("Shape \"loopsubdiv\" \"integer levels\" 20 \"point3 P\" [0 0 0 1 0 0 0 1 0]\n", 1, "levels");
    error_at("Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0 1 1 0]\n", 1, "needs \"integer indices\"");
    error_at(
        "Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0] \"integer indices\" [0 1 3]\n",
        1,
        "outside 0..3",
    );
    error_at("Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1]\n", 1, "multiple of 3");
    error_at("Shape \"plymesh\" \"string filename\" \"none.ply\"\n", 1, "none.ply");
    error_at("Shape \"curve\" \"point3 P\" [0 0 0 1 1 1 2 2 2]\n", 1, "3n + 1 control points");
    error_at(
        "Shape \"curve\" \"point3 P\" [0 0 0 1 1 1 2 2 2 3 3 3] \"string basis\" \"bspline\"\n",
        1,
        "must be \"bezier\"",
    );
    error_at(
        "Shape \"curve\" \"point3 P\" [0 0 0 1 1 1 2 2 2 3 3 3] \"string type\" \"ribbon\"\n",
        1,
        "ribbon curves are not supported",
    );
    error_at("Scale 1 2 1\nShape \"sphere\"\n", 2, "non-uniform scale");
    error_at(
        "AreaLightSource \"diffuse\"\nShape \"curve\" \"point3 P\" [0 0 0 1 1 1 2 2 2 3 3 3]\n",
        2,
        "curves cannot be area lights",
    );
    error_at(
        "AreaLightSource \"diffuse\"\nActiveTransform EndTime\nTranslate 1 0 0\nShape \"sphere\"\n",
        4,
        "moving area light",
    );
    error_at("AreaLightSource \"spot\"\n", 1, "unsupported area light");
    error_at("LightSource \"goniometric\"\n", 1, "unsupported light \"goniometric\"");
    error_at("LightSource \"infinite\" \"string filename\" \"sky.exr\"\n", 1, "sky.exr");
    error_at("ActiveTransform Sometimes\n", 1, "StartTime, EndTime or All");
    error_at("\"float x\" 1\n", 1, "expected a directive");
}

#[test]
fn a_parameter_given_twice_is_read_once_with_a_warning() {
    // As pbrt: the first value counts (real scene files repeat parameters).
    let (s, w) =
        scene_with_warnings(&format!("{CAMERA}WorldBegin\nShape \"sphere\" \"float radius\" 1 \"float radius\" 2\n"))
            .unwrap();
    match &s.shapes[0].geometry {
        Geometry::Sphere { steps, .. } => assert_eq!(steps[0][3], 1.0),
        other => panic!("{other:?}"),
    }
    assert!(w.iter().any(|w| w.contains("scene.pbrt:5:") && w.contains("\"radius\" given twice")), "{w:?}");
}

#[test]
fn a_gzipped_include_is_read() {
    use std::io::Write;
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(TRI.as_bytes()).unwrap();
    let s = scene(&format!("{CAMERA}WorldBegin\nInclude \"tri.pbrt.gz\"\n"), &[("tri.pbrt.gz", &gz.finish().unwrap())])
        .unwrap();
    assert_eq!(mesh(&s, 0)[0].len(), 3);
}

#[test]
fn errors_in_options_and_structure_name_their_place_too() {
    let whole = |text: &str| scene(text, &[]).err().unwrap();
    assert!(whole("WorldBegin\n").contains("no Camera"));
    assert!(whole(CAMERA).contains("no WorldBegin"));
    let e = whole(&format!("{CAMERA}WorldBegin\nAttributeBegin\n"));
    assert!(e.contains("scene.pbrt:5:") && e.contains("without a matching AttributeEnd"), "{e}");
    // Another filter or integrator is a hint: the scene loads, with a warning naming the line.
    let (_, w) =
        scene_with_warnings(&format!("PixelFilter \"gaussian\" \"float sigma\" 0.5\n{CAMERA}WorldBegin\n")).unwrap();
    assert!(w.len() == 1 && w[0].contains("scene.pbrt:1:") && w[0].contains("\"gaussian\" ignored"), "{w:?}");
    let (_, w) = scene_with_warnings(&format!(
        "Integrator \"bdpt\" \"integer maxdepth\" 3 \"bool visualizestrategies\" false\n{CAMERA}WorldBegin\n"
    ))
    .unwrap();
    assert!(w.iter().any(|w| w.contains("scene.pbrt:1:") && w.contains("\"bdpt\" is a hint")), "{w:?}");
    assert!(w.iter().any(|w| w.contains("\"bool visualizestrategies\" ignored")), "{w:?}");
    let e = whole(&format!("Integrator \"path\" \"integer maxdepht\" 5\n{CAMERA}WorldBegin\n"));
    assert!(e.contains("scene.pbrt:1:") && e.contains("unused parameter \"integer maxdepht\""), "{e}");
    let e = whole("LookAt 0 0 0 0 0 1 0 1 0\nCamera \"orthographic\"\nWorldBegin\n");
    assert!(e.contains("scene.pbrt:2:") && e.contains("unsupported camera"), "{e}");
    let e = whole("LookAt 0 0 0 0 0 1 0 1 0\nCamera \"perspective\" \"float fov\" 200\nWorldBegin\n");
    assert!(e.contains("scene.pbrt:2:") && e.contains("fov"), "{e}");
    let e = whole("LookAt 0 0 0 0 0 1 0 0 1\nCamera \"perspective\"\nWorldBegin\n");
    assert!(e.contains("scene.pbrt:1:") && e.contains("singular transform"), "{e}");
    // An error inside an included file names that file.
    let e = scene(&format!("{CAMERA}WorldBegin\nInclude \"inner.pbrt\"\n"), &[("inner.pbrt", b"\nShape \"cone\"\n")])
        .err()
        .unwrap();
    assert!(e.contains("inner.pbrt:2:") && e.contains("unsupported shape \"cone\""), "{e}");
}
