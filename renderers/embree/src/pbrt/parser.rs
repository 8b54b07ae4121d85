//! Directives, the graphics state they change, and the scene they build.

use super::lexer::{tokenize, Tok, Token};
use super::params::{ParamSet, SpectrumValue, Values};
use super::{ply, Loc, SceneError};
use crate::math::{Transform, Vec3};
use crate::scene::camera::Camera;
use crate::scene::light::{area_cdf, Light, LightTriangle};
use crate::scene::material::{ConductorIndex, Material, Roughness};
use crate::scene::shape::{Geometry, Shape};
use crate::scene::texture::{read_image, Encoding, Texture, UvMapping, Wrap};
use crate::scene::Scene;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Which of the two motion transforms directives change.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Active {
    Start,
    End,
    All,
}

/// What `AttributeBegin` saves.
#[derive(Debug, Clone)]
struct GraphicsState {
    ctm: [Transform; 2],
    active: Active,
    material: u32,
    /// Radiance and two-sidedness of the current AreaLightSource.
    area_light: Option<(Vec3, bool)>,
    reverse_orientation: bool,
}

/// The camera and image options before `WorldBegin`.
#[derive(Debug, Default)]
struct Options {
    camera: Option<(ParamSet, Transform)>,
    film: Option<ParamSet>,
    integrator: Option<ParamSet>,
}

struct Parser {
    /// Where relative file names are resolved: the main file's directory (as pbrt-v4 does).
    base: PathBuf,
    state: GraphicsState,
    stack: Vec<(GraphicsState, Loc, bool)>,
    coordinate_systems: HashMap<String, [Transform; 2]>,
    transform_times: [f32; 2],
    in_world: bool,
    options: Options,
    textures: HashMap<String, Arc<Texture>>,
    float_textures: HashMap<String, Arc<Texture>>,
    named_materials: HashMap<String, u32>,
    materials: Vec<Material>,
    shapes: Vec<Shape>,
    lights: Vec<Light>,
    include_depth: u32,
}

/// Reads tokens one at a time.
struct Cursor {
    tokens: Vec<Token>,
    pos: usize,
    end: Loc,
}

impl Cursor {
    fn peek(&self) -> Option<&Token> {
        self.tokens.get(self.pos)
    }
    fn next(&mut self) -> Option<Token> {
        let t = self.tokens.get(self.pos).cloned();
        self.pos += 1;
        t
    }
    fn string(&mut self, what: &str, at: &Loc) -> Result<String, SceneError> {
        match self.next() {
            Some(Token { tok: Tok::Str(s), .. }) => Ok(s),
            Some(t) => Err(SceneError::at(&t.loc, format!("expected {what} (a quoted string), found {:?}", t.tok))),
            None => Err(SceneError::at(at, format!("expected {what}, found the end of the file"))),
        }
    }
    fn numbers(&mut self, n: usize, directive: &str, at: &Loc) -> Result<Vec<f64>, SceneError> {
        // `Transform [ 16 numbers ]` and `Transform 16 numbers` are both pbrt.
        let bracketed = matches!(self.peek(), Some(Token { tok: Tok::Open, .. }));
        if bracketed {
            self.next();
        }
        let mut v = Vec::with_capacity(n);
        for _ in 0..n {
            match self.next() {
                Some(Token { tok: Tok::Num(x), .. }) if x.is_finite() => v.push(x),
                Some(t) => {
                    return Err(SceneError::at(&t.loc, format!("{directive} takes {n} numbers, found {:?}", t.tok)))
                }
                None => return Err(SceneError::at(at, format!("{directive} takes {n} numbers"))),
            }
        }
        if bracketed {
            match self.next() {
                Some(Token { tok: Tok::Close, .. }) => {}
                _ => return Err(SceneError::at(at, format!("{directive}: expected ] after {n} numbers"))),
            }
        }
        Ok(v)
    }
    /// A parameter list: `"type name" value` or `"type name" [ values ]`, repeated.
    fn params(&mut self, owner: String, at: &Loc) -> Result<ParamSet, SceneError> {
        let mut set = ParamSet::new(owner, at.clone());
        while let Some(Token { tok: Tok::Str(decl), loc }) = self.peek().cloned() {
            self.next();
            let mut nums = Vec::new();
            let mut strs = Vec::new();
            let mut bools = Vec::new();
            let mut push = |t: Token| -> Result<(), SceneError> {
                match t.tok {
                    Tok::Num(x) => nums.push(x),
                    Tok::Str(s) => strs.push(s),
                    Tok::Word(w) if w == "true" || w == "false" => bools.push(w == "true"),
                    other => {
                        return Err(SceneError::at(&t.loc, format!("unexpected {other:?} in the values of {decl:?}")))
                    }
                }
                Ok(())
            };
            match self.next() {
                Some(Token { tok: Tok::Open, .. }) => loop {
                    match self.next() {
                        Some(Token { tok: Tok::Close, .. }) => break,
                        Some(t) => push(t)?,
                        None => return Err(SceneError::at(&loc, format!("unclosed [ in the values of {decl:?}"))),
                    }
                },
                Some(t) => push(t)?,
                None => return Err(SceneError::at(&loc, format!("{decl:?} has no value"))),
            }
            let kinds = [!nums.is_empty(), !strs.is_empty(), !bools.is_empty()].iter().filter(|k| **k).count();
            if kinds > 1 {
                return Err(SceneError::at(&loc, format!("the values of {decl:?} mix numbers, strings and booleans")));
            }
            let values = if !strs.is_empty() {
                Values::Strs(strs)
            } else if !bools.is_empty() {
                Values::Bools(bools)
            } else {
                Values::Nums(nums)
            };
            set.push(&decl, values, loc)?;
        }
        Ok(set)
    }
}

