//! pbrt-v3 files: read as pbrt-v4's own `--upgrade` converts them, each
//! conversion a warning naming its line, and rendered exactly as the
//! pbrt-v4 file that conversion produces.

mod common;

use common::scene_with_warnings;

/// A scene in pbrt-v3's words.
const V3: &str = r#"LookAt 0 0 -5  0 0 0  0 1 0
Camera "perspective" "float fov" 45
Film "image" "integer xresolution" 16 "integer yresolution" 12 "string filename" "v3.exr"
Sampler "stratified" "integer xsamples" 2 "integer ysamples" 2 "bool jitter" "true"
Integrator "directlighting"
WorldBegin
LightSource "infinite" "color L" [0.3 0.3 0.3] "integer samples" 4
AttributeBegin
  AreaLightSource "area" "color L" [4 4 4] "integer nsamples" 2
  Translate 0 2 0
  Shape "sphere" "float radius" 0.4
AttributeEnd
Texture "checks" "color" "checkerboard" "float uscale" 4 "float vscale" 4 "color tex1" [0.8 0.1 0.1] "color tex2" [0.1 0.1 0.8]
Texture "half" "color" "scale" "texture tex1" "checks" "color tex2" [0.5 0.5 0.5]
Material "matte" "texture Kd" "half"
Shape "trianglemesh" "point P" [-3 -1 -3  3 -1 -3  3 -1 3  -3 -1 3] "integer indices" [0 1 2 0 2 3] "float uv" [0 0 1 0 1 1 0 1]
AttributeBegin
  Material "plastic" "color Kd" [0.2 0.5 0.2] "color Ks" [0.25 0.25 0.25] "float roughness" 0.1
  Translate -1.2 0 0
  Shape "sphere" "float radius" 0.5
AttributeEnd
AttributeBegin
  Material "metal" "float roughness" 0.05
  Shape "sphere" "float radius" 0.5
AttributeEnd
AttributeBegin
  Material "glass" "float index" 1.33
  Translate 1.2 0 0
  Shape "sphere" "float radius" 0.5
AttributeEnd
AttributeBegin
  Material "mirror"
  Translate 0 1 1
  Shape "sphere" "float radius" 0.3
AttributeEnd
WorldEnd
"#;

/// The same scene as pbrt-v4 writes it after the upgrade.
const V4: &str = r#"LookAt 0 0 -5  0 0 0  0 1 0
Camera "perspective" "float fov" 45
Film "rgb" "integer xresolution" 16 "integer yresolution" 12 "string filename" "v3.exr"
Integrator "path" "integer maxdepth" 1
WorldBegin
LightSource "infinite" "rgb L" [0.3 0.3 0.3]
AttributeBegin
  AreaLightSource "diffuse" "rgb L" [4 4 4]
  Translate 0 2 0
  Shape "sphere" "float radius" 0.4
AttributeEnd
Texture "checks" "spectrum" "checkerboard" "float uscale" 4 "float vscale" 4 "rgb tex1" [0.8 0.1 0.1] "rgb tex2" [0.1 0.1 0.8]
Texture "half" "spectrum" "scale" "texture tex" "checks" "float scale" 0.5
Material "diffuse" "texture reflectance" "half"
Shape "trianglemesh" "point3 P" [-3 -1 -3  3 -1 -3  3 -1 3  -3 -1 3] "integer indices" [0 1 2 0 2 3] "point2 uv" [0 0 1 0 1 1 0 1]
AttributeBegin
  Material "coateddiffuse" "rgb reflectance" [0.2 0.5 0.2] "float roughness" 0.1
  Translate -1.2 0 0
  Shape "sphere" "float radius" 0.5
AttributeEnd
AttributeBegin
  Material "conductor" "float roughness" 0.05
  Shape "sphere" "float radius" 0.5
AttributeEnd
AttributeBegin
  Material "dielectric" "float eta" 1.33
  Translate 1.2 0 0
  Shape "sphere" "float radius" 0.5
AttributeEnd
AttributeBegin
  Material "conductor" "float roughness" 0 "spectrum eta" "metal-Ag-eta" "spectrum k" "metal-Ag-k"
  Translate 0 1 1
  Shape "sphere" "float radius" 0.3
AttributeEnd
"#;

#[test]
fn a_pbrt_v3_scene_renders_as_its_pbrt_v4_upgrade() {
    let (v3, warnings) = scene_with_warnings(V3).unwrap();
    let (v4, none) = scene_with_warnings(V4).unwrap();
    assert!(none.is_empty(), "the pbrt-v4 file needs no conversion: {none:?}");
    assert_eq!(v3.max_depth, 1, "directlighting is a path of one bounce");
    let a = fbksd_embree::render::render_image(&v3, 16, 0);
    let b = fbksd_embree::render::render_image(&v4, 16, 0);
    assert_eq!(a.rgb, b.rgb, "the same image, sample for sample");
    assert!(a.rgb.iter().any(|v| *v > 0.0));
    // Each conversion is a warning at its line.
    let expect = [
        (3, "pbrt-v3 film \"image\" read as \"rgb\""),
        (5, "pbrt-v3 integrator \"directlighting\" read as \"path\""),
        (7, "pbrt-v3 parameter type \"color\" read as \"rgb\""),
        (7, "\"integer samples\" dropped"),
        (9, "pbrt-v3 area light \"area\" read as \"diffuse\""),
        (9, "\"integer nsamples\" dropped"),
        (14, "\"rgb tex2\" read as \"float scale\""),
        (15, "pbrt-v3 material \"matte\" read as \"diffuse\""),
        (15, "pbrt-v3 parameter \"Kd\" read as \"reflectance\""),
        (16, "pbrt-v3 parameter type \"point\" read as \"point3\""),
        (18, "pbrt-v3 material \"plastic\" read as \"coateddiffuse\""),
        (18, "\"rgb Ks\" dropped"),
        (23, "pbrt-v3 material \"metal\" read as \"conductor\""),
        (27, "pbrt-v3 material \"glass\" read as \"dielectric\""),
        (27, "pbrt-v3 parameter \"index\" read as \"eta\""),
        (32, "pbrt-v3 material \"mirror\" read as \"conductor\""),
    ];
    for (line, what) in expect {
        let at = format!("scene.pbrt:{line}: ");
        assert!(
            warnings.iter().any(|w| w.contains(&at) && w.contains(what)),
            "no warning {what:?} at line {line}: {warnings:#?}"
        );
    }
}

#[test]
fn a_v3_material_without_a_v4_counterpart_is_an_error_naming_it() {
    let text = V4.replace("Material \"conductor\" \"float roughness\" 0.05", "Material \"kdsubsurface\"");
    let err = scene_with_warnings(&text).err().unwrap();
    assert!(err.contains("scene.pbrt:22:") && err.contains("unsupported material \"subsurface\""), "{err}");
    assert!(err.contains("read from pbrt-v3's \"kdsubsurface\""), "{err}");
    // translucent has one: diffuse transmission.
    let text = V4.replace(
        "Material \"conductor\" \"float roughness\" 0.05",
        "Material \"translucent\" \"rgb Kd\" [0.4 0.4 0.4] \"rgb reflect\" [0 0 0] \"rgb transmit\" [1 1 1]",
    );
    let (_, warnings) = scene_with_warnings(&text).unwrap();
    assert!(warnings
        .iter()
        .any(|w| w.contains("scene.pbrt:22:") && w.contains("\"translucent\" read as \"diffusetransmission\"")));
}
