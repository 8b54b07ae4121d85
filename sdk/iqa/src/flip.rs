//! ꟻLIP (Andersson et al. 2020, "FLIP: A Difference Evaluator for
//! Alternating Images") and HDR-ꟻLIP (Andersson et al. 2021), as published
//! and as NVIDIA's `flip-evaluator` 1.7 computes them; tested against that
//! package.
//!
//! LDR-ꟻLIP on linear RGB in [0, 1] (clamped), at 67.02 pixels per degree
//! (0.7 m from a 0.7 m wide, 3840-pixel display):
//! 1. **Colour**: linear RGB → XYZ → YCxCz; each channel filtered by its
//!    contrast sensitivity function (Gaussians; the blue–yellow channel a sum
//!    of two), clamp-to-edge borders; back to linear RGB, clamped, then
//!    CIELab with the Hunt adjustment; the HyAB distance raised to 0.7 and
//!    remapped piecewise-linearly (pc = 0.4, pt = 0.95) against the
//!    green–blue distance.
//! 2. **Features**: on normalised luminance, first and second Gaussian
//!    derivatives (σ = 0.5 · 0.082 · ppd) give edges and points; the feature
//!    difference is `(max(|Δedge|, |Δpoint|) / √2)^0.5`.
//! 3. Per pixel `colour^(1 − feature)`; the value is the mean.
//!
//! HDR-ꟻLIP exposes the linear images at exposures from
//! `log₂(x_max / Y_max)` to `log₂(x_max / Y_median)` of the reference's
//! luminance (at least two, one stop apart at most), tone-maps each with
//! ACES, runs LDR-ꟻLIP, and keeps the per-pixel maximum.
//!
//! Departures, all documented: the mean is summed in f64 (the package sums
//! in f32, which drifts on large images by about 1e−6); an all-black
//! reference, on which the package stops the process, uses the single
//! exposure 0; cube roots and powers are our own polynomial forms (a few
//! ulps from the library's `powf`), which vectorise.
//!
//! Speed: each image is filtered in bands of rows (the seven row filters,
//! then the eight column filters, with the colour conversions fused in) that
//! stay in cache, at AVX2 where the CPU has it; a reference is prepared once
//! per exposure ([`FlipReference`]) and compared with any number of test
//! images, whose prepared bands are compared as soon as they are made.

// The published constants are kept as written, even where f32 holds fewer digits.
#![allow(clippy::excessive_precision)]

use crate::fastmath::{cbrt, pow};
use rayon::prelude::*;

const PI: f32 = std::f32::consts::PI;

/// The default pixels per degree: 0.7 m · (3840 px / 0.7 m) · π/180.
pub fn default_ppd() -> f32 {
    0.7f32 * (3840.0f32 / 0.7f32) * (PI / 180.0f32)
}

const TO_XYZ: [[f32; 3]; 3] = [
    [10135552.0 / 24577794.0, 8788810.0 / 24577794.0, 4435075.0 / 24577794.0],
    [2613072.0 / 12288897.0, 8788810.0 / 12288897.0, 887015.0 / 12288897.0],
    [1425312.0 / 73733382.0, 8788810.0 / 73733382.0, 70074185.0 / 73733382.0],
];
const FROM_XYZ: [[f32; 3]; 3] = [
    [3.241003275, -1.537398934, -0.498615861],
    [-0.969224334, 1.875930071, 0.041554224],
    [0.055639423, -0.204011202, 1.057148933],
];
const WHITE: [f32; 3] = [0.950428545, 1.0, 1.088900371];
const INV_WHITE: [f32; 3] = [1.052156925, 1.0, 0.918357670];

#[inline(always)]
fn mat(m: &[[f32; 3]; 3], v: [f32; 3]) -> [f32; 3] {
    let row = |i: usize| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2];
    [row(0), row(1), row(2)]
}

#[inline(always)]
fn xyz_to_ycxcz(v: [f32; 3]) -> [f32; 3] {
    let (x, y, z) = (v[0] * INV_WHITE[0], v[1] * INV_WHITE[1], v[2] * INV_WHITE[2]);
    [116.0 * y - 16.0, 500.0 * (x - y), 200.0 * (y - z)]
}

#[inline(always)]
fn ycxcz_to_xyz(v: [f32; 3]) -> [f32; 3] {
    let yp = (v[0] + 16.0) / 116.0;
    let (cx, cz) = (v[1] / 500.0, v[2] / 200.0);
    [(yp + cx) * WHITE[0], yp * WHITE[1], (yp - cz) * WHITE[2]]
}

