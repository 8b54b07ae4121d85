//! The Trowbridge–Reitz (GGX) microfacet distribution with visible-normal
//! sampling (Heitz 2018), in the local shading frame (z = normal).

use crate::math::{vec3, Vec3};
use std::f32::consts::PI;

/// An anisotropic GGX distribution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ggx {
    /// Roughness along the tangent.
    pub alpha_x: f32,
    /// Roughness along the bitangent.
    pub alpha_y: f32,
}

/// Below this the surface is treated as perfectly smooth (pbrt-v4's threshold).
pub const SMOOTH_ALPHA: f32 = 1e-3;

/// Largest roughness: beyond it the distribution is numerically flat anyway.
const MAX_ALPHA: f32 = 1e3;

impl Ggx {
    /// A distribution with the given α (clamped to a range that stays finite).
    pub fn new(alpha_x: f32, alpha_y: f32) -> Ggx {
        let clamp = |a: f32| if a.is_nan() { 0.0 } else { a.clamp(0.0, MAX_ALPHA) };
        Ggx { alpha_x: clamp(alpha_x), alpha_y: clamp(alpha_y) }
    }

    /// pbrt-v4's roughness → α (`√r`).
    pub fn roughness_to_alpha(r: f32) -> f32 {
        r.max(0.0).sqrt()
    }

    /// Whether sampling should use the mirror direction instead.
    pub fn effectively_smooth(&self) -> bool {
        self.alpha_x.max(self.alpha_y) < SMOOTH_ALPHA
    }

    /// The mean α, compared with a layout's roughness threshold.
    pub fn alpha(&self) -> f32 {
        0.5 * (self.alpha_x + self.alpha_y)
    }

    /// The normal distribution D(wm).
    pub fn d(&self, wm: Vec3) -> f32 {
        let cos2 = wm.z * wm.z;
        let sin2 = (1.0 - cos2).max(0.0);
        if cos2 == 0.0 {
            return 0.0;
        }
        let tan2 = sin2 / cos2;
        let (ax, ay) = (self.alpha_x, self.alpha_y);
        let e = if sin2 > 0.0 { tan2 * (wm.x * wm.x / (ax * ax) + wm.y * wm.y / (ay * ay)) / sin2 } else { 0.0 };
        let d = 1.0 / (PI * ax * ay * cos2 * cos2 * (1.0 + e) * (1.0 + e));
        if d.is_finite() {
            d
        } else {
            0.0
        }
    }

    /// Smith's Λ(w).
    pub fn lambda(&self, w: Vec3) -> f32 {
        let cos2 = w.z * w.z;
        if cos2 == 0.0 {
            return f32::INFINITY;
        }
        let a2_tan2 = (w.x * w.x * self.alpha_x * self.alpha_x + w.y * w.y * self.alpha_y * self.alpha_y) / cos2;
        ((1.0 + a2_tan2).sqrt() - 1.0) / 2.0
    }

    /// Masking G1(w).
    pub fn g1(&self, w: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(w))
    }

    /// Masking-shadowing G(wo, wi).
    pub fn g(&self, wo: Vec3, wi: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(wo) + self.lambda(wi))
    }

    /// The density of visible normals from `w`: G1(w) / |cos w| · D(wm) · |w·wm|.
    pub fn visible_d(&self, w: Vec3, wm: Vec3) -> f32 {
        if w.z == 0.0 {
            return 0.0;
        }
        let v = self.g1(w) / w.z.abs() * self.d(wm) * w.dot(wm).abs();
        if v.is_finite() {
            v
        } else {
            0.0
        }
    }

    /// Samples a visible normal from `w` with `u` ∈ [0, 1)².
    pub fn sample_wm(&self, w: Vec3, u: [f32; 2]) -> Vec3 {
        // Stretch the view direction to the hemisphere configuration.
        let mut wh = vec3(self.alpha_x * w.x, self.alpha_y * w.y, w.z).normalize();
        if wh.z < 0.0 {
            wh = -wh;
        }
        let t1 = if wh.z < 0.99999 { vec3(0.0, 0.0, 1.0).cross(wh).normalize() } else { vec3(1.0, 0.0, 0.0) };
        let t2 = wh.cross(t1);
        // A point on the unit disk, warped to the visible hemisphere's projection.
        let r = u[0].sqrt();
        let phi = 2.0 * PI * u[1];
        let (px, mut py) = (r * phi.cos(), r * phi.sin());
        let h = (1.0 - px * px).max(0.0).sqrt();
        let s = (1.0 + wh.z) / 2.0;
        py = (1.0 - s) * h + s * py;
        let pz = (1.0 - px * px - py * py).max(0.0).sqrt();
        let nh = t1 * px + t2 * py + wh * pz;
        // Unstretch.
        vec3(self.alpha_x * nh.x, self.alpha_y * nh.y, nh.z.max(1e-6)).normalize()
    }
}
