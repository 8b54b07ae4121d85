//! pbrt-v3 files, read as pbrt-v4 reads them after its own `pbrt --upgrade`:
//! before a directive is built, its pbrt-v3 type and parameter names become
//! their pbrt-v4 equivalents, and each conversion is reported as a warning
//! (the parameter types `color`, `point` and `vector` are converted where
//! parameter lists are read, in `params`).
//!
//! The rules follow pbrt-v4's upgrade: `matte` → `diffuse`, `plastic` and
//! `substrate` → `coateddiffuse`, `metal` and `mirror` → `conductor`,
//! `glass` → `dielectric`, `Kd` → `reflectance`, `bumpmap` →
//! `displacement`, `mapname` → `filename`, `nlevels` → `levels`, the
//! `scale` texture's `tex1`/`tex2` → `tex`/`scale`, `gamma` → `encoding`,
//! and so on. A v3 parameter with no v4 counterpart is dropped with a
//! warning, unless it holds the value the conversion implies anyway.

use super::params::{ParamSet, Values};
use super::SceneError;

/// What an upgrade did: the directive's pbrt-v4 type, and one note per conversion.
pub(super) struct Upgraded {
    pub(super) ty: String,
    pub(super) notes: Vec<String>,
}

impl Upgraded {
    fn new(ty: &str) -> Upgraded {
        Upgraded { ty: ty.into(), notes: Vec::new() }
    }

    /// The directive's type becomes `to`.
    fn retype(&mut self, what: &str, to: &str) {
        self.notes.push(format!("pbrt-v3 {what} \"{}\" read as \"{to}\"", self.ty));
        self.ty = to.into();
    }

    /// Renames a parameter, noting it when it was there.
    fn rename(&mut self, params: &mut ParamSet, from: &str, to: &str) {
        if params.rename(from, to) {
            self.notes.push(format!("pbrt-v3 parameter \"{from}\" read as \"{to}\""));
        }
    }

    /// Drops a v3 parameter that has no v4 counterpart; silent when it
    /// holds `expected` (the value the conversion implies).
    fn drop(&mut self, params: &mut ParamSet, name: &str, expected: Option<f64>) {
        let matches = expected.is_some() && params.constant(name) == expected;
        if let Some(p) = params.remove(name) {
            if !matches {
                self.notes.push(format!("pbrt-v3 parameter \"{} {name}\" dropped (no pbrt-v4 counterpart)", p.ty));
            }
        }
    }
}

/// Whether an RGB (or float) parameter is given as exactly `value` everywhere.
fn is(params: &ParamSet, name: &str, value: f64) -> bool {
    params.constant(name) == Some(value)
}

/// `Material` and `MakeNamedMaterial` types.
pub(super) fn material(ty: &str, params: &mut ParamSet) -> Result<Upgraded, SceneError> {
    let mut up = Upgraded::new(ty);
    up.rename(params, "bumpmap", "displacement");
    match ty {
        "matte" => {
            up.retype("material", "diffuse");
            up.rename(params, "Kd", "reflectance");
            // Oren–Nayar roughness: pbrt-v4's diffuse is Lambertian.
            up.drop(params, "sigma", Some(0.0));
        }
        "plastic" | "uber" => {
            if ty == "uber" {
                up.drop(params, "Kr", Some(0.0));
                up.drop(params, "Kt", Some(0.0));
                match params.get("opacity").map(|p| p.ty.as_str()) {
                    None => {}
                    Some("rgb" | "float") if is(params, "opacity", 1.0) => up.drop(params, "opacity", Some(1.0)),
                    Some(_) => return Err(params.invalid("opacity", "other than 1 has no pbrt-v4 counterpart")),
                }
                up.rename(params, "index", "eta");
            }
            if is(params, "Ks", 0.0) {
                // No specular layer: plain diffuse.
                up.retype("material", "diffuse");
                params.remove("roughness");
                params.remove("eta");
            } else {
                up.retype("material", "coateddiffuse");
            }
            up.drop(params, "Ks", None);
            up.rename(params, "Kd", "reflectance");
        }
        "substrate" => {
            up.retype("material", "coateddiffuse");
            up.drop(params, "Ks", Some(1.0));
            up.rename(params, "Kd", "reflectance");
        }
        "metal" => {
            up.retype("material", "conductor");
            up.drop(params, "Kr", Some(1.0));
        }
        "mirror" => {
            // pbrt-v4's upgrade makes a mirror of silver.
            up.retype("material", "conductor");
            up.drop(params, "Kr", Some(1.0));
            params.set("float", "roughness", Values::Nums(vec![0.0]));
            params.set("spectrum", "eta", Values::Strs(vec!["metal-Ag-eta".into()]));
            params.set("spectrum", "k", Values::Strs(vec!["metal-Ag-k".into()]));
        }
        "glass" => {
            up.retype("material", "dielectric");
            up.drop(params, "Kr", Some(1.0));
            up.drop(params, "Kt", Some(1.0));
            up.rename(params, "index", "eta");
        }
        "translucent" => {
            up.retype("material", "diffusetransmission");
            up.rename(params, "Kd", "transmittance");
            up.drop(params, "reflect", Some(0.0));
            up.drop(params, "transmit", Some(1.0));
            up.drop(params, "Ks", Some(0.0));
            up.drop(params, "roughness", None);
        }
        "kdsubsurface" => {
            up.retype("material", "subsurface");
            up.rename(params, "Kd", "reflectance");
        }
        "disney" => {
            up.retype("material", "diffuse");
            up.rename(params, "color", "reflectance");
        }
        "mix" => {
            // Two named materials and an amount become a list of two names.
            if let (Some(a), Some(b)) = (params.get("namedmaterial1").cloned(), params.get("namedmaterial2").cloned()) {
                let (Values::Strs(a), Values::Strs(b)) = (a.values, b.values) else {
                    return Err(params.invalid("namedmaterial1", "must be a material name"));
                };
                params.remove("namedmaterial1");
                params.remove("namedmaterial2");
                params.set("string", "materials", Values::Strs([b, a].concat()));
                up.notes.push("pbrt-v3 \"namedmaterial1\"/\"namedmaterial2\" read as \"materials\"".into());
            }
        }
        _ => {}
    }
    Ok(up)
}

