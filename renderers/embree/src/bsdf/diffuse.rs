//! Lambertian reflection.

use super::{cosine_hemisphere, same_hemisphere, BsdfSample};
use crate::math::Vec3;
use std::f32::consts::FRAC_1_PI;

/// Reflects `reflectance` of the incident light equally in all directions.
#[derive(Debug, Clone, Copy)]
pub struct Diffuse {
    /// Albedo, each channel in [0, 1].
    pub reflectance: Vec3,
}

impl Diffuse {
    pub(super) fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if same_hemisphere(wo, wi) {
            self.reflectance * FRAC_1_PI
        } else {
            Vec3::ZERO
        }
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if same_hemisphere(wo, wi) {
            wi.z.abs() * FRAC_1_PI
        } else {
            0.0
        }
    }

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
