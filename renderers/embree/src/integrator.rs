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

/// One camera path in flight. A path stops at each ray it needs traced,
/// so that a batch of paths can hand all their rays to Embree at once
/// (see [`Batch`]); each path is still a pure function of its sample.
#[derive(Debug, Clone)]
struct Path {
    out: SampleValues,
    wanted: Wanted,
    light_u: [f32; 2],
    dims: Dimensions,
    /// The ray to trace next.
    ray: Ray,
    l: Vec3,
    beta: Vec3,
    /// Per-channel share of later contributions that counts as diffuse (set at the first hit).
    diffuse_share: Vec3,
    diffuse: Vec3,
    specular_bounce: bool,
    found_non_specular: bool,
    eta_scale: f32,
    /// Origin of the last bounce and its BSDF pdf.
    prev: Option<(Vec3, f32)>,
    depth: u32,
    /// Whether the path wants its next ray traced.
    alive: bool,
    /// What the pending shadow ray brings if nothing blocks it.
    pending: Unoccluded,
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
pub struct Segment {
    /// The ray.
    pub ray: Ray,
    /// Its length.
    pub t_max: f32,
}

impl Path {
    fn new(scene: &Scene, pos: &Position, dims: Dimensions, wanted: Wanted) -> Path {
        Path {
            out: SampleValues::default(),
            wanted,
            light_u: pos.light,
            dims,
            ray: scene.camera.ray(pos.image_x, pos.image_y, pos.lens, pos.time),
            l: Vec3::ZERO,
            beta: Vec3::ONE,
            diffuse_share: Vec3::ZERO,
            diffuse: Vec3::ZERO,
            specular_bounce: false,
            found_non_specular: false,
            eta_scale: 1.0,
            prev: None,
            depth: 0,
            alive: true,
            pending: Unoccluded::default(),
        }
    }

