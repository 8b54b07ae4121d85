//! Reading the directives: the token cursor, the graphics state they
//! change (transforms, attribute stack, current material and area light)
//! and the options before `WorldBegin`.
//!
//! This half knows the file format and its ordering rules; what a shape,
//! material or texture directive turns into is left to `build`, so that
//! supporting a new directive and supporting a new kind of scene object
//! are separate edits.

use super::lexer::{tokenize, Tok, Token};
use super::params::{ParamSet, SpectrumValue, Values};
use super::{Loc, SceneError};
use crate::math::{Transform, Vec3};
use crate::scene::light::Light;
use crate::scene::material::{Bump, Material};
use crate::scene::shape::Shape;
use crate::scene::texture::Texture;
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
pub(super) struct GraphicsState {
    pub(super) ctm: [Transform; 2],
    active: Active,
    pub(super) material: u32,
    /// Radiance and two-sidedness of the current AreaLightSource.
    pub(super) area_light: Option<(Vec3, bool)>,
    pub(super) reverse_orientation: bool,
}

/// The camera and image options before `WorldBegin`.
#[derive(Debug, Default)]
pub(super) struct Options {
    pub(super) camera: Option<(ParamSet, Transform)>,
    pub(super) film: Option<ParamSet>,
    /// The integrator's type and parameters.
    pub(super) integrator: Option<(String, ParamSet)>,
}

pub(super) struct Parser {
    /// Where relative file names are resolved: the main file's directory (as pbrt-v4 does).
    base: PathBuf,
    pub(super) state: GraphicsState,
    stack: Vec<(GraphicsState, Loc, bool)>,
    coordinate_systems: HashMap<String, [Transform; 2]>,
    pub(super) transform_times: [f32; 2],
    in_world: bool,
    pub(super) options: Options,
    pub(super) textures: HashMap<String, Arc<Texture>>,
    pub(super) float_textures: HashMap<String, Arc<Texture>>,
    pub(super) named_materials: HashMap<String, u32>,
    pub(super) materials: Vec<Material>,
    /// Each material's bump or normal map.
    pub(super) bumps: Vec<Option<Bump>>,
    pub(super) shapes: Vec<Shape>,
    pub(super) lights: Vec<Light>,
    include_depth: u32,
    /// Constructs read with a conversion (pbrt-v3 forms, ignored hints), in file order.
    pub(super) warnings: std::cell::RefCell<Vec<SceneError>>,
    /// Objects (pbrt's `ObjectBegin`): name and shapes.
    pub(super) objects: Vec<(String, Vec<Shape>)>,
    object_names: HashMap<String, u32>,
    /// The object being defined, and the attribute stack depth its definition began at.
    pub(super) object: Option<(u32, usize)>,
    /// (object, object to world) per `ObjectInstance`.
    pub(super) placements: Vec<(u32, Transform)>,
    /// Survey mode: record each directive's error and go on to the next.
    keep_going: bool,
    problems: Vec<SceneError>,
    /// Directive and type counts (survey mode).
    uses: std::collections::BTreeMap<String, usize>,
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

/// How a directive counts in a survey: its name, and its type for those that have one.
fn used_as(directive: &str, c: &Cursor) -> String {
    let string = |k: usize| match c.tokens.get(c.pos + k) {
        Some(Token { tok: Tok::Str(s), .. }) => Some(s.clone()),
        _ => None,
    };
    let ty = match directive {
        "Shape" | "Material" | "LightSource" | "AreaLightSource" | "Camera" | "Sampler" | "Integrator" | "Film"
        | "PixelFilter" | "MakeNamedMedium" => string(0),
        "Texture" => string(2),
        // Its type is among its parameters: the string after "string type", up to the next directive.
        "MakeNamedMaterial" => c.tokens[c.pos.min(c.tokens.len())..]
            .iter()
            .take_while(|t| !matches!(t.tok, Tok::Word(_)))
            .skip_while(|t| !matches!(&t.tok, Tok::Str(s) if s == "string type"))
            .skip(1)
            .find_map(|t| match &t.tok {
                Tok::Str(s) => Some(s.clone()),
                _ => None,
            }),
        _ => None,
    };
    match ty {
        Some(ty) => format!("{directive} {ty:?}"),
        None => directive.to_string(),
    }
}

/// An error about a directive that was upgraded names what the file said.
fn upgraded_from(mut e: SceneError, v3: &str, v4: &str) -> SceneError {
    if v3 != v4 {
        e.message += &format!(" (read from pbrt-v3's {v3:?})");
    }
    e
}

/// Parses `path` and everything it includes, and builds the scene; also
/// returns a warning for each construct read with a conversion.
pub fn load(path: &Path) -> Result<(Scene, Vec<SceneError>), SceneError> {
    let mut parser = Parser::new(path, false);
    parser.file(path, None)?;
    parser.end(path)?;
    parser.finish(path)
}

/// What a scene uses and what stops it from loading: every directive is
/// read, past any errors.
#[derive(Default)]
pub struct Survey {
    /// How often each directive and type occurs (`Shape "sphere"`), in name order.
    pub uses: std::collections::BTreeMap<String, usize>,
    /// Every error, in file order; none when the scene loads.
    pub problems: Vec<SceneError>,
    /// Every conversion, in file order.
    pub warnings: Vec<SceneError>,
    /// The scene, when it loads.
    pub scene: Option<Scene>,
}

/// Surveys `path` and everything it includes (see [`Survey`]).
pub fn survey(path: &Path) -> Survey {
    let mut parser = Parser::new(path, true);
    if let Err(e) = parser.file(path, None).and_then(|()| parser.end(path)) {
        parser.problems.push(e);
    }
    let uses = std::mem::take(&mut parser.uses);
    let mut problems = std::mem::take(&mut parser.problems);
    let (scene, warnings) = if problems.is_empty() {
        match parser.finish(path) {
            Ok((scene, warnings)) => (Some(scene), warnings),
            Err(e) => {
                problems.push(e);
                (None, Vec::new())
            }
        }
    } else {
        (None, parser.warnings.take())
    };
    Survey { uses, problems, warnings, scene }
}

impl Parser {
    fn new(path: &Path, keep_going: bool) -> Parser {
        Parser {
            base: path.parent().map(Path::to_path_buf).unwrap_or_default(),
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
            bumps: vec![None],
            shapes: Vec::new(),
            lights: Vec::new(),
            include_depth: 0,
            warnings: Default::default(),
            objects: Vec::new(),
            object_names: HashMap::new(),
            object: None,
            placements: Vec::new(),
            keep_going,
            problems: Vec::new(),
            uses: Default::default(),
        }
    }

