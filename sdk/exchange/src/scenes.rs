//! The scene pool's metadata: one `fbksd-scene.json` per scene directory.
//!
//! ```json
//! {"name": "sphere", "path": "sphere.expr", "ref-img": "reference.exr",
//!  "renderer": "procedural", "category": "experimental", "tags": ["motion-blur"],
//!  "spp": [1, 4, 16, 64], "width": 500, "height": 500,
//!  "reference": {"method": "closed_form", "formula": "sphere_time"},
//!  "description": "…"}
//! ```
//!
//! `name`, `path` and `ref-img` are the original FBKSD's keys; the rest is
//! new: the renderer that loads the scene, what it stresses (tags), its
//! default budgets and resolution, and how its reference is made.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A metadata problem, with the file it is in.
#[derive(Debug, thiserror::Error)]
#[error("{file}: {message}")]
pub struct MetaError {
    /// The metadata file.
    pub file: String,
    /// What is wrong.
    pub message: String,
}

/// How a reference is made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "method", rename_all = "snake_case", deny_unknown_fields)]
pub enum ReferenceMethod {
    /// Render at `spp` samples per pixel.
    Render {
        /// Samples per pixel.
        spp: u64,
    },
    /// A closed form known by name.
    ClosedForm {
        /// `sphere_time` or `fireflies`.
        formula: String,
    },
}

/// A scene's `fbksd-scene.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneMeta {
    /// Scene name.
    pub name: String,
    /// Scene file, relative to the directory.
    pub path: String,
    /// Reference image, relative to the directory.
    #[serde(rename = "ref-img")]
    pub ref_img: String,
    /// Renderer name (`procedural`, `embree`, `analytic`).
    pub renderer: String,
    /// `experimental` or `production`.
    pub category: String,
    /// What the scene stresses.
    pub tags: Vec<String>,
    /// Default budgets.
    pub spp: Vec<u64>,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// How the reference is made.
    pub reference: ReferenceMethod,
    /// What the scene is.
    pub description: String,
    /// The directory (not in the file).
    #[serde(skip)]
    pub dir: PathBuf,
}

/// The metadata file's name.
pub const META_FILE: &str = "fbksd-scene.json";

/// A scene's digest, `sha256:<hex>`: every file beside the scene file but
/// its references (`reference*`), names and contents in name order, which
/// is the scene as a renderer reads it. One rule for the renderers'
/// reference caches and for the runner's provenance.
pub fn scene_digest(scene_file: &Path) -> std::io::Result<String> {
    use sha2::{Digest, Sha256};
    let dir = scene_file.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)?.map(|e| e.map(|e| e.path())).collect::<Result<_, _>>()?;
    files.retain(|p| p.is_file() && !p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("reference")));
    files.sort();
    let mut hasher = Sha256::new();
    for file in files {
        let name = file.file_name().unwrap_or_default().as_encoded_bytes().to_vec();
        hasher.update((name.len() as u64).to_le_bytes());
        hasher.update(&name);
        let bytes = std::fs::read(&file)?;
        hasher.update((bytes.len() as u64).to_le_bytes());
        hasher.update(&bytes);
    }
    Ok(format!("sha256:{:x}", hasher.finalize()))
}

/// A reference's key, `sha256:<hex>`: what makes it (a renderer's
/// `generator`, which names its version), at how many samples per pixel,
/// of which scene files ([`scene_digest`]). Every reference with one key is
/// the same image, so the service needs one per key; a renderer prints a
/// scene's key without building it (`fbksd-<renderer> reference --key`).
pub fn reference_key(generator: &str, samples_per_pixel: u64, scene_digest: &str) -> String {
    use sha2::{Digest, Sha256};
    let text = format!("fbksd reference\n{generator}\n{samples_per_pixel}\n{scene_digest}\n");
    format!("sha256:{:x}", Sha256::digest(text.as_bytes()))
}

/// The key ([`reference_key`]) of the reference a note (`reference.json`,
/// as every renderer writes it: `generator`, `samples_per_pixel`,
/// `scene_digest`) describes.
pub fn note_reference_key(note: &[u8]) -> Result<String, String> {
    let note: serde_json::Value = serde_json::from_slice(note).map_err(|e| e.to_string())?;
    let (Some(generator), Some(spp), Some(digest)) =
        (note["generator"].as_str(), note["samples_per_pixel"].as_u64(), note["scene_digest"].as_str())
    else {
        return Err("it must name generator, samples_per_pixel and scene_digest".into());
    };
    Ok(reference_key(generator, spp, digest))
}

/// The one rule for cached references, shared by every renderer: the
/// reference beside a scene is kept when it and its note (`reference.json`)
/// exist and the note's key ([`note_reference_key`]) is the one of this
/// `generator`, `samples_per_pixel` and `scene_digest` ([`scene_digest`]),
/// as a runner checks it. Returns the note's text when it is kept.
pub fn current_reference_note(
    meta: &SceneMeta,
    generator: &str,
    samples_per_pixel: u64,
    digest: &str,
) -> std::io::Result<Option<String>> {
    let (reference, note_file) = (meta.reference_file(), meta.reference_note_file());
    if !reference.is_file() || !note_file.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&note_file)?;
    let current =
        note_reference_key(text.as_bytes()).is_ok_and(|key| key == reference_key(generator, samples_per_pixel, digest));
    Ok(current.then_some(text))
}

