//! Plastic: a dielectric coating with GGX roughness over a Lambertian base.
//!
//! The coating reflects by the microfacet model with dielectric Fresnel.
//! Light it transmits reaches the base, bounces between base and coating,
//! and leaves: `R / (1 − R·F_int) · (1 − F(θi)) (1 − F(θo)) / (π η²)`,
//! where `F_int` is the coating's hemispherical reflectance seen from
//! inside (the classic plastic model of Weidlich–Wilkie / Mitsuba). With a
//! white base the diffuse part reflects exactly `1 − F(θo)`, so nothing is
//! created. Sampling picks the coating with a probability that follows its
//! Fresnel weight.

use super::fresnel::{dielectric as fresnel, reflect};
use super::microfacet::Ggx;
use super::{cosine_hemisphere, same_hemisphere, BsdfSample};
use crate::math::{vec3, Vec3};
use std::f32::consts::FRAC_1_PI;

/// A coated diffuse surface.
#[derive(Debug, Clone, Copy)]
pub struct Coated {
    /// The coating's microfacet distribution.
    pub distribution: Ggx,
    /// The coating's index of refraction.
    pub eta: f32,
    /// The base's albedo.
    pub reflectance: Vec3,
    /// The coating's hemispherical reflectance from inside,
    /// `1 − (1 − F_dr(η)) / η²` ([`Coated::internal_reflectance`]).
    pub internal_reflectance: f32,
}

impl Coated {
    /// The hemispherical reflectance of a coating of index `eta` seen from inside.
    pub fn internal_reflectance(eta: f32) -> f32 {
        1.0 - (1.0 - super::fresnel::diffuse_reflectance(eta)) / (eta * eta)
    }

    /// Probability of sampling the coating for outgoing `wo`.
    fn coat_probability(&self, wo: Vec3) -> f32 {
        let specular = fresnel(wo.z.abs(), self.eta);
        let diffuse = (1.0 - specular) * self.reflectance.average();
        if !(specular + diffuse > 0.0) {
            return 0.5;
        }
        (specular / (specular + diffuse)).clamp(0.1, 0.9)
    }

    /// (total, diffuse base, coating) values of f(wo, wi).
    pub(super) fn eval(&self, wo: Vec3, wi: Vec3) -> (Vec3, Vec3, Vec3) {
        if !same_hemisphere(wo, wi) {
            return (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
        }
        let transmitted = (1.0 - fresnel(wo.z.abs(), self.eta)) * (1.0 - fresnel(wi.z.abs(), self.eta));
        let r = self.reflectance;
        let bounces = (Vec3::ONE - r * self.internal_reflectance).map(|d| 1.0 / d.max(1e-6));
        let diffuse = r * bounces * (FRAC_1_PI * transmitted / (self.eta * self.eta));
        let mut coat = Vec3::ZERO;
        let d = &self.distribution;
        let wm = (wo + wi).normalize();
        if !d.effectively_smooth() && wm != Vec3::ZERO && wo.z != 0.0 && wi.z != 0.0 {
            let f = fresnel(wo.dot(wm).abs(), self.eta);
            let v = d.d(wm) * d.g(wo, wi) * f / (4.0 * wo.z * wi.z).abs();
            if v.is_finite() {
                coat = Vec3::splat(v);
            }
        }
        (diffuse + coat, diffuse, coat)
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if !same_hemisphere(wo, wi) {
            return 0.0;
        }
        let p_coat = self.coat_probability(wo);
        let diffuse = wi.z.abs() * FRAC_1_PI;
        let d = &self.distribution;
        let wm = (wo + wi).normalize();
        let coat = if d.effectively_smooth() || wm == Vec3::ZERO {
            0.0
        } else {
            d.visible_d(wo, wm.face_forward(vec3(0.0, 0.0, 1.0))) / (4.0 * wo.dot(wm).abs())
        };
        p_coat * coat + (1.0 - p_coat) * diffuse
    }

    pub(super) fn sample(&self, wo: Vec3, uc: f32, u: [f32; 2]) -> Option<BsdfSample> {
        let p_coat = self.coat_probability(wo);
        let d = &self.distribution;
        if uc < p_coat && d.effectively_smooth() {
            let wi = vec3(-wo.x, -wo.y, wo.z);
            let f = Vec3::splat(fresnel(wo.z.abs(), self.eta) / wi.z.abs());
            return Some(BsdfSample { f, wi, pdf: p_coat, delta: true, eta: 1.0, roughness: 0.0 });
        }
        let (wi, roughness) = if uc < p_coat {
            if wo.z == 0.0 {
                return None;
            }
            (reflect(wo, d.sample_wm(wo, u)), d.alpha())
        } else {
            (cosine_hemisphere(u), f32::INFINITY)
        };
        if !same_hemisphere(wo, wi) {
            return None;
        }
        let pdf = self.pdf(wo, wi);
        Some(BsdfSample { f: self.eval(wo, wi).0, wi, pdf, delta: false, eta: 1.0, roughness })
    }
}
