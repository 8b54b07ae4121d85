//! Image-based environment light: radiance from every direction, read from
//! a square image in pbrt-v4's equal-area octahedral mapping (Clarberg,
//! "Fast Equal-Area Mapping of the (Hemi)Sphere using SIMD", JGT 2008),
//! and sampled in proportion to the image.
//!
//! The mapping keeps area: each pixel covers the same solid angle, 4π/N.
//! Radiance is each pixel's value (nearest lookup, as pbrt-v4's
//! `ImageInfiniteLight`), so sampling the pixels in proportion to their
//! mean channel gives a density that follows the radiance exactly.

use crate::math::{vec3, Affine, Vec3};
use std::f32::consts::{FRAC_PI_4, PI};

/// The point of the unit square that the equal-area mapping sends to `d`
/// (a unit vector).
pub fn sphere_to_square(d: Vec3) -> [f32; 2] {
    let (x, y, z) = (d.x.abs(), d.y.abs(), d.z.abs());
    let r = (1.0 - z).max(0.0).sqrt();
    let (a, b) = (x.max(y), x.min(y));
    let ratio = if a == 0.0 { 0.0 } else { b / a };
    let mut phi = ratio.atan() * (2.0 / PI);
    if x < y {
        phi = 1.0 - phi;
    }
    let mut v = phi * r;
    let mut u = r - v;
    if d.z < 0.0 {
        // The lower hemisphere folds over the square's corners.
        (u, v) = (1.0 - v, 1.0 - u);
    }
    let (u, v) = (u.copysign(d.x), v.copysign(d.y));
    [((u + 1.0) * 0.5).clamp(0.0, 1.0), ((v + 1.0) * 0.5).clamp(0.0, 1.0)]
}

/// The unit vector the equal-area mapping sends square point `p` ∈ [0, 1]² to.
pub fn square_to_sphere(p: [f32; 2]) -> Vec3 {
    let (u, v) = (2.0 * p[0] - 1.0, 2.0 * p[1] - 1.0);
    let (up, vp) = (u.abs(), v.abs());
    let signed_distance = 1.0 - (up + vp);
    let r = 1.0 - signed_distance.abs();
    let phi = if r == 0.0 { 1.0 } else { (vp - up) / r + 1.0 } * FRAC_PI_4;
    let z = (1.0 - r * r).copysign(signed_distance);
    let scale = r * (2.0 - r * r).max(0.0).sqrt();
    vec3(phi.cos().copysign(u) * scale, phi.sin().copysign(v) * scale, z)
}

/// A loaded environment image, ready for lookups and sampling.
#[derive(Debug)]
pub struct EnvironmentMap {
    /// Side of the square image, in pixels.
    size: usize,
    /// Row-major radiance (scale applied).
    pixels: Vec<Vec3>,
    /// Cumulative row weights (normalised to end at 1), then per row the cumulative column weights.
    rows_cdf: Vec<f32>,
    columns_cdf: Vec<f32>,
    /// Mean of the pixels' weights (the mean channel).
    mean_weight: f32,
    /// Light space to world, and back (rotations and uniform scales).
    to_world: Affine,
    to_light: Affine,
    /// Mean radiance over the sphere, for choosing among lights.
    pub mean: Vec3,
}

fn weight(v: Vec3) -> f32 {
    v.average().max(0.0)
}

/// Cumulative sums of `w`, normalised to end at 1 (uniform when they are all 0).
fn cdf(w: impl Iterator<Item = f32>) -> (Vec<f32>, f64) {
    let mut sum = 0f64;
    let mut c: Vec<f64> = w
        .map(|w| {
            sum += w as f64;
            sum
        })
        .collect();
    let n = c.len();
    for (i, v) in c.iter_mut().enumerate() {
        *v = if sum > 0.0 { *v / sum } else { (i + 1) as f64 / n as f64 };
    }
    (c.into_iter().map(|v| v as f32).collect(), sum)
}

/// The index `i` with cdf[i-1] ≤ u < cdf[i], and `u`'s place within it.
fn pick(cdf: &[f32], u: f32) -> (usize, f32) {
    let i = cdf.partition_point(|c| *c <= u).min(cdf.len() - 1);
    let lo = if i == 0 { 0.0 } else { cdf[i - 1] };
    let width = cdf[i] - lo;
    (i, if width > 0.0 { ((u - lo) / width).clamp(0.0, 1.0 - f32::EPSILON) } else { 0.5 })
}

impl EnvironmentMap {
    /// An environment from a square image of `size × size` pixels
    /// (row-major, row 0 at v = 0), placed by `light_to_world`.
    pub fn new(size: usize, pixels: Vec<Vec3>, light_to_world: &crate::math::Transform) -> EnvironmentMap {
        assert_eq!(pixels.len(), size * size, "a square image");
        let row_weights = pixels.chunks_exact(size).map(|row| row.iter().map(|p| weight(*p)).sum::<f32>());
        let (rows_cdf, total) = cdf(row_weights);
        let columns_cdf = pixels.chunks_exact(size).flat_map(|row| cdf(row.iter().map(|p| weight(*p))).0).collect();
        let n = (size * size) as f64;
        let mean = pixels.iter().fold([0f64; 3], |a, p| [a[0] + p.x as f64, a[1] + p.y as f64, a[2] + p.z as f64]);
        EnvironmentMap {
            size,
            rows_cdf,
            columns_cdf,
            mean_weight: (total / n) as f32,
            to_world: Affine::new(light_to_world),
            to_light: Affine::new(&light_to_world.inverse()),
            mean: vec3((mean[0] / n) as f32, (mean[1] / n) as f32, (mean[2] / n) as f32),
            pixels,
        }
    }

