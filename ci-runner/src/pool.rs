//! The runner's scene pool: the scenes it benchmarks on, with their
//! references and feature buffers (made present by
//! [`crate::references::prepare`]), checked and hashed once when the runner
//! starts.
//!
//! The renderer image holds the scene root at [`SCENES_MOUNT`] without
//! references; the references stay on the runner's machine, where the
//! metrics are computed, and no container ever sees them.

use fbksd_exchange::scenes::SceneMeta;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// Where the renderer image holds the scene root.
pub const SCENES_MOUNT: &str = "/scenes";

/// One scene of the pool.
#[derive(Debug, Clone)]
pub struct PoolScene {
    /// Its directory relative to the scene root (`experimental/sphere`).
    pub rel: String,
    /// Its metadata (with the directory on this machine).
    pub meta: SceneMeta,
    /// Its digest ([`fbksd_exchange::scenes::scene_digest`]: the files beside
    /// the scene file), the same that the renderers' reference caches use.
    pub scene_hash: String,
    /// SHA-256 of its reference image.
    pub reference_hash: String,
}

impl PoolScene {
    /// The renderer command that loads it inside the renderer image.
    pub fn renderer_argv(&self) -> Vec<String> {
        let file = Path::new(SCENES_MOUNT).join(&self.rel).join(&self.meta.path);
        vec![format!("fbksd-{}", self.meta.renderer), normalize(&file).display().to_string()]
    }
}

/// Loads and hashes the scenes `dirs` (relative to `root`); each must have its reference.
pub fn load(root: &Path, dirs: &[String]) -> anyhow::Result<Vec<PoolScene>> {
    let mut scenes = Vec::new();
    for rel in dirs {
        let dir = root.join(rel);
        let meta = SceneMeta::load(&dir).map_err(|e| anyhow::anyhow!("scene pool: {e}"))?;
        let reference = meta.reference_file();
        let reference_bytes = std::fs::read(&reference).map_err(|e| {
            anyhow::anyhow!(
                "scene pool: {} has no reference ({e}); build it with: fbksd-{} reference {}",
                reference.display(),
                meta.renderer,
                dir.display()
            )
        })?;
        let scene_hash = fbksd_exchange::scenes::scene_digest(&meta.scene_file())?;
        scenes.push(PoolScene {
            rel: rel.clone(),
            scene_hash,
            reference_hash: format!("sha256:{:x}", Sha256::digest(&reference_bytes)),
            meta,
        });
    }
    if scenes.is_empty() {
        anyhow::bail!("scene pool: no scene under {}", root.display());
    }
    Ok(scenes)
}

/// `a/b/../c` → `a/c` (scene files of the small production scenes point into a sibling directory).
fn normalize(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for part in path.components() {
        match part {
            std::path::Component::ParentDir => {
                out.pop();
            }
            std::path::Component::CurDir => {}
            other => out.push(other),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn scene_paths_are_normalized_for_the_image() {
        let p = super::normalize(std::path::Path::new("/scenes/production-small/x/../../production/x/small.pbrt"));
        assert_eq!(p, std::path::Path::new("/scenes/production/x/small.pbrt"));
    }
}
