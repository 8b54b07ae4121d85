//! Building the scene: what the shape, material and texture directives
//! become, and the camera and `Scene` made when the files are read.
//!
//! Kept apart from the directive reader because this is where pbrt's
//! parameters meet the renderer's own types (meshes moved by the
//! transform steps, area lights, Embree curves, BSDF constants); the
//! parser only hands over a parameter list, the current graphics state and
//! where it came from.

use super::params::{ParamSet, SpectrumValue, Values};
use super::parser::Parser;
use super::tessellate::{self, TriMesh};
use super::{ply, Loc, SceneError};
use crate::math::{Transform, Vec3};
use crate::scene::camera::Camera;
use crate::scene::environment::EnvironmentMap;
use crate::scene::light::{area_cdf, Light, LightTriangle};
use crate::scene::material::{Bump, ConductorIndex, Material, Roughness};
use crate::scene::shape::{Geometry, Shape};
use crate::scene::texture::{read_image, Encoding, Texture, UvMapping, Wrap};
use crate::scene::{Instancing, Parts, Scene};
use std::path::Path;
use std::sync::Arc;

/// Vertex indices in groups of `n` (pbrt allows leaving them out when there is exactly one group).
fn index_groups<const N: usize>(
    params: &ParamSet,
    vertices: usize,
    loc: &Loc,
    what: &str,
) -> Result<Vec<[u32; N]>, SceneError> {
    let indices = match params.ints("indices")? {
        Some(i) => i,
        None if vertices == N => (0..N as i64).collect(),
        None => {
            return Err(SceneError::at(
                loc,
                format!("{what} needs \"integer indices\" (unless it has exactly {N} vertices)"),
            ))
        }
    };
    if indices.len() % N != 0 || indices.is_empty() {
        return Err(
            params.invalid("indices", &format!("needs a positive multiple of {N} values, got {}", indices.len()))
        );
    }
    if let Some(bad) = indices.iter().find(|i| **i < 0 || **i as usize >= vertices) {
        return Err(params.invalid("indices", &format!("has {bad}, outside 0..{vertices}")));
    }
    Ok(indices.chunks_exact(N).map(|c| std::array::from_fn(|k| c[k] as u32)).collect())
}

/// The shapes made of triangles here: disk, cylinder, bilinear patches, Loop subdivision surfaces.
fn tessellated(ty: &str, params: &ParamSet, loc: &Loc) -> Result<TriMesh, SceneError> {
    let positive = |name: &str, default: f32| -> Result<f32, SceneError> {
        let v = params.float(name, default)?;
        if v > 0.0 {
            Ok(v)
        } else {
            Err(params.invalid(name, "must be positive"))
        }
    };
    let phi_max = || -> Result<f32, SceneError> {
        let phi = params.float("phimax", 360.0)?;
        if phi > 0.0 && phi <= 360.0 {
            Ok(phi.to_radians())
        } else {
            Err(params.invalid("phimax", "must be in (0, 360] degrees"))
        }
    };
    let points = |what: &str| {
        params.triples("P", &["point3"])?.ok_or_else(|| SceneError::at(loc, format!("{what} needs \"point3 P\"")))
    };
    Ok(match ty {
        "disk" => {
            let radius = positive("radius", 1.0)?;
            let inner = params.float("innerradius", 0.0)?;
            if !(0.0..radius).contains(&inner) {
                return Err(params.invalid("innerradius", "must be at least 0 and less than the radius"));
            }
            tessellate::disk(params.float("height", 0.0)?, radius, inner, phi_max()?)
        }
        "cylinder" => {
            let (z0, z1) = (params.float("zmin", -1.0)?, params.float("zmax", 1.0)?);
            if z0 == z1 {
                return Err(params.invalid("zmax", "must differ from zmin"));
            }
            tessellate::cylinder(positive("radius", 1.0)?, z0.min(z1), z0.max(z1), phi_max()?)
        }
        "bilinearmesh" => {
            let p = points("bilinearmesh")?;
            let patches = index_groups::<4>(params, p.len(), loc, "bilinearmesh")?;
            let normals = params.triples("N", &["normal", "normal3"])?;
            let uvs = params.pairs("uv")?;
            if normals.as_ref().is_some_and(|n| n.len() != p.len()) {
                return Err(params.invalid("N", "needs one normal per vertex"));
            }
            if uvs.as_ref().is_some_and(|u| u.len() != p.len()) {
                return Err(params.invalid("uv", "needs one pair per vertex"));
            }
            tessellate::bilinear(&p, &patches, normals.as_deref(), uvs.as_deref(), 16)
        }
        "loopsubdiv" => {
            let p = points("loopsubdiv")?;
            let triangles = index_groups::<3>(params, p.len(), loc, "loopsubdiv")?;
            let levels = params.int("levels", 3)?;
            if !(0..=8).contains(&levels) {
                return Err(params.invalid("levels", "must be between 0 and 8"));
            }
            tessellate::loop_subdivision(&p, &triangles, levels as u32)
        }
        _ => unreachable!("the caller passes tessellated shapes only"),
    })
}