    /// Takes what the path's ray hit: adds emission and features, samples
    /// a light and the BSDF, and sets the next ray (or ends the path).
    /// Returns the light sample's shadow segment, to be answered by
    /// [`Path::shadow_answered`] before the next ray is traced.
    fn hit_answered(&mut self, scene: &Scene, hit: Option<SurfaceHit>) -> Option<Segment> {
        let wanted = self.wanted;
        let dims = self.dims;
        self.out.rays += 1;
        let ray = self.ray;
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
                let w = match self.prev {
                    Some((p, pdf)) if !self.specular_bounce => {
                        power_heuristic(pdf, scene.light_probability(li) * light.pdf(p, ray.dir, point, n))
                    }
                    _ => 1.0,
                };
                let c = self.beta * le * w;
                self.l += c;
                if self.depth > 0 {
                    self.diffuse += c * self.diffuse_share;
                }
            }
        }
        self.alive = false;
        let mut hit = hit?;
        let wo = -ray.dir;
        let material_index = scene.material_at(scene.shapes[hit.shape as usize].material, &hit, wo);
        let material = &scene.materials[material_index as usize];
        if let Some(bump) = &scene.bumps[material_index as usize] {
            let tangents = scene.tangents(&hit, ray.time);
            bump.apply(&mut hit, tangents);
        }
        let bsdf = material.bsdf(hit.uv);
        let depth = self.depth;
        // Geometry features.
        if wanted.geometry {
            if depth == 0 {
                self.out.depth = hit.t;
            }
            let features =
                || HitFeatures { world: hit.p, normal: hit.ns.face_forward(wo), albedo: material.albedo(hit.uv) };
            if depth < 2 {
                self.out.hits[depth as usize] = features();
            }
            if !self.found_non_specular && !bsdf.is_delta() {
                self.found_non_specular = true;
                self.out.non_specular = features();
            }
        }
        if depth >= scene.max_depth {
            return None;
        }
        let frame = Frame::from_normal(hit.ns);
        let wo_local = frame.to_local(wo);
        let base = depth * DIMS_PER_BOUNCE;
        // Next-event estimation: its shadow ray is answered later; nothing
        // below depends on it.
        let mut shadow = None;
        if !bsdf.is_delta() && (wanted.radiance || (depth == 0 && wanted.direct)) {
            let u_light = if depth == 0 { self.light_u } else { [dims.get(base + 1), dims.get(base + 2)] };
            let want_incident = depth == 0 && wanted.direct;
            if let Some((segment, lc)) =
                sample_light(scene, &hit, &bsdf, &frame, wo_local, dims.get(base), u_light, ray.time, want_incident)
            {
                let contribution = self.beta * lc.reflected;
                let mut pending = Unoccluded { color: contribution, ..Unoccluded::default() };
                if depth == 0 {
                    if wanted.direct {
                        pending.direct = Some(lc.incident);
                    }
                    if wanted.diffuse && !contribution.is_black() {
                        // Split by lobe at the light direction.
                        let part = bsdf.eval_diffuse_part(wo_local, lc.wi_local, wanted.roughness_threshold);
                        pending.diffuse = share(part, bsdf.eval(wo_local, lc.wi_local)) * contribution;
                    }
                } else {
                    pending.diffuse = contribution * self.diffuse_share;
                }
                self.pending = pending;
                shadow = Some(segment);
            }
        } else if depth == 0 && wanted.direct {
            // A specular first hit still receives direct light: measured as a white Lambertian would.
            let lambert = Bsdf::Diffuse(crate::bsdf::diffuse::Diffuse { reflectance: Vec3::ONE });
            let up = Vec3 { x: 0.0, y: 0.0, z: 1.0 };
            let frame = Frame::from_normal(hit.ns.face_forward(wo));
            if let Some((segment, lc)) =
                sample_light(scene, &hit, &lambert, &frame, up, dims.get(base), self.light_u, ray.time, true)
            {
                self.pending = Unoccluded { direct: Some(lc.incident), ..Unoccluded::default() };
                shadow = Some(segment);
            }
        }
        if shadow.is_some() {
            self.out.rays += 1;
        }
        // A segment of no length is blocked by the surface it leaves.
        let shadow = shadow.filter(|s| s.t_max > 0.0);
        // Without radiance, the path is done once the features are.
        if !wanted.radiance && (!wanted.geometry || (depth >= 1 && self.found_non_specular)) {
            return shadow;
        }
        // Continue the path by sampling the BSDF.
        let Some(s) = bsdf.sample(wo_local, dims.get(base + 3), [dims.get(base + 4), dims.get(base + 5)]) else {
            return shadow;
        };
        let wi = frame.to_world(s.wi);
        let weight = s.f * (s.wi.z.abs() / s.pdf);
        if depth == 0 && wanted.diffuse {
            self.diffuse_share = if s.delta {
                Vec3::splat(if s.roughness >= wanted.roughness_threshold { 1.0 } else { 0.0 })
            } else {
                share(bsdf.eval_diffuse_part(wo_local, s.wi, wanted.roughness_threshold), bsdf.eval(wo_local, s.wi))
            };
        }
        self.beta *= weight;
        self.specular_bounce = s.delta;
        // Radiance is scaled by 1/η² on refraction; roulette should not see that.
        self.eta_scale *= s.eta * s.eta;
        self.prev = Some((hit.p, s.pdf));
        self.ray = spawn(scene, &hit, wi, ray.time);
        self.depth += 1;
        // Russian roulette; not while the path still looks for its first
        // non-specular hit, whose features must not be left to chance.
        let rr_beta = self.beta * self.eta_scale;
        let searching = wanted.geometry && !self.found_non_specular;
        if wanted.radiance && !searching && rr_beta.max_component() < 1.0 && self.depth > 1 {
            let q = (1.0 - rr_beta.max_component()).max(0.0);
            if dims.get(base + 6) < q {
                return shadow;
            }
            self.beta = self.beta / (1.0 - q);
        }
        // A black throughput ends the path, unless it still looks for its features.
        self.alive = self.beta.is_finite() && (searching || !self.beta.is_black());
        shadow
    }

    /// Takes the answer to the shadow segment [`Path::hit_answered`] returned.
    fn shadow_answered(&mut self, occluded: bool) {
        let pending = std::mem::take(&mut self.pending);
        if !occluded {
            self.l += pending.color;
            self.diffuse += pending.diffuse;
            if let Some(direct) = pending.direct {
                self.out.direct = direct;
            }
        }
    }

    /// The sample's values, with nothing non-finite left in them.
    fn finish(&self) -> SampleValues {
        let mut out = self.out;
        out.color = self.l;
        out.diffuse = self.diffuse;
        out.repair_non_finite();
        out
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

/// Traces camera paths in batches, wavefront style: every live path's
/// next ray goes to Embree in one stream, then every shadow ray, which
/// costs less per ray than one call each. Holds its buffers between
/// batches; one per thread.
#[derive(Debug, Default)]
pub struct Batch {
    paths: Vec<Path>,
    /// Paths still tracing, by index.
    live: Vec<u32>,
    rays: Vec<Ray>,
    hits: Vec<Option<SurfaceHit>>,
    segments: Vec<Segment>,
    /// The path of each segment.
    owners: Vec<u32>,
    occluded: Vec<bool>,
}

impl Batch {
    /// Traces one path per start; the values come back in the same order.
    pub fn trace(
        &mut self,
        scene: &Scene,
        starts: impl IntoIterator<Item = (Position, Dimensions)>,
        wanted: &Wanted,
    ) -> impl Iterator<Item = SampleValues> + '_ {
        self.paths.clear();
        self.paths.extend(starts.into_iter().map(|(pos, dims)| Path::new(scene, &pos, dims, *wanted)));
        self.live.clear();
        self.live.extend(0..self.paths.len() as u32);
        while !self.live.is_empty() {
            self.rays.clear();
            self.rays.extend(self.live.iter().map(|&i| self.paths[i as usize].ray));
            scene.intersect_all(&self.rays, &mut self.hits);
            self.segments.clear();
            self.owners.clear();
            for (&i, hit) in self.live.iter().zip(self.hits.drain(..)) {
                let path = &mut self.paths[i as usize];
                let segment = path.hit_answered(scene, hit);
                match segment {
                    Some(segment) => {
                        self.segments.push(segment);
                        self.owners.push(i);
                    }
                    // No segment: the light sample, if any, was blocked or
                    // brought nothing.
                    None => path.shadow_answered(true),
                }
            }
            scene.occluded_all(&self.segments, &mut self.occluded);
            for (&i, &occluded) in self.owners.iter().zip(&self.occluded) {
                self.paths[i as usize].shadow_answered(occluded);
            }
            let paths = &self.paths;
            self.live.retain(|&i| paths[i as usize].alive);
        }
        self.paths.iter().map(Path::finish)
    }
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

/// One light sample at `hit`: the shadow segment to `time`'s light and
/// what the sample brings if that segment is clear. None when no shadow
/// ray is worth tracing.
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
) -> Option<(Segment, LightContribution)> {
    let (li, choose_pdf) = scene.choose_light(u_choose)?;
    let light = &scene.lights[li as usize];
    let ls = light.sample(hit.p, u)?;
    if ls.radiance.is_black() || ls.pdf <= 0.0 {
        return None;
    }
    let wi_local = frame.to_local(ls.wi);
    let f = bsdf.eval(wo_local, wi_local);
    let facing = wi_local.z * wo_local.z > 0.0;
    // No shadow ray when neither the colour nor DIRECT_LIGHT can gain from it.
    if f.is_black() && !(want_incident && facing) {
        return None;
    }
    let ray = spawn(scene, hit, ls.wi, time);
    let t_max = if ls.distance.is_finite() { ls.distance * (1.0 - 1e-4) - scene.epsilon(hit.p) } else { f32::INFINITY };
    let cos = wi_local.z.abs();
    let light_pdf = choose_pdf * ls.pdf;
    // A delta light cannot be found by a BSDF sample: its sample takes all the weight.
    let w = if light.is_delta() { 1.0 } else { power_heuristic(light_pdf, bsdf.pdf(wo_local, wi_local)) };
    let contribution = LightContribution {
        reflected: f * cos * ls.radiance * (w / light_pdf),
        // Light from behind the surface as the viewer sees it is not incident on the visible side.
        incident: if facing { ls.radiance * (cos / (light_pdf * std::f32::consts::PI)) } else { Vec3::ZERO },
        wi_local,
    };
    Some((Segment { ray, t_max }, contribution))
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
