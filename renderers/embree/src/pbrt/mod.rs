//! Scene input: the subset of the pbrt-v4 scene format that the renderer
//! supports, so users can bring real research scenes.
//!
//! - [`lexer`]: tokens with file and line.
//! - [`params`]: typed parameter lists; an unused parameter is an error.
//! - [`parser`]: directives and the graphics state they change.
//! - `build`: the scene they build (shapes, materials, textures, camera).
//! - [`ply`]: meshes for `plymesh`.
//! - [`tessellate`]: `disk`, `cylinder`, `bilinearmesh`, `loopsubdiv` as triangles.
//! - `upgrade`: pbrt-v3 forms read as pbrt-v4's `--upgrade` converts them.
//!
//! Supported: `Include`/`Import`; `LookAt`, `Translate`, `Scale`,
//! `Rotate`, `Transform`, `ConcatTransform`, `Identity`,
//! `CoordinateSystem`, `CoordSysTransform`, `TransformTimes`,
//! `ActiveTransform`, `ReverseOrientation`; `Camera "perspective"`,
//! `Film "rgb"`, `Sampler`, `Integrator "path"`, `PixelFilter "box"`,
//! `ColorSpace "srgb"`; `WorldBegin`, `AttributeBegin`/`End`,
//! `TransformBegin`/`End`; `ObjectBegin`/`End`, `ObjectInstance` (Embree
//! instances); `Texture` (`imagemap`, `checkerboard`,
//! `constant`, `scale`); `Material`, `MakeNamedMaterial`, `NamedMaterial`
//! (`diffuse`, `conductor`, `dielectric`, `thindielectric`, `coateddiffuse`,
//! `diffusetransmission`, `mix`, and
//! `interface`, whose shapes are left out as media are not rendered; each with a bump
//! map `"texture displacement"` or a `"string normalmap"`); `Shape`
//! (`trianglemesh`, `plymesh`, `sphere`, `curve`, and as triangles `disk`,
//! `cylinder`, `bilinearmesh`, `loopsubdiv`); `AreaLightSource
//! "diffuse"`; `LightSource` `"infinite"` (constant, or a square image in
//! pbrt-v4's equal-area mapping), `"point"`, `"spot"`, `"distant"`.
//! pbrt-v3 files are read as pbrt-v4's upgrade converts them (see
//! `upgrade`). Anything else is an error naming the file and line.

mod build;
pub mod lexer;
pub mod params;
pub mod parser;
pub mod ply;
pub mod tessellate;
mod upgrade;

use std::fmt;
use std::path::Path;
use std::sync::Arc;

/// A place in a scene file.
#[derive(Debug, Clone, PartialEq)]
pub struct Loc {
    /// The file.
    pub file: Arc<Path>,
    /// 1-based line.
    pub line: u32,
}

/// A scene error: what was wrong and where.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneError {
    /// Where, when known.
    pub loc: Option<Loc>,
    /// What.
    pub message: String,
}

impl SceneError {
    /// An error at `loc`.
    pub fn at(loc: &Loc, message: impl Into<String>) -> SceneError {
        SceneError { loc: Some(loc.clone()), message: message.into() }
    }
}

impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.loc {
            Some(loc) => write!(f, "{}:{}: {}", loc.file.display(), loc.line, self.message),
            None => f.write_str(&self.message),
        }
    }
}

impl std::error::Error for SceneError {}

/// Loads a pbrt-v4 scene file into a renderable scene. Constructs read
/// with a conversion (pbrt-v3 forms, hints this renderer ignores) are
/// printed to standard error, once per kind with how many more there were.
pub fn load(path: &Path) -> Result<crate::scene::Scene, SceneError> {
    let (scene, warnings) = load_with_warnings(path)?;
    for line in summarize(&warnings) {
        eprintln!("warning: {line}");
    }
    Ok(scene)
}

/// [`load`], returning the warnings (in file order) instead of printing them.
pub fn load_with_warnings(path: &Path) -> Result<(crate::scene::Scene, Vec<SceneError>), SceneError> {
    parser::load(path)
}

pub use parser::{survey, Survey};

/// A scene, mesh or other input file's bytes; pbrt reads gzipped ones
/// (`.pbrt.gz`, `.ply.gz`) too, so those are decompressed.
fn read_file(path: &Path) -> std::io::Result<Vec<u8>> {
    let data = std::fs::read(path)?;
    if path.extension().is_none_or(|e| e != "gz") {
        return Ok(data);
    }
    let mut plain = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(data.as_slice()), &mut plain)?;
    Ok(plain)
}

/// One line per kind of warning: the first place, and how many more.
pub fn summarize(warnings: &[SceneError]) -> Vec<String> {
    let mut kinds: Vec<(&str, &SceneError, usize)> = Vec::new();
    for w in warnings {
        match kinds.iter_mut().find(|(m, _, _)| *m == w.message) {
            Some(kind) => kind.2 += 1,
            None => kinds.push((&w.message, w, 0)),
        }
    }
    kinds
        .into_iter()
        .map(|(_, first, more)| match more {
            0 => first.to_string(),
            n => format!("{first} (and {n} more like it)"),
        })
        .collect()
}