/// CIELab's f(t): both branches computed and one chosen, so the pixel loop vectorises.
#[inline(always)]
fn lab_f(t: f32) -> f32 {
    const DELTA: f32 = 6.0 / 29.0;
    let delta_cube = DELTA * (DELTA * DELTA);
    let factor = 1.0 / (3.0 * (DELTA * DELTA));
    let term = 4.0f32 / 29.0;
    let root = cbrt(t.max(delta_cube));
    if t > delta_cube {
        root
    } else {
        factor * t + term
    }
}

#[inline(always)]
fn xyz_to_lab(v: [f32; 3]) -> [f32; 3] {
    let (fx, fy, fz) = (lab_f(v[0] * INV_WHITE[0]), lab_f(v[1] * INV_WHITE[1]), lab_f(v[2] * INV_WHITE[2]));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

#[inline(always)]
fn hunt(lab: [f32; 3]) -> [f32; 3] {
    [lab[0], (0.01 * lab[0]) * lab[1], (0.01 * lab[0]) * lab[2]]
}

#[inline(always)]
fn hyab(a: [f32; 3], b: [f32; 3]) -> f32 {
    let (da, db) = (a[1] - b[1], a[2] - b[2]);
    (a[0] - b[0]).abs() + (da * da + db * db).sqrt()
}

/// The contrast sensitivity kernels for a ppd.
struct Kernels {
    y: Vec<f32>,
    cx: Vec<f32>,
    cz1: Vec<f32>,
    cz2: Vec<f32>,
    g: Vec<f32>,
    dg: Vec<f32>,
    ddg: Vec<f32>,
}

impl Kernels {
    fn new(ppd: f32) -> Kernels {
        let pi_sq = PI * PI;
        let max_b = 0.04f32;
        let radius = ((3.0f32 * (max_b / (2.0f32 * pi_sq)).sqrt()) * ppd).ceil() as i32;
        let delta_x = 1.0f32 / ppd;
        let gauss = |x2: f32, a: f32, b: f32| (a * (PI / b).sqrt()) * ((-pi_sq * x2) / b).exp();
        let gauss_sqrt = |x2: f32, a: f32, b: f32| (a * (PI / b).sqrt()).sqrt() * ((-pi_sq * x2) / b).exp();
        let make = |f: &dyn Fn(f32) -> f32| -> Vec<f32> {
            (-radius..=radius)
                .map(|t| {
                    let ix = t as f32 * delta_x;
                    f(ix * ix)
                })
                .collect()
        };
        let mut y = make(&|x2| gauss(x2, 1.0, 0.0047));
        let mut cx = make(&|x2| gauss(x2, 1.0, 0.0053));
        let mut cz1 = make(&|x2| gauss_sqrt(x2, 34.1, 0.04));
        let mut cz2 = make(&|x2| gauss_sqrt(x2, 13.5, 0.025));
        let sum = |k: &[f32]| k.iter().fold(0f32, |a, v| a + v);
        let (sy, scx) = (1.0 / sum(&y), 1.0 / sum(&cx));
        let (s1, s2) = (sum(&cz1), sum(&cz2));
        let nz = 1.0 / (s1 * s1 + s2 * s2).sqrt();
        y.iter_mut().for_each(|v| *v *= sy);
        cx.iter_mut().for_each(|v| *v *= scx);
        cz1.iter_mut().for_each(|v| *v *= nz);
        cz2.iter_mut().for_each(|v| *v *= nz);

        // Feature kernels: Gaussian and its derivatives, σ = 0.5 · 0.082 · ppd.
        let sd = 0.5f32 * 0.082f32 * ppd;
        let r = (3.0f32 * sd).ceil() as i32;
        let mut g = Vec::new();
        let mut dg = Vec::new();
        let mut ddg = Vec::new();
        for t in -r..=r {
            let tf = t as f32;
            let gv = (-(tf * tf) / ((2.0 * sd) * sd)).exp();
            g.push(gv);
            dg.push(-tf * gv);
            ddg.push(((tf * tf) / (sd * sd) - 1.0) * gv);
        }
        let g_sum = sum(&g);
        let split = |k: &[f32]| {
            let pos = k.iter().filter(|v| **v > 0.0).fold(0f32, |a, v| a + v);
            let neg = k.iter().filter(|v| **v <= 0.0).fold(0f32, |a, v| a - v);
            (pos, neg)
        };
        let (dg_pos, dg_neg) = split(&dg);
        let (ddg_pos, ddg_neg) = split(&ddg);
        g.iter_mut().for_each(|v| *v /= g_sum);
        dg.iter_mut().for_each(|v| *v /= if *v > 0.0 { dg_pos } else { dg_neg });
        ddg.iter_mut().for_each(|v| *v /= if *v > 0.0 { ddg_pos } else { ddg_neg });
        Kernels { y, cx, cz1, cz2, g, dg, ddg }
    }

    /// Radius of the colour kernels and of the feature kernels.
    fn radii(&self) -> (usize, usize) {
        (self.y.len() / 2, self.g.len() / 2)
    }
}

/// `min(max(v, 0), 1)` with NaN becoming 0, as the reference does it.
#[inline(always)]
fn clamp01(v: f32) -> f32 {
    let v = if v > 0.0 { v } else { 0.0 };
    if v > 1.0 {
        1.0
    } else {
        v
    }
}

/// ACES (fitted, with the 0.6 pre-exposure cancelled), per channel.
const ACES: [f32; 6] = [0.6 * 0.6 * 2.51, 0.6 * 0.03, 0.0, 0.6 * 0.6 * 2.43, 0.6 * 0.59, 0.14];

#[inline(always)]
fn tone_map_aces(c: f32) -> f32 {
    let k = ACES;
    ((c * c) * k[0] + c * k[1] + k[2]) / ((c * c) * k[3] + c * k[4] + k[5])
}

/// How linear values enter LDR-ꟻLIP: clamped (LDR), or scaled by an
/// exposure, ACES tone-mapped and clamped (one exposure of HDR-ꟻLIP).
#[derive(Debug, Clone, Copy)]
enum Exposure {
    Ldr,
    Hdr(f32),
}

impl Exposure {
    #[inline(always)]
    fn apply(self, v: f32) -> f32 {
        match self {
            Exposure::Ldr => clamp01(v),
            Exposure::Hdr(m) => clamp01(tone_map_aces(v * m)),
        }
    }
}

/// Row-filtered planes per image row: the CSF kernels on Y, Cx and Cz (two),
/// and the feature kernels (dg, ddg, g) on the normalised luminance.
const ROW_PLANES: usize = 7;
/// What [`Prepared`] keeps per pixel: Hunt-adjusted L, a, b, edge, point.
const PREPARED_PLANES: usize = 5;

/// What ꟻLIP compares of one image at one exposure: per pixel the
/// Hunt-adjusted Lab of the CSF-filtered image and the edge and point
/// features of its normalised luminance, stored row by row
/// (`PREPARED_PLANES` runs of `w` values per row). A reference's are made
/// once and compared with any number of test images ([`FlipReference`]).
struct Prepared {
    rows: Vec<f32>,
}

/// `out[x] = Σⱼ k[j] · src(j)[x]`, summed in tap order per pixel (as the
/// reference implementation sums). The sums of a block of pixels stay in
/// registers across the taps: four vectors' worth or more, whose additions
/// are independent, so they pipeline (one vector's would wait on itself),
/// and each tap costs one load per vector instead of a load and a store
/// of the sums too. The pixels past the last whole block go a row per tap:
/// only a block of fixed size keeps its sums in registers (one loop over
/// blocks of any length, the tail's included, kept them in memory, and
/// `fbksd iqa bench` took 1.6–1.8× as long).
#[inline(always)]
fn correlate<'s>(out: &mut [f32], k: &[f32], src: impl Fn(usize) -> &'s [f32]) {
    const BLOCK: usize = 64;
    let n = out.len();
    let blocked = n / BLOCK * BLOCK;
    for (b, block) in out[..blocked].chunks_exact_mut(BLOCK).enumerate() {
        let x0 = b * BLOCK;
        let mut sums = [0f32; BLOCK];
        for (j, kw) in k.iter().enumerate() {
            let row: &[f32; BLOCK] = src(j)[x0..x0 + BLOCK].try_into().expect("a block of the row");
            for (s, v) in sums.iter_mut().zip(row) {
                *s += kw * v;
            }
        }
        block.copy_from_slice(&sums);
    }
    let tail = &mut out[blocked..];
    tail.fill(0.0);
    for (j, kw) in k.iter().enumerate() {
        for (o, v) in tail.iter_mut().zip(&src(j)[blocked..n]) {
            *o += kw * v;
        }
    }
}

