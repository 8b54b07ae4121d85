//! Reference images of production scenes, built by
//! `fbksd-embree reference <dir>` and cached beside the scene (not
//! committed), with a `reference.json` convergence note.
//!
//! The reference is the box filter of `spp` stratified samples per pixel
//! (the metadata's `render` method), rendered as two independent halves;
//! the note gives the estimated RMS error of their mean, `rms(a − b) / 2`,
//! beside the mean pixel value to read it against. A cached reference is
//! rebuilt when the renderer version, the spp or the scene's files change
//! (the rule every renderer shares:
//! [`fbksd_exchange::scenes::current_reference_note`]). Beside it go the
//! scene's feature buffers (albedo, normal, depth), which the results
//! viewer shows.

use crate::render::{render_features, render_image};
use anyhow::{bail, Context};
use fbksd_core::Feature;
pub use fbksd_exchange::scenes::{ReferenceMethod, SceneMeta};
use fbksd_exchange::scenes::{FEATURE_BUFFERS, FEATURE_BUFFER_SPP};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// What `reference.json` records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReferenceNote {
    /// Samples per pixel used.
    pub samples_per_pixel: u64,
    /// Estimated RMS error of the reference.
    pub estimated_error: f64,
    /// Mean pixel value.
    pub mean_value: f64,
    /// Seconds it took.
    pub seconds: f64,
    /// Non-finite sample values replaced (should be 0).
    pub repaired_samples: u64,
    /// What made it; a reference made by another version is rebuilt.
    pub generator: String,
    /// The scene's digest ([`fbksd_exchange::scenes::scene_digest`]); a
    /// reference of other scene files is rebuilt.
    #[serde(default)]
    pub scene_digest: String,
}

/// Bumped whenever rendering changes what a converged image is.
pub const RENDERER_VERSION: u32 = 3;

fn generator() -> String {
    format!("fbksd-embree {}, renderer {RENDERER_VERSION}", env!("CARGO_PKG_VERSION"))
}

impl std::fmt::Display for ReferenceNote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} spp, estimated RMS error {:.3e} (mean value {:.4}, {:.2}% of it), {:.1} s",
            self.samples_per_pixel,
            self.estimated_error,
            self.mean_value,
            100.0 * self.estimated_error / self.mean_value.max(1e-30),
            self.seconds
        )
    }
}

/// Builds (or keeps) a scene's reference; returns its note.
pub fn build(meta: &SceneMeta, force: bool, spp_override: Option<u64>) -> anyhow::Result<ReferenceNote> {
    let out = meta.reference_file();
    let note_file = meta.reference_note_file();
    let (spp, digest) = recipe(meta, spp_override)?;
    if !force {
        if let Some(text) = fbksd_exchange::scenes::current_reference_note(meta, &generator(), spp, &digest)? {
            if FEATURE_BUFFERS.iter().any(|name| !meta.feature_buffer_file(name).is_file()) {
                let scene = crate::pbrt::load(&meta.scene_file()).with_context(|| format!("loading {}", meta.name))?;
                write_feature_buffers(meta, &scene)?;
            }
            return Ok(serde_json::from_str(&text)?);
        }
    }
    let scene = crate::pbrt::load(&meta.scene_file()).with_context(|| format!("loading {}", meta.name))?;
    if (scene.width(), scene.height()) != (meta.width, meta.height) {
        bail!(
            "{}: metadata says {}×{} but the scene file says {}×{}",
            meta.name,
            meta.width,
            meta.height,
            scene.width(),
            scene.height()
        );
    }
    let started = Instant::now();
    let a = render_image(&scene, spp / 2, 1_000_001);
    let b = render_image(&scene, spp - spp / 2, 1_000_002);
    let w = (spp / 2) as f64 / spp as f64;
    let image: Vec<f32> =
        a.rgb.iter().zip(&b.rgb).map(|(a, b)| (*a as f64 * w + *b as f64 * (1.0 - w)) as f32).collect();
    let rms =
        (a.rgb.iter().zip(&b.rgb).map(|(a, b)| ((a - b) as f64).powi(2)).sum::<f64>() / a.rgb.len() as f64).sqrt();
    let mean_value = image.iter().map(|v| *v as f64).sum::<f64>() / image.len() as f64;
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    fbksd_iqa::image::write_exr(&out, scene.width(), scene.height(), &image)?;
    let note = ReferenceNote {
        samples_per_pixel: spp,
        estimated_error: rms / 2.0,
        mean_value,
        seconds: started.elapsed().as_secs_f64(),
        repaired_samples: a.repairs + b.repairs,
        generator: generator(),
        scene_digest: digest,
    };
    write_feature_buffers(meta, &scene)?;
    std::fs::write(&note_file, serde_json::to_vec_pretty(&note)?)?;
    Ok(note)
}

/// What a scene's reference is made with: samples per pixel and the scene digest.
fn recipe(meta: &SceneMeta, spp_override: Option<u64>) -> anyhow::Result<(u64, String)> {
    let ReferenceMethod::Render { spp } = meta.reference else {
        bail!("{}: the Embree renderer makes references by rendering (\"method\": \"render\")", meta.name);
    };
    Ok((spp_override.unwrap_or(spp).max(2), fbksd_exchange::scenes::scene_digest(&meta.scene_file())?))
}

/// The key ([`fbksd_exchange::scenes::reference_key`]) of the reference
/// [`build`] makes, without making it.
pub fn key(meta: &SceneMeta, spp_override: Option<u64>) -> anyhow::Result<String> {
    let (spp, digest) = recipe(meta, spp_override)?;
    Ok(fbksd_exchange::scenes::reference_key(&generator(), spp, &digest))
}

/// Writes the feature buffers of [`FEATURE_BUFFERS`] (the mean of
/// [`FEATURE_BUFFER_SPP`] samples per pixel of the first hit's albedo,
/// normal and depth; depth repeated in r, g and b).
fn write_feature_buffers(meta: &SceneMeta, scene: &crate::scene::Scene) -> anyhow::Result<()> {
    use Feature::*;
    for name in FEATURE_BUFFERS {
        let wanted = match name {
            "albedo" => [(TextureColorR, 0), (TextureColorG, 0), (TextureColorB, 0)],
            "normal" => [(NormalX, 0), (NormalY, 0), (NormalZ, 0)],
            _ => [(Depth, 0); 3],
        };
        let image = render_features(scene, FEATURE_BUFFER_SPP, 1_000_003, wanted);
        fbksd_iqa::image::write_exr(&meta.feature_buffer_file(name), scene.width(), scene.height(), &image)?;
    }
    Ok(())
}
