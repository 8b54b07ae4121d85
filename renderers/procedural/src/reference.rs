//! Reference images of procedural scenes.
//!
//! A scene directory's `fbksd-scene.json` (see [`fbksd_exchange::scenes`])
//! says how its reference is made. References are built by
//! `fbksd-procedural reference <dir>`, cached beside the scene (not
//! committed) and rebuilt when the sampler, the budget or the scene's files
//! change, with a `reference.json` note saying how converged they are:
//!
//! - `render`: the box filter of `spp` stratified samples per pixel, as two
//!   independent halves; the note gives the estimated RMS error of their
//!   mean, `rms(a − b) / 2`.
//! - `closed_form`: a formula known here by name, exact in every dimension
//!   but the pixel area, which is integrated by midpoint quadrature; the note
//!   gives the largest change between `q` and `2q` points per side.
//!
//! Beside it go the feature buffers the scene's program assigns (albedo,
//! normal, depth), which the results viewer shows.

use crate::render::{render_features, render_image, Sampler, Strata};
use crate::Scene;
use anyhow::bail;
use fbksd_core::Feature;
pub use fbksd_exchange::scenes::{ReferenceMethod, SceneMeta};
use fbksd_exchange::scenes::{FEATURE_BUFFERS, FEATURE_BUFFER_SPP};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// What `reference.json` records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReferenceNote {
    /// The method, as in the metadata.
    pub method: ReferenceMethod,
    /// Samples per pixel used (render) or quadrature points per pixel side (closed form).
    pub samples_per_pixel: u64,
    /// Estimated RMS error of the reference (render) or largest quadrature change (closed form).
    pub estimated_error: f64,
    /// Mean pixel value, to read the error against.
    pub mean_value: f64,
    /// Seconds it took.
    pub seconds: f64,
    /// What made it: `fbksd-procedural <version>, sampler <n>`. A reference
    /// made by another sampler is rebuilt.
    #[serde(default)]
    pub generator: String,
    /// The scene's digest ([`fbksd_exchange::scenes::scene_digest`]); a
    /// reference of other scene files is rebuilt.
    #[serde(default)]
    pub scene_digest: String,
}

fn generator() -> String {
    format!("fbksd-procedural {}, sampler {}", env!("CARGO_PKG_VERSION"), crate::render::SAMPLER_VERSION)
}

impl std::fmt::Display for ReferenceNote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.method {
            ReferenceMethod::Render { .. } => write!(
                f,
                "{} spp, estimated RMS error {:.3e} (mean value {:.4}), {:.1} s",
                self.samples_per_pixel, self.estimated_error, self.mean_value, self.seconds
            ),
            ReferenceMethod::ClosedForm { formula } => write!(
                f,
                "closed form {formula}, {}² quadrature points per pixel at kinks (1/64 of that elsewhere), largest change vs half as many {:.3e} (mean value {:.4}), {:.1} s",
                self.samples_per_pixel, self.estimated_error, self.mean_value, self.seconds
            ),
        }
    }
}

/// Builds (or keeps, by the shared rule of
/// [`fbksd_exchange::scenes::current_reference_note`]) a scene's reference;
/// returns its note.
pub fn build(meta: &SceneMeta, force: bool, spp_override: Option<u64>) -> anyhow::Result<ReferenceNote> {
    let out = meta.reference_file();
    let note_file = meta.reference_note_file();
    let (samples_per_pixel, digest) = recipe(meta, spp_override)?;
    if !force {
        if let Some(text) =
            fbksd_exchange::scenes::current_reference_note(meta, &generator(), samples_per_pixel, &digest)?
        {
            if feature_buffers_missing(meta) {
                let scene = Scene::load(&meta.scene_file()).map_err(anyhow::Error::msg)?;
                write_feature_buffers(meta, &scene)?;
            }
            return Ok(serde_json::from_str(&text)?);
        }
    }
    let scene = Scene::load(&meta.scene_file()).map_err(anyhow::Error::msg)?;
    if (scene.width, scene.height) != (meta.width, meta.height) {
        bail!(
            "{}: metadata says {}×{} but the scene file says {}×{}",
            meta.name,
            meta.width,
            meta.height,
            scene.width,
            scene.height
        );
    }
    let started = Instant::now();
    let (image, samples_per_pixel, estimated_error) = match &meta.reference.clone() {
        ReferenceMethod::Render { .. } => {
            let spp = samples_per_pixel;
            let a = render_image(&scene, spp / 2, 1_000_001).map_err(anyhow::Error::msg)?;
            let b = render_image(&scene, spp - spp / 2, 1_000_002).map_err(anyhow::Error::msg)?;
            let w = (spp / 2) as f64 / spp as f64;
            let mean: Vec<f32> =
                a.iter().zip(&b).map(|(a, b)| (*a as f64 * w + *b as f64 * (1.0 - w)) as f32).collect();
            let rms = (a.iter().zip(&b).map(|(a, b)| ((a - b) as f64).powi(2)).sum::<f64>() / a.len() as f64).sqrt();
            (mean, spp, rms / 2.0)
        }
        ReferenceMethod::ClosedForm { formula } => {
            let q = samples_per_pixel as u32;
            let fine = closed_form(formula, &scene, q)?;
            let coarse = closed_form(formula, &scene, q / 2)?;
            let change = fine.iter().zip(&coarse).map(|(a, b)| (a - b).abs() as f64).fold(0.0, f64::max);
            (fine, q as u64, change)
        }
    };
    let mean_value = image.iter().map(|v| *v as f64).sum::<f64>() / image.len() as f64;
    fbksd_iqa::image::write_exr(&out, scene.width, scene.height, &image)?;
    let note = ReferenceNote {
        method: meta.reference.clone(),
        samples_per_pixel,
        estimated_error,
        mean_value,
        seconds: started.elapsed().as_secs_f64(),
        generator: generator(),
        scene_digest: digest,
    };
    write_feature_buffers(meta, &scene)?;
    std::fs::write(&note_file, serde_json::to_vec_pretty(&note)?)?;
    Ok(note)
}