/// Per-thread scratch of [`band_pass`]: the four padded input rows, the
/// row-filtered planes of the band's input rows, the column accumulators and,
/// for a test image, the band's prepared rows.
struct BandScratch {
    padded: [Vec<f32>; 4],
    rows: Vec<f32>,
    acc: Vec<f32>,
    prepared: Vec<f32>,
}

impl BandScratch {
    fn new(w: usize, k: &Kernels) -> BandScratch {
        let pad = k.radii().0.max(k.radii().1);
        BandScratch {
            padded: std::array::from_fn(|_| vec![0f32; w + 2 * pad]),
            rows: Vec::new(),
            acc: vec![0f32; 8 * w],
            prepared: Vec::new(),
        }
    }
}

/// The row pass of one image row: colour transform and the seven row filters.
#[inline(always)]
fn row_pass(rgb_row: &[f32], exposure: Exposure, k: &Kernels, padded: &mut [Vec<f32>; 4], out: &mut [f32]) {
    let w = rgb_row.len() / 3;
    let (rc, rf) = k.radii();
    let pad = rc.max(rf);
    let [py, pcx, pcz, pyn] = padded;
    // The channels apart first (into the planes' tails, not yet used), so
    // that the colour loop reads unit strides and vectorises.
    for (x, p) in rgb_row.chunks_exact(3).enumerate() {
        (py[pad + x], pcx[pad + x], pcz[pad + x]) = (p[0], p[1], p[2]);
    }
    // One loop per exposure kind: with the kind tested inside, the
    // vectorised loop computed the tone map's division for LDR pixels too.
    #[inline(always)]
    fn colour(planes: [&mut [f32]; 4], apply: impl Fn(f32) -> f32) {
        let [py, pcx, pcz, pyn] = planes;
        for (((y, cx), cz), yn) in py.iter_mut().zip(pcx.iter_mut()).zip(pcz.iter_mut()).zip(pyn.iter_mut()) {
            let v = xyz_to_ycxcz(mat(&TO_XYZ, [apply(*y), apply(*cx), apply(*cz)]));
            (*y, *cx, *cz) = (v[0], v[1], v[2]);
            *yn = v[0] * (1.0 / 116.0) + 16.0 / 116.0;
        }
    }
    let planes = [&mut py[pad..pad + w], &mut pcx[pad..pad + w], &mut pcz[pad..pad + w], &mut pyn[pad..pad + w]];
    match exposure {
        Exposure::Ldr => colour(planes, |v| Exposure::Ldr.apply(v)),
        Exposure::Hdr(m) => colour(planes, |v| Exposure::Hdr(m).apply(v)),
    }
    // Clamp-to-edge borders.
    for plane in [&mut *py, &mut *pcx, &mut *pcz, &mut *pyn] {
        let (first, last) = (plane[pad], plane[pad + w - 1]);
        plane[..pad].fill(first);
        plane[pad + w..].fill(last);
    }
    let mut planes = out.chunks_exact_mut(w);
    let mut next = || planes.next().expect("seven row planes");
    fn shifted(plane: &[f32], pad: usize, r: usize, j: usize) -> &[f32] {
        &plane[pad - r + j..]
    }
    let (py, pcx, pcz, pyn) = (&*py, &*pcx, &*pcz, &*pyn);
    correlate(next(), &k.y, |j| shifted(py, pad, rc, j));
    correlate(next(), &k.cx, |j| shifted(pcx, pad, rc, j));
    correlate(next(), &k.cz1, |j| shifted(pcz, pad, rc, j));
    correlate(next(), &k.cz2, |j| shifted(pcz, pad, rc, j));
    correlate(next(), &k.dg, |j| shifted(pyn, pad, rf, j));
    correlate(next(), &k.ddg, |j| shifted(pyn, pad, rf, j));
    correlate(next(), &k.g, |j| shifted(pyn, pad, rf, j));
}

