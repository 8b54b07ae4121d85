//! Metrics that are a mean of a per-pixel error: MSE, relative MSE, SMAPE,
//! and the tone-mapped MSE behind PSNR.
//!
//! A pixel with a NaN or infinite channel in either image is left out of the
//! mean (and drawn as "no value" in the map); how many were left out, per
//! image, is reported with the value. Sums are per row in f64, then added in
//! row order, so a value does not depend on the number of threads.

use crate::image::Image;
use rayon::prelude::*;

/// The outcome of a per-pixel metric.
pub(crate) struct PixelMean {
    /// Mean over finite pixels and channels.
    pub mean: f64,
    /// Per-pixel mean over channels; NaN where a pixel was left out.
    pub map: Vec<f32>,
    /// Pixels with a non-finite channel in the reference.
    pub nonfinite_reference: u64,
    /// Pixels with a non-finite channel in the test image.
    pub nonfinite_test: u64,
    /// Pixels that entered the mean.
    pub counted: u64,
}

#[derive(Default, Clone, Copy)]
struct RowSum {
    sum: f64,
    counted: u64,
    nonfinite_reference: u64,
    nonfinite_test: u64,
}

/// Mean of `error(test, reference)` over every channel of every finite pixel.
pub(crate) fn pixel_mean(reference: &Image, test: &Image, error: impl Fn(f64, f64) -> f64 + Sync) -> PixelMean {
    let w = reference.width as usize;
    let mut map = vec![0f32; reference.pixels()];
    let rows: Vec<RowSum> = map
        .par_chunks_mut(w.max(1))
        .enumerate()
        .map(|(y, map_row)| {
            let mut row = RowSum::default();
            let r = &reference.rgb[y * w * 3..(y + 1) * w * 3];
            let t = &test.rgb[y * w * 3..(y + 1) * w * 3];
            for x in 0..w {
                let (rp, tp) = (&r[x * 3..x * 3 + 3], &t[x * 3..x * 3 + 3]);
                let bad_r = rp.iter().any(|v| !v.is_finite());
                let bad_t = tp.iter().any(|v| !v.is_finite());
                row.nonfinite_reference += bad_r as u64;
                row.nonfinite_test += bad_t as u64;
                if bad_r || bad_t {
                    map_row[x] = f32::NAN;
                    continue;
                }
                let e: f64 = (0..3).map(|c| error(tp[c] as f64, rp[c] as f64)).sum();
                row.sum += e;
                row.counted += 1;
                map_row[x] = (e / 3.0) as f32;
            }
            row
        })
        .collect();
    let total = rows.iter().fold(RowSum::default(), |a, r| RowSum {
        sum: a.sum + r.sum,
        counted: a.counted + r.counted,
        nonfinite_reference: a.nonfinite_reference + r.nonfinite_reference,
        nonfinite_test: a.nonfinite_test + r.nonfinite_test,
    });
    PixelMean {
        mean: if total.counted == 0 { f64::NAN } else { total.sum / (3 * total.counted) as f64 },
        map,
        nonfinite_reference: total.nonfinite_reference,
        nonfinite_test: total.nonfinite_test,
        counted: total.counted,
    }
}

/// The ε of relative MSE and SMAPE.
pub const EPSILON: f64 = 0.01;

/// Squared error.
pub(crate) fn squared(t: f64, r: f64) -> f64 {
    (t - r) * (t - r)
}

/// Relative squared error `(t − r)² / (r² + ε)`.
pub(crate) fn relative_squared(t: f64, r: f64) -> f64 {
    (t - r) * (t - r) / (r * r + EPSILON)
}

/// Symmetric absolute percentage error `|t − r| / (|t| + |r| + ε)`.
pub(crate) fn symmetric_absolute(t: f64, r: f64) -> f64 {
    (t - r).abs() / (t.abs() + r.abs() + EPSILON)
}

/// A linear value tone-mapped to the 8-bit range [0, 255] (sRGB curve,
/// clamped, not quantised; NaN maps to 0).
///
/// The power branch reads a table of `u^(5/6)` over `u = √v` (smooth on
/// the branch's domain) with linear interpolation: error below 1e−5 in
/// 8-bit units (the table fits the L1 cache), at a fraction of `powf`'s
/// cost — tone mapping dominated PSNR and SSIM.
#[inline]
pub fn tone_map(linear: f64) -> f64 {
    let v = if linear.is_nan() { 0.0 } else { linear.clamp(0.0, 1.0) };
    if v <= 0.003_130_8 {
        return 255.0 * v * 12.92;
    }
    if v >= 1.0 {
        return 255.0;
    }
    let table = power_table();
    let x = v.sqrt() * (TABLE_SIZE - 1) as f64;
    let i = (x as usize).min(TABLE_SIZE - 2);
    let f = x - i as f64;
    let p = table[i] + (table[i + 1] - table[i]) * f;
    255.0 * (1.055 * p - 0.055)
}

