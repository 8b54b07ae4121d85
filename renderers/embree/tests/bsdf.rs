//! The scattering models against their own definitions: sampling follows
//! the density (chi-square), sampled values agree with evaluation, no model
//! creates energy, reflection is reciprocal, and extreme parameters give
//! finite values.

use fbksd_embree::bsdf::coated::Coated;
use fbksd_embree::bsdf::conductor::Conductor;
use fbksd_embree::bsdf::dielectric::Dielectric;
use fbksd_embree::bsdf::diffuse::{Diffuse, DiffuseTransmission};
use fbksd_embree::bsdf::microfacet::Ggx;
use fbksd_embree::bsdf::Bsdf;
use fbksd_embree::math::{vec3, Vec3};
use std::f32::consts::PI;

/// A small deterministic generator (SplitMix64).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Plastic with a coating of index 1.5.
fn coated(distribution: Ggx, reflectance: Vec3) -> Bsdf {
    Bsdf::Coated(Coated {
        distribution,
        eta: 1.5,
        reflectance,
        internal_reflectance: Coated::internal_reflectance(1.5),
    })
}

fn gold() -> Vec3 {
    vec3(0.143, 0.374, 1.442)
}

fn gold_k() -> Vec3 {
    vec3(3.983, 2.385, 1.603)
}

/// Every model the renderer has, at representative settings.
fn models() -> Vec<(&'static str, Bsdf)> {
    vec![
        ("diffuse", Bsdf::Diffuse(Diffuse { reflectance: vec3(0.8, 0.5, 0.2) })),
        ("conductor α=0.3", Bsdf::Conductor(Conductor { distribution: Ggx::new(0.3, 0.3), eta: gold(), k: gold_k() })),
        (
            "conductor α=0.05,0.5",
            Bsdf::Conductor(Conductor { distribution: Ggx::new(0.05, 0.5), eta: gold(), k: gold_k() }),
        ),
        ("conductor α=1", Bsdf::Conductor(Conductor { distribution: Ggx::new(1.0, 1.0), eta: gold(), k: gold_k() })),
        ("dielectric α=0.3", Bsdf::Dielectric(Dielectric { distribution: Ggx::new(0.3, 0.3), eta: 1.5 })),
        ("dielectric α=0.1", Bsdf::Dielectric(Dielectric { distribution: Ggx::new(0.1, 0.1), eta: 1.33 })),
        ("coated α=0.2", coated(Ggx::new(0.2, 0.2), vec3(0.7, 0.2, 0.1))),
        ("coated smooth", coated(Ggx::new(0.0, 0.0), vec3(0.5, 0.5, 0.5))),
        (
            "diffuse transmission",
            Bsdf::DiffuseTransmission(DiffuseTransmission {
                reflectance: vec3(0.6, 0.3, 0.1),
                transmittance: vec3(0.2, 0.5, 0.3),
            }),
        ),
    ]
}

