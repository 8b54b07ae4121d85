//! Materials: the pbrt-v4 material types the scene pool uses, with their
//! parameters bound to textures, turned into a [`Bsdf`] at a surface point.

use crate::bsdf::{coated::Coated, conductor::Conductor, dielectric::Dielectric, diffuse::Diffuse, Bsdf};
use crate::bsdf::{fresnel::k_from_reflectance, microfacet::Ggx};
use crate::math::Vec3;
use crate::scene::texture::Texture;
use std::sync::Arc;

/// Roughness along the two tangent directions, as textures.
#[derive(Debug, Clone)]
pub struct Roughness {
    /// Along u.
    pub u: Arc<Texture>,
    /// Along v.
    pub v: Arc<Texture>,
    /// Whether the values are perceptual roughness (α = √r) rather than α.
    pub remap: bool,
}

impl Roughness {
    fn distribution(&self, uv: [f32; 2]) -> Ggx {
        let (u, v) = (self.u.eval_float(uv), self.v.eval_float(uv));
        if self.remap {
            Ggx::new(Ggx::roughness_to_alpha(u), Ggx::roughness_to_alpha(v))
        } else {
            Ggx::new(u, v)
        }
    }
}

/// How a conductor's index is given.
#[derive(Debug, Clone)]
pub enum ConductorIndex {
    /// Complex index η + i·k.
    EtaK(Arc<Texture>, Arc<Texture>),
    /// An artist's reflectance at normal incidence.
    Reflectance(Arc<Texture>),
}

/// A material.
#[derive(Debug, Clone)]
pub enum Material {
    /// pbrt `diffuse`.
    Diffuse {
        /// Albedo.
        reflectance: Arc<Texture>,
    },
    /// pbrt `conductor`.
    Conductor {
        /// The index of refraction.
        index: ConductorIndex,
        /// Roughness.
        roughness: Roughness,
    },
    /// pbrt `dielectric`.
    Dielectric {
        /// Index of refraction.
        eta: f32,
        /// Roughness.
        roughness: Roughness,
    },
    /// pbrt `coateddiffuse` (our coating model, see [`crate::bsdf::coated`]).
    CoatedDiffuse {
        /// The base's albedo.
        reflectance: Arc<Texture>,
        /// The coating's roughness.
        roughness: Roughness,
        /// The coating's index of refraction.
        eta: f32,
        /// See [`Coated::internal_reflectance`] (computed once).
        internal_reflectance: f32,
    },
}

impl Material {
    /// The BSDF at texture coordinates `uv`.
    pub fn bsdf(&self, uv: [f32; 2]) -> Bsdf {
        let clamp01 = |v: Vec3| v.map(|c| if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) });
        match self {
            Material::Diffuse { reflectance } => Bsdf::Diffuse(Diffuse { reflectance: clamp01(reflectance.eval(uv)) }),
            Material::Conductor { index, roughness } => {
                let (eta, k) = match index {
                    ConductorIndex::EtaK(eta, k) => (eta.eval(uv), k.eval(uv)),
                    ConductorIndex::Reflectance(r) => (Vec3::ONE, k_from_reflectance(clamp01(r.eval(uv)))),
                };
                Bsdf::Conductor(Conductor { distribution: roughness.distribution(uv), eta, k })
            }
            Material::Dielectric { eta, roughness } => {
                Bsdf::Dielectric(Dielectric { distribution: roughness.distribution(uv), eta: *eta })
            }
            Material::CoatedDiffuse { reflectance, roughness, eta, internal_reflectance } => Bsdf::Coated(Coated {
                distribution: roughness.distribution(uv),
                eta: *eta,
                reflectance: clamp01(reflectance.eval(uv)),
                internal_reflectance: *internal_reflectance,
            }),
        }
    }

    /// The albedo feature (TEXTURE_COLOR): the diffuse reflectance for
    /// diffuse and coated surfaces (the coating is deliberately not
    /// included), the normal-incidence reflectance for conductors, white
    /// for dielectrics.
    pub fn albedo(&self, uv: [f32; 2]) -> Vec3 {
        match self {
            Material::Diffuse { reflectance } | Material::CoatedDiffuse { reflectance, .. } => {
                reflectance.eval(uv).map(|c| c.clamp(0.0, 1.0))
            }
            Material::Conductor { .. } => match self.bsdf(uv) {
                Bsdf::Conductor(c) => crate::bsdf::fresnel::conductor(1.0, c.eta, c.k),
                _ => unreachable!("a conductor's BSDF is a conductor"),
            },
            Material::Dielectric { .. } => Vec3::ONE,
        }
    }
}