/// The column pass of output row `y`, from the ring of row-filtered planes
/// of the input rows around it ([`band_pass`]): the eight column filters, then the per-pixel colour
/// conversion and feature magnitudes.
#[inline(always)]
fn column_pass(b: &Bands<'_>, rows: &[f32], y: usize, acc: &mut [f32], out: &mut [f32]) {
    let (w, h, k) = (b.w, b.h, b.kernels);
    let (rc, rf) = k.radii();
    let ring = ring_rows(k);
    let plane = |yi: usize, p: usize| {
        let start = ((yi % ring) * ROW_PLANES + p) * w;
        &rows[start..start + w]
    };
    let source_row = |j: usize, r: usize| (y as isize + j as isize - r as isize).clamp(0, h as isize - 1) as usize;
    let (a0, rest) = acc.split_at_mut(w);
    let (a1, rest) = rest.split_at_mut(w);
    let (a2, rest) = rest.split_at_mut(w);
    let (a3, rest) = rest.split_at_mut(w);
    let (a4, rest) = rest.split_at_mut(w);
    let (a5, rest) = rest.split_at_mut(w);
    let (a6, a7) = rest.split_at_mut(w);
    let colour = |p: usize| move |j: usize| plane(source_row(j, rc), p);
    let feature = |p: usize| move |j: usize| plane(source_row(j, rf), p);
    correlate(a0, &k.y, colour(0));
    correlate(a1, &k.cx, colour(1));
    correlate(a2, &k.cz1, colour(2));
    correlate(a3, &k.cz2, colour(3));
    correlate(a4, &k.g, feature(4)); // dx: dg along the row, g down the column
    correlate(a5, &k.g, feature(5)); // ddx
    correlate(a6, &k.dg, feature(6)); // dy: g along the row, dg down the column
    correlate(a7, &k.ddg, feature(6)); // ddy
    let (lab, features) = out.split_at_mut(3 * w);
    let (l, rest) = lab.split_at_mut(w);
    let (a, b) = rest.split_at_mut(w);
    let (edge, point) = features.split_at_mut(w);
    for x in 0..w {
        let rgb = mat(&FROM_XYZ, ycxcz_to_xyz([a0[x], a1[x], a2[x] + a3[x]]));
        let v = hunt(xyz_to_lab(mat(&TO_XYZ, [clamp01(rgb[0]), clamp01(rgb[1]), clamp01(rgb[2])])));
        (l[x], a[x], b[x]) = (v[0], v[1], v[2]);
        edge[x] = (a4[x] * a4[x] + a6[x] * a6[x]).sqrt();
        point[x] = (a5[x] * a5[x] + a7[x] * a7[x]).sqrt();
    }
}