/// [`tone_map`] in f32 for SSIM's hot path; error below 1e−4 in 8-bit units.
///
/// The power branch reads a table indexed directly by the float's bits:
/// exponent and top 9 mantissa bits select a slot (2⁻⁹ wide, relatively),
/// the remaining bits interpolate linearly within it. No square root and no
/// float-to-integer conversion: a shift, two loads and a multiply-add.
#[cfg(test)]
pub fn tone_map_f32(linear: f32) -> f32 {
    tone_map_with(linear, bits_table())
}

/// [`tone_map_f32`] with its table passed in, for loops that fetch it once.
#[inline(always)]
pub(crate) fn tone_map_with(linear: f32, table: &[(f32, f32)]) -> f32 {
    let v = linear.clamp(0.0, 1.0);
    let v = if v.is_nan() { 0.0 } else { v };
    let bits = v.max(BITS_TABLE_START).to_bits();
    let slot = ((bits >> LOW_BITS) - (BITS_TABLE_START.to_bits() >> LOW_BITS)) as usize;
    let frac = (bits & ((1 << LOW_BITS) - 1)) as f32 * (1.0 / (1u32 << LOW_BITS) as f32);
    let (base, delta) = table[slot.min(BITS_TABLE_SLOTS - 1)];
    let power = base + delta * frac;
    if v >= 1.0 {
        255.0
    } else if v <= 0.003_130_8 {
        255.0 * 12.92 * v
    } else {
        power
    }
}

/// Mantissa bits below the slot index.
const LOW_BITS: u32 = 23 - 9;
/// 2⁻⁹: every power-branch value (> 0.0031308) is above it.
const BITS_TABLE_START: f32 = 1.0 / 512.0;
/// Slots from 2⁻⁹ up to 1: 9 exponents × 512.
const BITS_TABLE_SLOTS: usize = 9 * 512;

/// The bit-indexed table split into bases and slopes, for vector gathers.
pub(crate) fn bits_table_soa() -> &'static (Vec<f32>, Vec<f32>) {
    static TABLE: std::sync::OnceLock<(Vec<f32>, Vec<f32>)> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| bits_table().iter().copied().unzip())
}

/// [`tone_map_with`] on 8 values at once with AVX2 gathers.
///
/// # Safety
/// The CPU must support AVX2 and FMA; `bases` and `slopes` come from
/// [`bits_table_soa`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn tone_map_8(values: &mut [f32; 8], bases: &[f32], slopes: &[f32]) {
    use std::arch::x86_64::*;
    debug_assert!(bases.len() == BITS_TABLE_SLOTS && slopes.len() == BITS_TABLE_SLOTS);
    // SAFETY (whole block): AVX2/FMA are enabled by the caller's check; the
    // gather indices are clamped into 0..BITS_TABLE_SLOTS.
    unsafe {
        let x = _mm256_loadu_ps(values.as_ptr());
        // max(NaN, 0) gives 0, as the scalar version's NaN rule.
        let v = _mm256_min_ps(_mm256_max_ps(x, _mm256_setzero_ps()), _mm256_set1_ps(1.0));
        let bits = _mm256_castps_si256(_mm256_max_ps(v, _mm256_set1_ps(BITS_TABLE_START)));
        let first = _mm256_set1_epi32((BITS_TABLE_START.to_bits() >> LOW_BITS) as i32);
        let slot = _mm256_min_epi32(
            _mm256_sub_epi32(_mm256_srli_epi32::<{ LOW_BITS as i32 }>(bits), first),
            _mm256_set1_epi32(BITS_TABLE_SLOTS as i32 - 1),
        );
        let low = _mm256_and_si256(bits, _mm256_set1_epi32((1 << LOW_BITS) - 1));
        let frac = _mm256_mul_ps(_mm256_cvtepi32_ps(low), _mm256_set1_ps(1.0 / (1u32 << LOW_BITS) as f32));
        let base = _mm256_i32gather_ps::<4>(bases.as_ptr(), slot);
        let slope = _mm256_i32gather_ps::<4>(slopes.as_ptr(), slot);
        let power = _mm256_fmadd_ps(slope, frac, base);
        let linear = _mm256_mul_ps(v, _mm256_set1_ps(255.0 * 12.92));
        let small = _mm256_cmp_ps::<_CMP_LE_OQ>(v, _mm256_set1_ps(0.003_130_8));
        let full = _mm256_cmp_ps::<_CMP_GE_OQ>(v, _mm256_set1_ps(1.0));
        let out = _mm256_blendv_ps(_mm256_blendv_ps(power, linear, small), _mm256_set1_ps(255.0), full);
        _mm256_storeu_ps(values.as_mut_ptr(), out);
    }
}