/// The program of a renderer named in scene metadata: `fbksd-<name>` (or
/// `fbksd-<name>-renderer`) next to the running program, else on PATH.
pub fn renderer_program(name: &str) -> Result<PathBuf, String> {
    let candidates = [format!("fbksd-{name}"), format!("fbksd-{name}-renderer")];
    let here = std::env::current_exe().map_err(|e| format!("this program's path: {e}"))?;
    let path = std::env::var_os("PATH").unwrap_or_default();
    let dirs = here.parent().map(PathBuf::from).into_iter().chain(std::env::split_paths(&path));
    for dir in dirs {
        for c in &candidates {
            let p = dir.join(c);
            if p.is_file() {
                return Ok(p);
            }
        }
    }
    Err(format!(
        "no program for renderer {name:?}: looked for {} next to {} and on PATH",
        candidates.join(" and "),
        here.file_name().map_or("this program".into(), |n| n.to_string_lossy().into_owned())
    ))
}

impl SceneMeta {
    /// Reads a scene directory's metadata (or the file itself) and checks it
    /// against the scene file.
    pub fn load(path: &Path) -> Result<SceneMeta, MetaError> {
        let file = if path.is_dir() { path.join(META_FILE) } else { path.to_path_buf() };
        let fail = |message: String| MetaError { file: file.display().to_string(), message };
        let text = std::fs::read_to_string(&file).map_err(|e| fail(e.to_string()))?;
        let mut meta: SceneMeta = serde_json::from_str(&text).map_err(|e| fail(e.to_string()))?;
        meta.dir = file.parent().unwrap_or(Path::new(".")).to_path_buf();
        if meta.spp.is_empty() || meta.spp.contains(&0) {
            return Err(fail("spp must list positive budgets".into()));
        }
        if !["experimental", "production"].contains(&meta.category.as_str()) {
            return Err(fail(format!("category must be experimental or production, not {:?}", meta.category)));
        }
        if meta.width == 0 || meta.height == 0 {
            return Err(fail("width and height must be positive".into()));
        }
        Ok(meta)
    }

    /// Whether `path` is a scene directory or a metadata file.
    pub fn is_meta(path: &Path) -> bool {
        path.join(META_FILE).is_file() || path.file_name().is_some_and(|n| n == META_FILE)
    }

    /// Checks that the scene is `renderer`'s, for its `reference` command:
    /// another renderer's scene is named with the program that makes it.
    pub fn expect_renderer(&self, renderer: &str) -> Result<(), String> {
        if self.renderer == renderer {
            return Ok(());
        }
        Err(format!(
            "{}: a scene of the {} renderer (its {META_FILE}), not of fbksd-{renderer}: make its reference with fbksd-{} reference",
            self.dir.display(),
            self.renderer,
            self.renderer
        ))
    }

    /// The scene file.
    pub fn scene_file(&self) -> PathBuf {
        self.dir.join(&self.path)
    }

    /// The reference image.
    pub fn reference_file(&self) -> PathBuf {
        self.dir.join(&self.ref_img)
    }

    /// The reference's note (`reference.json` beside `reference.exr`): what
    /// made it, which [`current_reference_note`] and the runners read.
    pub fn reference_note_file(&self) -> PathBuf {
        self.reference_file().with_extension("json")
    }

    /// The feature buffer `name` (one of [`FEATURE_BUFFERS`]) made with the
    /// reference: `reference-albedo.exr` beside `reference.exr`. Its name
    /// starts like the reference's, so [`scene_digest`] leaves it out.
    pub fn feature_buffer_file(&self, name: &str) -> PathBuf {
        let reference = Path::new(&self.ref_img);
        let stem = reference.file_stem().unwrap_or_default().to_string_lossy();
        self.dir.join(reference.with_file_name(format!("{stem}-{name}.exr")))
    }
}

/// The feature buffers a renderer makes beside a scene's reference, so a
/// researcher sees what a feature-guided technique was given: the mean
/// first-hit albedo (texture colour), the mean first-hit normal (x, y, z as
/// r, g, b, in [-1, 1]) and the mean depth (the same in r, g and b).
pub const FEATURE_BUFFERS: [&str; 3] = ["albedo", "normal", "depth"];

/// Samples per pixel of the feature buffers: enough to average the pixel
/// footprint (edges, lens and time), far below a reference's.
pub const FEATURE_BUFFER_SPP: u64 = 16;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reference_key_changes_with_its_renderer_its_budget_and_its_scene() {
        let key = reference_key("fbksd-embree 0.1.0, renderer 3", 4096, "sha256:aa");
        assert!(key.starts_with("sha256:") && key.len() == 7 + 64, "{key}");
        assert_eq!(key, reference_key("fbksd-embree 0.1.0, renderer 3", 4096, "sha256:aa"));
        for other in [
            reference_key("fbksd-embree 0.1.0, renderer 4", 4096, "sha256:aa"),
            reference_key("fbksd-embree 0.1.0, renderer 3", 4095, "sha256:aa"),
            reference_key("fbksd-embree 0.1.0, renderer 3", 4096, "sha256:ab"),
        ] {
            assert_ne!(key, other);
        }
    }

    #[test]
    fn a_renderer_refuses_another_renderers_scene_and_names_the_right_program() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/experimental/spheres-sky");
        let meta = SceneMeta::load(&dir).unwrap();
        assert_eq!(meta.expect_renderer("mitsuba"), Ok(()));
        let message = meta.expect_renderer("procedural").unwrap_err();
        assert!(message.contains("a scene of the mitsuba renderer"), "{message}");
        assert!(message.ends_with("make its reference with fbksd-mitsuba reference"), "{message}");
    }
}