impl Parser {
    fn texture_ref(
        &self,
        v: SpectrumValue,
        float: bool,
        params: &ParamSet,
        name: &str,
    ) -> Result<Arc<Texture>, SceneError> {
        match v {
            SpectrumValue::Rgb(rgb) => Ok(Arc::new(Texture::Constant(rgb))),
            SpectrumValue::Texture(t) => {
                let map = if float { &self.float_textures } else { &self.textures };
                map.get(&t).cloned().ok_or_else(|| {
                    params.invalid(
                        name,
                        &format!(
                            "names {} texture {t:?}, which is not defined",
                            if float { "a float" } else { "a spectrum" }
                        ),
                    )
                })
            }
        }
    }

    /// A spectrum parameter as a texture, or `default`.
    fn spectrum_texture(&self, params: &ParamSet, name: &str, default: Vec3) -> Result<Arc<Texture>, SceneError> {
        match params.spectrum(name)? {
            None => Ok(Arc::new(Texture::Constant(default))),
            Some(v) => self.texture_ref(v, false, params, name),
        }
    }

    /// A float parameter as a texture, or `default`.
    fn float_texture(&self, params: &ParamSet, name: &str, default: f32) -> Result<Arc<Texture>, SceneError> {
        match params.float_or_texture(name)? {
            None => Ok(Arc::new(Texture::Constant(Vec3::splat(default)))),
            Some(v) => self.texture_ref(v, true, params, name),
        }
    }