/// Prepares the output rows `y0..` of one band (`out` holds
/// `PREPARED_PLANES · w` values per row): each output row's column pass
/// reads the row-filtered planes of the `2·reach + 1` input rows around
/// it, kept in a ring that the row pass fills just ahead, so the working
/// set stays in the core's cache. Bands recompute the `reach` input rows
/// they share with their neighbours.
#[inline(always)]
fn band_pass(b: &Bands<'_>, y0: usize, s: &mut BandScratch, out: &mut [f32]) {
    let (rgb, w, h, e, k) = (b.rgb, b.w, b.h, b.exposure, b.kernels);
    let ring = ring_rows(k);
    s.rows.resize(ring * ROW_PLANES * w, 0.0);
    let mut next = y0.saturating_sub(ring / 2);
    for (i, row) in out.chunks_exact_mut(PREPARED_PLANES * w).enumerate() {
        let y = y0 + i;
        while next <= (y + ring / 2).min(h - 1) {
            let slot = next % ring;
            let planes = &mut s.rows[slot * ROW_PLANES * w..(slot + 1) * ROW_PLANES * w];
            row_pass(&rgb[next * 3 * w..(next + 1) * 3 * w], e, k, &mut s.padded, planes);
            next += 1;
        }
        column_pass(b, &s.rows, y, &mut s.acc, row);
    }
}

/// Input rows a column pass reads: the longest kernel's.
fn ring_rows(k: &Kernels) -> usize {
    2 * k.radii().0.max(k.radii().1) + 1
}

/// The best build of the passes this CPU can run: AVX-512 (16 lanes),
/// AVX2 and FMA, or the baseline. The values are the same in each: Rust
/// never fuses a multiply and an add on its own.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Build {
    Avx512,
    Avx2,
    Baseline,
}

impl Build {
    /// Whether this CPU can run the build.
    fn supported(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            use std::is_x86_feature_detected as has;
            match self {
                Build::Avx512 => has!("avx512f") && has!("avx512vl") && has!("avx2") && has!("fma"),
                Build::Avx2 => has!("avx2") && has!("fma"),
                Build::Baseline => true,
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            self == Build::Baseline
        }
    }
}

