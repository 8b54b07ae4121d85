//! Image quality assessment for FBKSD: how far a technique's image is from
//! the reference.
//!
//! | acronym | metric | on | lower is better | error map (fixed scale) |
//! |---|---|---|---|---|
//! | `MSE` | mean of (t − r)² | linear HDR values | yes | per pixel, log₁₀ from 1e−4 to 1e2 |
//! | `rMSE` | mean of (t − r)² / (r² + ε), ε = 0.01 (Rousselle et al. 2011) | linear HDR values | yes | per pixel, log₁₀ from 1e−4 to 1e2 |
//! | `PSNR` | 10 log₁₀(255² / MSE₈), at most 100 dB | tone-mapped 8-bit range | no | — |
//! | `SSIM` | Wang et al. 2004, 11×11 Gaussian σ = 1.5, C1 = 6.5025, C2 = 58.5225 ([`ssim`]) | tone-mapped 8-bit range | no | 1 − S, linear 0 to 1 |
//! | `SMAPE` | mean of \|t − r\| / (\|t\| + \|r\| + ε), ε = 0.01 | linear HDR values | yes | per pixel, linear 0 to 1 |
//! | `FLIP` | LDR-ꟻLIP, Andersson et al. 2020 ([`flip`]) | linear values clamped to [0, 1] | yes | ꟻLIP per pixel, linear 0 to 1 |
//! | `HDR-FLIP` | HDR-ꟻLIP, Andersson et al. 2021: ACES, automatic exposures | linear HDR values | yes | ꟻLIP per pixel, linear 0 to 1 |
//!
//! Every mean runs over the three channels of every pixel. **Tone map**
//! (PSNR, SSIM): each channel clamped to [0, 1], the sRGB transfer curve,
//! times 255 — kept continuous (no rounding, and no value above 255, which
//! the original let through). **Colour**: channels are treated alike; no
//! luminance weighting. **Extremes**: a pixel with NaN or infinity in either
//! image is left out of the MSE, rMSE, SMAPE and PSNR means (SSIM's windows
//! read it as 0) and the number of such pixels per image is reported with
//! every value, so nothing non-finite reaches a mean unseen; black
//! reference pixels are handled by ε; PSNR of identical images is 100 dB,
//! not infinity; images smaller than the SSIM window use every pixel; sums
//! run in f64, per row then in row order, so values do not depend on the
//! thread count. Images are read from OpenEXR in full 32-bit float.
//!
//! ```
//! use fbksd_iqa::{evaluate, Metric, image::Image};
//! let reference = Image::new(2, 1, vec![0.5; 6]);
//! let test = Image::new(2, 1, vec![0.5, 0.5, 0.5, 0.7, 0.5, 0.5]);
//! let mse = evaluate(Metric::Mse, &reference, &test).unwrap();
//! assert!((mse.value - 0.04 / 6.0).abs() < 1e-9);
//! ```
#![deny(missing_docs)]

pub mod colormap;
pub mod external;
mod fastmath;
pub mod flip;
pub mod image;
mod pixelwise;
pub mod ssim;

pub use pixelwise::{tone_map, EPSILON};

use image::Image;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A built-in metric.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Metric {
    /// Mean squared error.
    Mse,
    /// Relative mean squared error.
    RelMse,
    /// Peak signal-to-noise ratio.
    Psnr,
    /// Structural similarity.
    Ssim,
    /// Symmetric mean absolute percentage error.
    Smape,
    /// LDR-ꟻLIP.
    Flip,
    /// HDR-ꟻLIP.
    HdrFlip,
}

/// What a metric is (shared with result uploads, hence defined with them).
pub use fbksd_exchange::MetricInfo;

impl Metric {
    /// Every built-in metric.
    pub const ALL: [Metric; 7] =
        [Metric::Mse, Metric::RelMse, Metric::Psnr, Metric::Ssim, Metric::Smape, Metric::Flip, Metric::HdrFlip];