    /// The checks at the end of the files.
    fn end(&self, path: &Path) -> Result<(), SceneError> {
        let end = Loc { file: Arc::from(path), line: 0 };
        if let Some((_, loc, _)) = self.stack.last() {
            let what = if self.object.is_some() {
                "ObjectBegin without a matching ObjectEnd"
            } else {
                "AttributeBegin without a matching AttributeEnd"
            };
            return Err(SceneError::at(loc, what));
        }
        if !self.in_world {
            return Err(SceneError::at(&end, "no WorldBegin: the file describes no scene"));
        }
        Ok(())
    }

    /// Notes a construct read with a conversion.
    pub(super) fn warn(&self, loc: &Loc, message: impl Into<String>) {
        self.warnings.borrow_mut().push(SceneError::at(loc, message));
    }

    /// Marks the hints among `params` (settings of pbrt's own renderer that
    /// this one has no use for) as read, with one warning naming those given.
    pub(super) fn ignore_hints(&self, params: &ParamSet, hints: &[&str]) {
        let given: Vec<String> =
            hints.iter().filter(|name| params.ignore(name)).map(|name| format!("{name:?}")).collect();
        self.warn_ignored(params, given);
    }

    /// One warning naming the ignored parameters of a directive, if any.
    pub(super) fn warn_ignored(&self, params: &ParamSet, ignored: Vec<String>) {
        if !ignored.is_empty() {
            self.warn(&params.loc, format!("{} ignored for {}", ignored.join(", "), params.owner));
        }
    }