fn best_build() -> Build {
    [Build::Avx512, Build::Avx2].into_iter().find(|b| b.supported()).unwrap_or(Build::Baseline)
}

/// [`band_pass`] and [`compare_row`] compiled for `$features`.
#[cfg(target_arch = "x86_64")]
macro_rules! compiled_for {
    ($module:ident, $features:literal) => {
        mod $module {
            use super::*;

            /// # Safety
            /// The CPU must support the features.
            #[target_feature(enable = $features)]
            pub(super) unsafe fn band_pass(b: &Bands<'_>, y0: usize, s: &mut BandScratch, out: &mut [f32]) {
                super::band_pass(b, y0, s, out)
            }

            /// # Safety
            /// The CPU must support the features.
            #[target_feature(enable = $features)]
            pub(super) unsafe fn compare_row(r: &[f32], t: &[f32], out: &mut [f32]) {
                super::compare_row(r, t, out)
            }
        }
    };
}
#[cfg(target_arch = "x86_64")]
compiled_for!(avx2, "avx2,fma");
#[cfg(target_arch = "x86_64")]
compiled_for!(avx512, "avx512f,avx512vl,avx2,fma");

/// How one image is prepared, band by band, at the best instruction set.
struct Bands<'a> {
    rgb: &'a [f32],
    w: usize,
    h: usize,
    exposure: Exposure,
    kernels: &'a Kernels,
    build: Build,
    /// Output rows per band: four bands per thread, enough to spread the work.
    rows: usize,
}

impl<'a> Bands<'a> {
    fn new(rgb: &'a [f32], w: usize, h: usize, exposure: Exposure, kernels: &'a Kernels) -> Bands<'a> {
        let rows = h.div_ceil(4 * rayon::current_num_threads()).max(128).min(h.max(1));
        Bands { rgb, w, h, exposure, kernels, build: best_build(), rows }
    }

    fn scratch(&self) -> BandScratch {
        BandScratch::new(self.w, self.kernels)
    }

    /// Prepares band `b` into `out`.
    fn run(&self, b: usize, s: &mut BandScratch, out: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        match self.build {
            // SAFETY: best_build detected the features.
            Build::Avx512 => return unsafe { avx512::band_pass(self, b * self.rows, s, out) },
            // SAFETY: as above.
            Build::Avx2 => return unsafe { avx2::band_pass(self, b * self.rows, s, out) },
            Build::Baseline => {}
        }
        band_pass(self, b * self.rows, s, out)
    }

    fn compare(&self, r: &[f32], t: &[f32], out: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        match self.build {
            // SAFETY: best_build detected the features.
            Build::Avx512 => return unsafe { avx512::compare_row(r, t, out) },
            // SAFETY: as above.
            Build::Avx2 => return unsafe { avx2::compare_row(r, t, out) },
            Build::Baseline => {}
        }
        compare_row(r, t, out)
    }

    /// The whole image prepared.
    fn prepare(&self) -> Prepared {
        let stride = PREPARED_PLANES * self.w;
        let mut rows = vec![0f32; stride * self.h];
        rows.par_chunks_mut(stride * self.rows)
            .enumerate()
            .for_each_init(|| self.scratch(), |s, (b, out)| self.run(b, s, out));
        Prepared { rows }
    }

    /// Prepares each band and compares it with the reference's at once, so
    /// the test image is never held prepared in full.
    fn compare_into(&self, reference: &Prepared, map: &mut [f32]) {
        let stride = PREPARED_PLANES * self.w;
        let bands = map.par_chunks_mut(self.w * self.rows).zip(reference.rows.par_chunks(stride * self.rows));
        bands.enumerate().for_each_init(
            || self.scratch(),
            |s, (b, (out, r))| {
                let mut prepared = std::mem::take(&mut s.prepared);
                prepared.resize(r.len(), 0.0);
                self.run(b, s, &mut prepared);
                for ((o, r), t) in out.chunks_mut(self.w).zip(r.chunks(stride)).zip(prepared.chunks(stride)) {
                    self.compare(r, t, o);
                }
                s.prepared = prepared;
            },
        );
    }
}

