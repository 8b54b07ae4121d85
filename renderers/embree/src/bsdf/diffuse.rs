//! Lambertian reflection.

use super::{cosine_hemisphere, cosine_hemisphere_lanes, same_hemisphere, BsdfSample};
use crate::lanes::{F32s, Mask, Vec3s};
use crate::math::Vec3;
use std::f32::consts::FRAC_1_PI;

/// Reflects `reflectance` of the incident light equally in all directions.
#[derive(Debug, Clone, Copy)]
pub struct Diffuse {
    /// Albedo, each channel in [0, 1].
    pub reflectance: Vec3,
}

impl Diffuse {
    #[inline(always)]
    pub(super) fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if same_hemisphere(wo, wi) {
            self.reflectance * FRAC_1_PI
        } else {
            Vec3::ZERO
        }
    }

    #[inline(always)]
    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if same_hemisphere(wo, wi) {
            wi.z.abs() * FRAC_1_PI
        } else {
            0.0
        }
    }

    #[inline(always)]
    pub(super) fn sample(&self, _wo: Vec3, u: [f32; 2]) -> Option<BsdfSample> {
        let wi = cosine_hemisphere(u);
        Some(BsdfSample {
            f: self.reflectance * FRAC_1_PI,
            wi,
            pdf: wi.z * FRAC_1_PI,
            delta: false,
            eta: 1.0,
            roughness: f32::INFINITY,
        })
    }
}

/// The twins of [`super::Bsdf`]'s methods for a diffuse BSDF (two-sided,
/// as the enum makes it), in lanes, with the same bits.
impl Diffuse {
    /// [`super::Bsdf::eval`] and [`super::Bsdf::pdf`] of lanes of diffuse BSDFs.
    #[inline(always)]
    pub fn eval_pdf_lanes(reflectance: Vec3s, wo: Vec3s, wi: Vec3s) -> (Vec3s, F32s) {
        let zero = F32s::splat(0.0);
        // Seen from below, both directions are mirrored, which changes neither test.
        let same = (wo.z * wi.z).gt(zero);
        let f = Vec3s::select(same, reflectance * FRAC_1_PI, Vec3s::ZERO);
        let pdf = F32s::select(same, wi.z.abs() * FRAC_1_PI, zero);
        (f, F32s::select(pdf.is_finite(), pdf, zero))
    }

    /// [`super::Bsdf::sample`] of lanes of diffuse BSDFs: the lanes with a
    /// sample, and its value, direction and density.
    #[inline(always)]
    pub fn sample_lanes(reflectance: Vec3s, wo: Vec3s, u: [F32s; 2]) -> (Mask, Vec3s, Vec3s, F32s) {
        let zero = F32s::splat(0.0);
        let wi = cosine_hemisphere_lanes(u);
        let (f, pdf) = (reflectance * FRAC_1_PI, wi.z * FRAC_1_PI);
        let wi = Vec3s::new(wi.x, wi.y, F32s::select(wo.z.lt(zero), -wi.z, wi.z));
        let ok = pdf.gt(zero) & pdf.is_finite() & f.is_finite() & !wi.z.eq(zero);
        (ok, f, wi, pdf)
    }
}

/// Lambertian reflection and Lambertian transmission (pbrt's
/// `diffusetransmission`: leaves, paper, lamp shades): `reflectance` back
/// to the side light came from, `transmittance` through to the other.
#[derive(Debug, Clone, Copy)]
pub struct DiffuseTransmission {
    /// Albedo of the reflection.
    pub reflectance: Vec3,
    /// Albedo of the transmission.
    pub transmittance: Vec3,
}

impl DiffuseTransmission {
    /// The chance of sampling reflection (as pbrt: by the largest channel).
    fn reflect_chance(&self) -> f32 {
        let (r, t) = (self.reflectance.max_component(), self.transmittance.max_component());
        if r + t > 0.0 {
            r / (r + t)
        } else {
            0.5
        }
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if same_hemisphere(wo, wi) {
            self.reflectance * FRAC_1_PI
        } else {
            self.transmittance * FRAC_1_PI
        }
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let pr = self.reflect_chance();
        let side = if same_hemisphere(wo, wi) { pr } else { 1.0 - pr };
        side * wi.z.abs() * FRAC_1_PI
    }

    pub(super) fn sample(&self, wo: Vec3, uc: f32, u: [f32; 2]) -> Option<BsdfSample> {
        let pr = self.reflect_chance();
        let mut wi = cosine_hemisphere(u);
        // Reflection stays on wo's side; transmission crosses to the other.
        let reflect = uc < pr;
        if (wo.z < 0.0) == reflect {
            wi.z = -wi.z;
        }
        let f = if reflect { self.reflectance } else { self.transmittance } * FRAC_1_PI;
        let pdf = if reflect { pr } else { 1.0 - pr } * wi.z.abs() * FRAC_1_PI;
        Some(BsdfSample { f, wi, pdf, delta: false, eta: 1.0, roughness: f32::INFINITY })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Bsdf;
    use crate::lanes::tests::{same, same3, Values};
    use crate::lanes::W;

    #[test]
    fn a_diffuse_bsdf_in_lanes_has_the_scalar_bits() {
        let mut values = Values::new(4);
        for _ in 0..2000 {
            let (reflectance, wo, wi) = (values.vectors(), values.vectors(), values.vectors());
            let u = [values.lanes().map(f32::abs), values.lanes().map(f32::abs)];
            let (f, pdf) = Diffuse::eval_pdf_lanes(reflectance, wo, wi);
            let (ok, sf, swi, spdf) = Diffuse::sample_lanes(reflectance, wo, u);
            for k in 0..W {
                let bsdf = Bsdf::Diffuse(Diffuse { reflectance: reflectance.lane(k) });
                let (wo, wi) = (wo.lane(k), wi.lane(k));
                assert!(same3(f.lane(k), bsdf.eval(wo, wi)) && same(pdf.0[k], bsdf.pdf(wo, wi)));
                let sample = bsdf.sample(wo, 0.5, [u[0].0[k], u[1].0[k]]);
                assert_eq!(ok.0[k], sample.is_some(), "{wo:?} {:?}", [u[0].0[k], u[1].0[k]]);
                if let Some(s) = sample {
                    assert!(same3(sf.lane(k), s.f) && same3(swi.lane(k), s.wi) && same(spdf.0[k], s.pdf));
                }
            }
        }
    }
}