    pub(super) fn texture(
        &self,
        class: &str,
        params: &ParamSet,
        float: bool,
        loc: &Loc,
    ) -> Result<Texture, SceneError> {
        let mapping = || -> Result<UvMapping, SceneError> {
            if let Some(m) = params.string("mapping")? {
                if m != "uv" {
                    return Err(params.invalid("mapping", "must be \"uv\" (the only supported mapping)"));
                }
            }
            Ok(UvMapping {
                su: params.float("uscale", 1.0)?,
                sv: params.float("vscale", 1.0)?,
                du: params.float("udelta", 0.0)?,
                dv: params.float("vdelta", 0.0)?,
            })
        };
        let value = |name: &str, default: f32| -> Result<Arc<Texture>, SceneError> {
            if float {
                self.float_texture(params, name, default)
            } else {
                self.spectrum_texture(params, name, Vec3::splat(default))
            }
        };
        Ok(match class {
            "constant" => return Ok((*value("value", 1.0)?).clone()),
            "scale" => Texture::Scale(value("tex", 1.0)?, self.float_texture(params, "scale", 1.0)?),
            "checkerboard" => {
                if params.int("dimension", 2)? != 2 {
                    return Err(params.invalid("dimension", "must be 2"));
                }
                Texture::Checkerboard { mapping: mapping()?, even: value("tex1", 1.0)?, odd: value("tex2", 0.0)? }
            }
            "imagemap" => {
                let file = params
                    .string("filename")?
                    .ok_or_else(|| SceneError::at(loc, "imagemap needs \"string filename\""))?;
                let encoding = match params.string("encoding")?.as_deref() {
                    None | Some("sRGB") => Encoding::Srgb,
                    Some("linear") => Encoding::Linear,
                    Some(g) if g.starts_with("gamma ") => Encoding::Gamma(
                        g[6..].trim().parse().map_err(|_| params.invalid("encoding", "has a bad gamma value"))?,
                    ),
                    Some(_) => return Err(params.invalid("encoding", "must be sRGB, linear or \"gamma <value>\"")),
                };
                let wrap = match params.string("wrap")?.as_deref() {
                    None | Some("repeat") => Wrap::Repeat,
                    Some("clamp") => Wrap::Clamp,
                    Some("black") => Wrap::Black,
                    Some(_) => return Err(params.invalid("wrap", "must be repeat, clamp or black")),
                };
                // Filtering is a hint: image textures are looked up bilinearly.
                if let Some(f) = params.string("filter")?.filter(|f| f != "bilinear") {
                    self.warn(loc, format!("texture filter {f:?} read as \"bilinear\""));
                }
                params.ignore("maxanisotropy");
                let mut image = read_image(&self.resolve(&file), encoding).map_err(|e| SceneError::at(loc, e))?;
                if float {
                    for p in &mut image.pixels {
                        *p = Vec3::splat(p.average());
                    }
                }
                Texture::Image {
                    image: Arc::new(image),
                    mapping: mapping()?,
                    scale: params.float("scale", 1.0)?,
                    invert: params.bool("invert", false)?,
                    wrap,
                }
            }
            other => {
                return Err(SceneError::at(
                    loc,
                    format!("unsupported texture class {other:?} (supported: imagemap, checkerboard, constant, scale)"),
                ))
            }
        })
    }

    fn roughness(&self, params: &ParamSet, default: f32) -> Result<Roughness, SceneError> {
        let both = params.float_or_texture("roughness")?;
        let get = |name: &str| -> Result<Arc<Texture>, SceneError> {
            match params.float_or_texture(name)? {
                Some(v) => self.texture_ref(v, true, params, name),
                None => match &both {
                    Some(v) => self.texture_ref(v.clone(), true, params, "roughness"),
                    None => Ok(Arc::new(Texture::Constant(Vec3::splat(default)))),
                },
            }
        };
        Ok(Roughness { u: get("uroughness")?, v: get("vroughness")?, remap: params.bool("remaproughness", true)? })
    }

    /// A material's bump map (`"texture displacement"`) or normal map (`"string normalmap"`).
    pub(super) fn bump(&self, params: &ParamSet, loc: &Loc) -> Result<Option<Bump>, SceneError> {
        let height = match params.float_or_texture("displacement")? {
            Some(v) => Some(self.texture_ref(v, true, params, "displacement")?),
            None => None,
        };
        let normal_map = params.string("normalmap")?;
        Ok(match (height, normal_map) {
            (Some(_), Some(_)) => return Err(params.invalid("normalmap", "cannot be given with a displacement")),
            (Some(h), None) => Some(Bump::Height(h)),
            (None, Some(file)) => {
                let image = read_image(&self.resolve(&file), Encoding::Linear).map_err(|e| SceneError::at(loc, e))?;
                Some(Bump::NormalMap(Arc::new(image)))
            }
            (None, None) => None,
        })
    }