fn direction(theta_deg: f32, phi_deg: f32) -> Vec3 {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    vec3(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
}

/// Outgoing directions: from above, near grazing, and from below (inside glass).
fn outgoing(bsdf: &Bsdf) -> Vec<Vec3> {
    let mut w = vec![direction(10.0, 30.0), direction(60.0, 200.0), direction(85.0, 100.0)];
    if matches!(bsdf, Bsdf::Dielectric(_) | Bsdf::DiffuseTransmission(_)) {
        w.push(direction(140.0, 45.0));
    }
    w
}

/// Pearson's chi-square of sampled directions against the integrated
/// density over a θ × φ grid (bins with expected count below 5 pooled),
/// as a Wilson–Hilferty z-score.
fn chi_square_z(bsdf: &Bsdf, wo: Vec3, rng: &mut Rng) -> f64 {
    const N_THETA: usize = 16;
    const N_PHI: usize = 32;
    const SAMPLES: usize = 400_000;
    let mut observed = vec![0f64; N_THETA * N_PHI];
    for _ in 0..SAMPLES {
        let Some(s) = bsdf.sample(wo, rng.next(), [rng.next(), rng.next()]) else { continue };
        if s.delta {
            continue;
        }
        let theta = s.wi.z.clamp(-1.0, 1.0).acos();
        let mut phi = s.wi.y.atan2(s.wi.x);
        if phi < 0.0 {
            phi += 2.0 * PI;
        }
        let i = ((theta / PI * N_THETA as f32) as usize).min(N_THETA - 1);
        let j = ((phi / (2.0 * PI) * N_PHI as f32) as usize).min(N_PHI - 1);
        observed[i * N_PHI + j] += 1.0;
    }
    // Expected counts: the density integrated over each bin (midpoint rule, 16 × 16 per bin).
    let mut expected = vec![0f64; N_THETA * N_PHI];
    const Q: usize = 16;
    for i in 0..N_THETA {
        for j in 0..N_PHI {
            let mut sum = 0f64;
            for a in 0..Q {
                for b in 0..Q {
                    let theta = (i as f64 + (a as f64 + 0.5) / Q as f64) * std::f64::consts::PI / N_THETA as f64;
                    let phi = (j as f64 + (b as f64 + 0.5) / Q as f64) * 2.0 * std::f64::consts::PI / N_PHI as f64;
                    let wi =
                        vec3((theta.sin() * phi.cos()) as f32, (theta.sin() * phi.sin()) as f32, theta.cos() as f32);
                    sum += bsdf.pdf(wo, wi) as f64 * theta.sin();
                }
            }
            let cell =
                (std::f64::consts::PI / N_THETA as f64) * (2.0 * std::f64::consts::PI / N_PHI as f64) / (Q * Q) as f64;
            expected[i * N_PHI + j] = sum * cell * SAMPLES as f64;
        }
    }
    let mut order: Vec<usize> = (0..expected.len()).collect();
    order.sort_by(|a, b| expected[*a].total_cmp(&expected[*b]));
    let (mut chi2, mut dof, mut pool_o, mut pool_e) = (0f64, 0usize, 0f64, 0f64);
    for k in order {
        if expected[k] < 5.0 {
            pool_o += observed[k];
            pool_e += expected[k];
            continue;
        }
        chi2 += (observed[k] - expected[k]).powi(2) / expected[k];
        dof += 1;
    }
    if pool_e > 5.0 {
        chi2 += (pool_o - pool_e).powi(2) / pool_e;
        dof += 1;
    } else {
        assert!(pool_o < 50.0, "{pool_o} samples fell where the density says almost none ({pool_e:.1}) should");
    }
    let k = (dof - 1) as f64;
    ((chi2 / k).cbrt() - (1.0 - 2.0 / (9.0 * k))) / (2.0 / (9.0 * k)).sqrt()
}

#[test]
fn sampling_matches_the_density_chi_square() {
    let mut rng = Rng(7);
    for (name, bsdf) in models() {
        for wo in outgoing(&bsdf) {
            let z = chi_square_z(&bsdf, wo, &mut rng);
            assert!(z < 5.0, "{name}, wo = {wo:?}: chi-square z-score {z:.1}");
        }
    }
}

#[test]
fn sampled_values_and_densities_agree_with_evaluation() {
    let mut rng = Rng(11);
    for (name, bsdf) in models() {
        for wo in outgoing(&bsdf) {
            for _ in 0..2000 {
                let Some(s) = bsdf.sample(wo, rng.next(), [rng.next(), rng.next()]) else { continue };
                if s.delta {
                    continue;
                }
                let (f, pdf) = (bsdf.eval(wo, s.wi), bsdf.pdf(wo, s.wi));
                let close = |a: f32, b: f32| (a - b).abs() <= 1e-3 * a.abs().max(b.abs()) + 1e-6;
                assert!(close(pdf, s.pdf), "{name}: pdf {pdf} vs sampled {}", s.pdf);
                for c in 0..3 {
                    assert!(close(f[c], s.f[c]), "{name}: f {f:?} vs sampled {:?}", s.f);
                }
            }
        }
    }
}

#[test]
fn no_model_reflects_or_transmits_more_than_it_receives() {
    let mut rng = Rng(3);
    // Perfect reflectors too: a white diffuse surface, and a conductor with reflectance 1.
    let mut all = models();
    all.push(("white diffuse", Bsdf::Diffuse(Diffuse { reflectance: Vec3::ONE })));
    all.push((
        "white diffuse transmission",
        Bsdf::DiffuseTransmission(DiffuseTransmission {
            reflectance: Vec3::splat(0.5),
            transmittance: Vec3::splat(0.5),
        }),
    ));
    let k = fbksd_embree::bsdf::fresnel::k_from_reflectance(Vec3::splat(0.9999));
    all.push((
        "ideal conductor α=0.5",
        Bsdf::Conductor(Conductor { distribution: Ggx::new(0.5, 0.5), eta: Vec3::ONE, k }),
    ));
    for (name, bsdf) in all {
        for wo in outgoing(&bsdf) {
            let n = 100_000;
            // Per channel: a model may sample by one channel and weight the others.
            let (mut sum, mut sum2) = ([0f64; 3], [0f64; 3]);
            for _ in 0..n {
                // Flux, not radiance: refraction's 1/η² is undone by η².
                let w = match bsdf.sample(wo, rng.next(), [rng.next(), rng.next()]) {
                    Some(s) => (s.f * (s.wi.z.abs() / s.pdf * s.eta * s.eta)).to_array(),
                    None => [0.0; 3],
                };
                for c in 0..3 {
                    let w = w[c] as f64;
                    assert!(w.is_finite() && w >= 0.0, "{name}: weight {w}");
                    sum[c] += w;
                    sum2[c] += w * w;
                }
            }
            for c in 0..3 {
                let mean = sum[c] / n as f64;
                let sigma = ((sum2[c] / n as f64 - mean * mean).max(0.0) / n as f64).sqrt();
                assert!(
                    mean <= 1.0 + 1e-3 + 4.0 * sigma,
                    "{name}, wo = {wo:?}, channel {c}: albedo {mean:.4} ± {sigma:.4}"
                );
            }
        }
    }
}

#[test]
fn smooth_white_plastic_reflects_everything() {
    // The coating reflects F(θo); the white base returns all of the rest.
    let mut rng = Rng(17);
    let bsdf = coated(Ggx::new(0.0, 0.0), Vec3::ONE);
    for theta in [0.0, 30.0, 60.0, 80.0] {
        let wo = direction(theta, 20.0);
        let n = 200_000;
        let mean = (0..n)
            .map(|_| match bsdf.sample(wo, rng.next(), [rng.next(), rng.next()]) {
                Some(s) => (s.f.x * s.wi.z.abs() / s.pdf) as f64,
                None => 0.0,
            })
            .sum::<f64>()
            / n as f64;
        assert!((mean - 1.0).abs() < 0.01, "θo = {theta}: albedo {mean}");
    }
}

#[test]
fn reflection_is_reciprocal() {
    let mut rng = Rng(5);
    for (name, bsdf) in models() {
        if matches!(bsdf, Bsdf::Dielectric(_)) {
            continue; // Radiance transport through glass is not symmetric (η²).
        }
        for _ in 0..500 {
            let a = direction(rng.next() * 89.0, rng.next() * 360.0);
            let b = direction(rng.next() * 89.0, rng.next() * 360.0);
            let (ab, ba) = (bsdf.eval(a, b), bsdf.eval(b, a));
            for c in 0..3 {
                assert!((ab[c] - ba[c]).abs() <= 1e-4 * ab[c].abs().max(1.0), "{name}: f(a,b) {ab:?} ≠ f(b,a) {ba:?}");
            }
        }
    }
}

#[test]
fn glass_reflection_and_refraction_are_reciprocal_up_to_eta_squared() {
    let bsdf = Bsdf::Dielectric(Dielectric { distribution: Ggx::new(0.3, 0.3), eta: 1.5 });
    let (outside, inside) = (direction(30.0, 10.0), direction(160.0, 200.0));
    let (into, out_of) = (bsdf.eval(outside, inside).x, bsdf.eval(inside, outside).x);
    // f(o→i)·η_o² = f(i→o)·η_i² for radiance.
    assert!(into > 0.0 && (into * 1.5 * 1.5 - out_of).abs() < 1e-3 * out_of, "{into} vs {out_of}");
}

#[test]
fn extreme_parameters_give_finite_values() {
    let mut rng = Rng(13);
    let mut extremes = vec![];
    for alpha in [0.0, 1e-7, 1e-3, 0.999e-3, 1e-2, 10.0, 1e4, f32::MAX, f32::NAN] {
        extremes.push(Bsdf::Conductor(Conductor { distribution: Ggx::new(alpha, alpha), eta: gold(), k: gold_k() }));
        extremes.push(Bsdf::Dielectric(Dielectric { distribution: Ggx::new(alpha, alpha), eta: 1.5 }));
        extremes.push(Bsdf::Dielectric(Dielectric { distribution: Ggx::new(alpha, alpha), eta: 1.0 }));
        extremes.push(Bsdf::Dielectric(Dielectric { distribution: Ggx::new(alpha, alpha), eta: 1.0001 }));
        extremes.push(coated(Ggx::new(alpha, alpha), Vec3::ONE));
    }
    // Grazing and exactly tangent directions included.
    let dirs = [
        direction(89.999, 0.0),
        direction(90.0, 45.0),
        direction(0.0, 0.0),
        direction(179.9, 10.0),
        vec3(1.0, 0.0, 0.0),
    ];
    for bsdf in &extremes {
        for wo in dirs {
            for _ in 0..200 {
                let wi = direction(rng.next() * 180.0, rng.next() * 360.0);
                assert!(bsdf.eval(wo, wi).is_finite() && bsdf.pdf(wo, wi).is_finite(), "{bsdf:?} wo {wo:?} wi {wi:?}");
                if let Some(s) = bsdf.sample(wo, rng.next(), [rng.next(), rng.next()]) {
                    let w = s.f * (s.wi.z.abs() / s.pdf);
                    assert!(w.is_finite() && s.wi.is_finite(), "{bsdf:?} wo {wo:?}: sample {s:?}");
                }
            }
        }
    }
}
