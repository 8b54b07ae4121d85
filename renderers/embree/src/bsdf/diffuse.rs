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
