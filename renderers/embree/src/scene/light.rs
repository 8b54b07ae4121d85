//! Lights: diffuse area lights on triangle meshes and spheres, a constant
//! environment, and the delta lights (point, spot, distant). Each samples
//! a point (or direction) as seen from a receiving point and reports the
//! density in solid angle, for next-event estimation with multiple
//! importance sampling; a delta light's one direction has density 1 and
//! cannot be found by a BSDF sample.

use crate::lanes::{F32s, Mask, Vec3s};
use crate::math::{vec3, Frame, Vec3};
use crate::scene::shape::triangle_area;
use std::f32::consts::PI;

/// A light source.
#[derive(Debug, Clone)]
pub enum Light {
    /// A diffuse emitter on a triangle mesh, sampled by area.
    Mesh {
        /// The shape that carries it.
        shape: u32,
        /// Its triangles, ready for sampling.
        triangles: Vec<LightTriangle>,
        /// Cumulative triangle areas, normalised to end at 1.
        cdf: Vec<f32>,
        /// Total area.
        area: f32,
        /// Emitted radiance.
        radiance: Vec3,
        /// Emits on both sides.
        two_sided: bool,
    },
    /// A diffuse emitter on a sphere, sampled by the cone it subtends.
    Sphere {
        /// The shape that carries it.
        shape: u32,
        /// Centre.
        center: Vec3,
        /// Radius.
        radius: f32,
        /// Emitted radiance.
        radiance: Vec3,
        /// Emits inwards too.
        two_sided: bool,
        /// Normals point inwards (emits inside only, unless two-sided).
        flip: bool,
    },
    /// Constant radiance from every direction.
    Environment {
        /// The radiance.
        radiance: Vec3,
    },
    /// Radiance from every direction, from an image (pbrt's `infinite` with a `filename`).
    ImageEnvironment {
        /// The image, its sampling distribution and placement.
        map: std::sync::Arc<crate::scene::environment::EnvironmentMap>,
    },
    /// Light from one point, the same in every direction (pbrt's `point`).
    Point {
        /// Position.
        position: Vec3,
        /// Radiant intensity (per steradian).
        intensity: Vec3,
    },
    /// A point light limited to a cone, with a smooth fall-off towards its
    /// edge (pbrt's `spot`).
    Spot {
        /// Position.
        position: Vec3,
        /// Unit axis of the cone, away from the light.
        axis: Vec3,
        /// Radiant intensity on the axis.
        intensity: Vec3,
        /// Cosine of the angle where the fall-off begins.
        cos_falloff_start: f32,
        /// Cosine of the cone's half-angle: nothing beyond it.
        cos_falloff_end: f32,
    },
    /// Parallel light from one direction, as from the sun (pbrt's `distant`).
    Distant {
        /// Unit direction towards the light.
        direction: Vec3,
        /// Radiance: the irradiance on a surface facing the light.
        radiance: Vec3,
    },
}

/// A triangle of a mesh light: a vertex, two edges and the emitting side's unit normal.
#[derive(Debug, Clone, Copy)]
pub struct LightTriangle {
    /// First vertex.
    pub p0: Vec3,
    /// Second vertex − first.
    pub e1: Vec3,
    /// Third vertex − first.
    pub e2: Vec3,
    /// Unit normal from the winding (flipped when the mesh says so).
    pub n: Vec3,
    /// Vertex normals, when the mesh has them: the emitting side then
    /// follows the normal interpolated at the point, as at a ray hit.
    pub vertex_normals: Option<[Vec3; 3]>,
}

impl LightTriangle {
    /// The triangles of a static mesh: normals from the winding, flipped
    /// when `flip` (without vertex normals), and the vertex normals.
    pub fn of_mesh(
        positions: &[[f32; 3]],
        indices: &[[u32; 3]],
        normals: Option<&[Vec3]>,
        flip: bool,
    ) -> Vec<LightTriangle> {
        indices
            .iter()
            .map(|idx| {
                let v = |k: usize| Vec3::from_array(positions[idx[k] as usize]);
                let (p0, e1, e2) = (v(0), v(1) - v(0), v(2) - v(0));
                let n = e1.cross(e2).normalize();
                let n = if flip && normals.is_none() { -n } else { n };
                let vertex_normals = normals.map(|ns| idx.map(|i| ns[i as usize]));
                LightTriangle { p0, e1, e2, n, vertex_normals }
            })
            .collect()
    }
}