    pub(super) fn material(&self, ty: &str, params: &ParamSet, loc: &Loc) -> Result<Material, SceneError> {
        let eta = |default: f32| -> Result<f32, SceneError> {
            let eta = match params.spectrum("eta")? {
                None => default,
                Some(SpectrumValue::Rgb(v)) if v.x == v.y && v.y == v.z => v.x,
                Some(_) => return Err(params.invalid("eta", "must be one float (dispersion is not supported)")),
            };
            if !(eta > 0.0) {
                return Err(params.invalid("eta", "must be positive"));
            }
            Ok(eta)
        };
        Ok(match ty {
            "diffuse" => {
                Material::Diffuse { reflectance: self.spectrum_texture(params, "reflectance", Vec3::splat(0.5))? }
            }
            "conductor" => {
                let reflectance = params.spectrum("reflectance")?;
                let index = match reflectance {
                    Some(r) => {
                        if params.spectrum("eta")?.is_some() || params.spectrum("k")?.is_some() {
                            return Err(params.invalid("reflectance", "cannot be given with eta or k"));
                        }
                        ConductorIndex::Reflectance(self.texture_ref(r, false, params, "reflectance")?)
                    }
                    None => ConductorIndex::EtaK(
                        self.spectrum_texture(params, "eta", Vec3::from_array([0.200, 0.924, 1.102]))?,
                        self.spectrum_texture(params, "k", Vec3::from_array([3.912, 2.452, 2.142]))?,
                    ),
                };
                Material::Conductor { index, roughness: self.roughness(params, 0.0)? }
            }
            "dielectric" => Material::Dielectric { eta: eta(1.5)?, roughness: self.roughness(params, 0.0)? },
            "coateddiffuse" => {
                let eta = eta(1.5)?;
                Material::CoatedDiffuse {
                    reflectance: self.spectrum_texture(params, "reflectance", Vec3::splat(0.5))?,
                    roughness: self.roughness(params, 0.0)?,
                    eta,
                    internal_reflectance: crate::bsdf::coated::Coated::internal_reflectance(eta),
                }
            }
            "thindielectric" => Material::ThinDielectric { eta: eta(1.5)? },
            "diffusetransmission" => {
                let scale = params.float("scale", 1.0)?;
                let scaled = |name: &str| -> Result<Arc<Texture>, SceneError> {
                    let t = self.spectrum_texture(params, name, Vec3::splat(0.25))?;
                    Ok(if scale == 1.0 { t } else { Arc::new(Texture::Scale(t, Arc::new(Texture::Constant(Vec3::splat(scale))))) })
                };
                Material::DiffuseTransmission { reflectance: scaled("reflectance")?, transmittance: scaled("transmittance")? }
            }
            "" | "none" | "interface" => Material::Interface,
            "mix" => {
                let names = match params.get("materials").map(|p| &p.values) {
                    Some(Values::Strs(names)) if names.len() == 2 => names.clone(),
                    _ => return Err(params.invalid("materials", "must name two materials")),
                };
                params.ignore("materials");
                let index = |name: &String| {
                    self.named_materials
                        .get(name)
                        .copied()
                        .ok_or_else(|| params.invalid("materials", &format!("names {name:?}, which is not defined")))
                };
                Material::Mix { materials: [index(&names[0])?, index(&names[1])?], amount: self.float_texture(params, "amount", 0.5)? }
            }
            other => {
                return Err(SceneError::at(
                    loc,
                    format!(
                        "unsupported material {other:?} (supported: diffuse, conductor, dielectric, thindielectric, coateddiffuse, diffusetransmission, mix, interface)"
                    ),
                ))
            }
        })
    }

