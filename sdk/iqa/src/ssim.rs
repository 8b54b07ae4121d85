//! SSIM (Wang et al. 2004) as thesis §4.4 defines it, computed so that it
//! equals scikit-image's `structural_similarity(ref, test, data_range=255,
//! gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
//! channel_axis=2)` on the tone-mapped images:
//!
//! - each channel tone-mapped to [0, 255] ([`tone_map`]);
//! - local statistics by an 11 × 11 Gaussian window (σ = 1.5, radius 5,
//!   weights normalised), applied separably, borders mirrored as scipy's
//!   `reflect` mode (`d c b a | a b c d | d c b a`);
//! - `S = (2μxμy + C1)(2σxy + C2) / ((μx² + μy² + C1)(σx² + σy² + C2))`,
//!   C1 = 6.5025, C2 = 58.5225;
//! - the value is the mean of S over pixels at least 5 from every border
//!   (windows wholly inside the image), averaged over the three channels.
//!   Images narrower or lower than 11 pixels have no such pixel: their
//!   value is the mean over all pixels (scikit-image refuses them).
//!
//! The error map is `1 − S` averaged over channels, at every pixel.
//! Values are shifted by −128 before the squares are filtered, which keeps
//! the variance's cancellation small in f32 (SSIM is shift-invariant in σ).
//! It streams: each input row is tone-mapped and blurred horizontally once
//! into a ring of 11 rows, and each output row is formed as soon as its
//! window is complete, so no full-size temporary image is made.

use crate::image::Image;
use crate::pixelwise::{bits_table, tone_map_with};
#[cfg(target_arch = "x86_64")]
use crate::pixelwise::{bits_table_soa, tone_map_8};
use rayon::prelude::*;

/// First stabilising constant, (0.01 · 255)².
pub const C1: f64 = 6.5025;
/// Second stabilising constant, (0.03 · 255)².
pub const C2: f64 = 58.5225;
const RADIUS: usize = 5;
const SIGMA: f64 = 1.5;
const SHIFT: f32 = 128.0;

fn kernel() -> [f32; 2 * RADIUS + 1] {
    let mut k = [0f64; 2 * RADIUS + 1];
    for (i, v) in k.iter_mut().enumerate() {
        let x = i as f64 - RADIUS as f64;
        *v = (-0.5 * x * x / (SIGMA * SIGMA)).exp();
    }
    let sum: f64 = k.iter().sum();
    k.map(|v| (v / sum) as f32)
}

/// scipy's `reflect` index for position `i` (may be negative) in `0..n`.
fn reflect(i: isize, n: usize) -> usize {
    let n = n as isize;
    let period = 2 * n;
    let mut m = i.rem_euclid(period);
    if m >= n {
        m = period - 1 - m;
    }
    m as usize
}

/// Horizontal blur of one row, mirrored borders.
#[inline(always)]
fn blur_row(row: &[f32], out: &mut [f32], k: &[f32; 2 * RADIUS + 1]) {
    let w = row.len();
    out.fill(0.0);
    if w > 2 * RADIUS {
        // Interior: every tap in range, a loop the compiler vectorises. The
        // kernel is symmetric: mirrored taps are added before multiplying.
        let inner = w - 2 * RADIUS;
        for (o, c) in out[RADIUS..w - RADIUS].iter_mut().zip(&row[RADIUS..RADIUS + inner]) {
            *o = k[RADIUS] * c;
        }
        for j in 0..RADIUS {
            let (left, right) = (&row[j..j + inner], &row[2 * RADIUS - j..2 * RADIUS - j + inner]);
            for (o, (l, r)) in out[RADIUS..w - RADIUS].iter_mut().zip(left.iter().zip(right)) {
                *o += k[j] * (l + r);
            }
        }
    }
    let border = |x: usize| -> f32 {
        (0..=2 * RADIUS).map(|j| k[j] * row[reflect(x as isize + j as isize - RADIUS as isize, w)]).sum()
    };
    if w > 2 * RADIUS {
        for x in (0..RADIUS).chain(w - RADIUS..w) {
            out[x] = border(x);
        }
    } else {
        for (x, o) in out.iter_mut().enumerate() {
            *o = border(x);
        }
    }
}

