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
//! Departures, both documented: the mean is summed in f64 (the package sums
//! in f32, which drifts on large images by about 1e−6); an all-black
//! reference, on which the package stops the process, uses the single
//! exposure 0.

// The published constants are kept as written, even where f32 holds fewer digits.
#![allow(clippy::excessive_precision)]

use rayon::prelude::*;

const PI: f32 = std::f32::consts::PI;

/// The default pixels per degree: 0.7 m · (3840 px / 0.7 m) · π/180.
pub fn default_ppd() -> f32 {
    0.7f32 * (3840.0f32 / 0.7f32) * (PI / 180.0f32)
}

/// A planar image: one Vec per channel.
type Planes = [Vec<f32>; 3];

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

fn mat(m: &[[f32; 3]; 3], v: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

fn xyz_to_ycxcz(v: [f32; 3]) -> [f32; 3] {
    let (x, y, z) = (v[0] * INV_WHITE[0], v[1] * INV_WHITE[1], v[2] * INV_WHITE[2]);
    [116.0 * y - 16.0, 500.0 * (x - y), 200.0 * (y - z)]
}

fn ycxcz_to_xyz(v: [f32; 3]) -> [f32; 3] {
    let yp = (v[0] + 16.0) / 116.0;
    let (cx, cz) = (v[1] / 500.0, v[2] / 200.0);
    [(yp + cx) * WHITE[0], yp * WHITE[1], (yp - cz) * WHITE[2]]
}

fn xyz_to_lab(v: [f32; 3]) -> [f32; 3] {
    let delta = 6.0f32 / 29.0;
    let delta_square = delta * delta;
    let delta_cube = delta * delta_square;
    let factor = 1.0 / (3.0 * delta_square);
    let term = 4.0f32 / 29.0;
    let f = |t: f32| if t > delta_cube { t.powf(1.0 / 3.0) } else { factor * t + term };
    let (fx, fy, fz) = (f(v[0] * INV_WHITE[0]), f(v[1] * INV_WHITE[1]), f(v[2] * INV_WHITE[2]));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

fn hunt(lab: [f32; 3]) -> [f32; 3] {
    [lab[0], (0.01 * lab[0]) * lab[1], (0.01 * lab[0]) * lab[2]]
}

fn hyab(a: [f32; 3], b: [f32; 3]) -> f32 {
    let (da, db) = (a[1] - b[1], a[2] - b[2]);
    (a[0] - b[0]).abs() + (da * da + db * db).sqrt()
}

/// A 1-D correlation with clamp-to-edge borders, rows or columns.
fn filter_rows(input: &[f32], w: usize, h: usize, k: &[f32]) -> Vec<f32> {
    let r = k.len() / 2;
    let mut out = vec![0f32; w * h];
    out.par_chunks_mut(w).zip(input.par_chunks(w)).for_each(|(o, row)| {
        for (x, v) in o.iter_mut().enumerate() {
            let mut sum = 0f32;
            for (j, kw) in k.iter().enumerate() {
                let xi = (x as isize + j as isize - r as isize).clamp(0, w as isize - 1) as usize;
                sum += kw * row[xi];
            }
            *v = sum;
        }
    });
    out
}

fn filter_columns(input: &[f32], w: usize, h: usize, k: &[f32]) -> Vec<f32> {
    let r = k.len() / 2;
    let mut out = vec![0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, o)| {
        // Accumulate whole rows in tap order: each pixel still adds its terms in order.
        for (j, kw) in k.iter().enumerate() {
            let yi = (y as isize + j as isize - r as isize).clamp(0, h as isize - 1) as usize;
            for (v, s) in o.iter_mut().zip(&input[yi * w..yi * w + w]) {
                *v += kw * s;
            }
        }
    });
    out
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
}

/// YCxCz planes of a linear RGB image.
fn ycxcz_planes(rgb: &[f32]) -> Planes {
    let n = rgb.len() / 3;
    let mut planes: Planes = std::array::from_fn(|_| vec![0f32; n]);
    for (i, p) in rgb.chunks_exact(3).enumerate() {
        let v = xyz_to_ycxcz(mat(&TO_XYZ, [p[0], p[1], p[2]]));
        for c in 0..3 {
            planes[c][i] = v[c];
        }
    }
    planes
}

/// The Hunt-adjusted Lab of the CSF-filtered image, per pixel.
fn filtered_hunt(planes: &Planes, w: usize, h: usize, k: &Kernels) -> Vec<[f32; 3]> {
    let sep = |p: &[f32], kk: &[f32]| filter_columns(&filter_rows(p, w, h, kk), w, h, kk);
    let y = sep(&planes[0], &k.y);
    let cx = sep(&planes[1], &k.cx);
    let (cz1, cz2) = (sep(&planes[2], &k.cz1), sep(&planes[2], &k.cz2));
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let rgb = mat(&FROM_XYZ, ycxcz_to_xyz([y[i], cx[i], cz1[i] + cz2[i]]));
            let clamped = rgb.map(clamp01);
            hunt(xyz_to_lab(mat(&TO_XYZ, clamped)))
        })
        .collect()
}

