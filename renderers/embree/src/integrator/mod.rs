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
//!
//! Paths are traced in batches, wavefront style ([`Batch`], in
//! [`wavefront`]): each bounce is a few passes over the batch's paths,
//! kept in lanes of 16. The shading steps below are written for one path;
//! the passes call them lane by lane, which the compiler vectorises where
//! the case is a common one (see [`crate::scene::flat`]). Each sample is a
//! pure function of its seed whichever lanes it shares.

use crate::bsdf::Bsdf;
use crate::math::{Frame, Vec3};
use crate::scene::camera::Ray;
use crate::scene::light::LightSample;
use crate::scene::Scene;
use fbksd_renderer::sampler::Dimensions;

pub mod wavefront;
pub use crate::lanes::Isa;
pub use wavefront::Batch;

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

/// What a path carries from bounce to bounce.
#[derive(Debug, Clone, Copy, Default)]
struct PathState {
    /// The sample's index in its batch.
    sample: u32,
    /// Its dimensions' key (see [`Dimensions::key`]).
    key: u64,
    /// The first light sample.
    light_u: [f32; 2],
    /// The ray to trace next.
    ray: Ray,
    l: Vec3,
    beta: Vec3,
    /// Per-channel share of later contributions that counts as diffuse (set at the first hit).
    diffuse_share: Vec3,
    diffuse: Vec3,
    eta_scale: f32,
    /// Origin of the last bounce and its BSDF pdf, when there was one.
    prev_p: Vec3,
    prev_pdf: f32,
    has_prev: bool,
    specular_bounce: bool,
    found_non_specular: bool,
    /// Whether the path wants its next ray traced.
    alive: bool,
    /// Rays traced.
    rays: u32,
}

/// A path at the surface its ray hit, as the shading steps see it.
#[derive(Debug, Clone, Copy)]
struct At {
    /// The hit point, its unit geometric normal and distance along the ray.
    p: Vec3,
    ng: Vec3,
    t: f32,
    /// The shading frame and the direction back along the ray in it.
    frame: Frame,
    wo: Vec3,
    /// The ray's time.
    time: f32,
}

impl At {
    #[inline(always)]
    fn new(p: Vec3, ng: Vec3, ns: Vec3, t: f32, ray: &Ray) -> At {
        let frame = Frame::from_normal(ns);
        At { p, ng, t, wo: frame.to_local(-ray.dir), frame, time: ray.time }
    }
}

/// The contributions of a light sample, added once its shadow ray is found clear.
#[derive(Debug, Clone, Copy, Default)]
struct Unoccluded {
    color: Vec3,
    diffuse: Vec3,
    /// DIRECT_LIGHT, when this light sample is the first hit's.
    direct: Option<Vec3>,
}

/// A segment to test for occlusion: a ray and how far along it to look.
#[derive(Debug, Clone, Copy)]
struct Segment {
    ray: Ray,
    t_max: f32,
}

/// `a / b` per channel, 0 where `b` is 0.
#[inline(always)]
fn share(a: Vec3, b: Vec3) -> Vec3 {
    let s = |a: f32, b: f32| if b > 0.0 { (a / b).clamp(0.0, 1.0) } else { 0.0 };
    Vec3 { x: s(a.x, b.x), y: s(a.y, b.y), z: s(a.z, b.z) }
}

