//! Unidirectional path tracing with next-event estimation, multiple
//! importance sampling (power heuristic) and Russian roulette, producing
//! every feature of the sample layout on the way.
//!
//! Features follow thesis appendix A:
//! - COLOR: the path's radiance.
//! - DIRECT_LIGHT: at the first hit, the cosine-weighted incident direct
//!   radiance from one light sample, E/π (so a Lambertian surface's
//!   directly lit radiance is its albedo times this).
//! - DEPTH: distance from the camera to the first hit (0 on a miss).
//! - WORLD, NORMAL (shading normal, facing the viewer) and TEXTURE_COLOR
//!   (albedo, see [`crate::scene::material::Material::albedo`]) at the
//!   first (number 0) and second (number 1) hits; 0 where the path missed.
//! - The `_NS` features at the first hit whose BSDF is not purely
//!   specular (the path followed through mirrors and glass).
//! - DIFFUSE_COLOR: the part of COLOR scattered at the first hit by lobes
//!   whose roughness (α) is at least the layout's threshold; light seen
//!   directly is excluded. Exact in expectation: each first-hit
//!   contribution is weighted by f_diffuse / f.
//!
//! Dimensions: the camera uses IMAGE_X/Y, LENS_U/V and TIME; the first
//! light sample uses LIGHT_X/Y; everything else comes from
//! [`fbksd_renderer::sampler::Dimensions`], 8 per bounce.

use crate::bsdf::Bsdf;
use crate::math::{Frame, Vec3};
use crate::scene::camera::Ray;
use crate::scene::shape::SurfaceHit;
use crate::scene::Scene;
use fbksd_renderer::sampler::Dimensions;

/// Which features to compute.
#[derive(Debug, Clone, Copy, Default)]
pub struct Wanted {
    /// COLOR or DIFFUSE_COLOR: the path's radiance. Without it, paths stop
    /// as soon as the geometry features are known and no light is sampled
    /// beyond DIRECT_LIGHT.
    pub radiance: bool,
    /// DIRECT_LIGHT.
    pub direct: bool,
    /// DEPTH, WORLD/NORMAL/TEXTURE_COLOR (either number), or any `_NS` feature.
    pub geometry: bool,
    /// DIFFUSE_COLOR.
    pub diffuse: bool,
    /// The layout's roughness threshold.
    pub roughness_threshold: f32,
}

/// Where a sample lies: the seven random parameters.
#[derive(Debug, Clone, Copy)]
pub struct Position {
    /// Raster x (pixels).
    pub image_x: f32,
    /// Raster y (pixels).
    pub image_y: f32,
    /// Lens position.
    pub lens: [f32; 2],
    /// Shutter fraction.
    pub time: f32,
    /// The first light sample.
    pub light: [f32; 2],
}

/// Geometry features of one hit.
#[derive(Debug, Clone, Copy, Default)]
pub struct HitFeatures {
    /// Position.
    pub world: Vec3,
    /// Shading normal, facing the incoming ray.
    pub normal: Vec3,
    /// Albedo.
    pub albedo: Vec3,
}

/// Everything a sample can report.
#[derive(Debug, Clone, Copy, Default)]
pub struct SampleValues {
    /// Radiance.
    pub color: Vec3,
    /// See the module documentation.
    pub direct: Vec3,
    /// Distance to the first hit.
    pub depth: f32,
    /// First and second hits.
    pub hits: [HitFeatures; 2],
    /// First non-specular hit.
    pub non_specular: HitFeatures,
    /// Diffuse part of `color`.
    pub diffuse: Vec3,
    /// Rays traced (closest-hit and shadow), for the benchmark.
    pub rays: u32,
    /// Whether a non-finite value had to be replaced (a renderer bug; counted and reported).
    pub repaired: bool,
}

#[inline(always)]
fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2.is_infinite() {
        return 1.0;
    }
    if a2 + b2 == 0.0 {
        0.0
    } else {
        a2 / (a2 + b2)
    }
}

/// Dimensions used per bounce.
const DIMS_PER_BOUNCE: u32 = 8;