    /// The metric's acronym.
    pub fn acronym(self) -> &'static str {
        match self {
            Metric::Mse => "MSE",
            Metric::RelMse => "rMSE",
            Metric::Psnr => "PSNR",
            Metric::Ssim => "SSIM",
            Metric::Smape => "SMAPE",
            Metric::Flip => "FLIP",
            Metric::HdrFlip => "HDR-FLIP",
        }
    }

    /// Looks a metric up by acronym (case-insensitive).
    pub fn from_acronym(name: &str) -> Option<Metric> {
        Metric::ALL.into_iter().find(|m| m.acronym().eq_ignore_ascii_case(name))
    }

    /// The metric's description.
    pub fn info(self) -> MetricInfo {
        let (name, reference) = match self {
            Metric::Mse => ("Mean squared error", ""),
            Metric::RelMse => ("Relative mean squared error", "Rousselle, Knaus and Zwicker 2011, Adaptive sampling and reconstruction using greedy error minimization"),
            Metric::Psnr => ("Peak signal-to-noise ratio", ""),
            Metric::Ssim => ("Structural similarity", "Wang, Bovik, Sheikh and Simoncelli 2004, Image quality assessment: from error visibility to structural similarity"),
            Metric::Smape => ("Symmetric mean absolute percentage error", ""),
            Metric::Flip => ("FLIP (LDR)", "Andersson, Nilsson, Akenine-Möller, Oskarsson, Åström and Fairchild 2020, FLIP: A Difference Evaluator for Alternating Images"),
            Metric::HdrFlip => ("FLIP (HDR)", "Andersson, Nilsson, Shirley and Akenine-Möller 2021, Visualizing Errors in Rendered High Dynamic Range Images"),
        };
        MetricInfo {
            acronym: self.acronym().into(),
            name: name.into(),
            reference: reference.into(),
            lower_is_better: !matches!(self, Metric::Psnr | Metric::Ssim),
            has_error_map: self != Metric::Psnr,
        }
    }

    /// How the metric's error map turns values into colours.
    pub fn map_scale(self) -> MapScale {
        match self {
            Metric::Mse | Metric::RelMse => MapScale::Log10 { min: -4.0, max: 2.0 },
            _ => MapScale::Linear { max: 1.0 },
        }
    }
}

/// A fixed mapping of error values to [0, 1] for colouring, the same for
/// every image, so maps of two techniques compare side by side.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum MapScale {
    /// `v / max`, clamped.
    Linear {
        /// The value drawn brightest.
        max: f32,
    },
    /// `(log₁₀ v − min) / (max − min)`, clamped (0 and below draw darkest).
    Log10 {
        /// log₁₀ of the value drawn darkest.
        min: f32,
        /// log₁₀ of the value drawn brightest.
        max: f32,
    },
}

impl MapScale {
    /// Position of `v` on the colour map, in [0, 1] (NaN stays NaN; +∞ is 1).
    pub fn position(self, v: f32) -> f32 {
        if v.is_nan() {
            return f32::NAN;
        }
        match self {
            MapScale::Linear { max } => (v / max).clamp(0.0, 1.0),
            MapScale::Log10 { min, max } => {
                if v <= 0.0 {
                    0.0
                } else {
                    // log₁₀ from the vectorising log₂ (within 1e−7): maps colour millions of values.
                    let log10 = fastmath::log2(v) * std::f32::consts::LOG10_2;
                    ((log10 - min) / (max - min)).clamp(0.0, 1.0)
                }
            }
        }
    }
}

/// A per-pixel error image.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorMap {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// One value per pixel; NaN where the pixel has no value.
    pub values: Vec<f32>,
    /// How values become colours.
    pub scale: MapScale,
}

impl ErrorMap {
    /// Writes the map as a PNG in the error colour map.
    pub fn write_png(&self, path: &Path) -> std::io::Result<()> {
        use ::image::codecs::png::{CompressionType, FilterType, PngEncoder};
        use ::image::ImageEncoder;
        // Row by row into one buffer: a flat_map's collect cost more than the colours.
        let width = (self.width as usize).max(1);
        let mut bytes = vec![0u8; self.values.len() * 3];
        bytes.par_chunks_mut(width * 3).zip(self.values.par_chunks(width)).for_each(|(out, values)| {
            for (rgb, v) in out.chunks_exact_mut(3).zip(values) {
                rgb.copy_from_slice(&colormap::color(self.scale.position(*v)));
            }
        });
        let fail = |e: &dyn std::fmt::Display| std::io::Error::other(format!("{}: {e}", path.display()));
        let file = std::io::BufWriter::new(std::fs::File::create(path).map_err(|e| fail(&e))?);
        // Fast compression: a runner writes six maps per run, and the default
        // level spends most of their time for a few per cent of size.
        PngEncoder::new_with_quality(file, CompressionType::Fast, FilterType::Adaptive)
            .write_image(&bytes, self.width, self.height, ::image::ExtendedColorType::Rgb8)
            .map_err(|e| fail(&e))
    }
}

