//! The runner's scene pool: the scenes it benchmarks on, with their
//! references and feature buffers, made where missing ([`make_missing_references`], with the
//! renderer programs next to the runner or on PATH; the server is told of
//! the progress) and checked and hashed once when the runner starts.
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

/// Makes the references of the scenes `dirs` (relative to `root`) that
/// have none, one after another, telling the server which one and at what
/// budget every few seconds (it shows this while jobs wait).
pub async fn make_missing_references(
    root: &Path,
    dirs: &[String],
    api: &crate::api::Api,
    runner_token: &str,
) -> anyhow::Result<()> {
    let mut missing = Vec::new();
    let mut kept = Vec::new();
    for rel in dirs {
        let meta = SceneMeta::load(&root.join(rel)).map_err(|e| anyhow::anyhow!("scene pool: {e}"))?;
        if meta.reference_file().is_file() {
            kept.push((rel, meta));
        } else {
            missing.push((rel, meta));
        }
    }
    // A kept reference is still handed to its renderer, which keeps it when
    // it is current and makes only the feature buffers it lacks.
    for (rel, meta) in &kept {
        let program = fbksd_exchange::scenes::renderer_program(&meta.renderer)
            .map_err(|e| anyhow::anyhow!("scene pool: the reference of {rel}: {e}"))?;
        let exit = tokio::process::Command::new(&program).arg("reference").arg(root.join(rel)).status().await?;
        if !exit.success() {
            anyhow::bail!("scene pool: {} reference {} failed ({exit})", program.display(), root.join(rel).display());
        }
    }
    for (i, (rel, meta)) in missing.iter().enumerate() {
        let budget = match &meta.reference {
            fbksd_exchange::scenes::ReferenceMethod::Render { spp } => format!("{spp} spp"),
            fbksd_exchange::scenes::ReferenceMethod::ClosedForm { formula } => format!("closed form {formula}"),
        };
        let status = format!(
            "making reference {} of {}: {rel} ({}×{}, {budget})",
            i + 1,
            missing.len(),
            meta.width,
            meta.height
        );
        tracing::info!("{status}");
        let program = fbksd_exchange::scenes::renderer_program(&meta.renderer)
            .map_err(|e| anyhow::anyhow!("scene pool: the reference of {rel}: {e}"))?;
        let mut child = tokio::process::Command::new(&program)
            .arg("reference")
            .arg(root.join(rel))
            .kill_on_drop(true)
            .spawn()
            .map_err(|e| anyhow::anyhow!("scene pool: {}: {e}", program.display()))?;
        let exit = loop {
            if let Err(e) = api.status(runner_token, Some(&status)).await {
                tracing::warn!("telling the server what this runner prepares: {e}");
            }
            tokio::select! {
                exit = child.wait() => break exit?,
                () = tokio::time::sleep(std::time::Duration::from_secs(5)) => {}
            }
        };
        if !exit.success() {
            anyhow::bail!("scene pool: {} reference {} failed ({exit})", program.display(), root.join(rel).display());
        }
    }
    Ok(())
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