/// The local statistics of one image row, horizontally blurred: x, y,
/// x² + y², xy (values shifted by −128). SSIM needs σx² + σy² only as a
/// sum, so x² and y² share one plane.
struct RowStats {
    planes: [Vec<f32>; 4],
}

impl RowStats {
    fn new(w: usize) -> Self {
        RowStats { planes: std::array::from_fn(|_| vec![0f32; w]) }
    }

    #[inline(always)]
    fn compute<const AVX2: bool>(
        &mut self,
        reference: &Image,
        test: &Image,
        c: usize,
        y: usize,
        scratch: &mut [Vec<f32>; 4],
        k: &[f32; 2 * RADIUS + 1],
    ) {
        let w = reference.width as usize;
        let (r, t) = (&reference.rgb[y * w * 3..(y + 1) * w * 3], &test.rgb[y * w * 3..(y + 1) * w * 3]);
        // Gather the channel into contiguous rows first: the tone map then
        // runs over plain slices, which vectorises.
        let [a, b, squares, ab] = scratch;
        for (x, (va, vb)) in a.iter_mut().zip(b.iter_mut()).enumerate() {
            *va = r[x * 3 + c];
            *vb = t[x * 3 + c];
        }
        let table = bits_table();
        for row in [&mut *a, &mut *b] {
            let mut chunks = row.chunks_exact_mut(8);
            #[cfg(target_arch = "x86_64")]
            if AVX2 {
                let (bases, slopes) = bits_table_soa();
                for chunk in &mut chunks {
                    let chunk: &mut [f32; 8] = chunk.try_into().expect("chunks of 8");
                    // SAFETY: AVX2 is true only on the path whose caller detected AVX2 and FMA.
                    unsafe { tone_map_8(chunk, bases, slopes) };
                    for v in chunk.iter_mut() {
                        *v -= SHIFT;
                    }
                }
            }
            for v in chunks.into_remainder() {
                *v = tone_map_with(*v, table) - SHIFT;
            }
        }
        for x in 0..w {
            squares[x] = a[x] * a[x] + b[x] * b[x];
            ab[x] = a[x] * b[x];
        }
        for (plane, raw) in self.planes.iter_mut().zip(scratch.iter()) {
            blur_row(raw, plane, k);
        }
    }
}

/// [`channel_rows`] compiled for AVX2 and FMA (checked at run time).
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn channel_rows_avx2(band: Band<'_>, out: Output<'_>) {
    channel_rows::<true>(band, out)
}

/// [`channel_rows`] at the best instruction set this CPU has.
fn channel_rows_dispatch(band: Band<'_>, out: Output<'_>) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
        // SAFETY: the features were just detected.
        return unsafe { channel_rows_avx2(band, out) };
    }
    channel_rows::<false>(band, out)
}

/// One band of rows of one channel to compute.
struct Band<'a> {
    reference: &'a Image,
    test: &'a Image,
    c: usize,
    rows: std::ops::Range<usize>,
    k: &'a [f32; 2 * RADIUS + 1],
}

/// Where one band of rows of one channel goes: `(1 − S) / 3` added to the
/// error map, and each row's sum of S over the columns `x0..x1`.
struct Output<'a> {
    map: &'a mut [f32],
    row_sums: &'a mut [f64],
    x0: usize,
    x1: usize,
}

