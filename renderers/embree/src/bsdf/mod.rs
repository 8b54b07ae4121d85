//! Scattering functions in the local shading frame (z = shading normal):
//! the interface ([`Bsdf`]: evaluate, sample, density) and the models the
//! scene pool needs, one per file.
//!
//! - [`diffuse`]: Lambertian reflection.
//! - [`conductor`]: smooth or GGX-rough metal with complex Fresnel.
//! - [`dielectric`]: smooth or GGX-rough glass (reflection and transmission),
//!   and thin glass sheets.
//! - [`coated`]: a dielectric GGX coating over a diffuse base (plastic).
//! - [`diffuse::DiffuseTransmission`]: Lambertian reflection and transmission.
//!
//! Reflection-only models are two-sided: seen from below, they act as if
//! mirrored. Values are radiance-transport values (transmission divided by
//! η²). Each sample says whether it came from a delta lobe, and which lobe's
//! roughness produced it, so the integrator can split DIFFUSE_COLOR.

pub mod coated;
pub mod conductor;
pub mod dielectric;
pub mod diffuse;
pub mod fresnel;
pub mod microfacet;

use crate::lanes::{F32s, Vec3s};
use crate::math::{vec3, Vec3};

/// A direction sampled from a BSDF.
#[derive(Debug, Clone, Copy)]
pub struct BsdfSample {
    /// The BSDF value (for a delta lobe: the lobe's weight divided by |cos θi|).
    pub f: Vec3,
    /// The sampled incident direction (local).
    pub wi: Vec3,
    /// Its density (for a delta lobe: the probability of choosing it).
    pub pdf: f32,
    /// Whether it came from a delta (perfectly smooth) lobe.
    pub delta: bool,
    /// The relative index crossed (1 for reflection).
    pub eta: f32,
    /// Roughness (α) of the lobe that produced it: 0 smooth, ∞ diffuse.
    pub roughness: f32,
}

/// A BSDF with its textures already evaluated at one surface point.
#[derive(Debug, Clone, Copy)]
pub enum Bsdf {
    /// Lambertian.
    Diffuse(diffuse::Diffuse),
    /// Metal.
    Conductor(conductor::Conductor),
    /// Glass.
    Dielectric(dielectric::Dielectric),
    /// Plastic: coating over a diffuse base.
    Coated(coated::Coated),
    /// Lambertian reflection and transmission.
    DiffuseTransmission(diffuse::DiffuseTransmission),
    /// A thin glass sheet: specular reflection and straight transmission.
    ThinDielectric(dielectric::ThinDielectric),
}

/// Flips `w` to the upper hemisphere when `flip` (two-sided reflection).
#[inline(always)]
fn upper(w: Vec3, flip: bool) -> Vec3 {
    if flip {
        vec3(w.x, w.y, -w.z)
    } else {
        w
    }
}

impl Bsdf {
    /// Whether the model only reflects (and so is two-sided).
    #[inline(always)]
    fn reflective(&self) -> bool {
        !matches!(self, Bsdf::Dielectric(_) | Bsdf::DiffuseTransmission(_) | Bsdf::ThinDielectric(_))
    }

    /// Whether every lobe is a delta: no light sampling, and the surface
    /// does not count as the "first non-specular" hit.
    #[inline(always)]
    pub fn is_delta(&self) -> bool {
        match self {
            Bsdf::Diffuse(_) => false,
            Bsdf::Conductor(c) => c.distribution.effectively_smooth(),
            Bsdf::Dielectric(d) => d.is_delta(),
            Bsdf::Coated(_) | Bsdf::DiffuseTransmission(_) => false,
            Bsdf::ThinDielectric(_) => true,
        }
    }