    /// A `LightSource`, placed by the current transform.
    pub(super) fn light(&self, ty: &str, params: &ParamSet, loc: &Loc) -> Result<Light, SceneError> {
        let [t0, t1] = self.state.ctm;
        if t0 != t1 && ty != "infinite" {
            return Err(SceneError::at(loc, "a moving light is not supported"));
        }
        // An RGB spectrum, or pbrt's default: the colour space's illuminant, white in RGB.
        let rgb = |name: &str| -> Result<Vec3, SceneError> {
            match params.spectrum(name)? {
                None => Ok(Vec3::ONE),
                Some(SpectrumValue::Rgb(v)) => Ok(v),
                Some(SpectrumValue::Texture(_)) => Err(params.invalid(name, "cannot be a texture")),
            }
        };
        let point = |name: &str, default: Vec3| -> Result<Vec3, SceneError> {
            match params.triples(name, &["point3", "point"])?.as_deref() {
                None => Ok(default),
                Some([p]) => Ok(*p),
                Some(_) => Err(params.invalid(name, "takes one point")),
            }
        };
        let scale = params.float("scale", 1.0)?;
        // pbrt-v4's "power" (and "illuminance") set the light's photometric
        // power for a white light; an RGB colour then multiplies it, as in pbrt.
        let target = |name: &str, per_unit: f32| -> Result<f32, SceneError> {
            let v = params.float(name, -1.0)?;
            Ok(if v > 0.0 { v / per_unit } else { 1.0 })
        };
        let from = || point("from", Vec3::ZERO);
        let to = || point("to", Vec3 { x: 0.0, y: 0.0, z: 1.0 });
        Ok(match ty {
            "infinite" => {
                if params.ignore("portal") {
                    self.warn(loc, "\"portal\" ignored: a hint for sampling the environment through windows");
                }
                match params.string("filename")? {
                    None => Light::Environment {
                        radiance: rgb("L")? * scale * target("illuminance", std::f32::consts::PI)?,
                    },
                    Some(file) => {
                        if params.has("L") {
                            return Err(params.invalid("L", "cannot be given with a filename"));
                        }
                        if params.has("illuminance") {
                            return Err(params.invalid("illuminance", "is not supported with an image"));
                        }
                        let path = self.resolve(&file);
                        let image = read_image(&path, Encoding::Srgb).map_err(|e| SceneError::at(loc, e))?;
                        if image.width != image.height {
                            return Err(params.invalid(
                                "filename",
                                &format!(
                                    "names a {}×{} image: environment maps are square, in pbrt-v4's equal-area mapping (pbrt's imgtool makeequiarea converts a latitude–longitude map)",
                                    image.width, image.height
                                ),
                            ));
                        }
                        let pixels = image.pixels.into_iter().map(|p| p * scale).collect();
                        let map = EnvironmentMap::new(image.width, pixels, &t0);
                        Light::ImageEnvironment { map: Arc::new(map) }
                    }
                }
            }
            "point" => {
                let intensity = rgb("I")? * scale * target("power", 4.0 * std::f32::consts::PI)?;
                Light::Point { position: t0.point(from()?), intensity }
            }
            "spot" => {
                let cone = params.float("coneangle", 30.0)?;
                let delta = params.float("conedeltaangle", 5.0)?;
                if !(cone > 0.0 && cone <= 180.0 && (0.0..=cone).contains(&delta)) {
                    return Err(params
                        .invalid("coneangle", "must be in (0, 180] degrees, with conedeltaangle between 0 and it"));
                }
                let cos_falloff_end = cone.to_radians().cos();
                let cos_falloff_start = (cone - delta).to_radians().cos();
                let (from, to) = (from()?, to()?);
                let axis = t0.vector(to - from).normalize();
                if axis == Vec3::ZERO {
                    return Err(params.invalid("to", "must differ from \"from\""));
                }
                let solid_angle = 2.0
                    * std::f32::consts::PI
                    * ((1.0 - cos_falloff_start) + (cos_falloff_start - cos_falloff_end) / 2.0);
                let intensity = rgb("I")? * scale * target("power", solid_angle)?;
                Light::Spot { position: t0.point(from), axis, intensity, cos_falloff_start, cos_falloff_end }
            }
            "distant" => {
                let direction = t0.vector(from()? - to()?).normalize();
                if direction == Vec3::ZERO {
                    return Err(params.invalid("to", "must differ from \"from\""));
                }
                Light::Distant { direction, radiance: rgb("L")? * scale * target("illuminance", 1.0)? }
            }
            other => {
                return Err(SceneError::at(
                    loc,
                    format!(
                        "unsupported light {other:?} (supported: infinite, point, spot, distant, and AreaLightSource)"
                    ),
                ))
            }
        })
    }

