//! Scene input: the subset of the pbrt-v4 scene format that the renderer
//! supports, so users can bring real research scenes.
//!
//! - [`lexer`]: tokens with file and line.
//! - [`params`]: typed parameter lists; an unused parameter is an error.
//! - [`parser`]: directives and the graphics state they change.
//! - `build`: the scene they build (shapes, materials, textures, camera).
//! - [`ply`]: meshes for `plymesh`.
//!
//! Supported: `Include`/`Import`; `LookAt`, `Translate`, `Scale`,
//! `Rotate`, `Transform`, `ConcatTransform`, `Identity`,
//! `CoordinateSystem`, `CoordSysTransform`, `TransformTimes`,
//! `ActiveTransform`, `ReverseOrientation`; `Camera "perspective"`,
//! `Film "rgb"`, `Sampler`, `Integrator "path"`, `PixelFilter "box"`,
//! `ColorSpace "srgb"`; `WorldBegin`, `AttributeBegin`/`End`,
//! `TransformBegin`/`End`; `Texture` (`imagemap`, `checkerboard`,
//! `constant`, `scale`); `Material`, `MakeNamedMaterial`, `NamedMaterial`
//! (`diffuse`, `conductor`, `dielectric`, `coateddiffuse`); `Shape`
//! (`trianglemesh`, `plymesh`, `sphere`, `curve`); `AreaLightSource
//! "diffuse"`; `LightSource` `"infinite"` (constant), `"point"`, `"spot"`,
//! `"distant"`. Anything else is an error naming the file and line.

mod build;
pub mod lexer;
pub mod params;
pub mod parser;
pub mod ply;

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

/// Loads a pbrt-v4 scene file into a renderable scene.
pub fn load(path: &Path) -> Result<crate::scene::Scene, SceneError> {
    parser::load(path)
}