/// Traces one camera path.
pub fn trace(scene: &Scene, pos: &Position, dims: &Dimensions, wanted: &Wanted) -> SampleValues {
    let mut out = SampleValues::default();
    let mut ray = scene.camera.ray(pos.image_x, pos.image_y, pos.lens, pos.time);
    let mut l = Vec3::ZERO;
    let mut beta = Vec3::ONE;
    // Per-channel share of later contributions that counts as diffuse (set at the first hit).
    let mut diffuse_share = Vec3::ZERO;
    let mut diffuse = Vec3::ZERO;
    let mut specular_bounce = false;
    let mut found_non_specular = false;
    let mut eta_scale = 1.0f32;
    let mut prev: Option<(Vec3, f32)> = None; // (origin of the last bounce, its BSDF pdf)
    let mut depth = 0u32;
    let mut rays = 0u32;
    loop {
        rays += 1;
        let hit = scene.intersect(&ray, f32::INFINITY);
        // Emission the path found: the environment, or an area light it hit.
        let emitter = match &hit {
            None => scene.environment.map(|l| (l, Vec3::ZERO, Vec3::ZERO)),
            Some(h) => scene.shapes[h.shape as usize].light.map(|l| (l, h.p, h.ng)),
        };
        if let Some((li, point, n)) = emitter {
            let light = &scene.lights[li as usize];
            let le = light.emitted(n, -ray.dir);
            if !le.is_black() {
                // Weighted against the light sample that could have found it (MIS).
                let w = match prev {
                    Some((p, pdf)) if !specular_bounce => {
                        power_heuristic(pdf, scene.light_probability(li) * light.pdf(p, ray.dir, point, n))
                    }
                    _ => 1.0,
                };
                let c = beta * le * w;
                l += c;
                if depth > 0 {
                    diffuse += c * diffuse_share;
                }
            }
        }
        let Some(hit) = hit else { break };
        let wo = -ray.dir;
        let shape = &scene.shapes[hit.shape as usize];
        let material = &scene.materials[shape.material as usize];
        let bsdf = material.bsdf(hit.uv);
        // Geometry features.
        if wanted.geometry {
            if depth == 0 {
                out.depth = hit.t;
            }
            let features =
                || HitFeatures { world: hit.p, normal: hit.ns.face_forward(wo), albedo: material.albedo(hit.uv) };
            if depth < 2 {
                out.hits[depth as usize] = features();
            }
            if !found_non_specular && !bsdf.is_delta() {
                found_non_specular = true;
                out.non_specular = features();
            }
        }
        if depth >= scene.max_depth {
            break;
        }
        let frame = Frame::from_normal(hit.ns);
        let wo_local = frame.to_local(wo);
        let base = depth * DIMS_PER_BOUNCE;
        // Next-event estimation.
        if !bsdf.is_delta() && (wanted.radiance || (depth == 0 && wanted.direct)) {
            let u_light = if depth == 0 { pos.light } else { [dims.get(base + 1), dims.get(base + 2)] };
            let lc = sample_light(
                scene,
                &hit,
                &bsdf,
                &frame,
                wo_local,
                dims.get(base),
                u_light,
                ray.time,
                depth == 0 && wanted.direct,
                &mut rays,
            );
            let contribution = beta * lc.reflected;
            l += contribution;
            if depth == 0 {
                if wanted.direct {
                    out.direct = lc.incident;
                }
                if wanted.diffuse && !contribution.is_black() {
                    // Split by lobe at the light direction.
                    let part = bsdf.eval_diffuse_part(wo_local, lc.wi_local, wanted.roughness_threshold);
                    diffuse += share(part, bsdf.eval(wo_local, lc.wi_local)) * contribution;
                }
            } else {
                diffuse += contribution * diffuse_share;
            }
        } else if depth == 0 && wanted.direct {
            // A specular first hit still receives direct light: measured as a white Lambertian would.
            let lambert = Bsdf::Diffuse(crate::bsdf::diffuse::Diffuse { reflectance: Vec3::ONE });
            let up = Vec3 { x: 0.0, y: 0.0, z: 1.0 };
            let frame = Frame::from_normal(hit.ns.face_forward(wo));
            out.direct =
                sample_light(scene, &hit, &lambert, &frame, up, dims.get(base), pos.light, ray.time, true, &mut rays)
                    .incident;
        }
        // Without radiance, the path is done once the features are.
        if !wanted.radiance && (!wanted.geometry || (depth >= 1 && found_non_specular)) {
            break;
        }
        // Continue the path by sampling the BSDF.
        let Some(s) = bsdf.sample(wo_local, dims.get(base + 3), [dims.get(base + 4), dims.get(base + 5)]) else {
            break;
        };
        let wi = frame.to_world(s.wi);
        let weight = s.f * (s.wi.z.abs() / s.pdf);
        if depth == 0 && wanted.diffuse {
            diffuse_share = if s.delta {
                Vec3::splat(if s.roughness >= wanted.roughness_threshold { 1.0 } else { 0.0 })
            } else {
                share(bsdf.eval_diffuse_part(wo_local, s.wi, wanted.roughness_threshold), bsdf.eval(wo_local, s.wi))
            };
        }
        beta *= weight;
        specular_bounce = s.delta;
        // Radiance is scaled by 1/η² on refraction; roulette should not see that.
        eta_scale *= s.eta * s.eta;
        prev = Some((hit.p, s.pdf));
        ray = spawn(scene, &hit, wi, ray.time);
        depth += 1;
        // Russian roulette; not while the path still looks for its first
        // non-specular hit, whose features must not be left to chance.
        let rr_beta = beta * eta_scale;
        let searching = wanted.geometry && !found_non_specular;
        if wanted.radiance && !searching && rr_beta.max_component() < 1.0 && depth > 1 {
            let q = (1.0 - rr_beta.max_component()).max(0.0);
            if dims.get(base + 6) < q {
                break;
            }
            beta = beta / (1.0 - q);
        }
        if !beta.is_finite() || (beta.is_black() && !searching) {
            break;
        }
    }
    out.rays = rays;
    out.color = l;
    out.diffuse = diffuse;
    // A last line of defence: nothing non-finite leaves the renderer. Any
    // replacement is counted and reported, so it is a visible bug, not a fix.
    let mut repaired = false;
    let mut clean = |v: &mut Vec3| {
        if !v.is_finite() {
            repaired = true;
            *v = Vec3::ZERO;
        }
    };
    clean(&mut out.color);
    clean(&mut out.direct);
    clean(&mut out.diffuse);
    for h in out.hits.iter_mut().chain(std::iter::once(&mut out.non_specular)) {
        clean(&mut h.world);
        clean(&mut h.normal);
        clean(&mut h.albedo);
    }
    if !out.depth.is_finite() {
        repaired = true;
        out.depth = 0.0;
    }
    out.repaired = repaired;
    out
}