/// What a scene's reference is made with: samples per pixel (quadrature
/// points per side for a closed form) and the scene digest.
fn recipe(meta: &SceneMeta, spp_override: Option<u64>) -> anyhow::Result<(u64, String)> {
    let samples_per_pixel = match &meta.reference {
        ReferenceMethod::Render { spp } => spp_override.unwrap_or(*spp).max(2),
        ReferenceMethod::ClosedForm { .. } => spp_override.unwrap_or(256),
    };
    Ok((samples_per_pixel, fbksd_exchange::scenes::scene_digest(&meta.scene_file())?))
}

/// The key ([`fbksd_exchange::scenes::reference_key`]) of the reference
/// [`build`] makes, without making it.
pub fn key(meta: &SceneMeta, spp_override: Option<u64>) -> anyhow::Result<String> {
    let (samples_per_pixel, digest) = recipe(meta, spp_override)?;
    Ok(fbksd_exchange::scenes::reference_key(&generator(), samples_per_pixel, &digest))
}

/// The features of each buffer of [`fbksd_exchange::scenes::FEATURE_BUFFERS`]
/// (depth repeated in r, g and b, so it shows grey).
fn buffer_features(name: &str) -> [(Feature, u8); 3] {
    match name {
        "albedo" => [(Feature::TextureColorR, 0), (Feature::TextureColorG, 0), (Feature::TextureColorB, 0)],
        "normal" => [(Feature::NormalX, 0), (Feature::NormalY, 0), (Feature::NormalZ, 0)],
        _ => [(Feature::Depth, 0); 3],
    }
}

/// Whether a buffer the scene's program assigns has no file yet (a
/// reference cached before buffers were made).
fn feature_buffers_missing(meta: &SceneMeta) -> bool {
    FEATURE_BUFFERS.iter().any(|name| !meta.feature_buffer_file(name).is_file())
        && Scene::load(&meta.scene_file()).is_ok_and(|scene| {
            FEATURE_BUFFERS.iter().any(|name| {
                !meta.feature_buffer_file(name).is_file()
                    && buffer_features(name).iter().any(|(f, n)| scene.program.feature_slot(*f, *n).is_some())
            })
        })
}

/// Writes the feature buffers the scene's program assigns (mean of
/// [`FEATURE_BUFFER_SPP`] samples per pixel) and removes any other left
/// from an earlier version of the scene.
fn write_feature_buffers(meta: &SceneMeta, scene: &Scene) -> anyhow::Result<()> {
    for name in FEATURE_BUFFERS {
        let file = meta.feature_buffer_file(name);
        let wanted = buffer_features(name);
        if !wanted.iter().any(|(f, n)| scene.program.feature_slot(*f, *n).is_some()) {
            let _ = std::fs::remove_file(&file);
            continue;
        }
        let image = render_features(scene, FEATURE_BUFFER_SPP, 1_000_003, &wanted).map_err(anyhow::Error::msg)?;
        fbksd_iqa::image::write_exr(&file, scene.width, scene.height, &image)?;
    }
    Ok(())
}