/// Edges and points of the normalised luminance, per pixel.
fn features(yc: &[f32], w: usize, h: usize, k: &Kernels) -> (Vec<f32>, Vec<f32>) {
    let yn: Vec<f32> = yc.iter().map(|v| v * (1.0 / 116.0) + 16.0 / 116.0).collect();
    let hd = filter_rows(&yn, w, h, &k.dg);
    let hdd = filter_rows(&yn, w, h, &k.ddg);
    let hg = filter_rows(&yn, w, h, &k.g);
    let dx = filter_columns(&hd, w, h, &k.g);
    let ddx = filter_columns(&hdd, w, h, &k.g);
    let dy = filter_columns(&hg, w, h, &k.dg);
    let ddy = filter_columns(&hg, w, h, &k.ddg);
    let edge = dx.iter().zip(&dy).map(|(a, b)| (a * a + b * b).sqrt()).collect();
    let point = ddx.iter().zip(&ddy).map(|(a, b)| (a * a + b * b).sqrt()).collect();
    (edge, point)
}

/// `min(max(v, 0), 1)` with NaN becoming 0, as the reference does it.
fn clamp01(v: f32) -> f32 {
    let v = if v > 0.0 { v } else { 0.0 };
    if v > 1.0 {
        1.0
    } else {
        v
    }
}

/// The LDR-ꟻLIP error map of two linear RGB images (values clamped to [0, 1]).
pub fn flip_ldr_map(reference: &[f32], test: &[f32], w: usize, h: usize, ppd: f32) -> Vec<f32> {
    let k = Kernels::new(ppd);
    let clamp = |img: &[f32]| img.iter().map(|v| clamp01(*v)).collect::<Vec<f32>>();
    let (r, t) = (ycxcz_planes(&clamp(reference)), ycxcz_planes(&clamp(test)));
    let (hr, ht) = (filtered_hunt(&r, w, h, &k), filtered_hunt(&t, w, h, &k));
    let (er, pr) = features(&r[0], w, h, &k);
    let (et, pt) = features(&t[0], w, h, &k);

    // The largest colour difference: pure green against pure blue.
    let green = hunt(xyz_to_lab(mat(&TO_XYZ, [0.0, 1.0, 0.0])));
    let blue = hunt(xyz_to_lab(mat(&TO_XYZ, [0.0, 0.0, 1.0])));
    let cmax = hyab(green, blue).powf(0.7);
    let (pc, ptt) = (0.4f32, 0.95f32);
    let pccmax = pc * cmax;
    (0..w * h)
        .into_par_iter()
        .map(|i| {
            let mut cd = hyab(hr[i], ht[i]).powf(0.7);
            cd = if cd < pccmax { cd * (ptt / pccmax) } else { ptt + ((cd - pccmax) / (cmax - pccmax)) * (1.0 - ptt) };
            let fd = ((1.0f32 / 2.0f32.sqrt()) * (er[i] - et[i]).abs().max((pr[i] - pt[i]).abs())).powf(0.5);
            cd.powf(1.0 - fd)
        })
        .collect()
}

/// ACES (fitted, with the 0.6 pre-exposure cancelled), per channel.
const ACES: [f32; 6] = [0.6 * 0.6 * 2.51, 0.6 * 0.03, 0.0, 0.6 * 0.6 * 2.43, 0.6 * 0.59, 0.14];

fn tone_map_aces(c: f32) -> f32 {
    let k = ACES;
    ((c * c) * k[0] + c * k[1] + k[2]) / ((c * c) * k[3] + c * k[4] + k[5])
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
    let (start, stop, count) = exposures(reference);
    let step = (stop - start) / (count - 1) as f32;
    let mut out = vec![0f32; w * h];
    for i in 0..count {
        let m = 2f32.powf(start + i as f32 * step);
        let expose = |img: &[f32]| img.iter().map(|v| clamp01(tone_map_aces(v * m))).collect::<Vec<f32>>();
        let e = flip_ldr_map(&expose(reference), &expose(test), w, h, ppd);
        for (o, v) in out.iter_mut().zip(e) {
            if v > *o {
                *o = v;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

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