/// A light sample seen from a receiving point.
#[derive(Debug, Clone, Copy)]
pub struct LightSample {
    /// Unit direction from the receiver to the light.
    pub wi: Vec3,
    /// Distance to the light point (∞ for the environment).
    pub distance: f32,
    /// Radiance arriving along `-wi`.
    pub radiance: Vec3,
    /// Density in solid angle at the receiver (light selection excluded).
    pub pdf: f32,
}

/// pbrt's smooth step: 0 below `a`, 1 above `b`, a cubic between.
fn smooth_step(a: f32, b: f32, x: f32) -> f32 {
    if a == b {
        return if x < a { 0.0 } else { 1.0 };
    }
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

impl Light {
    /// Whether the light is a delta light: reached only by light sampling.
    #[inline]
    pub fn is_delta(&self) -> bool {
        matches!(self, Light::Point { .. } | Light::Spot { .. } | Light::Distant { .. })
    }

    /// Whether the light surrounds the scene (found by rays that miss everything).
    #[inline]
    pub fn is_environment(&self) -> bool {
        matches!(self, Light::Environment { .. } | Light::ImageEnvironment { .. })
    }

    /// Emitted radiance leaving a point with normal `n` towards `w`.
    #[inline]
    pub fn emitted(&self, n: Vec3, w: Vec3) -> Vec3 {
        match self {
            Light::Mesh { radiance, two_sided, .. } | Light::Sphere { radiance, two_sided, .. } => {
                if *two_sided || n.dot(w) > 0.0 {
                    *radiance
                } else {
                    Vec3::ZERO
                }
            }
            Light::Environment { radiance } => *radiance,
            Light::ImageEnvironment { map } => map.radiance(-w),
            Light::Point { .. } | Light::Spot { .. } | Light::Distant { .. } => Vec3::ZERO,
        }
    }

    /// Power, for choosing among lights (`scene_radius` bounds the environment's).
    pub fn power(&self, area: f32, scene_radius: f32) -> f32 {
        match self {
            Light::Mesh { radiance, two_sided, .. } | Light::Sphere { radiance, two_sided, .. } => {
                radiance.average() * area * PI * if *two_sided { 2.0 } else { 1.0 }
            }
            Light::Environment { radiance } => radiance.average() * PI * PI * scene_radius * scene_radius * 4.0,
            Light::ImageEnvironment { map } => map.mean.average() * PI * PI * scene_radius * scene_radius * 4.0,
            Light::Point { intensity, .. } => 4.0 * PI * intensity.average(),
            Light::Spot { intensity, cos_falloff_start, cos_falloff_end, .. } => {
                intensity.average()
                    * 2.0
                    * PI
                    * ((1.0 - cos_falloff_start) + (cos_falloff_start - cos_falloff_end) / 2.0)
            }
            Light::Distant { radiance, .. } => radiance.average() * PI * scene_radius * scene_radius,
        }
    }

    /// Samples the light from receiver `p` with `u` ∈ [0, 1)².
    #[inline]
    pub fn sample(&self, p: Vec3, u: [f32; 2]) -> Option<LightSample> {
        match self {
            Light::Environment { radiance } => {
                let z = 1.0 - 2.0 * u[0];
                let r = (1.0 - z * z).max(0.0).sqrt();
                let phi = 2.0 * PI * u[1];
                let wi = vec3(r * phi.cos(), r * phi.sin(), z);
                Some(LightSample { wi, distance: f32::INFINITY, radiance: *radiance, pdf: 1.0 / (4.0 * PI) })
            }
            Light::Mesh { triangles, cdf, area, radiance, two_sided, .. } => {
                // Pick a triangle by area, then reuse u[0] within it.
                let k = if cdf.len() == 1 { 0 } else { cdf.partition_point(|c| *c <= u[0]).min(cdf.len() - 1) };
                let lo = if k == 0 { 0.0 } else { cdf[k - 1] };
                let t = &triangles[k];
                let (point, [b1, b2]) = triangle_point(t.p0, t.e1, t.e2, [remap(u[0], lo, cdf[k]), u[1]]);
                let n = match t.vertex_normals {
                    Some([n0, n1, n2]) => t.n.face_forward(n0 * (1.0 - b1 - b2) + n1 * b1 + n2 * b2),
                    None => t.n,
                };
                area_sample(p, point, n, 1.0 / area, *radiance, *two_sided)
            }
            Light::Sphere { center, radius, flip, radiance, two_sided, .. } => {
                // The emitting side's normal: outward, or inward under ReverseOrientation.
                let oriented = |n: Vec3| if *flip { -n } else { n };
                let to_center = *center - p;
                let dc2 = to_center.length_squared();
                let r2 = radius * radius;
                if dc2 <= r2 * 1.0001 {
                    // Inside (or on) the sphere: sample by area.
                    let z = 1.0 - 2.0 * u[0];
                    let rr = (1.0 - z * z).max(0.0).sqrt();
                    let phi = 2.0 * PI * u[1];
                    let n = vec3(rr * phi.cos(), rr * phi.sin(), z);
                    let area = 4.0 * PI * r2;
                    return area_sample(p, *center + n * *radius, oriented(n), 1.0 / area, *radiance, *two_sided);
                }
                // Outside: sample the cone of directions the sphere subtends.
                let dc = dc2.sqrt();
                let sin2_max = r2 / dc2;
                let cos_max = (1.0 - sin2_max).max(0.0).sqrt();
                let mut one_minus_cos_max = 1.0 - cos_max;
                let mut cos_theta = (cos_max - 1.0) * u[0] + 1.0;
                let mut sin2_theta = 1.0 - cos_theta * cos_theta;
                if sin2_max < 0.000_685_23 {
                    // Small cone: the series expansion keeps precision.
                    sin2_theta = sin2_max * u[0];
                    cos_theta = (1.0 - sin2_theta).sqrt();
                    one_minus_cos_max = sin2_max / 2.0;
                }
                let frame = Frame::from_normal(to_center / dc);
                let sin_theta = sin2_theta.max(0.0).sqrt();
                let phi = 2.0 * PI * u[1];
                let wi = frame.to_world(vec3(sin_theta * phi.cos(), sin_theta * phi.sin(), cos_theta)).normalize();
                // Distance to the near side of the sphere along wi.
                let b = wi.dot(to_center);
                let disc = (r2 - (dc2 - b * b)).max(0.0);
                let distance = (b - disc.sqrt()).max(0.0);
                let point = p + wi * distance;
                let n = oriented((point - *center).normalize());
                let radiance = self.emitted(n, -wi);
                let pdf = 1.0 / (2.0 * PI * one_minus_cos_max);
                (pdf.is_finite() && distance > 0.0).then_some(LightSample { wi, distance, radiance, pdf })
            }
            Light::ImageEnvironment { map } => {
                let (wi, radiance, pdf) = map.sample(u)?;
                Some(LightSample { wi, distance: f32::INFINITY, radiance, pdf })
            }
            Light::Point { position, intensity } => {
                let (wi, distance) = Self::towards(p, *position)?;
                Some(LightSample { wi, distance, radiance: *intensity / (distance * distance), pdf: 1.0 })
            }
            Light::Spot { position, axis, intensity, cos_falloff_start, cos_falloff_end } => {
                let (wi, distance) = Self::towards(p, *position)?;
                let falloff = smooth_step(*cos_falloff_end, *cos_falloff_start, axis.dot(-wi));
                let radiance = *intensity * (falloff / (distance * distance));
                Some(LightSample { wi, distance, radiance, pdf: 1.0 })
            }
            Light::Distant { direction, radiance } => {
                Some(LightSample { wi: *direction, distance: f32::INFINITY, radiance: *radiance, pdf: 1.0 })
            }
        }
    }

    /// The unit direction and distance from `p` to `to`, unless they coincide.
    fn towards(p: Vec3, to: Vec3) -> Option<(Vec3, f32)> {
        let d = to - p;
        let distance = d.length();
        (distance > 0.0 && distance.is_finite()).then(|| (d / distance, distance))
    }

    /// The solid-angle density of [`Light::sample`] from `p` reaching the
    /// light point `point` with normal `n` along `wi`.
    pub fn pdf(&self, p: Vec3, wi: Vec3, point: Vec3, n: Vec3) -> f32 {
        let area_pdf = |pdf_area: f32| {
            let dist2 = (point - p).length_squared();
            let cos = n.dot(wi).abs();
            if cos == 0.0 {
                0.0
            } else {
                pdf_area * dist2 / cos
            }
        };
        match self {
            Light::Environment { .. } => 1.0 / (4.0 * PI),
            Light::ImageEnvironment { map } => map.pdf(wi),
            Light::Mesh { area, .. } => area_pdf(1.0 / area),
            Light::Sphere { center, radius, .. } => {
                let dc2 = (*center - p).length_squared();
                let r2 = radius * radius;
                if dc2 <= r2 * 1.0001 {
                    return area_pdf(1.0 / (4.0 * PI * r2));
                }
                let sin2_max = r2 / dc2;
                let one_minus_cos_max =
                    if sin2_max < 0.000_685_23 { sin2_max / 2.0 } else { 1.0 - (1.0 - sin2_max).max(0.0).sqrt() };
                1.0 / (2.0 * PI * one_minus_cos_max)
            }
            // A BSDF sample never finds a delta light.
            Light::Point { .. } | Light::Spot { .. } | Light::Distant { .. } => 0.0,
        }
    }
}

/// `u` ∈ [`lo`, `hi`) stretched back to [0, 1): the part of a random
/// number left once it chose the interval.
#[inline(always)]
pub fn remap(u: f32, lo: f32, hi: f32) -> f32 {
    ((u - lo) / (hi - lo)).clamp(0.0, 1.0 - f32::EPSILON)
}

/// The point of the triangle (`p0`, `p0 + e1`, `p0 + e2`) that `u` ∈ [0, 1)²
/// picks uniformly by area, and its barycentrics (b1, b2).
#[inline(always)]
pub fn triangle_point(p0: Vec3, e1: Vec3, e2: Vec3, u: [f32; 2]) -> (Vec3, [f32; 2]) {
    let s = u[0].sqrt();
    // Barycentrics (1 − √u₀, u₁√u₀, (1 − u₁)√u₀): uniform over the triangle.
    let (b1, b2) = (u[1] * s, (1.0 - u[1]) * s);
    (p0 + e1 * b1 + e2 * b2, [b1, b2])
}

/// A sample of a diffuse emitter at `point` (normal `n`) seen from `p`,
/// the point having been chosen with density `pdf_area` by area.
#[inline(always)]
pub fn area_sample(
    p: Vec3,
    point: Vec3,
    n: Vec3,
    pdf_area: f32,
    radiance: Vec3,
    two_sided: bool,
) -> Option<LightSample> {
    let d = point - p;
    let dist2 = d.length_squared();
    let distance = dist2.sqrt();
    if !(distance > 0.0) {
        return None;
    }
    let wi = d / distance;
    let cos = n.dot(wi).abs();
    if cos == 0.0 {
        return None;
    }
    let pdf = pdf_area * dist2 / cos;
    // As `Light::emitted` towards −wi.
    let radiance = if two_sided || n.dot(-wi) > 0.0 { radiance } else { Vec3::ZERO };
    (pdf.is_finite() && pdf > 0.0).then_some(LightSample { wi, distance, radiance, pdf })
}

/// Light samples in lanes (see [`LightSample`]); `ok` marks the lanes that have one.
#[derive(Debug, Clone, Copy, Default)]
pub struct LightSamples {
    /// The lanes with a sample.
    pub ok: Mask,
    /// Unit directions to the light.
    pub wi: Vec3s,
    /// Distances to the light points.
    pub distance: F32s,
    /// Radiance arriving along −wi.
    pub radiance: Vec3s,
    /// Densities in solid angle.
    pub pdf: F32s,
}

impl LightSamples {
    /// Lane `k`'s sample, if it has one.
    pub fn lane(&self, k: usize) -> Option<LightSample> {
        self.ok.0[k].then(|| LightSample {
            wi: self.wi.lane(k),
            distance: self.distance.0[k],
            radiance: self.radiance.lane(k),
            pdf: self.pdf.0[k],
        })
    }

    /// Sets lane `k`'s sample.
    pub fn set_lane(&mut self, k: usize, sample: Option<LightSample>) {
        self.ok.0[k] = sample.is_some();
        let s = sample.unwrap_or(LightSample { wi: Vec3::ZERO, distance: 0.0, radiance: Vec3::ZERO, pdf: 0.0 });
        self.wi.set_lane(k, s.wi);
        self.distance.0[k] = s.distance;
        self.radiance.set_lane(k, s.radiance);
        self.pdf.0[k] = s.pdf;
    }
}

/// [`triangle_point`] in lanes (the point only).
#[inline(always)]
pub fn triangle_point_lanes(p0: Vec3s, e1: Vec3s, e2: Vec3s, u: [F32s; 2]) -> Vec3s {
    let s = u[0].sqrt();
    let (b1, b2) = (u[1] * s, (F32s::splat(1.0) - u[1]) * s);
    p0 + e1 * b1 + e2 * b2
}

/// [`area_sample`] in lanes.
#[inline(always)]
pub fn area_sample_lanes(
    p: Vec3s,
    point: Vec3s,
    n: Vec3s,
    pdf_area: F32s,
    radiance: Vec3s,
    two_sided: Mask,
) -> LightSamples {
    let zero = F32s::splat(0.0);
    let d = point - p;
    let dist2 = d.length_squared();
    let distance = dist2.sqrt();
    let wi = d * (F32s::splat(1.0) / distance);
    let cos = n.dot(wi).abs();
    let pdf = pdf_area * dist2 / cos;
    let radiance = Vec3s::select(two_sided | n.dot(-wi).gt(zero), radiance, Vec3s::ZERO);
    let ok = distance.gt(zero) & !cos.eq(zero) & pdf.is_finite() & pdf.gt(zero);
    LightSamples { ok, wi, distance, radiance, pdf }
}

/// The normalised cumulative areas of a mesh's triangles.
pub fn area_cdf(positions: &[[f32; 3]], indices: &[[u32; 3]]) -> (Vec<f32>, f32) {
    let mut sum = 0f64;
    let mut cdf: Vec<f64> = indices
        .iter()
        .map(|i| {
            sum += triangle_area(positions, i) as f64;
            sum
        })
        .collect();
    for c in &mut cdf {
        *c /= sum.max(f64::MIN_POSITIVE);
    }
    (cdf.into_iter().map(|c| c as f32).collect(), sum as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The mean of `f` over a stratified grid of `n × n` points of [0, 1)².
    fn mean_over_square(n: usize, mut f: impl FnMut([f32; 2]) -> f64) -> f64 {
        let mut sum = 0.0;
        for i in 0..n {
            for j in 0..n {
                sum += f([(i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32]);
            }
        }
        sum / (n * n) as f64
    }

    /// Irradiance E at `p` (normal `n`) from light samples, and the check that
    /// [`Light::pdf`] agrees with each sample's density.
    fn estimate_irradiance(light: &Light, p: Vec3, n: Vec3, point_of: impl Fn(&LightSample) -> (Vec3, Vec3)) -> f64 {
        mean_over_square(400, |u| {
            let Some(s) = light.sample(p, u) else { return 0.0 };
            let (point, normal) = point_of(&s);
            let pdf = light.pdf(p, s.wi, point, normal);
            assert!((pdf - s.pdf).abs() <= 1e-3 * s.pdf, "pdf {pdf} vs sampled {}", s.pdf);
            (s.radiance.x * s.wi.dot(n).max(0.0) / s.pdf) as f64
        })
    }

    #[test]
    fn a_quad_light_gives_lamberts_irradiance() {
        // A unit square at height 1 facing down, seen from the origin facing up.
        let positions = [[-0.5, 1.0, -0.5], [0.5, 1.0, -0.5], [0.5, 1.0, 0.5], [-0.5, 1.0, 0.5]];
        let indices = [[0, 1, 2], [0, 2, 3]];
        let (cdf, area) = area_cdf(&positions, &indices);
        let triangles = LightTriangle::of_mesh(&positions, &indices, None, false);
        assert!(triangles.iter().all(|t| t.n.y == -1.0), "the winding faces down");
        let light = Light::Mesh { shape: 0, triangles, cdf, area, radiance: Vec3::ONE, two_sided: false };
        let (p, n) = (Vec3::ZERO, vec3(0.0, 1.0, 0.0));
        let e = estimate_irradiance(&light, p, n, |s| (p + s.wi * s.distance, vec3(0.0, -1.0, 0.0)));
        // Lambert: E = L/2 Σ βᵢ n·(Rᵢ × Rᵢ₊₁)/|Rᵢ × Rᵢ₊₁| over the polygon's edges.
        let r: Vec<Vec3> = positions.iter().map(|v| Vec3::from_array(*v).normalize()).collect();
        let exact: f64 = (0..4)
            .map(|i| {
                let (a, b) = (r[i], r[(i + 1) % 4]);
                (a.dot(b).acos() * a.cross(b).normalize().dot(n).abs() / 2.0) as f64
            })
            .sum();
        assert!((e - exact).abs() < 2e-3 * exact, "estimated {e}, Lambert {exact}");
    }

    #[test]
    fn a_sphere_light_gives_its_closed_form_irradiance_outside_and_inside() {
        let light = Light::Sphere {
            shape: 0,
            center: vec3(0.0, 3.0, 1.0),
            radius: 0.8,
            radiance: Vec3::ONE,
            two_sided: true,
            flip: false,
        };
        let center = vec3(0.0, 3.0, 1.0);
        let normal_at = |s: &LightSample, p: Vec3| {
            let point = p + s.wi * s.distance;
            (point, (point - center).normalize())
        };
        let (p, n) = (Vec3::ZERO, vec3(0.0, 1.0, 0.0));
        let e = estimate_irradiance(&light, p, n, |s| normal_at(s, p));
        // E = π L sin²α cos θ for a sphere wholly above the horizon.
        let d = center.length();
        let exact = (PI * (0.8 / d) * (0.8 / d) * (center.y / d)) as f64;
        assert!((e - exact).abs() < 2e-3 * exact, "estimated {e}, exact {exact}");
        // Inside a two-sided emitting sphere, the radiance arrives from everywhere: E = π L.
        let inside = center + vec3(0.1, -0.2, 0.3);
        let e = estimate_irradiance(&light, inside, n, |s| normal_at(s, inside));
        assert!((e - PI as f64).abs() < 0.02 * PI as f64, "inside: {e}");
        // A one-sided sphere under ReverseOrientation is a dome: it lights its inside only.
        let dome = Light::Sphere { shape: 0, center, radius: 0.8, radiance: Vec3::ONE, two_sided: false, flip: true };
        let inward = |s: &LightSample, p: Vec3| {
            let (point, n) = normal_at(s, p);
            (point, -n)
        };
        let e = estimate_irradiance(&dome, inside, n, |s| inward(s, inside));
        assert!((e - PI as f64).abs() < 0.02 * PI as f64, "inside the dome: {e}");
        assert_eq!(estimate_irradiance(&dome, p, n, |s| inward(s, p)), 0.0, "outside the dome");
    }
}