/// `LightSource` and `AreaLightSource` types (`area` is `AreaLightSource`'s v2/v3 name).
pub(super) fn light(ty: &str, params: &mut ParamSet, area: bool) -> Upgraded {
    let mut up = Upgraded::new(ty);
    if area && ty == "area" {
        up.retype("area light", "diffuse");
    }
    for name in ["samples", "nsamples"] {
        if let Some(p) = params.remove(name) {
            up.notes.push(format!("\"{} {name}\" dropped: how many light samples to take is the technique's", p.ty));
        }
    }
    // A grey RGB scale is a float scale.
    if params.get("scale").is_some_and(|p| p.ty == "rgb") {
        if let Some(s) = params.constant("scale") {
            params.set("float", "scale", Values::Nums(vec![s]));
            up.notes.push("pbrt-v3 \"rgb scale\" read as \"float scale\"".into());
        }
    }
    up.rename(params, "mapname", "filename");
    up
}

/// `Texture` classes.
pub(super) fn texture(class: &str, params: &mut ParamSet) -> Upgraded {
    let mut up = Upgraded::new(class);
    match class {
        "scale" if params.has("tex1") || params.has("tex2") => {
            // pbrt-v4's scale texture is a texture times a float: the grey one of the two is the float.
            let grey2 = params.get("tex2").is_some_and(|p| p.ty == "float" || params.constant("tex2").is_some());
            let (tex, scale) = if grey2 { ("tex1", "tex2") } else { ("tex2", "tex1") };
            up.rename(params, tex, "tex");
            if let Some(v) = params.get(scale).filter(|p| p.ty == "rgb").and_then(|_| params.constant(scale)) {
                params.remove(scale);
                params.set("float", "scale", Values::Nums(vec![v]));
                up.notes.push(format!("pbrt-v3 \"rgb {scale}\" read as \"float scale\""));
            } else {
                up.rename(params, scale, "scale");
            }
        }
        "imagemap" => {
            if let Some(p) = params.remove("trilinear") {
                let trilinear = matches!(&p.values, Values::Bools(b) if b == &[true])
                    || matches!(&p.values, Values::Strs(s) if s == &["true"]);
                params.set(
                    "string",
                    "filter",
                    Values::Strs(vec![if trilinear { "trilinear" } else { "bilinear" }.into()]),
                );
                up.notes.push("pbrt-v3 \"bool trilinear\" read as \"string filter\"".into());
            }
            if let Some(p) = params.remove("gamma") {
                let encoding = match &p.values {
                    Values::Bools(b) if b == &[true] => "sRGB".to_string(),
                    Values::Strs(s) if s == &["true"] => "sRGB".to_string(),
                    Values::Nums(g) if g.len() == 1 && g[0] != 0.0 => format!("gamma {}", g[0]),
                    _ => "linear".to_string(),
                };
                params.set("string", "encoding", Values::Strs(vec![encoding]));
                up.notes.push(format!("pbrt-v3 \"{} gamma\" read as \"string encoding\"", p.ty));
            }
        }
        _ => {}
    }
    up
}

/// `Shape` types.
pub(super) fn shape(ty: &str, params: &mut ParamSet) -> Upgraded {
    let mut up = Upgraded::new(ty);
    if ty == "loopsubdiv" {
        up.rename(params, "nlevels", "levels");
    }
    if ty == "trianglemesh" {
        // v3 texture coordinates: "point2 st", or "float uv" / "float st" pairs.
        if !params.has("uv") {
            up.rename(params, "st", "uv");
        }
        for name in ["discarddegenerateUVs", "shadowalpha", "S"] {
            up.drop(params, name, None);
        }
    }
    up
}

/// `Film` types.
pub(super) fn film(ty: &str, params: &mut ParamSet) -> Upgraded {
    let mut up = Upgraded::new(ty);
    if ty == "image" {
        up.retype("film", "rgb");
    }
    up.rename(params, "maxsampleluminance", "maxcomponentvalue");
    up
}

/// `Integrator` types.
pub(super) fn integrator(ty: &str, params: &mut ParamSet) -> Upgraded {
    let mut up = Upgraded::new(ty);
    if ty == "directlighting" {
        // Direct lighting is a path of one bounce.
        up.retype("integrator", "path");
        params.set("integer", "maxdepth", Values::Nums(vec![1.0]));
    }
    up
}