    /// The BSDF value f(wo, wi) (delta lobes excluded).
    #[inline(always)]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let flip = self.reflective() && wo.z < 0.0;
        let (wo, wi) = (upper(wo, flip), upper(wi, flip));
        match self {
            Bsdf::Diffuse(b) => b.eval(wo, wi),
            Bsdf::Conductor(b) => b.eval(wo, wi),
            Bsdf::Dielectric(b) => b.eval(wo, wi),
            Bsdf::Coated(b) => b.eval(wo, wi).0,
            Bsdf::DiffuseTransmission(b) => b.eval(wo, wi),
            Bsdf::ThinDielectric(_) => Vec3::ZERO,
        }
    }

    /// The part of f(wo, wi) from lobes at least as rough as `threshold`.
    #[inline(always)]
    pub fn eval_diffuse_part(&self, wo: Vec3, wi: Vec3, threshold: f32) -> Vec3 {
        let flip = self.reflective() && wo.z < 0.0;
        let (wo, wi) = (upper(wo, flip), upper(wi, flip));
        let whole = |roughness: f32, f: Vec3| if roughness >= threshold { f } else { Vec3::ZERO };
        match self {
            Bsdf::Diffuse(b) => b.eval(wo, wi),
            Bsdf::DiffuseTransmission(b) => b.eval(wo, wi),
            Bsdf::ThinDielectric(_) => Vec3::ZERO,
            Bsdf::Conductor(b) => whole(b.distribution.alpha(), b.eval(wo, wi)),
            Bsdf::Dielectric(b) => whole(b.distribution.alpha(), b.eval(wo, wi)),
            Bsdf::Coated(b) => {
                let (_, diffuse, specular) = b.eval(wo, wi);
                diffuse + whole(b.distribution.alpha(), specular)
            }
        }
    }

    /// The density of [`Bsdf::sample`] producing `wi` (delta lobes excluded).
    #[inline(always)]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let flip = self.reflective() && wo.z < 0.0;
        let (wo, wi) = (upper(wo, flip), upper(wi, flip));
        let p = match self {
            Bsdf::Diffuse(b) => b.pdf(wo, wi),
            Bsdf::Conductor(b) => b.pdf(wo, wi),
            Bsdf::Dielectric(b) => b.pdf(wo, wi),
            Bsdf::Coated(b) => b.pdf(wo, wi),
            Bsdf::DiffuseTransmission(b) => b.pdf(wo, wi),
            Bsdf::ThinDielectric(_) => 0.0,
        };
        if p.is_finite() {
            p
        } else {
            0.0
        }
    }

    /// Samples an incident direction with `uc` ∈ [0, 1) (lobe choice) and `u` ∈ [0, 1)².
    #[inline(always)]
    pub fn sample(&self, wo: Vec3, uc: f32, u: [f32; 2]) -> Option<BsdfSample> {
        let flip = self.reflective() && wo.z < 0.0;
        let wo = upper(wo, flip);
        let mut s = match self {
            Bsdf::Diffuse(b) => b.sample(wo, u),
            Bsdf::Conductor(b) => b.sample(wo, u),
            Bsdf::Dielectric(b) => b.sample(wo, uc, u),
            Bsdf::Coated(b) => b.sample(wo, uc, u),
            Bsdf::DiffuseTransmission(b) => b.sample(wo, uc, u),
            Bsdf::ThinDielectric(b) => b.sample(wo, uc),
        }?;
        s.wi = upper(s.wi, flip);
        (s.pdf > 0.0 && s.pdf.is_finite() && s.f.is_finite() && s.wi.z != 0.0).then_some(s)
    }
}

/// A cosine-weighted direction on the upper hemisphere (Malley's method
/// on the concentric disk, which keeps strata compact).
#[inline(always)]
pub fn cosine_hemisphere(u: [f32; 2]) -> Vec3 {
    let (x, y) = crate::scene::camera::concentric_disk(u);
    vec3(x, y, (1.0 - x * x - y * y).max(0.0).sqrt())
}

/// [`cosine_hemisphere`] in lanes.
#[inline(always)]
pub fn cosine_hemisphere_lanes(u: [F32s; 2]) -> Vec3s {
    let (x, y) = crate::scene::camera::concentric_disk_lanes(u);
    Vec3s::new(x, y, (F32s::splat(1.0) - x * x - y * y).max(F32s::splat(0.0)).sqrt())
}

/// Whether two local directions lie on the same side of the surface.
#[inline(always)]
pub fn same_hemisphere(a: Vec3, b: Vec3) -> bool {
    a.z * b.z > 0.0
}