/// A named closed form, integrated over each pixel by `q × q` midpoint
/// quadrature where the integrand has a kink and `q/8 × q/8` (at least
/// 4 × 4) where it is smooth.
pub fn closed_form(formula: &str, scene: &Scene, q: u32) -> anyhow::Result<Vec<f32>> {
    use rayon::prelude::*;
    let (w, h) = (scene.width as f64, scene.height as f64);
    // Each formula: the expectation over every dimension but (X, Y), and
    // whether a pixel may hold a kink (needs the fine quadrature).
    type Formula = Box<dyn Fn(f64, f64) -> [f64; 3] + Sync>;
    let (f, kinky): (Formula, Box<dyn Fn(f64, f64) -> bool + Sync>) = match formula {
        // Listing C.1: inside the ball (u−½)² + (v−½)² + (t−½)² ≤ ¼ for t
        // uniform in [0, 1): a chord of length 2√(¼ − ρ²).
        "sphere_time" => (
            Box::new(move |x, y| {
                let rho2 = (x / w - 0.5).powi(2) + (y / h - 0.5).powi(2);
                let v = 2.0 * (0.25 - rho2).max(0.0).sqrt();
                [v, v, v]
            }),
            Box::new(move |x, y| {
                let near = |px: f64, py: f64| (((px / w - 0.5).powi(2) + (py / h - 0.5).powi(2)) - 0.25).abs();
                near(x + 0.5, y + 0.5) < 2.0 / w.min(h)
            }),
        ),
        // fireflies.expr: base glow plus, with probability p(x, y), a spike of
        // 1000: the expectation is base + 1000 p.
        "fireflies" => (
            Box::new(move |x, y| {
                let (u, v) = (x / w, y / h);
                let base = 0.05 + 0.25 * u;
                let r2 = (u - 0.5).powi(2) + (v - 0.5).powi(2);
                let p = 0.002 * (-r2 / 0.02).exp();
                let e = base + 1000.0 * p;
                [e, e * 0.8, e * 0.6]
            }),
            Box::new(|_, _| false),
        ),
        other => bail!("unknown closed form {other:?} (sphere_time, fireflies)"),
    };
    let (iw, ih) = (scene.width as usize, scene.height as usize);
    let mut image = vec![0f32; iw * ih * 3];
    image.par_chunks_mut(iw * 3).enumerate().for_each(|(y, row)| {
        for x in 0..iw {
            let (px, py) = (x as f64, y as f64);
            let n = if kinky(px, py) { q.max(8) } else { (q / 8).max(4) };
            let mut sum = [0.0f64; 3];
            for j in 0..n {
                for i in 0..n {
                    let v = f(px + (i as f64 + 0.5) / n as f64, py + (j as f64 + 0.5) / n as f64);
                    for c in 0..3 {
                        sum[c] += v[c];
                    }
                }
            }
            for c in 0..3 {
                row[x * 3 + c] = (sum[c] / (n * n) as f64) as f32;
            }
        }
    });
    Ok(image)
}

/// Prints samples per second for listing C.1 and the Mandelbrot scene, on
/// one thread and on all cores.
pub fn bench(scenes: &Path) -> anyhow::Result<()> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    for (name, spp) in [("sphere", 64u64), ("mandelbrot", 16)] {
        let meta = SceneMeta::load(&scenes.join(name))?;
        let scene = Scene::load(&meta.scene_file()).map_err(anyhow::Error::msg)?;
        let samples = scene.width as f64 * scene.height as f64 * spp as f64;
        let mut line = format!("{name:<11} {}×{} × {spp} spp:", scene.width, scene.height);
        for threads in [1, cores] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
            // Best of three: the figure a quiet machine gives.
            let best = (0..3)
                .map(|i| {
                    let t = Instant::now();
                    pool.install(|| render_image(&scene, spp, i)).map_err(anyhow::Error::msg)?;
                    Ok(t.elapsed().as_secs_f64())
                })
                .collect::<anyhow::Result<Vec<f64>>>()?
                .into_iter()
                .fold(f64::INFINITY, f64::min);
            line += &format!(
                "  {:6.1} M samples/s on {threads} thread{}",
                samples / best / 1e6,
                if threads == 1 { "" } else { "s" }
            );
        }
        println!("{line}");
    }
    println!("(sample generation included; colour only; {cores} cores; target ≥ 25 M samples/s per thread)");
    // The sampler alone, one thread: a pixel's samples in batches (as
    // rendering draws them) against one at a time (the same values).
    let (w, h, spp) = (500u32, 500u32, 64u64);
    let sampler = Sampler::new(w, h, 0);
    let strata = Strata::new(spp);
    let needed = 0b1_0011; // IMAGE_X, IMAGE_Y and TIME, as listing C.1
    let mut batch = vec![[0.0f64; 7]; spp as usize];
    let time = |f: &mut dyn FnMut(u32, u32)| {
        (0..3)
            .map(|_| {
                let t = Instant::now();
                for y in 0..h {
                    for x in 0..w {
                        f(x, y);
                    }
                }
                t.elapsed().as_secs_f64()
            })
            .fold(f64::INFINITY, f64::min)
    };
    let mut sink = 0.0;
    let batched = time(&mut |x, y| {
        sampler.pixel_samples(&sampler.pixel(x, y), &strata, 0, needed, &mut batch);
        sink += batch[3][0];
    });
    let single = time(&mut |x, y| {
        let pixel = sampler.pixel(x, y);
        for s in 0..spp {
            sink += sampler.pixel_sample(&pixel, &strata, s, needed)[0];
        }
    });
    let per_second = |t: f64| (w * h) as f64 * spp as f64 / t / 1e6;
    println!(
        "sampler alone, 1 thread: {:.1} M samples/s in batches, {:.1} M samples/s one at a time ({:.1}×){}",
        per_second(batched),
        per_second(single),
        single / batched,
        // Printing depends on the sums, so neither loop is optimised away.
        if sink.is_nan() { " " } else { "" }
    );
    Ok(())
}