/// Per-pixel ꟻLIP of one row of a prepared reference against the same row
/// of a prepared test image, kept where larger than `out`'s value
/// (HDR-ꟻLIP's maximum over exposures).
#[inline(always)]
fn compare_row(r: &[f32], t: &[f32], out: &mut [f32]) {
    let w = out.len();
    // The largest colour difference: pure green against pure blue.
    let green = hunt(xyz_to_lab(mat(&TO_XYZ, [0.0, 1.0, 0.0])));
    let blue = hunt(xyz_to_lab(mat(&TO_XYZ, [0.0, 0.0, 1.0])));
    let cmax = hyab(green, blue).powf(0.7);
    let (pc, ptt) = (0.4f32, 0.95f32);
    let pccmax = pc * cmax;
    let p = |img: &[f32], plane: usize, x: usize| img[plane * w + x];
    for (x, o) in out.iter_mut().enumerate() {
        let lab = |img: &[f32]| [p(img, 0, x), p(img, 1, x), p(img, 2, x)];
        let mut cd = pow(hyab(lab(r), lab(t)), 0.7);
        cd = if cd < pccmax { cd * (ptt / pccmax) } else { ptt + ((cd - pccmax) / (cmax - pccmax)) * (1.0 - ptt) };
        let (de, dp) = ((p(r, 3, x) - p(t, 3, x)).abs(), (p(r, 4, x) - p(t, 4, x)).abs());
        let fd = ((1.0f32 / 2.0f32.sqrt()) * de.max(dp)).sqrt();
        let v = pow(cd, 1.0 - fd);
        if v > *o {
            *o = v;
        }
    }
}

/// A reference made ready for ꟻLIP: prepared at each exposure once, then
/// compared with any number of test images of its size.
pub struct FlipReference {
    w: usize,
    h: usize,
    kernels: Kernels,
    exposures: Vec<(Exposure, Prepared)>,
}

impl FlipReference {
    /// For LDR-ꟻLIP (values clamped to [0, 1]).
    pub fn ldr(reference: &[f32], w: usize, h: usize, ppd: f32) -> FlipReference {
        FlipReference::new(reference, w, h, ppd, vec![Exposure::Ldr])
    }

    /// For HDR-ꟻLIP, at the exposures the reference's luminance gives ([`exposures`]).
    pub fn hdr(reference: &[f32], w: usize, h: usize, ppd: f32) -> FlipReference {
        let (start, stop, count) = exposures(reference);
        let step = (stop - start) / (count - 1) as f32;
        let list = (0..count).map(|i| Exposure::Hdr(2f32.powf(start + i as f32 * step))).collect();
        FlipReference::new(reference, w, h, ppd, list)
    }

    fn new(reference: &[f32], w: usize, h: usize, ppd: f32, list: Vec<Exposure>) -> FlipReference {
        assert_eq!(reference.len(), 3 * w * h, "ꟻLIP: the reference is not {w}×{h}");
        let kernels = Kernels::new(ppd);
        let exposures = list.into_iter().map(|e| (e, Bands::new(reference, w, h, e, &kernels).prepare())).collect();
        FlipReference { w, h, kernels, exposures }
    }

    /// The error map of `test` (linear RGB, the reference's size).
    pub fn map(&self, test: &[f32]) -> Vec<f32> {
        let (w, h) = (self.w, self.h);
        assert_eq!(test.len(), 3 * w * h, "ꟻLIP: the test image is not the reference's size");
        let mut map = vec![0f32; w * h];
        for (exposure, reference) in &self.exposures {
            Bands::new(test, w, h, *exposure, &self.kernels).compare_into(reference, &mut map);
        }
        map
    }
}

/// The LDR-ꟻLIP error map of two linear RGB images (values clamped to [0, 1]).
pub fn flip_ldr_map(reference: &[f32], test: &[f32], w: usize, h: usize, ppd: f32) -> Vec<f32> {
    FlipReference::ldr(reference, w, h, ppd).map(test)
}

