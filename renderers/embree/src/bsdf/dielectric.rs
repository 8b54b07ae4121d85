//! Glass: Fresnel-weighted reflection and refraction, perfectly smooth or
//! with GGX microfacets (pbrt-v4's DielectricBxDF, radiance transport).

use super::fresnel::{dielectric as fresnel, reflect, refract};
use super::microfacet::Ggx;
use super::{same_hemisphere, BsdfSample};
use crate::math::{vec3, Vec3};

/// A dielectric interface; the normal points to the outside.
#[derive(Debug, Clone, Copy)]
pub struct Dielectric {
    /// The microfacet distribution.
    pub distribution: Ggx,
    /// Index inside / index outside.
    pub eta: f32,
}

const UP: Vec3 = vec3(0.0, 0.0, 1.0);

impl Dielectric {
    /// Smooth, or index 1 (a pass-through interface).
    pub fn is_delta(&self) -> bool {
        self.eta == 1.0 || self.distribution.effectively_smooth()
    }

    /// The half vector of a reflected or refracted pair, facing +z; `None`
    /// for back-facing microfacets.
    fn half_vector(&self, wo: Vec3, wi: Vec3) -> Option<(Vec3, f32, bool)> {
        let (cos_o, cos_i) = (wo.z, wi.z);
        let reflect = cos_i * cos_o > 0.0;
        let etap = if reflect {
            1.0
        } else if cos_o > 0.0 {
            self.eta
        } else {
            1.0 / self.eta
        };
        let wm = wi * etap + wo;
        if cos_i == 0.0 || cos_o == 0.0 || wm.length_squared() == 0.0 {
            return None;
        }
        let wm = wm.normalize().face_forward(UP);
        if wm.dot(wi) * cos_i < 0.0 || wm.dot(wo) * cos_o < 0.0 {
            return None;
        }
        Some((wm, etap, reflect))
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if self.is_delta() {
            return Vec3::ZERO;
        }
        let Some((wm, etap, reflect)) = self.half_vector(wo, wi) else { return Vec3::ZERO };
        let d = &self.distribution;
        let f = fresnel(wo.dot(wm), self.eta);
        let v = if reflect {
            d.d(wm) * d.g(wo, wi) * f / (4.0 * wi.z * wo.z).abs()
        } else {
            let denom = (wi.dot(wm) + wo.dot(wm) / etap).powi(2) * wi.z * wo.z;
            d.d(wm) * (1.0 - f) * d.g(wo, wi) * (wi.dot(wm) * wo.dot(wm) / denom).abs() / (etap * etap)
        };
        if v.is_finite() {
            Vec3::splat(v)
        } else {
            Vec3::ZERO
        }
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.is_delta() {
            return 0.0;
        }
        let Some((wm, etap, reflect)) = self.half_vector(wo, wi) else { return 0.0 };
        let r = fresnel(wo.dot(wm), self.eta);
        let t = 1.0 - r;
        let d = &self.distribution;
        if reflect {
            d.visible_d(wo, wm) / (4.0 * wo.dot(wm).abs()) * r / (r + t)
        } else {
            let denom = (wi.dot(wm) + wo.dot(wm) / etap).powi(2);
            d.visible_d(wo, wm) * wi.dot(wm).abs() / denom * t / (r + t)
        }
    }

    pub(super) fn sample(&self, wo: Vec3, uc: f32, u: [f32; 2]) -> Option<BsdfSample> {
        if self.eta == 1.0 {
            // Index 1: light passes straight through.
            return Some(BsdfSample {
                f: Vec3::ONE / wo.z.abs(),
                wi: -wo,
                pdf: 1.0,
                delta: true,
                eta: 1.0,
                roughness: 0.0,
            });
        }
        if self.distribution.effectively_smooth() {
            let r = fresnel(wo.z, self.eta);
            let t = 1.0 - r;
            if uc < r / (r + t) {
                let wi = vec3(-wo.x, -wo.y, wo.z);
                let f = Vec3::splat(r / wi.z.abs());
                return Some(BsdfSample { f, wi, pdf: r / (r + t), delta: true, eta: 1.0, roughness: 0.0 });
            }
            let (wi, etap) = refract(wo, UP, self.eta)?;
            let f = Vec3::splat(t / wi.z.abs() / (etap * etap));
            return Some(BsdfSample { f, wi, pdf: t / (r + t), delta: true, eta: etap, roughness: 0.0 });
        }
        if wo.z == 0.0 {
            return None;
        }
        let d = &self.distribution;
        let wm = d.sample_wm(wo, u);
        let r = fresnel(wo.dot(wm), self.eta);
        let t = 1.0 - r;
        let roughness = d.alpha();
        if uc < r / (r + t) {
            let wi = reflect(wo, wm);
            if !same_hemisphere(wo, wi) {
                return None;
            }
            let pdf = d.visible_d(wo, wm) / (4.0 * wo.dot(wm).abs()) * r / (r + t);
            let f = d.d(wm) * d.g(wo, wi) * r / (4.0 * wi.z * wo.z).abs();
            Some(BsdfSample { f: Vec3::splat(f), wi, pdf, delta: false, eta: 1.0, roughness })
        } else {
            let (wi, etap) = refract(wo, wm, self.eta)?;
            if same_hemisphere(wo, wi) || wi.z == 0.0 {
                return None;
            }
            let denom = (wi.dot(wm) + wo.dot(wm) / etap).powi(2);
            let pdf = d.visible_d(wo, wm) * wi.dot(wm).abs() / denom * t / (r + t);
            let f = t * d.d(wm) * d.g(wo, wi) * (wi.dot(wm) * wo.dot(wm) / (wi.z * wo.z * denom)).abs() / (etap * etap);
            Some(BsdfSample { f: Vec3::splat(f), wi, pdf, delta: false, eta: etap, roughness })
        }
    }
}

/// A thin sheet of glass (pbrt's `thindielectric`: window panes): light is
/// reflected or passes straight through, after any number of reflections
/// inside the sheet, and never bends.
#[derive(Debug, Clone, Copy)]
pub struct ThinDielectric {
    /// Index inside / index outside.
    pub eta: f32,
}

impl ThinDielectric {
    pub(super) fn sample(&self, wo: Vec3, uc: f32) -> Option<BsdfSample> {
        let cos = wo.z.abs();
        let mut r = super::fresnel::dielectric(cos, self.eta);
        let mut t = 1.0 - r;
        // The light bouncing between the two faces: a geometric series.
        if r < 1.0 {
            r += t * t * r / (1.0 - r * r);
            t = 1.0 - r;
        }
        let (wi, share) = if uc < r { (vec3(-wo.x, -wo.y, wo.z), r) } else { (-wo, t) };
        (cos > 0.0 && share > 0.0).then(|| BsdfSample {
            f: Vec3::splat(share / cos),
            wi,
            pdf: share,
            delta: true,
            eta: 1.0,
            roughness: 0.0,
        })
    }
}
