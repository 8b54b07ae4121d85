//! Fresnel reflectance of dielectric and conducting interfaces, and
//! refraction.

use crate::math::{vec3, Vec3};

/// Unpolarised Fresnel reflectance of a dielectric interface for a cosine
/// `cos_i` on the outside (`cos_i < 0`: light arrives from inside) and
/// relative index `eta` = inside / outside.
#[inline]
pub fn dielectric(cos_i: f32, eta: f32) -> f32 {
    let (mut cos_i, mut eta) = (cos_i.clamp(-1.0, 1.0), eta);
    if cos_i < 0.0 {
        eta = 1.0 / eta;
        cos_i = -cos_i;
    }
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let parallel = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let perpendicular = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let r = (parallel * parallel + perpendicular * perpendicular) / 2.0;
    if r.is_finite() {
        r
    } else {
        1.0
    }
}

/// Hemispherical average of the dielectric Fresnel reflectance for light
/// arriving from outside, `∫₀¹ 2μ F(μ, η) dμ` (midpoint rule, 1024 points).
pub fn diffuse_reflectance(eta: f32) -> f32 {
    const N: usize = 1024;
    (0..N)
        .map(|i| {
            let mu = (i as f32 + 0.5) / N as f32;
            2.0 * mu * dielectric(mu, eta)
        })
        .sum::<f32>()
        / N as f32
}

/// Fresnel reflectance of a conductor with complex index `eta + i·k`, per channel.
#[inline]
pub fn conductor(cos_i: f32, eta: Vec3, k: Vec3) -> Vec3 {
    let c = |eta: f32, k: f32| complex_fresnel(cos_i.clamp(0.0, 1.0), eta, k);
    vec3(c(eta.x, k.x), c(eta.y, k.y), c(eta.z, k.z))
}

fn complex_fresnel(cos_i: f32, eta_re: f32, eta_im: f32) -> f32 {
    #[derive(Clone, Copy)]
    struct C(f32, f32);
    let mul = |a: C, b: C| C(a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0);
    let div = |a: C, b: C| {
        let d = b.0 * b.0 + b.1 * b.1;
        C((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
    };
    let sqrt = |z: C| {
        let n = (z.0 * z.0 + z.1 * z.1).sqrt();
        if n == 0.0 {
            return C(0.0, 0.0);
        }
        let t1 = (0.5 * (n + z.0.abs())).sqrt();
        let t2 = 0.5 * z.1 / t1;
        if z.0 >= 0.0 {
            C(t1, t2)
        } else {
            C(t2.abs(), t1.copysign(z.1))
        }
    };
    let norm = |z: C| z.0 * z.0 + z.1 * z.1;
    let eta = C(eta_re, eta_im);
    let sin2_i = 1.0 - cos_i * cos_i;
    let sin2_t = div(C(sin2_i, 0.0), mul(eta, eta));
    let cos_t = sqrt(C(1.0 - sin2_t.0, -sin2_t.1));
    let ci = C(cos_i, 0.0);
    let e_ci = mul(eta, ci);
    let e_ct = mul(eta, cos_t);
    let parallel = div(C(e_ci.0 - cos_t.0, e_ci.1 - cos_t.1), C(e_ci.0 + cos_t.0, e_ci.1 + cos_t.1));
    let perpendicular = div(C(ci.0 - e_ct.0, -e_ct.1), C(ci.0 + e_ct.0, e_ct.1));
    let r = (norm(parallel) + norm(perpendicular)) / 2.0;
    if r.is_finite() {
        r.clamp(0.0, 1.0)
    } else {
        1.0
    }
}

/// pbrt-v4's conductor from an artist's reflectance `r` (η = 1, k = 2√r / √(1 − r)).
pub fn k_from_reflectance(r: Vec3) -> Vec3 {
    r.map(|r| {
        let r = r.clamp(0.0, 0.9999);
        2.0 * r.sqrt() / (1.0 - r).sqrt()
    })
}

/// Mirror of `wo` about `n`.
#[inline(always)]
pub fn reflect(wo: Vec3, n: Vec3) -> Vec3 {
    -wo + n * (2.0 * wo.dot(n))
}

/// Refraction of `wi` through an interface with normal `n` (on the side of
/// the outside) and relative index `eta`; returns the direction and the
/// index ratio actually crossed, or `None` at total internal reflection.
#[inline]
pub fn refract(wi: Vec3, n: Vec3, eta: f32) -> Option<(Vec3, f32)> {
    let (mut n, mut eta, mut cos_i) = (n, eta, n.dot(wi));
    if cos_i < 0.0 {
        eta = 1.0 / eta;
        cos_i = -cos_i;
        n = -n;
    }
    let sin2_t = (1.0 - cos_i * cos_i).max(0.0) / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    Some((-wi / eta + n * (cos_i / eta - cos_t), eta))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_limits() {
        assert!((dielectric(1.0, 1.5) - 0.04).abs() < 1e-6);
        assert!(dielectric(0.1, 1.0) < 1e-9);
        assert_eq!(dielectric(-0.1, 1.5), 1.0); // total internal reflection
        assert!((dielectric(0.0, 1.5) - 1.0).abs() < 1e-6);
        // A conductor with k = 0 is a dielectric.
        assert!((conductor(0.7, Vec3::splat(1.5), Vec3::ZERO).x - dielectric(0.7, 1.5)).abs() < 1e-5);
        let r = conductor(1.0, Vec3::ONE, k_from_reflectance(Vec3::splat(0.6)));
        assert!((r.x - 0.6).abs() < 1e-4, "{r:?}");
    }

    #[test]
    fn diffuse_reflectance_matches_known_values() {
        // η = 1: nothing is reflected; η = 1.5: about 0.092 (Egan and Hilgeman's fit gives 0.0918).
        assert!(diffuse_reflectance(1.0) < 1e-6);
        assert!((diffuse_reflectance(1.5) - 0.092).abs() < 0.002, "{}", diffuse_reflectance(1.5));
    }

    #[test]
    fn refraction_obeys_snell() {
        let wi = vec3(0.6, 0.0, 0.8);
        let (wt, eta) = refract(wi, vec3(0.0, 0.0, 1.0), 1.5).unwrap();
        assert_eq!(eta, 1.5);
        assert!((wt.length() - 1.0).abs() < 1e-6);
        assert!((wt.x.abs() * 1.5 - 0.6).abs() < 1e-6 && wt.z < 0.0);
        assert!(refract(vec3(0.9, 0.0, -0.435_889_9), vec3(0.0, 0.0, 1.0), 1.5).is_none());
    }
}