/// `(start, stop, count)` exposures of HDR-ꟻLIP for a reference.
pub fn exposures(reference: &[f32]) -> (f32, f32, usize) {
    let k = ACES;
    let t = 0.85f32;
    let (a, b, c) = (k[0] - t * k[3], k[1] - t * k[4], k[2] - t * k[5]);
    let x_max = if a == 0.0 {
        -c / b
    } else {
        let d1 = -0.5f32 * (b / a);
        d1 + (d1 * d1 - c / a).sqrt()
    };
    let mut lum: Vec<f32> = reference
        .chunks_exact(3)
        .map(|p| {
            let l = 0.2126f32 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
            if l.is_nan() {
                0.0
            } else {
                l
            }
        })
        .collect();
    let y_max = lum.iter().fold(-1e30f32, |m, v| if *v > m { *v } else { m });
    if y_max <= 0.0 {
        return (0.0, 0.0, 2); // All-black reference: one exposure, 2⁰.
    }
    let middle = lum.len() / 2;
    let (_, median, _) = lum.select_nth_unstable_by(middle, |a, b| a.total_cmp(b));
    let y_median = median.max(f32::EPSILON);
    let start = (x_max / y_max).log2();
    let stop = (x_max / y_median).log2().max(start);
    let count = 2f32.max((stop - start).ceil()) as usize;
    (start, stop, count)
}

/// The HDR-ꟻLIP error map of two linear RGB images.
pub fn flip_hdr_map(reference: &[f32], test: &[f32], w: usize, h: usize, ppd: f32) -> Vec<f32> {
    FlipReference::hdr(reference, w, h, ppd).map(test)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_build_of_the_passes_gives_the_same_bits() {
        let (w, h) = (67, 41);
        let image = |seed: u32| -> Vec<f32> {
            (0..w * h * 3)
                .map(|i| ((i as u32).wrapping_mul(2_654_435_761) ^ seed) as f32 / u32::MAX as f32 * 3.0)
                .collect()
        };
        let (reference, test) = (image(1), image(2));
        let kernels = Kernels::new(default_ppd());
        let maps: Vec<(Build, Vec<u32>, Vec<u32>)> = [Build::Baseline, Build::Avx2, Build::Avx512]
            .into_iter()
            .filter(|b| b.supported())
            .map(|build| {
                let e = Exposure::Hdr(0.5);
                let prepared = Bands { build, ..Bands::new(&reference, w, h, e, &kernels) }.prepare();
                let mut map = vec![0f32; w * h];
                Bands { build, ..Bands::new(&test, w, h, e, &kernels) }.compare_into(&prepared, &mut map);
                (build, prepared.rows.iter().map(|v| v.to_bits()).collect(), map.iter().map(|v| v.to_bits()).collect())
            })
            .collect();
        for (build, prepared, map) in &maps[1..] {
            assert!(prepared == &maps[0].1 && map == &maps[0].2, "{build:?} differs from the baseline");
        }
    }

    #[test]
    fn correlate_sums_each_pixel_in_tap_order() {
        // Widths around the block size: whole blocks, a tail, and both.
        let k: Vec<f32> = (0..21).map(|j| ((j * 7919) % 23) as f32 / 23.0 - 0.4).collect();
        let rows: Vec<Vec<f32>> =
            (0..k.len()).map(|j| (0..300).map(|x| ((x * 31 + j * 17) % 101) as f32 / 7.0 - 5.0).collect()).collect();
        for n in [1, 63, 64, 65, 128, 200, 300] {
            let mut out = vec![f32::NAN; n];
            correlate(&mut out, &k, |j| &rows[j]);
            for (x, o) in out.iter().enumerate() {
                let sum = k.iter().zip(&rows).fold(0f32, |s, (kw, row)| s + kw * row[x]);
                assert_eq!(o.to_bits(), sum.to_bits(), "pixel {x} of {n}");
            }
        }
    }

    #[test]
    fn default_ppd_is_the_reference_value() {
        assert_eq!(default_ppd().to_bits(), 0x42860A92);
    }

    #[test]
    fn kernels_have_the_published_sizes() {
        let k = Kernels::new(default_ppd());
        assert_eq!((k.y.len(), k.g.len()), (21, 19));
        assert!((k.y.iter().sum::<f32>() - 1.0).abs() < 1e-5);
        assert!((k.dg.iter().filter(|v| **v > 0.0).sum::<f32>() - 1.0).abs() < 1e-5);
    }

    #[test]
    fn identical_images_have_no_error_and_exposures_order() {
        let img: Vec<f32> = (0..16 * 8 * 3).map(|i| (i % 7) as f32 / 7.0).collect();
        assert!(flip_ldr_map(&img, &img, 16, 8, default_ppd()).iter().all(|v| *v == 0.0));
        let (start, stop, n) = exposures(&img);
        assert!(start <= stop && n >= 2);
        assert_eq!(exposures(&[0.0; 12]), (0.0, 0.0, 2));
    }
}
