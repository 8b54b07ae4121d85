//! Metals: a mirror when smooth, GGX microfacets when rough, with the
//! complex Fresnel reflectance of `eta + i·k` (pbrt-v4's ConductorBxDF).

use super::fresnel::{conductor as fresnel, reflect};
use super::microfacet::Ggx;
use super::{same_hemisphere, BsdfSample};
use crate::math::{vec3, Vec3};

/// A conductor.
#[derive(Debug, Clone, Copy)]
pub struct Conductor {
    /// The microfacet distribution.
    pub distribution: Ggx,
    /// Real part of the index, per channel.
    pub eta: Vec3,
    /// Imaginary part (absorption), per channel.
    pub k: Vec3,
}

impl Conductor {
    pub(super) fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if !same_hemisphere(wo, wi) || self.distribution.effectively_smooth() {
            return Vec3::ZERO;
        }
        let (cos_o, cos_i) = (wo.z.abs(), wi.z.abs());
        let wm = (wi + wo).normalize();
        if cos_i == 0.0 || cos_o == 0.0 || wm == Vec3::ZERO {
            return Vec3::ZERO;
        }
        let f = fresnel(wo.dot(wm).abs(), self.eta, self.k);
        let d = &self.distribution;
        f * (d.d(wm) * d.g(wo, wi) / (4.0 * cos_i * cos_o))
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if !same_hemisphere(wo, wi) || self.distribution.effectively_smooth() {
            return 0.0;
        }
        let wm = (wo + wi).normalize();
        if wm == Vec3::ZERO {
            return 0.0;
        }
        let wm = wm.face_forward(vec3(0.0, 0.0, 1.0));
        self.distribution.visible_d(wo, wm) / (4.0 * wo.dot(wm).abs())
    }

    pub(super) fn sample(&self, wo: Vec3, u: [f32; 2]) -> Option<BsdfSample> {
        if self.distribution.effectively_smooth() {
            let wi = vec3(-wo.x, -wo.y, wo.z);
            let f = fresnel(wi.z.abs(), self.eta, self.k) / wi.z.abs();
            return Some(BsdfSample { f, wi, pdf: 1.0, delta: true, eta: 1.0, roughness: 0.0 });
        }
        if wo.z == 0.0 {
            return None;
        }
        let wm = self.distribution.sample_wm(wo, u);
        let wi = reflect(wo, wm);
        if !same_hemisphere(wo, wi) {
            return None;
        }
        let pdf = self.distribution.visible_d(wo, wm) / (4.0 * wo.dot(wm).abs());
        Some(BsdfSample { f: self.eval(wo, wi), wi, pdf, delta: false, eta: 1.0, roughness: self.distribution.alpha() })
    }
}
