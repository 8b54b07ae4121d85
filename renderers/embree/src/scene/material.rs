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
    /// pbrt `mix`: at each point one of two materials, the second with
    /// probability `amount` (chosen by [`crate::scene::Scene::material_at`]).
    Mix {
        /// The two materials (indices into the scene's materials).
        materials: [u32; 2],
        /// The probability of the second.
        amount: Arc<Texture>,
    },
    /// pbrt `thindielectric`.
    ThinDielectric {
        /// Index of refraction.
        eta: f32,
    },
    /// pbrt `diffusetransmission`.
    DiffuseTransmission {
        /// Albedo of the reflection.
        reflectance: Arc<Texture>,
        /// Albedo of the transmission.
        transmittance: Arc<Texture>,
    },
    /// pbrt `interface`: the boundary of a participating medium, itself
    /// invisible. Media are not rendered, so its shapes are left out.
    Interface,
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
            Material::ThinDielectric { eta } => {
                Bsdf::ThinDielectric(crate::bsdf::dielectric::ThinDielectric { eta: *eta })
            }
            Material::DiffuseTransmission { reflectance, transmittance } => {
                Bsdf::DiffuseTransmission(crate::bsdf::diffuse::DiffuseTransmission {
                    reflectance: clamp01(reflectance.eval(uv)),
                    transmittance: clamp01(transmittance.eval(uv)),
                })
            }
            // Resolved before shading (a mix), or never hit (an interface): black if it were.
            Material::Mix { .. } | Material::Interface => Bsdf::Diffuse(Diffuse { reflectance: Vec3::ZERO }),
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
            Material::Diffuse { reflectance }
            | Material::CoatedDiffuse { reflectance, .. }
            | Material::DiffuseTransmission { reflectance, .. } => reflectance.eval(uv).map(|c| c.clamp(0.0, 1.0)),
            Material::Conductor { .. } => match self.bsdf(uv) {
                Bsdf::Conductor(c) => crate::bsdf::fresnel::conductor(1.0, c.eta, c.k),
                _ => unreachable!("a conductor's BSDF is a conductor"),
            },
            Material::Dielectric { .. } | Material::ThinDielectric { .. } => Vec3::ONE,
            Material::Mix { .. } | Material::Interface => Vec3::ZERO,
        }
    }
}

/// A perturbation of the shading normal, as pbrt's materials take it: a
/// bump map (`"texture displacement"`) or a normal map (`"string normalmap"`).
#[derive(Debug, Clone)]
pub enum Bump {
    /// Heights along the normal, a float texture (pbrt's `BumpMap`).
    Height(Arc<Texture>),
    /// Normals in the tangent frame (∂p/∂u, n), RGB in [0, 1] for [−1, 1]
    /// (pbrt's `NormalMap`: bilinear, repeating, v flipped).
    NormalMap(Arc<crate::scene::texture::ImageData>),
}

impl Bump {
    /// Perturbs `hit`'s shading normal, given its tangents ∂p/∂u and ∂p/∂v;
    /// it stays on the side of the unperturbed one.
    pub fn apply(&self, hit: &mut crate::scene::shape::SurfaceHit, (dpdu, dpdv): (Vec3, Vec3)) {
        let n = hit.ns;
        let perturbed = match self {
            Bump::Height(texture) => {
                // Without ray differentials pbrt's step is 0.0005 in u and v;
                // the displaced point's tangents give the normal.
                const DELTA: f32 = 0.0005;
                let [u, v] = hit.uv;
                let height = texture.eval_float(hit.uv);
                let du = (texture.eval_float([u + DELTA, v]) - height) / DELTA;
                let dv = (texture.eval_float([u, v + DELTA]) - height) / DELTA;
                (dpdu + n * du).cross(dpdv + n * dv)
            }
            Bump::NormalMap(image) => {
                let [u, v] = hit.uv;
                let c = crate::scene::texture::bilinear(image, u, 1.0 - v, crate::scene::texture::Wrap::Repeat);
                let local = (c * 2.0 - Vec3::ONE).normalize();
                // The frame: x along ∂p/∂u (made perpendicular to n), z the normal.
                let x = (dpdu - n * n.dot(dpdu)).normalize();
                if x == Vec3::ZERO {
                    return;
                }
                let y = n.cross(x);
                x * local.x + y * local.y + n * local.z
            }
        }
        .normalize();
        if perturbed.is_finite() && perturbed != Vec3::ZERO {
            hit.ns = perturbed.face_forward(n);
        }
    }
}