    pub(super) fn shape(&mut self, ty: &str, params: &ParamSet, loc: &Loc) -> Result<(), SceneError> {
        let [t0, t1] = self.state.ctm;
        let moving = t0 != t1;
        let steps: Vec<Transform> = if moving { vec![t0, t1] } else { vec![t0] };
        let flip = self.state.reverse_orientation ^ t0.swaps_handedness();
        let geometry = match ty {
            "trianglemesh" | "plymesh" | "loopsubdiv" | "bilinearmesh" | "disk" | "cylinder" => {
                let (positions, indices, normals, uvs) = if ty == "plymesh" {
                    let file = params
                        .string("filename")?
                        .ok_or_else(|| SceneError::at(loc, "plymesh needs \"string filename\""))?;
                    let m = ply::read(&self.resolve(&file)).map_err(|e| SceneError::at(loc, e))?;
                    (m.positions, m.indices, m.normals, m.uvs)
                } else if ty != "trianglemesh" {
                    let m = tessellated(ty, params, loc)?;
                    (m.positions, m.indices, m.normals, m.uvs)
                } else {
                    let p = params
                        .triples("P", &["point3", "point"])?
                        .ok_or_else(|| SceneError::at(loc, "trianglemesh needs \"point3 P\""))?;
                    let indices = index_groups::<3>(params, p.len(), loc, "trianglemesh")?;
                    let n = params.triples("N", &["normal", "normal3"])?;
                    let uv = params.pairs("uv")?;
                    (p, indices, n, uv)
                };
                if normals.as_ref().is_some_and(|n| n.len() != positions.len()) {
                    return Err(params.invalid("N", "needs one normal per vertex"));
                }
                if uvs.as_ref().is_some_and(|u| u.len() != positions.len()) {
                    return Err(params.invalid("uv", "needs one pair per vertex"));
                }
                if positions.iter().any(|p| !p.is_finite()) {
                    return Err(SceneError::at(loc, "a vertex position is not finite"));
                }
                Geometry::Mesh {
                    positions: steps
                        .iter()
                        .map(|t| positions.iter().map(|p| t.point(*p).to_array()).collect())
                        .collect(),
                    indices,
                    // pbrt-v4 negates given normals under ReverseOrientation (not for handedness).
                    normals: normals.map(|n| {
                        let sign = if self.state.reverse_orientation { -1.0 } else { 1.0 };
                        steps.iter().map(|t| n.iter().map(|v| t.normal(*v).normalize() * sign).collect()).collect()
                    }),
                    uvs,
                    flip,
                }
            }
            "sphere" => {
                let radius = params.float("radius", 1.0)?;
                if !(radius > 0.0) {
                    return Err(params.invalid("radius", "must be positive"));
                }
                let mut sphere_steps = Vec::new();
                for t in &steps {
                    let scale = t.uniform_scale().ok_or_else(|| {
                        SceneError::at(loc, "a sphere under a non-uniform scale or shear is not supported")
                    })?;
                    let c = t.point(Vec3::ZERO);
                    sphere_steps.push([c.x, c.y, c.z, (radius as f64 * scale) as f32]);
                }
                let rotation = Transform::from_matrix(std::array::from_fn(|i| {
                    std::array::from_fn(|j| {
                        if i < 3 && j < 3 {
                            t0.m[i][j]
                        } else if i == j {
                            1.0
                        } else {
                            0.0
                        }
                    })
                }))
                .ok_or_else(|| SceneError::at(loc, "singular sphere transform"))?;
                Geometry::Sphere { steps: sphere_steps, to_object: rotation.inverse(), flip }
            }
            "curve" => {
                let p = params
                    .triples("P", &["point3", "point"])?
                    .ok_or_else(|| SceneError::at(loc, "curve needs \"point3 P\""))?;
                if params.string("basis")?.is_some_and(|b| b != "bezier") {
                    return Err(params.invalid("basis", "must be \"bezier\" (the only supported basis)"));
                }
                if params.int("degree", 3)? != 3 {
                    return Err(params.invalid("degree", "must be 3 (cubic curves only)"));
                }
                let round = match params.string("type")?.as_deref() {
                    None | Some("flat") => false,
                    Some("cylinder") => true,
                    Some(_) => {
                        return Err(params.invalid("type", "must be flat or cylinder (ribbon curves are not supported)"))
                    }
                };
                // A tessellation hint for pbrt; Embree intersects curves directly.
                params.int("splitdepth", 3)?;
                if p.len() < 4 || (p.len() - 1) % 3 != 0 {
                    return Err(params
                        .invalid("P", &format!("needs 3n + 1 control points for n cubic segments, got {}", p.len())));
                }
                let width = params.float("width", 1.0)?;
                let (w0, w1) = (params.float("width0", width)?, params.float("width1", width)?);
                if !(w0 >= 0.0 && w1 >= 0.0) {
                    return Err(params.invalid("width", "must not be negative"));
                }
                let segments = (p.len() - 1) / 3;
                let mut points_steps = Vec::new();
                for t in &steps {
                    let scale = t
                        .uniform_scale()
                        .ok_or_else(|| SceneError::at(loc, "a curve under a non-uniform scale is not supported"))?
                        as f32;
                    // Embree wants 4 control points per segment; shared ends are repeated.
                    let mut points = Vec::with_capacity(segments * 4);
                    for s in 0..segments {
                        for k in 0..4 {
                            let i = s * 3 + k;
                            let w = w0 + (w1 - w0) * (i as f32 / (p.len() - 1) as f32);
                            let q = t.point(p[i]);
                            points.push([q.x, q.y, q.z, 0.5 * w * scale]);
                        }
                    }
                    points_steps.push(points);
                }
                let first = (0..segments as u32).map(|s| s * 4).collect();
                Geometry::Curves { points: points_steps, first, round }
            }
            other => {
                return Err(SceneError::at(
                    loc,
                    format!(
                        "unsupported shape {other:?} (supported: trianglemesh, plymesh, sphere, curve, disk, cylinder, bilinearmesh, loopsubdiv)"
                    ),
                ))
            }
        };
        let shape_index = self.shapes.len() as u32;
        let mut light = None;
        if let (Some(_), Some((object, _))) = (&self.state.area_light, &self.object) {
            return Err(SceneError::at(
                loc,
                format!(
                    "an area light in object {:?} (pbrt does not instance area lights either)",
                    self.objects[*object as usize].0
                ),
            ));
        }
        if let Some((radiance, two_sided)) = &self.state.area_light {
            if geometry.moves() {
                return Err(SceneError::at(loc, "a moving area light is not supported"));
            }
            let l = match &geometry {
                Geometry::Mesh { positions, indices, normals, flip, .. } => {
                    let (cdf, area) = area_cdf(&positions[0], indices);
                    let normals = normals.as_ref().map(|n| n[0].as_slice());
                    let triangles = LightTriangle::of_mesh(&positions[0], indices, normals, *flip);
                    Light::Mesh { shape: shape_index, triangles, cdf, area, radiance: *radiance, two_sided: *two_sided }
                }
                Geometry::Sphere { steps, flip, .. } => {
                    let s = steps[0];
                    Light::Sphere {
                        shape: shape_index,
                        center: Vec3::from_array([s[0], s[1], s[2]]),
                        radius: s[3],
                        radiance: *radiance,
                        two_sided: *two_sided,
                        flip: *flip,
                    }
                }
                Geometry::Curves { .. } => return Err(SceneError::at(loc, "curves cannot be area lights")),
            };
            if !radiance.is_black() {
                self.lights.push(l);
                light = Some(self.lights.len() as u32 - 1);
            }
        }
        if matches!(self.materials[self.state.material as usize], Material::Interface) {
            if light.is_some() {
                return Err(SceneError::at(loc, "an area light on a shape with an interface material"));
            }
            self.warn(loc, "a shape with an interface material left out: it bounds a participating medium, and media are not rendered");
            return Ok(());
        }
        let shape = Shape { geometry, material: self.state.material, light };
        match self.object {
            Some((object, _)) => self.objects[object as usize].1.push(shape),
            None => self.shapes.push(shape),
        }
        Ok(())
    }