/// `a / b` per channel, 0 where `b` is 0.
#[inline]
fn share(a: Vec3, b: Vec3) -> Vec3 {
    let s = |a: f32, b: f32| if b > 0.0 { (a / b).clamp(0.0, 1.0) } else { 0.0 };
    Vec3 { x: s(a.x, b.x), y: s(a.y, b.y), z: s(a.z, b.z) }
}

/// A ray leaving `hit` along `dir`, offset off the surface on `dir`'s side.
#[inline]
fn spawn(scene: &Scene, hit: &SurfaceHit, dir: Vec3, time: f32) -> Ray {
    // The hit point's error grows with the distance travelled (curves are hit at origin + t·dir).
    let eps = scene.epsilon(hit.p).max(hit.t * 2e-6);
    let n = if dir.dot(hit.ng) > 0.0 { hit.ng } else { -hit.ng };
    Ray { origin: hit.p + n * eps, dir, time }
}

/// What one light sample brings to a hit.
#[derive(Debug, Clone, Copy, Default)]
struct LightContribution {
    /// MIS-weighted reflected radiance towards `wo`.
    reflected: Vec3,
    /// Incident direct radiance E/π (for DIRECT_LIGHT).
    incident: Vec3,
    /// The sampled direction, local.
    wi_local: Vec3,
}

/// One light sample at `hit`, with its shadow ray at `time`.
#[allow(clippy::too_many_arguments)]
#[inline]
fn sample_light(
    scene: &Scene,
    hit: &SurfaceHit,
    bsdf: &Bsdf,
    frame: &Frame,
    wo_local: Vec3,
    u_choose: f32,
    u: [f32; 2],
    time: f32,
    want_incident: bool,
    rays: &mut u32,
) -> LightContribution {
    let none = LightContribution::default();
    let Some((li, choose_pdf)) = scene.choose_light(u_choose) else { return none };
    let light = &scene.lights[li as usize];
    let Some(ls) = light.sample(hit.p, u) else { return none };
    if ls.radiance.is_black() || ls.pdf <= 0.0 {
        return none;
    }
    let wi_local = frame.to_local(ls.wi);
    let f = bsdf.eval(wo_local, wi_local);
    let facing = wi_local.z * wo_local.z > 0.0;
    // No shadow ray when neither the colour nor DIRECT_LIGHT can gain from it.
    if f.is_black() && !(want_incident && facing) {
        return none;
    }
    let ray = spawn(scene, hit, ls.wi, time);
    let t_max = if ls.distance.is_finite() { ls.distance * (1.0 - 1e-4) - scene.epsilon(hit.p) } else { f32::INFINITY };
    *rays += 1;
    if t_max <= 0.0 || scene.occluded(&ray, t_max) {
        return none;
    }
    let cos = wi_local.z.abs();
    let light_pdf = choose_pdf * ls.pdf;
    let w = power_heuristic(light_pdf, bsdf.pdf(wo_local, wi_local));
    LightContribution {
        reflected: f * cos * ls.radiance * (w / light_pdf),
        // Light from behind the surface as the viewer sees it is not incident on the visible side.
        incident: if facing { ls.radiance * (cos / (light_pdf * std::f32::consts::PI)) } else { Vec3::ZERO },
        wi_local,
    }
}