/// The value of a metric on a pair of images.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    /// The value.
    pub value: f64,
    /// The error map, for metrics that have one.
    pub map: Option<ErrorMap>,
    /// Pixels with NaN or infinity in the reference.
    pub nonfinite_reference: u64,
    /// Pixels with NaN or infinity in the test image.
    pub nonfinite_test: u64,
}

/// What a metric's value file (`--value-file`, `<spp>_0_<METRIC>.json`) holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValueRecord {
    /// The metric's acronym.
    pub metric: String,
    /// The value.
    pub value: f64,
    /// Pixels with NaN or infinity in the reference.
    #[serde(default)]
    pub nonfinite_reference: u64,
    /// Pixels with NaN or infinity in the test image.
    #[serde(default)]
    pub nonfinite_test: u64,
}

/// Why a metric could not be computed.
#[derive(Debug, thiserror::Error)]
pub enum IqaError {
    /// The images differ in size.
    #[error("the images differ in size: reference {0}×{1}, test {2}×{3}")]
    SizeMismatch(u32, u32, u32, u32),
    /// An image has no pixel.
    #[error("the images are empty")]
    Empty,
    /// No pixel is finite in both images.
    #[error("no pixel is finite in both images ({0} non-finite in the reference, {1} in the test image)")]
    NothingFinite(u64, u64),
    /// Reading or writing failed.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// An external metric failed.
    #[error("{0}")]
    External(String),
}

/// The image's values with NaN and infinity read as 0, copied only when
/// `nonfinite` says there are any.
fn finite_or_zero(img: &Image, nonfinite: u64) -> std::borrow::Cow<'_, [f32]> {
    if nonfinite == 0 {
        std::borrow::Cow::Borrowed(&img.rgb)
    } else {
        img.rgb.iter().map(|v| if v.is_finite() { *v } else { 0.0 }).collect::<Vec<f32>>().into()
    }
}

/// A reference image and what the metrics derive from it alone (ꟻLIP's
/// filtered reference at each exposure), made at most once and reused for
/// every test image scored against it: a runner scoring many runs of a
/// scene holds one per scene.
pub struct Reference<'a> {
    image: std::borrow::Cow<'a, Image>,
    nonfinite: std::sync::OnceLock<u64>,
    flip_ldr: std::sync::OnceLock<flip::FlipReference>,
    flip_hdr: std::sync::OnceLock<flip::FlipReference>,
}