    /// A directive's parameter list; warns of the pbrt-v3 parameter types it was read with.
    fn params(&self, c: &mut Cursor, owner: String, at: &Loc) -> Result<ParamSet, SceneError> {
        let mut params = c.params(owner, at)?;
        for (loc, message) in params.upgrades.drain(..) {
            self.warn(&loc, message);
        }
        Ok(params)
    }

    /// The pbrt-v4 type of an upgraded directive; warns of each conversion.
    fn upgraded(&self, up: super::upgrade::Upgraded, loc: &Loc) -> String {
        for note in &up.notes {
            self.warn(loc, note.clone());
        }
        up.ty
    }

    pub(super) fn resolve(&self, name: &str) -> PathBuf {
        let p = Path::new(name);
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.base.join(p)
        }
    }

    fn file(&mut self, path: &Path, from: Option<&Loc>) -> Result<(), SceneError> {
        let src =
            super::read_file(path).and_then(|b| String::from_utf8(b).map_err(std::io::Error::other)).map_err(|e| {
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
            if self.keep_going {
                *self.uses.entry(used_as(directive, &cursor)).or_default() += 1;
            }
            let result = self.directive(directive, &token.loc, &mut cursor);
            match result {
                Err(e) if self.keep_going => {
                    self.problems.push(e);
                    // On to the next directive.
                    while cursor.peek().is_some_and(|t| !matches!(t.tok, Tok::Word(_))) {
                        cursor.next();
                    }
                }
                other => other?,
            }
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
                let params = self.params(c, format!("Camera {ty:?}"), loc)?;
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
                let mut params = self.params(c, format!("Film {ty:?}"), loc)?;
                let ty = self.upgraded(super::upgrade::film(&ty, &mut params), loc);
                if ty != "rgb" && ty != "gbuffer" {
                    return Err(SceneError::at(loc, format!("unsupported film {ty:?} (supported: rgb, gbuffer)")));
                }
                self.options.film = Some(params);
            }
            "Sampler" => {
                self.need_world(loc, name, false)?;
                let ty = c.string("a sampler type", loc)?;
                let params = self.params(c, format!("Sampler {ty:?}"), loc)?;
                // Samples come from the technique or our own sampler: the
                // sampler and its settings are hints, kept for compatibility.
                params.int("pixelsamples", 16)?;
                params.ignore_all();
            }
            "Integrator" => {
                self.need_world(loc, name, false)?;
                let ty = c.string("an integrator type", loc)?;
                let mut params = self.params(c, format!("Integrator {ty:?}"), loc)?;
                let ty = self.upgraded(super::upgrade::integrator(&ty, &mut params), loc);
                if ty != "path" && ty != "volpath" {
                    self.warn(loc, format!("integrator {ty:?} is a hint: scenes are rendered by the path tracer"));
                }
                self.options.integrator = Some((ty, params));
            }
            "PixelFilter" => {
                self.need_world(loc, name, false)?;
                let ty = c.string("a filter type", loc)?;
                let params = self.params(c, format!("PixelFilter {ty:?}"), loc)?;
                params.ignore_all();
                if ty != "box" {
                    self.warn(
                        loc,
                        format!("pixel filter {ty:?} ignored: references are box filtered, and techniques reconstruct the image"),
                    );
                }
            }
            "ColorSpace" => {
                let cs = c.string("a colour space", loc)?;
                if cs != "srgb" {
                    return Err(SceneError::at(loc, format!("unsupported colour space {cs:?} (supported: srgb)")));
                }
            }
            "Option" => {
                // `Option "type name" value`: global settings of pbrt's own renderer.
                let decl = c.string("an option", loc)?;
                c.next();
                self.warn(loc, format!("Option {decl:?} ignored (it sets pbrt's own renderer)"));
            }
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
                let mut params = self.params(c, format!("Texture {tex_name:?} ({class})"), loc)?;
                let class = self.upgraded(super::upgrade::texture(&class, &mut params), loc);
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
                let mut params = self.params(c, format!("Material {ty:?}"), loc)?;
                let v4 = self.upgraded(super::upgrade::material(&ty, &mut params)?, loc);
                let m = self.material(&v4, &params, loc).map_err(|e| upgraded_from(e, &ty, &v4))?;
                let bump = self.bump(&params, loc)?;
                params.check_unused()?;
                self.materials.push(m);
                self.bumps.push(bump);
                self.state.material = self.materials.len() as u32 - 1;
            }
            "MakeNamedMaterial" => {
                self.need_world(loc, name, true)?;
                let material_name = c.string("a material name", loc)?;
                let mut params = self.params(c, format!("MakeNamedMaterial {material_name:?}"), loc)?;
                let ty = params
                    .string("type")?
                    .ok_or_else(|| SceneError::at(loc, "MakeNamedMaterial needs \"string type\""))?;
                let v4 = self.upgraded(super::upgrade::material(&ty, &mut params)?, loc);
                let m = self.material(&v4, &params, loc).map_err(|e| upgraded_from(e, &ty, &v4))?;
                let bump = self.bump(&params, loc)?;
                params.check_unused()?;
                self.materials.push(m);
                self.bumps.push(bump);
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
                let mut params = self.params(c, format!("AreaLightSource {ty:?}"), loc)?;
                let ty = self.upgraded(super::upgrade::light(&ty, &mut params, true), loc);
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
                let mut params = self.params(c, format!("LightSource {ty:?}"), loc)?;
                let ty = self.upgraded(super::upgrade::light(&ty, &mut params, false), loc);
                let light = self.light(&ty, &params, loc)?;
                params.check_unused()?;
                if light.is_environment() && self.lights.iter().any(Light::is_environment) {
                    return Err(SceneError::at(loc, "a second infinite light (only one is supported)"));
                }
                self.lights.push(light);
            }
            "Shape" => {
                self.need_world(loc, name, true)?;
                let ty = c.string("a shape type", loc)?;
                let mut params = self.params(c, format!("Shape {ty:?}"), loc)?;
                let ty = self.upgraded(super::upgrade::shape(&ty, &mut params), loc);
                self.shape(&ty, &params, loc)?;
                params.check_unused()?;
            }
            "ObjectBegin" => {
                self.need_world(loc, name, true)?;
                let object = c.string("an object name", loc)?;
                if let Some((current, _)) = &self.object {
                    return Err(SceneError::at(
                        loc,
                        format!("ObjectBegin inside object {:?}", self.objects[*current as usize].0),
                    ));
                }
                if self.object_names.contains_key(&object) {
                    return Err(SceneError::at(loc, format!("object {object:?} is defined twice")));
                }
                // As in pbrt, an object's definition is an attribute block of its own.
                self.stack.push((self.state.clone(), loc.clone(), false));
                self.object_names.insert(object.clone(), self.objects.len() as u32);
                self.object = Some((self.objects.len() as u32, self.stack.len()));
                self.objects.push((object, Vec::new()));
            }
            "ObjectEnd" => {
                match self.object.take() {
                    Some((_, depth)) if depth == self.stack.len() => {}
                    Some(_) => return Err(SceneError::at(loc, "ObjectEnd inside an attribute block of the object")),
                    None => return Err(SceneError::at(loc, "ObjectEnd without ObjectBegin")),
                }
                let (saved, _, _) = self.stack.pop().expect("ObjectBegin pushed the state");
                self.state = saved;
            }
            "ObjectInstance" => {
                self.need_world(loc, name, true)?;
                let object = c.string("an object name", loc)?;
                if self.object.is_some() {
                    return Err(SceneError::at(loc, "ObjectInstance inside an object's definition"));
                }
                let index = *self
                    .object_names
                    .get(&object)
                    .ok_or_else(|| SceneError::at(loc, format!("no object named {object:?}")))?;
                let [t0, t1] = self.state.ctm;
                if t0 != t1 {
                    return Err(SceneError::at(loc, "a moving object instance is not supported"));
                }
                self.placements.push((index, t0));
            }
            "MakeNamedMedium" | "MediumInterface" | "Attribute" => {
                return Err(SceneError::at(loc, format!("unsupported directive {name}")))
            }
            other => return Err(SceneError::at(loc, format!("unknown directive {other:?}"))),
        }
        Ok(())
    }
}
