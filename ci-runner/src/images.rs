//! The images a runner uses, from the manifest `deploy/build-images.sh`
//! writes: `{"base": tag, "cpp": tag, "python": tag, "renderer": tag}`.
//! Tags are derived from the images' content; the runner resolves each to
//! its image id (a content digest) and records that in every result.

use bollard::Docker;
use fbksd_exchange::technique::Environment;
use serde::Deserialize;
use std::path::Path;

/// One image: the tag it was asked for and the id Docker holds for it.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// `name:content-hash`.
    pub tag: String,
    /// `sha256:…`, the image's content digest on this engine.
    pub id: String,
}

/// The environment images and the trusted renderer image.
#[derive(Debug, Clone)]
pub struct Images {
    /// gcc, CMake and the C/C++ SDK.
    pub cpp: Image,
    /// Python 3, numpy and the Python SDK.
    pub python: Image,
    /// The built-in renderers and the scene files (no references).
    pub renderer: Image,
}

#[derive(Deserialize)]
struct Manifest {
    cpp: String,
    python: String,
    renderer: String,
}

impl Images {
    /// Reads the manifest and checks that every image is on the engine.
    pub async fn resolve(manifest: &Path, docker: &Docker) -> anyhow::Result<Images> {
        let text = std::fs::read_to_string(manifest).map_err(|e| {
            anyhow::anyhow!(
                "image manifest {}: {e} (build the images: bash deploy/build-images.sh)",
                manifest.display()
            )
        })?;
        let m: Manifest =
            serde_json::from_str(&text).map_err(|e| anyhow::anyhow!("image manifest {}: {e}", manifest.display()))?;
        let resolve = |tag: String| async move {
            match docker.inspect_image(&tag).await {
                Ok(image) => Ok(Image { id: image.id.unwrap_or_default(), tag }),
                Err(e) => Err(anyhow::anyhow!(
                    "image {tag} is not on this Docker engine ({e}): build it with bash deploy/build-images.sh"
                )),
            }
        };
        Ok(Images {
            cpp: resolve(m.cpp).await?,
            python: resolve(m.python).await?,
            renderer: resolve(m.renderer).await?,
        })
    }

    /// The image that builds and runs a technique of `environment`.
    pub fn for_environment(&self, environment: Environment) -> &Image {
        match environment {
            Environment::Cpp => &self.cpp,
            Environment::Python => &self.python,
        }
    }
}