pub(crate) fn bits_table() -> &'static [(f32, f32)] {
    static TABLE: std::sync::OnceLock<Vec<(f32, f32)>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let curve = |x: f64| 255.0 * (1.055 * x.powf(1.0 / 2.4) - 0.055);
        let first = BITS_TABLE_START.to_bits() >> LOW_BITS;
        (0..BITS_TABLE_SLOTS as u32)
            .map(|i| {
                let a = f32::from_bits((first + i) << LOW_BITS) as f64;
                let b = f32::from_bits((first + i + 1) << LOW_BITS) as f64;
                (curve(a) as f32, (curve(b) - curve(a)) as f32)
            })
            .collect()
    })
}

/// The exact sRGB curve, for tests of [`tone_map`].
#[cfg(test)]
pub fn tone_map_exact(linear: f64) -> f64 {
    let v = if linear.is_nan() { 0.0 } else { linear.clamp(0.0, 1.0) };
    255.0 * if v <= 0.003_130_8 { v * 12.92 } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 }
}

const TABLE_SIZE: usize = 4097;

fn power_table() -> &'static [f64] {
    static TABLE: std::sync::OnceLock<Vec<f64>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| (0..TABLE_SIZE).map(|i| (i as f64 / (TABLE_SIZE - 1) as f64).powf(5.0 / 6.0)).collect())
}

/// Pixels with a non-finite channel in the reference and in the test image.
pub(crate) fn count_nonfinite(reference: &Image, test: &Image) -> (u64, u64) {
    (nonfinite_pixels(reference), nonfinite_pixels(test))
}

/// Pixels with a non-finite channel.
pub(crate) fn nonfinite_pixels(img: &Image) -> u64 {
    // Non-finite floats have every exponent bit set: a branch-free test per
    // channel, OR-ed per pixel, that vectorises.
    const EXPONENT: u32 = 0x7F80_0000;
    img.rgb
        .par_chunks(3 * 4096)
        .map(|chunk| {
            chunk
                .chunks_exact(3)
                .map(|p| {
                    let bad = |v: f32| (v.to_bits() & EXPONENT == EXPONENT) as u64;
                    bad(p[0]) | bad(p[1]) | bad(p[2])
                })
                .sum::<u64>()
        })
        .sum()
}

/// Squared error of tone-mapped values.
pub(crate) fn tone_mapped_squared(t: f64, r: f64) -> f64 {
    let d = tone_map(t) - tone_map(r);
    d * d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tone_map_table_is_accurate() {
        let mut worst: f64 = 0.0;
        for i in 0..=200_000 {
            let v = i as f64 / 200_000.0;
            worst = worst.max((tone_map(v) - tone_map_exact(v)).abs());
        }
        assert!(worst < 5e-5, "worst {worst}");
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            let (bases, slopes) = bits_table_soa();
            for i in 0..=25_000 {
                let mut v: [f32; 8] = std::array::from_fn(|j| (i * 8 + j) as f32 / 200_000.0);
                v[7] = [f32::NAN, -1.0, 2.0, 1.0][i % 4];
                let want: Vec<f32> = v.iter().map(|x| tone_map_f32(*x)).collect();
                // SAFETY: the features were just detected.
                unsafe { tone_map_8(&mut v, bases, slopes) };
                for (got, want) in v.iter().zip(&want) {
                    assert!((got - want).abs() < 1e-4, "{got} vs {want}");
                }
            }
        }
        let mut worst32: f64 = 0.0;
        for i in 0..=200_000 {
            let v = i as f32 / 200_000.0;
            worst32 = worst32.max((tone_map_f32(v) as f64 - tone_map_exact(v as f64)).abs());
        }
        assert!(worst32 < 1e-4, "f32 worst {worst32}");
        assert_eq!((tone_map_f32(-1.0), tone_map_f32(2.0), tone_map_f32(f32::NAN)), (0.0, 255.0, 0.0));
        assert_eq!((tone_map(-1.0), tone_map(2.0), tone_map(f64::NAN)), (0.0, 255.0, 0.0));
    }
}