    /// The scene, and the warnings of the whole load.
    pub(super) fn finish(self, path: &Path) -> Result<(Scene, Vec<SceneError>), SceneError> {
        let loc = Loc { file: Arc::from(path), line: 1 };
        let (width, height) = match &self.options.film {
            Some(film) => {
                let (w, h) = (film.int("xresolution", 1280)?, film.int("yresolution", 720)?);
                film.string("filename")?;
                // The sensor's response and the output encoding are pbrt's own
                // film; references are linear radiance.
                self.ignore_hints(
                    film,
                    &["sensor", "iso", "whitebalance", "maxcomponentvalue", "diagonal", "savefp16", "writefp16"],
                );
                film.check_unused()?;
                if !(1..=65536).contains(&w) || !(1..=65536).contains(&h) {
                    return Err(film.invalid("xresolution", "and yresolution must be between 1 and 65536"));
                }
                (w as u32, h as u32)
            }
            None => (1280, 720),
        };
        let max_depth = match &self.options.integrator {
            Some((ty, p)) => {
                let d = p.int("maxdepth", 5)?;
                if p.bool("regularize", false)? {
                    return Err(p.invalid("regularize", "is not supported"));
                }
                // Settings of pbrt's own path tracers (light sampler, roulette) are hints;
                // another integrator's settings are all hints.
                if ty == "path" || ty == "volpath" {
                    self.ignore_hints(p, &["lightsampler", "lightsamplestrategy", "rrthreshold", "pixelbounds"]);
                } else {
                    self.warn_ignored(p, p.ignore_all());
                }
                p.check_unused()?;
                if !(0..=10_000).contains(&d) {
                    return Err(p.invalid("maxdepth", "must be between 0 and 10000"));
                }
                d as u32
            }
            None => 5,
        };
        let (camera_params, camera_to_world) =
            self.options.camera.clone().ok_or_else(|| SceneError::at(&loc, "no Camera before WorldBegin"))?;
        let p = &camera_params;
        let fov = p.float("fov", 90.0)?;
        if !(fov > 0.0 && fov < 180.0) {
            return Err(p.invalid("fov", "must be between 0 and 180 degrees"));
        }
        let screen = match p.floats("screenwindow")? {
            Some(v) if v.len() == 4 => [v[0], v[1], v[2], v[3]],
            Some(_) => return Err(p.invalid("screenwindow", "takes 4 values")),
            None => Camera::default_screen(width, height),
        };
        let lens_radius = p.float("lensradius", 0.0)?;
        let focal_distance = p.float("focaldistance", 1e6)?;
        let shutter = [p.float("shutteropen", 0.0)?, p.float("shutterclose", 1.0)?];
        if lens_radius < 0.0 {
            return Err(p.invalid("lensradius", "must not be negative"));
        }
        if !(focal_distance > 0.0) {
            return Err(p.invalid("focaldistance", "must be positive"));
        }
        if shutter[1] < shutter[0] {
            return Err(p.invalid("shutterclose", "is before shutteropen"));
        }
        p.check_unused()?;
        let camera = Camera {
            camera_to_world: crate::math::Affine::new(&camera_to_world),
            width,
            height,
            tan_half_fov: (fov.to_radians() / 2.0).tan(),
            screen,
            lens_radius,
            focal_distance,
            shutter,
        };
        // A scene directory's `scene.pbrt` or `small.pbrt` is named after the directory.
        let stem = path.file_stem().map_or("scene".into(), |s| s.to_string_lossy().into_owned());
        let dir = path.parent().and_then(|d| d.file_name()).map(|d| d.to_string_lossy().into_owned());
        let name = match dir {
            Some(dir) if stem == "scene" || stem == "small" => dir,
            _ => stem,
        };
        let warnings = self.warnings.take();
        // Objects' shapes go after the top-level ones, each object's together.
        let mut shapes = self.shapes;
        let mut instancing = Instancing { objects: Vec::new(), placements: self.placements };
        for (_, object_shapes) in self.objects {
            let start = shapes.len() as u32;
            shapes.extend(object_shapes);
            instancing.objects.push(start..shapes.len() as u32);
        }
        let scene = Scene::build(Parts {
            name,
            camera,
            max_depth,
            shapes,
            materials: self.materials,
            bumps: self.bumps,
            lights: self.lights,
            transform_times: self.transform_times,
            instancing,
        })
        .map_err(|e| SceneError { loc: None, message: e.to_string() })?;
        Ok((scene, warnings))
    }
}