/// S for rows `rows` of channel `c`, accumulated into `out`.
#[inline(always)]
fn channel_rows<const AVX2: bool>(band: Band<'_>, out: Output<'_>) {
    let Band { reference, test, c, rows, k } = band;
    let (w, h) = (reference.width as usize, reference.height as usize);
    // A ring of the horizontally blurred statistics of the 11 rows a window needs.
    let mut ring: Vec<(isize, RowStats)> = (0..2 * RADIUS + 1).map(|_| (-1, RowStats::new(w))).collect();
    let mut scratch: [Vec<f32>; 4] = std::array::from_fn(|_| vec![0f32; w]);
    let mut sums: [Vec<f32>; 4] = std::array::from_fn(|_| vec![0f32; w]);
    let mut s_row = vec![0f32; w];
    for (i, y) in rows.enumerate() {
        // Bring the window's 11 rows into the ring (each computed once).
        let mut slots = [0usize; 2 * RADIUS + 1];
        for (j, slot_of) in slots.iter_mut().enumerate() {
            let source = reflect(y as isize + j as isize - RADIUS as isize, h);
            // Rows mirrored at a border may repeat; the ring slot is keyed by source row.
            let slot = source % ring.len();
            if ring[slot].0 != source as isize {
                ring[slot].1.compute::<AVX2>(reference, test, c, source, &mut scratch, k);
                ring[slot].0 = source as isize;
            }
            *slot_of = slot;
        }
        // Vertical blur, mirrored rows added before multiplying.
        for (p, sum) in sums.iter_mut().enumerate() {
            for (s, v) in sum.iter_mut().zip(&ring[slots[RADIUS]].1.planes[p]) {
                *s = k[RADIUS] * v;
            }
            for j in 0..RADIUS {
                let (top, bottom) = (&ring[slots[j]].1.planes[p], &ring[slots[2 * RADIUS - j]].1.planes[p]);
                for (s, (a, b)) in sum.iter_mut().zip(top.iter().zip(bottom)) {
                    *s += k[j] * (a + b);
                }
            }
        }
        let map_row = &mut out.map[i * w..(i + 1) * w];
        // In f32: the sums it reads are f32 already, and 8 lanes beat 4.
        let (c1, c2, shift) = (C1 as f32, C2 as f32, SHIFT);
        for (x, s) in s_row.iter_mut().enumerate() {
            let (ux, uy) = (sums[0][x], sums[1][x]);
            let variances = sums[2][x] - ux * ux - uy * uy;
            let vxy = sums[3][x] - ux * uy;
            let (ux, uy) = (ux + shift, uy + shift);
            *s = ((2.0 * ux * uy + c1) * (2.0 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (variances + c2));
        }
        for (m, s) in map_row.iter_mut().zip(&s_row) {
            *m += (1.0 - s) * (1.0 / 3.0);
        }
        out.row_sums[i] = s_row[out.x0..out.x1].iter().map(|v| *v as f64).sum();
    }
}

/// `(SSIM, 1 − S map)` of two images of the same size.
pub(crate) fn ssim(reference: &Image, test: &Image) -> (f64, Vec<f32>) {
    let (w, h) = (reference.width as usize, reference.height as usize);
    let k = kernel();
    // Windows wholly inside the image, when there are any.
    let (x0, x1, y0, y1) =
        if w > 2 * RADIUS && h > 2 * RADIUS { (RADIUS, w - RADIUS, RADIUS, h - RADIUS) } else { (0, w, 0, h) };
    // Bands of rows per task: each recomputes the 10 halo rows it shares with its neighbours.
    let band = (h / (4 * rayon::current_num_threads())).clamp(32, 256).min(h.max(1));
    let mut map = vec![0f32; w * h];
    let mut row_sums = vec![0f64; h];
    let mut total = 0.0;
    for c in 0..3 {
        map.par_chunks_mut(band * w).zip(row_sums.par_chunks_mut(band)).enumerate().for_each(|(b, (map, sums))| {
            let start = b * band;
            let rows = start..start + sums.len();
            channel_rows_dispatch(Band { reference, test, c, rows, k: &k }, Output { map, row_sums: sums, x0, x1 });
        });
        total += row_sums[y0..y1].iter().sum::<f64>() / ((x1 - x0) * (y1 - y0)) as f64;
    }
    (total / 3.0, map)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reflect_matches_scipy() {
        let got: Vec<usize> = (-3..7).map(|i| reflect(i, 4)).collect();
        assert_eq!(got, [2, 1, 0, 0, 1, 2, 3, 3, 2, 1]);
        assert_eq!(reflect(-6, 2), 1);
    }

    #[test]
    fn kernel_is_normalised_and_symmetric() {
        let k = kernel();
        assert!((k.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        assert_eq!(k[0], k[10]);
    }

    #[test]
    fn blur_keeps_constants() {
        for w in [13, 3] {
            let mut out = vec![0f32; w];
            blur_row(&vec![3.5f32; w], &mut out, &kernel());
            assert!(out.iter().all(|v| (v - 3.5).abs() < 1e-5), "{out:?}");
        }
    }
}