    fn pixel_of(&self, uv: [f32; 2]) -> usize {
        let at = |t: f32| ((t * self.size as f32) as usize).min(self.size - 1);
        at(uv[1]) * self.size + at(uv[0])
    }

    fn uv_of(&self, world_dir: Vec3) -> [f32; 2] {
        sphere_to_square(self.to_light.vector(world_dir).normalize())
    }

    /// Radiance arriving from world direction `dir` (towards the environment).
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        self.pixels[self.pixel_of(self.uv_of(dir))]
    }

    /// Density in solid angle of [`EnvironmentMap::sample`] choosing `dir`.
    pub fn pdf(&self, dir: Vec3) -> f32 {
        self.density(self.pixels[self.pixel_of(self.uv_of(dir))])
    }

    /// The density in solid angle of sampling a pixel of radiance `radiance`.
    fn density(&self, radiance: Vec3) -> f32 {
        if !(self.mean_weight > 0.0) {
            return 1.0 / (4.0 * PI);
        }
        // Density over the square, then over the sphere: the mapping's Jacobian is 4π everywhere.
        weight(radiance) / self.mean_weight / (4.0 * PI)
    }

    /// A direction towards the environment, in proportion to its radiance:
    /// (world direction, radiance, density in solid angle).
    pub fn sample(&self, u: [f32; 2]) -> Option<(Vec3, Vec3, f32)> {
        let (row, v) = pick(&self.rows_cdf, u[1]);
        let (column, s) = pick(&self.columns_cdf[row * self.size..][..self.size], u[0]);
        let uv = [(column as f32 + s) / self.size as f32, (row as f32 + v) / self.size as f32];
        let dir = self.to_world.vector(square_to_sphere(uv)).normalize();
        let radiance = self.pixels[row * self.size + column];
        let pdf = self.density(radiance);
        (pdf > 0.0 && dir.is_finite()).then_some((dir, radiance, pdf))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mapping_round_trips_and_keeps_area() {
        // Uniform points on the square land uniformly on the sphere:
        // E[z] = 0, E[z²] = 1/3, E[x·y] = 0; and each maps back to itself.
        let n = 400;
        let (mut z1, mut z2, mut xy) = (0f64, 0f64, 0f64);
        for i in 0..n {
            for j in 0..n {
                let p = [(i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32];
                let d = square_to_sphere(p);
                assert!((d.length() - 1.0).abs() < 1e-5, "{p:?} → {d:?}");
                let q = sphere_to_square(d);
                assert!((q[0] - p[0]).abs() < 2e-4 && (q[1] - p[1]).abs() < 2e-4, "{p:?} → {d:?} → {q:?}");
                z1 += d.z as f64;
                z2 += (d.z * d.z) as f64;
                xy += (d.x * d.y) as f64;
            }
        }
        let m = (n * n) as f64;
        assert!((z1 / m).abs() < 1e-3 && (z2 / m - 1.0 / 3.0).abs() < 1e-3 && (xy / m).abs() < 1e-3);
        // The poles and the equator's axes.
        assert!((square_to_sphere([0.5, 0.5]) - vec3(0.0, 0.0, 1.0)).length() < 1e-6);
        assert!(square_to_sphere([0.0, 0.0]).z == -1.0);
    }

    #[test]
    fn sampling_density_matches_the_radiance_and_integrates_to_one() {
        // A 16 × 16 map: dark everywhere but a bright block.
        let size = 16;
        let pixels: Vec<Vec3> = (0..size * size)
            .map(|i| if (i / size) % 16 < 4 && (i % size) < 5 { Vec3::splat(50.0) } else { Vec3::splat(0.1) })
            .collect();
        let map = EnvironmentMap::new(size, pixels, &crate::math::Transform::IDENTITY);
        // ∫ pdf dω over uniform sphere directions is 1 (cells aligned with the pixels).
        let n = 256;
        let mut integral = 0f64;
        for i in 0..n {
            for j in 0..n {
                let d = square_to_sphere([(i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32]);
                integral += map.pdf(d) as f64 * 4.0 * std::f64::consts::PI / (n * n) as f64;
            }
        }
        assert!((integral - 1.0).abs() < 1e-3, "{integral}");
        // Each sample's radiance / pdf averages to the map's irradiance integral 4π·mean.
        let mut est = 0f64;
        let m = 64;
        for i in 0..m {
            for j in 0..m {
                let (d, l, pdf) = map.sample([(i as f32 + 0.5) / m as f32, (j as f32 + 0.5) / m as f32]).unwrap();
                assert_eq!(l, map.radiance(d), "the sample's radiance is the lookup in its direction");
                assert!((pdf - map.pdf(d)).abs() < 1e-4 * pdf, "pdf {pdf} vs {}", map.pdf(d));
                est += (l.x / pdf) as f64;
            }
        }
        let want = 4.0 * std::f64::consts::PI * map.mean.x as f64;
        assert!((est / (m * m) as f64 - want).abs() < 1e-3 * want, "{} vs {want}", est / (m * m) as f64);
    }
}