/// Parses `path` and everything it includes, and builds the scene.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut parser = Parser {
        base,
        state: GraphicsState {
            ctm: [Transform::IDENTITY; 2],
            active: Active::All,
            material: 0,
            area_light: None,
            reverse_orientation: false,
        },
        stack: Vec::new(),
        coordinate_systems: HashMap::new(),
        transform_times: [0.0, 1.0],
        in_world: false,
        options: Options::default(),
        textures: HashMap::new(),
        float_textures: HashMap::new(),
        named_materials: HashMap::new(),
        // pbrt's default material.
        materials: vec![Material::Diffuse { reflectance: Arc::new(Texture::Constant(Vec3::splat(0.5))) }],
        shapes: Vec::new(),
        lights: Vec::new(),
        include_depth: 0,
    };
    parser.file(path, None)?;
    let end = Loc { file: Arc::from(path), line: 0 };
    if let Some((_, loc, _)) = parser.stack.last() {
        return Err(SceneError::at(loc, "AttributeBegin without a matching AttributeEnd"));
    }
    if !parser.in_world {
        return Err(SceneError::at(&end, "no WorldBegin: the file describes no scene"));
    }
    parser.finish(path)
}

impl Parser {
    fn resolve(&self, name: &str) -> PathBuf {
        let p = Path::new(name);
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.base.join(p)
        }
    }

    fn file(&mut self, path: &Path, from: Option<&Loc>) -> Result<(), SceneError> {
        let src = std::fs::read_to_string(path).map_err(|e| {
            let message = format!("cannot read {}: {e}", path.display());
            match from {
                Some(loc) => SceneError::at(loc, message),
                None => SceneError { loc: None, message },
            }
        })?;
        let tokens = tokenize(&src, path)?;
        let end = Loc { file: Arc::from(path), line: src.lines().count() as u32 };
        let mut cursor = Cursor { tokens, pos: 0, end };
        while let Some(token) = cursor.next() {
            let Tok::Word(directive) = &token.tok else {
                return Err(SceneError::at(&token.loc, format!("expected a directive, found {:?}", token.tok)));
            };
            self.directive(directive, &token.loc, &mut cursor)?;
        }
        let _ = cursor.end;
        Ok(())
    }

    fn transform(&mut self, loc: &Loc, f: impl Fn(&Transform) -> Option<Transform>) -> Result<(), SceneError> {
        for (i, ctm) in self.state.ctm.iter_mut().enumerate() {
            let active = match self.state.active {
                Active::All => true,
                Active::Start => i == 0,
                Active::End => i == 1,
            };
            if active {
                *ctm = f(ctm).ok_or_else(|| {
                    SceneError::at(loc, "singular transform (zero scale, zero axis or degenerate LookAt)")
                })?;
            }
        }
        Ok(())
    }

    fn need_world(&self, loc: &Loc, directive: &str, inside: bool) -> Result<(), SceneError> {
        match (self.in_world, inside) {
            (false, true) => Err(SceneError::at(loc, format!("{directive} must come after WorldBegin"))),
            (true, false) => Err(SceneError::at(loc, format!("{directive} must come before WorldBegin"))),
            _ => Ok(()),
        }
    }

    fn directive(&mut self, name: &str, loc: &Loc, c: &mut Cursor) -> Result<(), SceneError> {
        match name {
            "Include" | "Import" => {
                let file = c.string("a file name", loc)?;
                self.include_depth += 1;
                if self.include_depth > 32 {
                    return Err(SceneError::at(loc, "Include nested more than 32 deep (a cycle?)"));
                }
                let path = self.resolve(&file);
                self.file(&path, Some(loc))?;
                self.include_depth -= 1;
            }
            "Identity" => self.transform(loc, |_| Some(Transform::IDENTITY))?,
            "Translate" => {
                let v = c.numbers(3, name, loc)?;
                self.transform(loc, |m| Some(m.compose(&Transform::translate([v[0], v[1], v[2]]))))?;
            }
            "Scale" => {
                let v = c.numbers(3, name, loc)?;
                self.transform(loc, |m| Some(m.compose(&Transform::scale([v[0], v[1], v[2]])?)))?;
            }
            "Rotate" => {
                let v = c.numbers(4, name, loc)?;
                self.transform(loc, |m| Some(m.compose(&Transform::rotate(v[0], [v[1], v[2], v[3]])?)))?;
            }
            "LookAt" => {
                let v = c.numbers(9, name, loc)?;
                let look = Transform::look_at([v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]);
                self.transform(loc, |m| Some(m.compose(look.as_ref()?)))?;
            }
            "Transform" | "ConcatTransform" => {
                let v = c.numbers(16, name, loc)?;
                // pbrt's matrices are column-major in the file.
                let m: [[f64; 4]; 4] = std::array::from_fn(|i| std::array::from_fn(|j| v[j * 4 + i]));
                let t = Transform::from_matrix(m);
                let replace = name == "Transform";
                self.transform(loc, |ctm| {
                    let t = t?;
                    Some(if replace { t } else { ctm.compose(&t) })
                })?;
            }
            "CoordinateSystem" => {
                let n = c.string("a name", loc)?;
                self.coordinate_systems.insert(n, self.state.ctm);
            }
            "CoordSysTransform" => {
                let n = c.string("a name", loc)?;
                self.state.ctm = *self
                    .coordinate_systems
                    .get(&n)
                    .ok_or_else(|| SceneError::at(loc, format!("no coordinate system named {n:?}")))?;
            }
            "TransformTimes" => {
                self.need_world(loc, name, false)?;
                let v = c.numbers(2, name, loc)?;
                if v[1] < v[0] {
                    return Err(SceneError::at(loc, "TransformTimes: the end time is before the start time"));
                }
                self.transform_times = [v[0] as f32, v[1] as f32];
            }
            "ActiveTransform" => {
                self.state.active = match c.next() {
                    Some(Token { tok: Tok::Word(w), .. }) if w == "StartTime" => Active::Start,
                    Some(Token { tok: Tok::Word(w), .. }) if w == "EndTime" => Active::End,
                    Some(Token { tok: Tok::Word(w), .. }) if w == "All" => Active::All,
                    _ => return Err(SceneError::at(loc, "ActiveTransform takes StartTime, EndTime or All")),
                };
            }
            "ReverseOrientation" => self.state.reverse_orientation = !self.state.reverse_orientation,
            "Camera" => {
                self.need_world(loc, name, false)?;
                let ty = c.string("a camera type", loc)?;
                let params = c.params(format!("Camera {ty:?}"), loc)?;
                if ty != "perspective" {
                    return Err(SceneError::at(loc, format!("unsupported camera {ty:?} (supported: perspective)")));
                }
                // The CTM maps world to camera; pbrt names the camera's frame.
                let world_to_camera = self.state.ctm[0];
                if self.state.ctm[0] != self.state.ctm[1] {
                    return Err(SceneError::at(loc, "a moving camera is not supported"));
                }
                self.coordinate_systems.insert("camera".into(), [world_to_camera.inverse(); 2]);
                self.options.camera = Some((params, world_to_camera.inverse()));
            }
            "Film" => {
                self.need_world(loc, name, false)?;
                let ty = c.string("a film type", loc)?;
                let params = c.params(format!("Film {ty:?}"), loc)?;
                if ty != "rgb" && ty != "gbuffer" {
                    return Err(SceneError::at(loc, format!("unsupported film {ty:?} (supported: rgb, gbuffer)")));
                }
                self.options.film = Some(params);
            }
            "Sampler" => {
                self.need_world(loc, name, false)?;
                let ty = c.string("a sampler type", loc)?;
                let params = c.params(format!("Sampler {ty:?}"), loc)?;
                // Samples come from the technique or our own sampler; the
                // count is only a hint, kept for compatibility.
                params.int("pixelsamples", 16)?;
                params.check_unused()?;
            }
            "Integrator" => {
                self.need_world(loc, name, false)?;
                let ty = c.string("an integrator type", loc)?;
                let params = c.params(format!("Integrator {ty:?}"), loc)?;
                if ty != "path" && ty != "volpath" {
                    return Err(SceneError::at(loc, format!("unsupported integrator {ty:?} (supported: path)")));
                }
                self.options.integrator = Some(params);
            }
            "PixelFilter" => {
                self.need_world(loc, name, false)?;
                let ty = c.string("a filter type", loc)?;
                let params = c.params(format!("PixelFilter {ty:?}"), loc)?;
                if ty != "box" {
                    return Err(SceneError::at(
                        loc,
                        format!("unsupported pixel filter {ty:?}: references are box filtered and techniques reconstruct the image; use \"box\""),
                    ));
                }
                let (x, y) = (params.float("xradius", 0.5)?, params.float("yradius", 0.5)?);
                if x != 0.5 || y != 0.5 {
                    return Err(params.invalid("xradius", "must be 0.5 (one pixel)"));
                }
                params.check_unused()?;
            }
            "ColorSpace" => {
                let cs = c.string("a colour space", loc)?;
                if cs != "srgb" {
                    return Err(SceneError::at(loc, format!("unsupported colour space {cs:?} (supported: srgb)")));
                }
            }
            "Option" => return Err(SceneError::at(loc, "Option is not supported")),
            "WorldBegin" => {
                self.need_world(loc, name, false)?;
                self.in_world = true;
                self.state.ctm = [Transform::IDENTITY; 2];
                self.state.active = Active::All;
                self.coordinate_systems.insert("world".into(), self.state.ctm);
            }
            "WorldEnd" => {} // pbrt-v3 files end with it; nothing to do.
            "AttributeBegin" | "TransformBegin" => {
                self.stack.push((self.state.clone(), loc.clone(), name == "TransformBegin"));
            }
            "AttributeEnd" | "TransformEnd" => {
                let transform_only = name == "TransformEnd";
                match self.stack.pop() {
                    Some((saved, _, was_transform)) if was_transform == transform_only => {
                        if transform_only {
                            self.state.ctm = saved.ctm;
                            self.state.active = saved.active;
                        } else {
                            self.state = saved;
                        }
                    }
                    Some((_, begin, _)) => {
                        return Err(SceneError::at(
                            loc,
                            format!("{name} does not match the Begin at line {}", begin.line),
                        ))
                    }
                    None => return Err(SceneError::at(loc, format!("{name} without a matching Begin"))),
                }
            }
            "Texture" => {
                self.need_world(loc, name, true)?;
                let tex_name = c.string("a texture name", loc)?;
                let kind = c.string("\"spectrum\" or \"float\"", loc)?;
                let class = c.string("a texture class", loc)?;
                let params = c.params(format!("Texture {tex_name:?} ({class})"), loc)?;
                let float = match kind.as_str() {
                    "float" => true,
                    "spectrum" | "color" => false,
                    _ => {
                        return Err(SceneError::at(
                            loc,
                            format!("texture type must be \"spectrum\" or \"float\", not {kind:?}"),
                        ))
                    }
                };
                let texture = self.texture(&class, &params, float, loc)?;
                params.check_unused()?;
                let map = if float { &mut self.float_textures } else { &mut self.textures };
                map.insert(tex_name, Arc::new(texture));
            }
            "Material" => {
                self.need_world(loc, name, true)?;
                let ty = c.string("a material type", loc)?;
                let params = c.params(format!("Material {ty:?}"), loc)?;
                let m = self.material(&ty, &params, loc)?;
                params.check_unused()?;
                self.materials.push(m);
                self.state.material = self.materials.len() as u32 - 1;
            }
            "MakeNamedMaterial" => {
                self.need_world(loc, name, true)?;
                let material_name = c.string("a material name", loc)?;
                let params = c.params(format!("MakeNamedMaterial {material_name:?}"), loc)?;
                let ty = params
                    .string("type")?
                    .ok_or_else(|| SceneError::at(loc, "MakeNamedMaterial needs \"string type\""))?;
                let m = self.material(&ty, &params, loc)?;
                params.check_unused()?;
                self.materials.push(m);
                self.named_materials.insert(material_name, self.materials.len() as u32 - 1);
            }
            "NamedMaterial" => {
                self.need_world(loc, name, true)?;
                let material_name = c.string("a material name", loc)?;
                self.state.material = *self
                    .named_materials
                    .get(&material_name)
                    .ok_or_else(|| SceneError::at(loc, format!("no material named {material_name:?}")))?;
            }
            "AreaLightSource" => {
                self.need_world(loc, name, true)?;
                let ty = c.string("a light type", loc)?;
                let params = c.params(format!("AreaLightSource {ty:?}"), loc)?;
                if ty != "diffuse" {
                    return Err(SceneError::at(loc, format!("unsupported area light {ty:?} (supported: diffuse)")));
                }
                let radiance = match params.spectrum("L")? {
                    None => Vec3::ONE,
                    Some(SpectrumValue::Rgb(v)) => v,
                    Some(SpectrumValue::Texture(_)) => return Err(params.invalid("L", "cannot be a texture")),
                };
                let scale = params.float("scale", 1.0)?;
                let two_sided = params.bool("twosided", false)?;
                params.check_unused()?;
                self.state.area_light = Some((radiance * scale, two_sided));
            }
            "LightSource" => {
                self.need_world(loc, name, true)?;
                let ty = c.string("a light type", loc)?;
                let params = c.params(format!("LightSource {ty:?}"), loc)?;
                if ty != "infinite" {
                    return Err(SceneError::at(
                        loc,
                        format!("unsupported light {ty:?} (supported: infinite, and AreaLightSource)"),
                    ));
                }
                if params.string("filename")?.is_some() {
                    return Err(params.invalid(
                        "filename",
                        "is not supported: environment maps are not implemented; give a constant \"rgb L\"",
                    ));
                }
                let radiance = match params.spectrum("L")? {
                    None => Vec3::ONE,
                    Some(SpectrumValue::Rgb(v)) => v,
                    Some(SpectrumValue::Texture(_)) => return Err(params.invalid("L", "cannot be a texture")),
                };
                let scale = params.float("scale", 1.0)?;
                params.check_unused()?;
                if self.lights.iter().any(|l| matches!(l, Light::Environment { .. })) {
                    return Err(SceneError::at(loc, "a second infinite light (only one is supported)"));
                }
                self.lights.push(Light::Environment { radiance: radiance * scale });
            }
            "Shape" => {
                self.need_world(loc, name, true)?;
                let ty = c.string("a shape type", loc)?;
                let params = c.params(format!("Shape {ty:?}"), loc)?;
                self.shape(&ty, &params, loc)?;
                params.check_unused()?;
            }
            "ObjectBegin" | "ObjectEnd" | "ObjectInstance" | "MakeNamedMedium" | "MediumInterface" | "Attribute" => {
                return Err(SceneError::at(loc, format!("unsupported directive {name}")))
            }
            other => return Err(SceneError::at(loc, format!("unknown directive {other:?}"))),
        }
        Ok(())
    }

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

    fn texture(&self, class: &str, params: &ParamSet, float: bool, loc: &Loc) -> Result<Texture, SceneError> {
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
                if let Some(f) = params.string("filter")? {
                    if f != "bilinear" {
                        return Err(params.invalid("filter", "must be \"bilinear\" (the only supported filter)"));
                    }
                }
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

    fn material(&self, ty: &str, params: &ParamSet, loc: &Loc) -> Result<Material, SceneError> {
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
            "" | "none" | "interface" => {
                return Err(SceneError::at(loc, "interface materials (participating media) are not supported"))
            }
            other => {
                return Err(SceneError::at(
                    loc,
                    format!(
                        "unsupported material {other:?} (supported: diffuse, conductor, dielectric, coateddiffuse)"
                    ),
                ))
            }
        })
    }

    fn shape(&mut self, ty: &str, params: &ParamSet, loc: &Loc) -> Result<(), SceneError> {
        let [t0, t1] = self.state.ctm;
        let moving = t0 != t1;
        let steps: Vec<Transform> = if moving { vec![t0, t1] } else { vec![t0] };
        let flip = self.state.reverse_orientation ^ t0.swaps_handedness();
        let geometry = match ty {
            "trianglemesh" | "plymesh" => {
                let (positions, indices, normals, uvs) = if ty == "plymesh" {
                    let file = params
                        .string("filename")?
                        .ok_or_else(|| SceneError::at(loc, "plymesh needs \"string filename\""))?;
                    let m = ply::read(&self.resolve(&file)).map_err(|e| SceneError::at(loc, e))?;
                    (m.positions, m.indices, m.normals, m.uvs)
                } else {
                    let p = params
                        .triples("P", &["point3", "point"])?
                        .ok_or_else(|| SceneError::at(loc, "trianglemesh needs \"point3 P\""))?;
                    let indices = match params.ints("indices")? {
                        Some(i) => i,
                        None if p.len() == 3 => vec![0, 1, 2],
                        None => {
                            return Err(SceneError::at(
                                loc,
                                "trianglemesh needs \"integer indices\" (unless it has exactly 3 vertices)",
                            ))
                        }
                    };
                    if indices.len() % 3 != 0 || indices.is_empty() {
                        return Err(params.invalid(
                            "indices",
                            &format!("needs a positive multiple of 3 values, got {}", indices.len()),
                        ));
                    }
                    if let Some(bad) = indices.iter().find(|i| **i < 0 || **i as usize >= p.len()) {
                        return Err(params.invalid("indices", &format!("has {bad}, outside 0..{}", p.len())));
                    }
                    let n = params.triples("N", &["normal", "normal3"])?;
                    let uv = params.pairs("uv")?;
                    let indices = indices.chunks_exact(3).map(|c| [c[0] as u32, c[1] as u32, c[2] as u32]).collect();
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
                    format!("unsupported shape {other:?} (supported: trianglemesh, plymesh, sphere, curve)"),
                ))
            }
        };
        let shape_index = self.shapes.len() as u32;
        let mut light = None;
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
        self.shapes.push(Shape { geometry, material: self.state.material, light });
        Ok(())
    }

    fn finish(self, path: &Path) -> Result<Scene, SceneError> {
        let loc = Loc { file: Arc::from(path), line: 1 };
        let (width, height) = match &self.options.film {
            Some(film) => {
                let (w, h) = (film.int("xresolution", 1280)?, film.int("yresolution", 720)?);
                film.string("filename")?;
                film.check_unused()?;
                if !(1..=65536).contains(&w) || !(1..=65536).contains(&h) {
                    return Err(film.invalid("xresolution", "and yresolution must be between 1 and 65536"));
                }
                (w as u32, h as u32)
            }
            None => (1280, 720),
        };
        let max_depth = match &self.options.integrator {
            Some(p) => {
                let d = p.int("maxdepth", 5)?;
                if p.bool("regularize", false)? {
                    return Err(p.invalid("regularize", "is not supported"));
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
        Scene::build(name, camera, max_depth, self.shapes, self.materials, self.lights, self.transform_times)
            .map_err(|e| SceneError { loc: None, message: e.to_string() })
    }
}