/// A ray leaving the hit along `dir`, offset off the surface on `dir`'s side.
#[inline(always)]
fn spawn(scene: &Scene, at: &At, dir: Vec3) -> Ray {
    // The hit point's error grows with the distance travelled (curves are hit at origin + t·dir).
    let eps = scene.epsilon(at.p).max(at.t * 2e-6);
    let n = if dir.dot(at.ng) > 0.0 { at.ng } else { -at.ng };
    Ray { origin: at.p + n * eps, dir, time: at.time }
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

/// One light sample at a hit: a light chosen with `u_choose`, sampled with `u`.
#[inline(always)]
fn sample_light(
    scene: &Scene,
    at: &At,
    bsdf: &Bsdf,
    u_choose: f32,
    u: [f32; 2],
    want_incident: bool,
) -> Option<(Segment, LightContribution)> {
    let (li, choose_pdf) = scene.choose_light(u_choose)?;
    let light = &scene.lights[li as usize];
    let ls = light.sample(at.p, u)?;
    light_contribution(scene, at, bsdf, choose_pdf, light.is_delta(), &ls, want_incident)
}

/// The shadow segment of light sample `ls` (of a light chosen with
/// probability `choose_pdf`) and what it brings if that segment is clear.
/// None when no shadow ray is worth tracing.
#[inline(always)]
fn light_contribution(
    scene: &Scene,
    at: &At,
    bsdf: &Bsdf,
    choose_pdf: f32,
    delta_light: bool,
    ls: &LightSample,
    want_incident: bool,
) -> Option<(Segment, LightContribution)> {
    if ls.radiance.is_black() || ls.pdf <= 0.0 {
        return None;
    }
    let wi_local = at.frame.to_local(ls.wi);
    let f = bsdf.eval(at.wo, wi_local);
    let facing = wi_local.z * at.wo.z > 0.0;
    // No shadow ray when neither the colour nor DIRECT_LIGHT can gain from it.
    if f.is_black() && !(want_incident && facing) {
        return None;
    }
    let ray = spawn(scene, at, ls.wi);
    let t_max = if ls.distance.is_finite() { ls.distance * (1.0 - 1e-4) - scene.epsilon(at.p) } else { f32::INFINITY };
    let cos = wi_local.z.abs();
    let light_pdf = choose_pdf * ls.pdf;
    // A delta light cannot be found by a BSDF sample: its sample takes all the weight.
    let w = if delta_light { 1.0 } else { power_heuristic(light_pdf, bsdf.pdf(at.wo, wi_local)) };
    let contribution = LightContribution {
        reflected: f * cos * ls.radiance * (w / light_pdf),
        // Light from behind the surface as the viewer sees it is not incident on the visible side.
        incident: if facing { ls.radiance * (cos / (light_pdf * std::f32::consts::PI)) } else { Vec3::ZERO },
        wi_local,
    };
    Some((Segment { ray, t_max }, contribution))
}

/// What a light sample's contribution adds to the path's values, if its shadow ray is clear.
#[inline(always)]
fn unoccluded(wanted: &Wanted, depth: u32, at: &At, bsdf: &Bsdf, s: &PathState, lc: &LightContribution) -> Unoccluded {
    let contribution = s.beta * lc.reflected;
    let mut pending = Unoccluded { color: contribution, ..Unoccluded::default() };
    if depth == 0 {
        if wanted.direct {
            pending.direct = Some(lc.incident);
        }
        if wanted.diffuse && !contribution.is_black() {
            // Split by lobe at the light direction.
            let part = bsdf.eval_diffuse_part(at.wo, lc.wi_local, wanted.roughness_threshold);
            pending.diffuse = share(part, bsdf.eval(at.wo, lc.wi_local)) * contribution;
        }
    } else {
        pending.diffuse = contribution * s.diffuse_share;
    }
    pending
}

/// Continues the path by sampling the BSDF (or ends it): the next ray, the
/// throughput, Russian roulette.
#[inline(always)]
fn scatter(scene: &Scene, wanted: &Wanted, depth: u32, at: &At, bsdf: &Bsdf, s: &mut PathState) {
    s.alive = false;
    // Without radiance, the path is done once the features are.
    if !wanted.radiance && (!wanted.geometry || (depth >= 1 && s.found_non_specular)) {
        return;
    }
    let dims = Dimensions::from_key(s.key);
    let base = depth * DIMS_PER_BOUNCE;
    let Some(bs) = bsdf.sample(at.wo, dims.get(base + 3), [dims.get(base + 4), dims.get(base + 5)]) else {
        return;
    };
    let wi = at.frame.to_world(bs.wi);
    let weight = bs.f * (bs.wi.z.abs() / bs.pdf);
    if depth == 0 && wanted.diffuse {
        s.diffuse_share = if bs.delta {
            Vec3::splat(if bs.roughness >= wanted.roughness_threshold { 1.0 } else { 0.0 })
        } else {
            share(bsdf.eval_diffuse_part(at.wo, bs.wi, wanted.roughness_threshold), bsdf.eval(at.wo, bs.wi))
        };
    }
    s.beta *= weight;
    s.specular_bounce = bs.delta;
    // Radiance is scaled by 1/η² on refraction; roulette should not see that.
    s.eta_scale *= bs.eta * bs.eta;
    (s.prev_p, s.prev_pdf, s.has_prev) = (at.p, bs.pdf, true);
    s.ray = spawn(scene, at, wi);
    // Russian roulette; not while the path still looks for its first
    // non-specular hit, whose features must not be left to chance.
    let rr_beta = s.beta * s.eta_scale;
    let searching = wanted.geometry && !s.found_non_specular;
    if wanted.radiance && !searching && rr_beta.max_component() < 1.0 && depth + 1 > 1 {
        let q = (1.0 - rr_beta.max_component()).max(0.0);
        if dims.get(base + 6) < q {
            return;
        }
        s.beta = s.beta / (1.0 - q);
    }
    // A black throughput ends the path, unless it still looks for its features.
    s.alive = s.beta.is_finite() && (searching || !s.beta.is_black());
}

/// The shading steps above for lanes of paths at constant diffuse hits,
/// with the same bits (see [`crate::lanes`]).
mod diffuse_lanes {
    use super::{Wanted, DIMS_PER_BOUNCE};
    use crate::bsdf::diffuse::Diffuse;
    use crate::lanes::{F32s, Frames, Mask, Vec3s, W};
    use crate::scene::light::LightSamples;
    use crate::scene::Scene;
    use fbksd_renderer::sampler::Dimensions;

    /// [`super::At`] in lanes.
    #[derive(Debug, Clone, Copy)]
    pub(super) struct At {
        pub p: Vec3s,
        pub ng: Vec3s,
        pub t: F32s,
        pub frame: Frames,
        pub wo: Vec3s,
    }

    impl At {
        #[inline(always)]
        pub fn new(p: Vec3s, ng: Vec3s, ns: Vec3s, t: F32s, dir: Vec3s) -> At {
            let frame = Frames::from_normal(ns);
            At { p, ng, t, wo: frame.to_local(-dir), frame }
        }
    }

    /// Dimension `d` of each lane's key.
    #[inline(always)]
    pub fn dimension(keys: &[u64; W], d: u32) -> F32s {
        F32s::from_fn(|k| Dimensions::from_key(keys[k]).get(d))
    }

    #[inline(always)]
    fn power_heuristic(a: F32s, b: F32s) -> F32s {
        let (a2, b2) = (a * a, b * b);
        let zero = F32s::splat(0.0);
        let w = F32s::select((a2 + b2).eq(zero), zero, a2 / (a2 + b2));
        F32s::select(a2.is_infinite(), F32s::splat(1.0), w)
    }

    #[inline(always)]
    fn share(a: Vec3s, b: Vec3s) -> Vec3s {
        let s = |a: F32s, b: F32s| {
            F32s::select(b.gt(F32s::splat(0.0)), (a / b).map(|v| v.clamp(0.0, 1.0)), F32s::splat(0.0))
        };
        Vec3s::new(s(a.x, b.x), s(a.y, b.y), s(a.z, b.z))
    }

    /// [`super::spawn`]: the rays' origins.
    #[inline(always)]
    pub fn spawn(scene: &Scene, at: &At, dir: Vec3s) -> Vec3s {
        let eps = scene.epsilon_lanes(at.p).max(at.t * 2e-6);
        let n = Vec3s::select(dir.dot(at.ng).gt(F32s::splat(0.0)), at.ng, -at.ng);
        at.p + n * eps
    }

    /// [`super::LightContribution`] in lanes.
    #[derive(Debug, Clone, Copy)]
    pub struct LightContribution {
        pub reflected: Vec3s,
        pub incident: Vec3s,
        pub wi_local: Vec3s,
    }

    /// [`super::light_contribution`]: the lanes worth a shadow ray, the
    /// rays' origins (along the samples' directions) and lengths, and the
    /// contributions.
    #[inline(always)]
    pub fn light_contribution(
        scene: &Scene,
        at: &At,
        reflectance: Vec3s,
        choose_pdf: F32s,
        delta_light: Mask,
        ls: &LightSamples,
        want_incident: bool,
    ) -> (Mask, Vec3s, F32s, LightContribution) {
        let zero = F32s::splat(0.0);
        let wi_local = at.frame.to_local(ls.wi);
        let (f, bsdf_pdf) = Diffuse::eval_pdf_lanes(reflectance, at.wo, wi_local);
        let facing = (wi_local.z * at.wo.z).gt(zero);
        let worth = !f.is_black() | (facing & want_incident);
        let ok = ls.ok & !ls.radiance.is_black() & !ls.pdf.le(zero) & worth;
        let origin = spawn(scene, at, ls.wi);
        let t_max = F32s::select(
            ls.distance.is_finite(),
            ls.distance * (1.0 - 1e-4) - scene.epsilon_lanes(at.p),
            F32s::splat(f32::INFINITY),
        );
        let cos = wi_local.z.abs();
        let light_pdf = choose_pdf * ls.pdf;
        let w = F32s::select(delta_light, F32s::splat(1.0), power_heuristic(light_pdf, bsdf_pdf));
        let contribution = LightContribution {
            reflected: f * cos * ls.radiance * (w / light_pdf),
            incident: Vec3s::select(facing, ls.radiance * (cos / (light_pdf * std::f32::consts::PI)), Vec3s::ZERO),
            wi_local,
        };
        (ok, origin, t_max, contribution)
    }

    /// [`super::unoccluded`]: colour, diffuse part, and DIRECT_LIGHT (at the first hit, when wanted).
    #[inline(always)]
    pub fn unoccluded(
        wanted: &Wanted,
        depth: u32,
        at: &At,
        reflectance: Vec3s,
        beta: Vec3s,
        diffuse_share: Vec3s,
        lc: &LightContribution,
    ) -> (Vec3s, Vec3s, Vec3s) {
        let contribution = beta * lc.reflected;
        if depth > 0 {
            return (contribution, contribution * diffuse_share, Vec3s::ZERO);
        }
        let direct = if wanted.direct { lc.incident } else { Vec3s::ZERO };
        let diffuse = if wanted.diffuse {
            // A diffuse BSDF is all diffuse part.
            let (f, _) = Diffuse::eval_pdf_lanes(reflectance, at.wo, lc.wi_local);
            Vec3s::select(!contribution.is_black(), share(f, f) * contribution, Vec3s::ZERO)
        } else {
            Vec3s::ZERO
        };
        (contribution, diffuse, direct)
    }

    /// The lanes' paths after [`super::scatter`] (see [`super::PathState`]).
    #[derive(Debug, Clone, Copy)]
    pub struct Scattered {
        pub alive: Mask,
        /// Lanes with a new ray and throughput (the others keep theirs).
        pub moved: Mask,
        pub beta: Vec3s,
        pub diffuse_share: Vec3s,
        pub origin: Vec3s,
        pub dir: Vec3s,
        pub pdf: F32s,
    }

    /// The state of the paths [`super::scatter`] reads, in lanes.
    #[derive(Debug, Clone, Copy)]
    pub struct Throughput<'a> {
        pub keys: &'a [u64; W],
        pub beta: Vec3s,
        pub eta_scale: F32s,
        pub diffuse_share: Vec3s,
        pub found_non_specular: Mask,
    }

    /// [`super::scatter`].
    #[inline(always)]
    pub fn scatter(
        scene: &Scene,
        wanted: &Wanted,
        depth: u32,
        at: &At,
        reflectance: Vec3s,
        s: &Throughput,
    ) -> Scattered {
        let (zero, one) = (F32s::splat(0.0), F32s::splat(1.0));
        // Without radiance, the path is done once the features are.
        let done = match (wanted.radiance, wanted.geometry) {
            (true, _) => Mask::splat(false),
            (false, false) => Mask::splat(true),
            (false, true) => s.found_non_specular & (depth >= 1),
        };
        let base = depth * DIMS_PER_BOUNCE;
        let u = [dimension(s.keys, base + 4), dimension(s.keys, base + 5)];
        let (sampled, f, wi, pdf) = Diffuse::sample_lanes(reflectance, at.wo, u);
        let moved = !done & sampled;
        let dir = at.frame.to_world(wi);
        let weight = f * (wi.z.abs() / pdf);
        let diffuse_share = if depth == 0 && wanted.diffuse {
            let (f, _) = Diffuse::eval_pdf_lanes(reflectance, at.wo, wi);
            share(f, f)
        } else {
            s.diffuse_share
        };
        let beta = s.beta * weight;
        // Russian roulette (as scatter; the eta scale of a diffuse bounce is 1).
        let rr_beta = beta * s.eta_scale;
        let searching = !s.found_non_specular & wanted.geometry;
        let roulette = !searching & rr_beta.max_component().lt(one) & (wanted.radiance && depth + 1 > 1);
        let q = (one - rr_beta.max_component()).max(zero);
        let survived = !(roulette & dimension(s.keys, base + 6).lt(q));
        let beta = Vec3s::select(roulette, beta * (one / (one - q)), beta);
        let alive = moved & survived & beta.is_finite() & (searching | !beta.is_black());
        Scattered { alive, moved, beta, diffuse_share, origin: spawn(scene, at, dir), dir, pdf }
    }
}