impl<'a> Reference<'a> {
    /// A reference that owns its image.
    pub fn new(image: Image) -> Reference<'static> {
        Reference::from_cow(std::borrow::Cow::Owned(image))
    }

    /// A reference that borrows its image.
    pub fn borrowed(image: &'a Image) -> Reference<'a> {
        Reference::from_cow(std::borrow::Cow::Borrowed(image))
    }

    fn from_cow(image: std::borrow::Cow<'a, Image>) -> Reference<'a> {
        Reference { image, nonfinite: Default::default(), flip_ldr: Default::default(), flip_hdr: Default::default() }
    }

    /// The image.
    pub fn image(&self) -> &Image {
        &self.image
    }

    /// Makes now what `metric` derives from the reference alone (otherwise
    /// made by its first evaluation).
    pub fn prepare(&self, metric: Metric) {
        if matches!(metric, Metric::Flip | Metric::HdrFlip) {
            self.flip(metric);
        }
    }

    fn nonfinite(&self) -> u64 {
        *self.nonfinite.get_or_init(|| pixelwise::nonfinite_pixels(&self.image))
    }

    /// ꟻLIP's prepared reference: non-finite values read as 0.
    fn flip(&self, metric: Metric) -> &flip::FlipReference {
        let make = || {
            let r = finite_or_zero(&self.image, self.nonfinite());
            let (w, h) = (self.image.width as usize, self.image.height as usize);
            if metric == Metric::Flip {
                flip::FlipReference::ldr(&r, w, h, flip::default_ppd())
            } else {
                flip::FlipReference::hdr(&r, w, h, flip::default_ppd())
            }
        };
        if metric == Metric::Flip {
            self.flip_ldr.get_or_init(make)
        } else {
            self.flip_hdr.get_or_init(make)
        }
    }
}

/// Computes a built-in metric.
pub fn evaluate(metric: Metric, reference: &Image, test: &Image) -> Result<Evaluation, IqaError> {
    evaluate_against(metric, &Reference::borrowed(reference), test)
}

/// Computes a built-in metric against a [`Reference`], reusing what it
/// already derived.
pub fn evaluate_against(metric: Metric, reference: &Reference<'_>, test: &Image) -> Result<Evaluation, IqaError> {
    let prepared = reference;
    let reference = prepared.image();
    if (reference.width, reference.height) != (test.width, test.height) {
        return Err(IqaError::SizeMismatch(reference.width, reference.height, test.width, test.height));
    }
    if reference.pixels() == 0 {
        return Err(IqaError::Empty);
    }
    if matches!(metric, Metric::Flip | Metric::HdrFlip) {
        let nonfinite_reference = prepared.nonfinite();
        let nonfinite_test = pixelwise::nonfinite_pixels(test);
        // ꟻLIP filters the whole image: non-finite values read as 0 (and are
        // counted); copied only when there are any.
        let t = finite_or_zero(test, nonfinite_test);
        let w = reference.width as usize;
        let values = prepared.flip(metric).map(&t);
        let rows: Vec<f64> = values.par_chunks(w).map(|row| row.iter().map(|v| *v as f64).sum()).collect();
        let value = rows.iter().sum::<f64>() / values.len() as f64;
        let map = ErrorMap { width: reference.width, height: reference.height, values, scale: metric.map_scale() };
        return Ok(Evaluation { value, map: Some(map), nonfinite_reference, nonfinite_test });
    }
    if metric == Metric::Ssim {
        let (nonfinite_reference, nonfinite_test) = pixelwise::count_nonfinite(reference, test);
        let (value, map) = ssim::ssim(reference, test);
        let map = ErrorMap { width: reference.width, height: reference.height, values: map, scale: metric.map_scale() };
        return Ok(Evaluation { value, map: Some(map), nonfinite_reference, nonfinite_test });
    }
    // One call per error function, not through a fn pointer: each is
    // inlined into its own copy of the loop (a call per value cost more
    // than the arithmetic).
    let mean = match metric {
        Metric::Mse => pixelwise::pixel_mean(reference, test, pixelwise::squared),
        Metric::RelMse => pixelwise::pixel_mean(reference, test, pixelwise::relative_squared),
        Metric::Smape => pixelwise::pixel_mean(reference, test, pixelwise::symmetric_absolute),
        Metric::Psnr | Metric::Ssim | Metric::Flip | Metric::HdrFlip => {
            pixelwise::pixel_mean(reference, test, pixelwise::tone_mapped_squared)
        }
    };
    if mean.counted == 0 {
        return Err(IqaError::NothingFinite(mean.nonfinite_reference, mean.nonfinite_test));
    }
    let (value, values) = match metric {
        Metric::Psnr => {
            // MSE below 255²·1e−10 (identical images) reads 100 dB, not infinity.
            let psnr =
                if mean.mean <= 255.0 * 255.0 * 1e-10 { 100.0 } else { 10.0 * (255.0 * 255.0 / mean.mean).log10() };
            (psnr.min(100.0), None)
        }
        _ => (mean.mean, Some(mean.map)),
    };
    Ok(Evaluation {
        value,
        map: values.map(|values| ErrorMap {
            width: reference.width,
            height: reference.height,
            values,
            scale: metric.map_scale(),
        }),
        nonfinite_reference: mean.nonfinite_reference,
        nonfinite_test: mean.nonfinite_test,
    })
}