impl SampleValues {
    /// A last line of defence: nothing non-finite leaves the renderer. Any
    /// replacement is counted and reported, so it is a visible bug, not a fix.
    #[inline]
    fn repair_non_finite(&mut self) {
        let depth = self.depth;
        let [h0, h1] = &mut self.hits;
        let ns = &mut self.non_specular;
        let vectors = [
            &mut self.color,
            &mut self.direct,
            &mut self.diffuse,
            &mut h0.world,
            &mut h0.normal,
            &mut h0.albedo,
            &mut h1.world,
            &mut h1.normal,
            &mut h1.albedo,
            &mut ns.world,
            &mut ns.normal,
            &mut ns.albedo,
        ];
        // One sum of v · 0 instead of a test per value: it is ±0 exactly
        // when no value is infinite or NaN.
        if vectors.iter().fold(depth * 0.0, |sum, v| sum + v.dot(Vec3::ZERO)) == 0.0 {
            return;
        }
        for v in vectors {
            if !v.is_finite() {
                self.repaired = true;
                *v = Vec3::ZERO;
            }
        }
        if !depth.is_finite() {
            self.repaired = true;
            self.depth = 0.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_values_are_zeroed_and_counted_finite_ones_kept() {
        let v = |x: f32| Vec3 { x, y: 0.5, z: -2.0 };
        let mut clean = SampleValues { color: v(1.0), depth: 3.0, ..SampleValues::default() };
        clean.hits[1].albedo = v(-0.0);
        let before = clean;
        clean.repair_non_finite();
        assert!(!clean.repaired);
        assert_eq!((clean.color, clean.hits[1].albedo, clean.depth), (before.color, before.hits[1].albedo, 3.0));

        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut values = SampleValues { color: v(1.0), depth: 3.0, ..SampleValues::default() };
            values.non_specular.normal = v(bad);
            values.repair_non_finite();
            assert!(values.repaired, "{bad}");
            assert_eq!(values.non_specular.normal, Vec3::ZERO);
            assert_eq!((values.color, values.depth), (v(1.0), 3.0), "finite values kept");

            let mut values = SampleValues { depth: bad, ..SampleValues::default() };
            values.repair_non_finite();
            assert!(values.repaired && values.depth == 0.0, "depth {bad}");
        }
    }
}
