//! The batch: camera paths traced together, wavefront style.
//!
//! A batch keeps its paths in chunks of [`W`] lanes ([`Paths`]: one lane
//! array per field), and each bounce is a few passes over the chunks: trace
//! every live path's ray (a chunk is one Embree packet), reconstruct the
//! surfaces hit, add the emission found, pick the materials, take a light
//! sample and prepare its shadow ray, sample the BSDF, trace the shadow
//! rays, then retire the paths that ended (live paths from the back move
//! into their lanes).
//!
//! The common cases ([`crate::scene::flat`]: plain meshes, constant diffuse
//! materials, small mesh lights) are shaded in SIMD lanes by the lane twins
//! of the shading steps; a lane-by-lane patch then shades the other lanes
//! with the steps themselves. Both give the same bits, and so does every
//! instruction set the passes are compiled for ([`Isa`]): the same
//! operations in the same order, and no multiply-add is fused.

use super::diffuse_lanes::{self, dimension, Throughput};
use super::{
    sample_light, scatter, unoccluded, At, HitFeatures, PathState, Position, SampleValues, Segment, Unoccluded, Wanted,
    DIMS_PER_BOUNCE,
};
use crate::bsdf::{diffuse::Diffuse, Bsdf};
use crate::embree::{HitPacket, RayPacket, Valid, INVALID_ID};
use crate::lanes::{each, F32s, Isa, Mask, U32s, Vec3s, W};
use crate::math::{vec3, Frame, Vec3};
use crate::scene::camera::Ray;
use crate::scene::flat::{FlatLights, NONE};
use crate::scene::light::LightSamples;
use crate::scene::shape::SurfaceHit;
use crate::scene::Scene;
use fbksd_renderer::sampler::Dimensions;

/// The states of W paths ([`PathState`]), in lanes.
#[derive(Debug, Clone, Default)]
struct Paths {
    sample: U32s,
    key: [u64; W],
    light_u: [F32s; 2],
    org: Vec3s,
    dir: Vec3s,
    time: F32s,
    l: Vec3s,
    beta: Vec3s,
    diffuse_share: Vec3s,
    diffuse: Vec3s,
    eta_scale: F32s,
    prev_p: Vec3s,
    prev_pdf: F32s,
    has_prev: Mask,
    specular_bounce: Mask,
    found_non_specular: Mask,
    alive: Mask,
    rays: U32s,
}

impl Paths {
    fn get(&self, k: usize) -> PathState {
        PathState {
            sample: self.sample.0[k],
            key: self.key[k],
            light_u: [self.light_u[0].0[k], self.light_u[1].0[k]],
            ray: Ray { origin: self.org.lane(k), dir: self.dir.lane(k), time: self.time.0[k] },
            l: self.l.lane(k),
            beta: self.beta.lane(k),
            diffuse_share: self.diffuse_share.lane(k),
            diffuse: self.diffuse.lane(k),
            eta_scale: self.eta_scale.0[k],
            prev_p: self.prev_p.lane(k),
            prev_pdf: self.prev_pdf.0[k],
            has_prev: self.has_prev.0[k],
            specular_bounce: self.specular_bounce.0[k],
            found_non_specular: self.found_non_specular.0[k],
            alive: self.alive.0[k],
            rays: self.rays.0[k],
        }
    }

    fn put(&mut self, k: usize, s: &PathState) {
        self.sample.0[k] = s.sample;
        self.key[k] = s.key;
        (self.light_u[0].0[k], self.light_u[1].0[k]) = (s.light_u[0], s.light_u[1]);
        self.org.set_lane(k, s.ray.origin);
        self.dir.set_lane(k, s.ray.dir);
        self.time.0[k] = s.ray.time;
        self.l.set_lane(k, s.l);
        self.beta.set_lane(k, s.beta);
        self.diffuse_share.set_lane(k, s.diffuse_share);
        self.diffuse.set_lane(k, s.diffuse);
        self.eta_scale.0[k] = s.eta_scale;
        self.prev_p.set_lane(k, s.prev_p);
        self.prev_pdf.0[k] = s.prev_pdf;
        self.has_prev.0[k] = s.has_prev;
        self.specular_bounce.0[k] = s.specular_bounce;
        self.found_non_specular.0[k] = s.found_non_specular;
        self.alive.0[k] = s.alive;
        self.rays.0[k] = s.rays;
    }

    fn ray(&self, k: usize) -> Ray {
        Ray { origin: self.org.lane(k), dir: self.dir.lane(k), time: self.time.0[k] }
    }
}

/// What one bounce found for W paths, and their shadow rays.
#[derive(Debug, Clone, Default)]
struct Found {
    /// The rays traced and what they hit.
    packet: HitPacket,
    /// Lanes whose path traced a ray this bounce.
    live: Mask,
    /// Lanes whose ray hit a surface.
    hit: Mask,
    /// Lanes whose surface came from the flat tables.
    plain: Mask,
    /// The surface hit (see [`SurfaceHit`]); `instance` is [`NONE`] at the top level.
    p: Vec3s,
    ng: Vec3s,
    ns: Vec3s,
    uv: [F32s; 2],
    shape: U32s,
    instance: U32s,
    /// The light the ray found (the emitter it hit, or the environment), or [`NONE`].
    emitter: U32s,
    /// The material at the hit, and whether it is constant diffuse (`fast`, with its reflectance).
    material: U32s,
    fast: Mask,
    reflectance: Vec3s,
    /// The light samples of the fast lanes, their lights' selection
    /// probabilities, and whether those lights are delta lights.
    light: LightSamples,
    choose_pdf: F32s,
    delta_light: Mask,
    /// The shadow rays, and what each brings if it is clear.
    shadow: RayPacket,
    shadow_valid: Valid,
    pending_color: Vec3s,
    pending_diffuse: Vec3s,
    pending_direct: Vec3s,
    has_direct: Mask,
}

impl Found {
    /// Lane `k`'s path at its hit.
    fn at(&self, k: usize, ray: &Ray) -> At {
        At::new(self.p.lane(k), self.ng.lane(k), self.ns.lane(k), self.packet.ray.tfar[k], ray)
    }

    /// The chunk's paths at their hits, in lanes.
    #[inline(always)]
    fn at_lanes(&self, paths: &Paths) -> diffuse_lanes::At {
        diffuse_lanes::At::new(self.p, self.ng, self.ns, F32s(self.packet.ray.tfar), paths.dir)
    }

    fn surface_hit(&self, k: usize) -> SurfaceHit {
        SurfaceHit {
            p: self.p.lane(k),
            ng: self.ng.lane(k),
            ns: self.ns.lane(k),
            uv: [self.uv[0].0[k], self.uv[1].0[k]],
            t: self.packet.ray.tfar[k],
            instance: (self.instance.0[k] != NONE).then_some(self.instance.0[k]),
            shape: self.shape.0[k],
            primitive: self.packet.hit.prim_id[k],
        }
    }

    /// Sets lane `k`'s shadow ray (traced when its segment has a length) and what it brings.
    fn set_shadow(&mut self, scene: &Scene, k: usize, shadow: Option<(Segment, Unoccluded)>) {
        let (segment, pending) = shadow.unwrap_or((Segment { ray: Ray::default(), t_max: 0.0 }, Unoccluded::default()));
        let ray = &segment.ray;
        self.shadow.set(k, ray.origin.to_array(), ray.dir.to_array(), 0.0, segment.t_max, scene.embree_time(ray.time));
        // A segment of no length is blocked by the surface it leaves.
        self.shadow_valid.0[k] = if segment.t_max > 0.0 { -1 } else { 0 };
        self.pending_color.set_lane(k, pending.color);
        self.pending_diffuse.set_lane(k, pending.diffuse);
        self.pending_direct.set_lane(k, pending.direct.unwrap_or(Vec3::ZERO));
        self.has_direct.0[k] = pending.direct.is_some();
    }
}

/// A packet's lane mask from `m`.
#[inline(always)]
fn valid(m: Mask) -> Valid {
    Valid(each(|k| if m.0[k] { -1 } else { 0 }))
}

/// Runs the batch's bounces compiled for `isa`.
fn run(isa: Isa, batch: &mut Batch, scene: &Scene, wanted: &Wanted) {
    /// [`Batch::bounces`] compiled for `$features`.
    #[cfg(target_arch = "x86_64")]
    macro_rules! compiled_for {
        ($name:ident, $features:literal) => {
            /// # Safety
            /// The CPU must support the features.
            #[target_feature(enable = $features)]
            unsafe fn $name(batch: &mut Batch, scene: &Scene, wanted: &Wanted) {
                batch.bounces(scene, wanted)
            }
        };
    }
    #[cfg(target_arch = "x86_64")]
    {
        compiled_for!(avx512, "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma");
        compiled_for!(avx2, "avx2,fma");
        assert!(isa.supported(), "this CPU lacks {isa:?}");
        match isa {
            // SAFETY: the CPU has the features (checked above).
            Isa::Avx512 => return unsafe { avx512(batch, scene, wanted) },
            // SAFETY: as above.
            Isa::Avx2 => return unsafe { avx2(batch, scene, wanted) },
            Isa::Baseline => {}
        }
    }
    batch.bounces(scene, wanted)
}

/// Traces camera paths in batches (see the module documentation). Holds its
/// buffers between batches; one per thread.
#[derive(Debug)]
pub struct Batch {
    /// Each sample's values.
    out: Vec<SampleValues>,
    /// The paths in flight: lanes 0..`live` (in chunks of W).
    paths: Vec<Paths>,
    live: usize,
    /// What the rays of the chunk being shaded found.
    found: Found,
    /// The BSDF of each of its lanes whose material is not constant diffuse.
    bsdfs: [Bsdf; W],
    /// Each chunk's raster positions, lens positions and shutter times.
    camera: Vec<[F32s; 5]>,
    /// Whether a sample's values may hold something non-finite.
    suspect: bool,
}

impl Default for Batch {
    fn default() -> Batch {
        Batch {
            out: Vec::new(),
            paths: Vec::new(),
            live: 0,
            found: Found::default(),
            bsdfs: [Bsdf::Diffuse(Diffuse { reflectance: Vec3::ZERO }); W],
            camera: Vec::new(),
            suspect: false,
        }
    }
}

impl Batch {
    /// Traces one path per start; the values come back in the same order.
    pub fn trace(
        &mut self,
        scene: &Scene,
        starts: impl IntoIterator<Item = (Position, Dimensions)>,
        wanted: &Wanted,
    ) -> impl Iterator<Item = &SampleValues> + '_ {
        self.trace_with(Isa::best(), scene, starts, wanted)
    }

    /// [`Batch::trace`] with the passes compiled for `isa`, which this CPU
    /// must have ([`Isa::available`]); every instruction set gives the same values.
    pub fn trace_with(
        &mut self,
        isa: Isa,
        scene: &Scene,
        starts: impl IntoIterator<Item = (Position, Dimensions)>,
        wanted: &Wanted,
    ) -> impl Iterator<Item = &SampleValues> + '_ {
        self.start(starts);
        // Features and DIRECT_LIGHT are written as they are found; colours
        // are checked as each path ends.
        self.suspect = wanted.geometry || wanted.direct;
        run(isa, self, scene, wanted);
        if self.suspect {
            self.out.iter_mut().for_each(SampleValues::repair_non_finite);
        }
        self.out.iter()
    }

    /// One path per start: its sample, key and first light sample, and
    /// where its camera ray starts (made in lanes by [`Batch::camera_rays`]).
    fn start(&mut self, starts: impl IntoIterator<Item = (Position, Dimensions)>) {
        self.out.clear();
        self.paths.clear();
        self.camera.clear();
        for (i, (pos, dims)) in starts.into_iter().enumerate() {
            let k = i % W;
            if k == 0 {
                self.paths.push(Paths::default());
                self.camera.push([F32s::default(); 5]);
            }
            let (paths, camera) = (&mut self.paths[i / W], &mut self.camera[i / W]);
            (paths.sample.0[k], paths.key[k]) = (i as u32, dims.key());
            (paths.light_u[0].0[k], paths.light_u[1].0[k]) = (pos.light[0], pos.light[1]);
            paths.alive.0[k] = true;
            for (lane, v) in camera.iter_mut().zip([pos.image_x, pos.image_y, pos.lens[0], pos.lens[1], pos.time]) {
                lane.0[k] = v;
            }
            self.out.push(SampleValues::default());
        }
        self.live = self.out.len();
    }

    /// The paths' camera rays, and their throughputs at the camera.
    #[inline(always)]
    fn camera_rays(&mut self, scene: &Scene) {
        for (paths, [x, y, lens_u, lens_v, time]) in self.paths.iter_mut().zip(&self.camera) {
            (paths.org, paths.dir, paths.time) = scene.camera.rays_lanes(*x, *y, [*lens_u, *lens_v], *time);
            (paths.beta, paths.eta_scale) = (Vec3s::splat(Vec3::ONE), F32s::splat(1.0));
        }
    }

    /// Every bounce of the batch's paths, until none is left: each chunk's
    /// whole bounce at once (its rays, shading, shadow rays and next rays),
    /// so that what its rays found stays in the cache.
    #[inline(always)]
    fn bounces(&mut self, scene: &Scene, wanted: &Wanted) {
        self.camera_rays(scene);
        let mut depth = 0;
        while self.live > 0 {
            let chunks = self.live.div_ceil(W);
            for paths in &mut self.paths[..chunks] {
                let mut chunk = Chunk {
                    scene,
                    wanted,
                    depth,
                    paths,
                    found: &mut self.found,
                    bsdfs: &mut self.bsdfs,
                    out: &mut self.out,
                    suspect: &mut self.suspect,
                };
                chunk.bounce();
            }
            self.retire(chunks);
            depth += 1;
        }
    }
}

/// One chunk of a batch in one bounce: its paths, what their rays found,
/// and the batch's values.
struct Chunk<'a> {
    scene: &'a Scene,
    wanted: &'a Wanted,
    depth: u32,
    paths: &'a mut Paths,
    found: &'a mut Found,
    /// The BSDF of each lane whose material is not constant diffuse.
    bsdfs: &'a mut [Bsdf; W],
    out: &'a mut [SampleValues],
    suspect: &'a mut bool,
}

impl Chunk<'_> {
    /// The chunk's bounce, pass by pass.
    #[inline(always)]
    fn bounce(&mut self) {
        self.trace_rays();
        self.surfaces();
        self.emission();
        self.materials();
        if self.wanted.geometry {
            self.features();
        }
        if self.depth < self.scene.max_depth {
            self.next_events();
            self.scatter();
            self.trace_shadows();
        } else {
            self.paths.alive = Mask::splat(false);
        }
        self.end_paths();
    }

    /// Writes the values of the paths that ended this bounce.
    #[inline(always)]
    fn end_paths(&mut self) {
        let Chunk { paths, found, out, suspect, .. } = self;
        for k in (found.live & !paths.alive).lanes() {
            let out = &mut out[paths.sample.0[k] as usize];
            (out.color, out.diffuse, out.rays) = (paths.l.lane(k), paths.diffuse.lane(k), paths.rays.0[k]);
            **suspect |= !(out.color.is_finite() && out.diffuse.is_finite());
        }
    }

    /// Traces every live path's ray, a packet per chunk (the camera rays
    /// of a chunk are coherent: its paths start in one or two pixels).
    #[inline(always)]
    fn trace_rays(&mut self) {
        let Chunk { scene, depth, paths, found, .. } = self;
        let (scene, depth) = (*scene, *depth);
        let ray = &mut found.packet.ray;
        [ray.org_x, ray.org_y, ray.org_z] = [paths.org.x.0, paths.org.y.0, paths.org.z.0];
        [ray.dir_x, ray.dir_y, ray.dir_z] = [paths.dir.x.0, paths.dir.y.0, paths.dir.z.0];
        (ray.tnear, ray.tfar) = ([0.0; W], [f32::INFINITY; W]);
        ray.time = scene.embree_time_lanes(paths.time).0;
        (ray.mask, ray.flags) = ([u32::MAX; W], [0; W]);
        found.live = paths.alive;
        paths.rays = paths.rays.wrapping_add(paths.alive.count());
        scene.intersect(&valid(paths.alive), &mut found.packet, depth == 0);
    }

    /// The surfaces hit: the plain meshes' in lanes, the others one by one.
    #[inline(always)]
    fn surfaces(&mut self) {
        let Chunk { scene, paths, found, .. } = self;
        let scene = *scene;
        let flat = &scene.flat;
        let environment = U32s::splat(scene.environment.unwrap_or(NONE));
        let hits = &found.packet.hit;
        let geometry = U32s(hits.geom_id);
        found.hit = found.live & !geometry.eq(U32s::splat(INVALID_ID));
        let first = U32s::from_fn(|k| flat.first_triangle.at(geometry.0[k]));
        let top_level = U32s(hits.inst_id[0]).eq(U32s::splat(INVALID_ID));
        found.plain = found.hit & top_level & !first.eq(U32s::splat(NONE));
        found.shape = geometry;
        found.instance = U32s::splat(NONE);
        if found.plain.any() {
            // As Geometry::surface computes it.
            let index = first.wrapping_add(U32s(hits.prim_id));
            let triangle = |k: usize| flat.triangles.at(index.0[k]);
            let (b1, b2) = (F32s(hits.u), F32s(hits.v));
            let b0 = F32s::splat(1.0) - b1 - b2;
            let (p0, p1, p2) = (
                Vec3s::from_fn(|k| triangle(k).p[0]),
                Vec3s::from_fn(|k| triangle(k).p[1]),
                Vec3s::from_fn(|k| triangle(k).p[2]),
            );
            found.p = p0 * b0 + p1 * b1 + p2 * b2;
            found.ng = Vec3s::from_fn(|k| triangle(k).ng);
            found.ns = found.ng;
            found.uv = [b1 + b2, b2];
        }
        let hit_light = U32s::from_fn(|k| flat.shape_light.at(geometry.0[k]));
        found.emitter = U32s::select(found.hit, hit_light, U32s::select(found.live, environment, U32s::splat(NONE)));
        for k in (found.hit & !found.plain).lanes() {
            let hit = scene.hit(&found.packet, k).expect("a lane that hit");
            let s = scene.surface(&hit, &paths.ray(k));
            found.p.set_lane(k, s.p);
            found.ng.set_lane(k, s.ng);
            found.ns.set_lane(k, s.ns);
            (found.uv[0].0[k], found.uv[1].0[k]) = (s.uv[0], s.uv[1]);
            found.shape.0[k] = s.shape;
            found.instance.0[k] = s.instance.unwrap_or(NONE);
            found.emitter.0[k] = flat.shape_light.at(s.shape);
        }
    }

    /// Emission the paths found (an area light hit, or the environment),
    /// weighted against the light sample that could have found it (MIS).
    #[inline(always)]
    fn emission(&mut self) {
        let Chunk { scene, depth, paths, found, .. } = self;
        let (scene, depth) = (*scene, *depth);
        let emitting = !found.emitter.eq(U32s::splat(NONE));
        for k in emitting.lanes() {
            let li = found.emitter.0[k];
            let light = &scene.lights[li as usize];
            let dir = paths.dir.lane(k);
            let (point, n) =
                if found.hit.0[k] { (found.p.lane(k), found.ng.lane(k)) } else { (Vec3::ZERO, Vec3::ZERO) };
            let le = light.emitted(n, -dir);
            if le.is_black() {
                continue;
            }
            let w = if paths.has_prev.0[k] && !paths.specular_bounce.0[k] {
                let light_pdf = light.pdf(paths.prev_p.lane(k), dir, point, n);
                super::power_heuristic(paths.prev_pdf.0[k], scene.light_probability(li) * light_pdf)
            } else {
                1.0
            };
            let c = paths.beta.lane(k) * le * w;
            paths.l.set_lane(k, paths.l.lane(k) + c);
            if depth > 0 {
                paths.diffuse.set_lane(k, paths.diffuse.lane(k) + c * paths.diffuse_share.lane(k));
            }
        }
    }

    /// The material at each hit: constant diffuse ones in lanes; mixes
    /// resolved, bump maps applied and BSDFs made one by one.
    #[inline(always)]
    fn materials(&mut self) {
        let Chunk { scene, paths, found, bsdfs, .. } = self;
        let scene = *scene;
        let flat = &scene.flat;
        // A path that found nothing ends here.
        paths.alive = found.hit;
        found.material = U32s::from_fn(|k| flat.shape_material.at(found.shape.0[k]));
        let material = found.material;
        found.fast = found.hit & Mask::from_fn(|k| flat.diffuse.at(material.0[k]));
        found.reflectance = Vec3s::from_fn(|k| flat.reflectance.at(material.0[k]));
        let general = found.hit & !found.fast;
        for k in general.lanes() {
            let mut hit = found.surface_hit(k);
            let ray = paths.ray(k);
            let material = scene.material_at(found.material.0[k], &hit, -ray.dir);
            if let Some(bump) = &scene.bumps[material as usize] {
                let tangents = scene.tangents(&hit, ray.time);
                bump.apply(&mut hit, tangents);
                found.ns.set_lane(k, hit.ns);
            }
            found.material.0[k] = material;
            if flat.diffuse.at(material) {
                found.fast.0[k] = true;
                found.reflectance.set_lane(k, flat.reflectance.at(material));
            } else {
                bsdfs[k] = scene.materials[material as usize].bsdf(hit.uv);
            }
        }
    }

    /// The geometry features at each hit.
    fn features(&mut self) {
        let Chunk { scene, depth, paths, found, bsdfs, out, .. } = self;
        let (scene, depth) = (*scene, *depth);
        for k in found.hit.lanes() {
            let out = &mut out[paths.sample.0[k] as usize];
            let hit = found.surface_hit(k);
            let wo = -paths.dir.lane(k);
            let material = &scene.materials[found.material.0[k] as usize];
            let is_delta = !found.fast.0[k] && bsdfs[k].is_delta();
            if depth == 0 {
                out.depth = hit.t;
            }
            let features =
                || HitFeatures { world: hit.p, normal: hit.ns.face_forward(wo), albedo: material.albedo(hit.uv) };
            if depth < 2 {
                out.hits[depth as usize] = features();
            }
            if !paths.found_non_specular.0[k] && !is_delta {
                paths.found_non_specular.0[k] = true;
                out.non_specular = features();
            }
        }
    }

    /// Next-event estimation at each hit: a light sample and its shadow ray
    /// (traced later; nothing before then depends on it).
    #[inline(always)]
    fn next_events(&mut self) {
        let Chunk { scene, wanted, depth, paths, found, bsdfs, .. } = self;
        let (scene, wanted, depth) = (*scene, *wanted, *depth);
        let want_nee = wanted.radiance || (depth == 0 && wanted.direct);
        let want_incident = depth == 0 && wanted.direct;
        let base = depth * DIMS_PER_BOUNCE;
        let flat = &scene.flat;
        // The light sample's random numbers.
        let light_u =
            if depth == 0 { paths.light_u } else { [dimension(&paths.key, base + 1), dimension(&paths.key, base + 2)] };
        let u_choose = dimension(&paths.key, base);
        // Constant diffuse hits choose a light, and sample a plain one, in lanes ...
        let fast = found.fast & want_nee;
        let mut sampled = Mask::splat(false);
        found.light.ok = Mask::splat(false);
        if fast.any() && !scene.lights.is_empty() {
            found.delta_light = Mask::splat(false);
            if scene.lights.len() == 1 {
                let light = flat.lights.at(0);
                if light.plain {
                    found.light = light.sample_lanes(&flat.light_triangles, found.p, light_u);
                    found.choose_pdf = F32s::splat(flat.light_pmf.at(0));
                    sampled = found.fast;
                }
            } else if let Some(cdf) = flat.light_cdf {
                let below =
                    cdf.iter().fold(U32s::splat(0), |n, c| n.wrapping_add(F32s::splat(*c).le(u_choose).count()));
                let chosen = below.min(U32s::splat(scene.lights.len() as u32 - 1));
                let lights = FlatLights::gather(&flat.lights, chosen);
                found.light = lights.sample(&flat.light_triangles, found.p, light_u);
                found.choose_pdf = F32s::from_fn(|k| flat.light_pmf.at(chosen.0[k]));
                sampled = found.fast & lights.plain;
            }
        }
        // ... and sample any other light one by one.
        let unsampled = fast & !sampled;
        for k in unsampled.lanes() {
            let chosen = scene.choose_light(u_choose.0[k]).map(|(li, pdf)| (&scene.lights[li as usize], pdf));
            let u = [light_u[0].0[k], light_u[1].0[k]];
            found.light.set_lane(k, chosen.and_then(|(light, _)| light.sample(found.p.lane(k), u)));
            found.choose_pdf.0[k] = chosen.map_or(0.0, |(_, pdf)| pdf);
            found.delta_light.0[k] = chosen.is_some_and(|(light, _)| light.is_delta());
        }
        // Their contributions, in lanes.
        if fast.any() {
            let at = found.at_lanes(paths);
            let (worth, origin, t_max, lc) = diffuse_lanes::light_contribution(
                scene,
                &at,
                found.reflectance,
                found.choose_pdf,
                found.delta_light,
                &found.light,
                want_incident,
            );
            let shadow = worth & fast;
            let (color, diffuse, direct) =
                diffuse_lanes::unoccluded(wanted, depth, &at, found.reflectance, paths.beta, paths.diffuse_share, &lc);
            paths.rays = paths.rays.wrapping_add(shadow.count());
            let ray = &mut found.shadow;
            [ray.org_x, ray.org_y, ray.org_z] = [origin.x.0, origin.y.0, origin.z.0];
            [ray.dir_x, ray.dir_y, ray.dir_z] = [found.light.wi.x.0, found.light.wi.y.0, found.light.wi.z.0];
            (ray.tnear, ray.tfar) = ([0.0; W], t_max.0);
            ray.time = scene.embree_time_lanes(paths.time).0;
            (ray.mask, ray.flags) = ([u32::MAX; W], [0; W]);
            // A segment of no length is blocked by the surface it leaves.
            found.shadow_valid = valid(shadow & t_max.gt(F32s::splat(0.0)));
            found.pending_color = Vec3s::select(shadow, color, Vec3s::ZERO);
            found.pending_diffuse = Vec3s::select(shadow, diffuse, Vec3s::ZERO);
            found.pending_direct = Vec3s::select(shadow, direct, Vec3s::ZERO);
            found.has_direct = shadow & want_incident;
        } else {
            found.shadow_valid = Valid::default();
        }
        // The other hits, one by one.
        let general = found.hit & !found.fast;
        for k in general.lanes() {
            let state = paths.get(k);
            let at = found.at(k, &state.ray);
            let bsdf = &bsdfs[k];
            let u = [light_u[0].0[k], light_u[1].0[k]];
            let shadow = if !bsdf.is_delta() && want_nee {
                sample_light(scene, &at, bsdf, u_choose.0[k], u, want_incident)
                    .map(|(seg, lc)| (seg, unoccluded(wanted, depth, &at, bsdf, &state, &lc)))
            } else if want_incident {
                // A specular first hit still receives direct light: measured as a white Lambertian would.
                let lambert = Bsdf::Diffuse(Diffuse { reflectance: Vec3::ONE });
                let frame = Frame::from_normal(found.ns.lane(k).face_forward(-state.ray.dir));
                let up = At { frame, wo: vec3(0.0, 0.0, 1.0), ..at };
                sample_light(scene, &up, &lambert, u_choose.0[k], u, true)
                    .map(|(seg, lc)| (seg, Unoccluded { direct: Some(lc.incident), ..Unoccluded::default() }))
            } else {
                None
            };
            paths.rays.0[k] += shadow.is_some() as u32;
            found.set_shadow(scene, k, shadow);
        }
    }

    /// Each path's next ray, from its BSDF: constant diffuse ones in lanes, the others one by one.
    #[inline(always)]
    fn scatter(&mut self) {
        let Chunk { scene, wanted, depth, paths, found, bsdfs, .. } = self;
        let (scene, wanted, depth) = (*scene, *wanted, *depth);
        if found.fast.any() {
            let at = found.at_lanes(paths);
            let throughput = Throughput {
                keys: &paths.key,
                beta: paths.beta,
                eta_scale: paths.eta_scale,
                diffuse_share: paths.diffuse_share,
                found_non_specular: paths.found_non_specular,
            };
            let s = diffuse_lanes::scatter(scene, wanted, depth, &at, found.reflectance, &throughput);
            let moved = s.moved & found.fast;
            paths.beta = Vec3s::select(moved, s.beta, paths.beta);
            paths.diffuse_share = Vec3s::select(moved, s.diffuse_share, paths.diffuse_share);
            paths.org = Vec3s::select(moved, s.origin, paths.org);
            paths.dir = Vec3s::select(moved, s.dir, paths.dir);
            paths.prev_p = Vec3s::select(moved, found.p, paths.prev_p);
            paths.prev_pdf = F32s::select(moved, s.pdf, paths.prev_pdf);
            paths.has_prev = paths.has_prev | moved;
            paths.specular_bounce = paths.specular_bounce & !moved;
            // The other lanes' paths end here unless the general code continues them below.
            paths.alive = s.alive & found.fast;
        } else {
            paths.alive = Mask::splat(false);
        }
        let general = found.hit & !found.fast;
        for k in general.lanes() {
            let mut state = paths.get(k);
            let at = found.at(k, &state.ray);
            scatter(scene, wanted, depth, &at, &bsdfs[k], &mut state);
            paths.put(k, &state);
        }
    }

    /// Traces the shadow rays and adds what the clear ones bring.
    #[inline(always)]
    fn trace_shadows(&mut self) {
        let Chunk { scene, wanted, depth, paths, found, out, .. } = self;
        let (scene, wanted, depth) = (*scene, *wanted, *depth);
        if found.shadow_valid.0.iter().all(|v| *v == 0) {
            return;
        }
        scene.occluded(&found.shadow_valid, &mut found.shadow);
        let clear = Mask::from_fn(|k| found.shadow_valid.0[k] != 0 && !found.shadow.occluded(k));
        paths.l = Vec3s::select(clear, paths.l + found.pending_color, paths.l);
        paths.diffuse = Vec3s::select(clear, paths.diffuse + found.pending_diffuse, paths.diffuse);
        if depth == 0 && wanted.direct {
            for k in (clear & found.has_direct).lanes() {
                out[paths.sample.0[k] as usize].direct = found.pending_direct.lane(k);
            }
        }
    }
}

impl Batch {
    /// Once a quarter of the lanes in use hold ended paths, moves live
    /// paths from the back into the ended paths' lanes at the front, so the
    /// live ones fill the first lanes (until then the ended paths' lanes are
    /// masked off). Only the holes are filled: a path's values do not depend
    /// on its lane.
    fn retire(&mut self, chunks: usize) {
        let alive: usize = self.paths[..chunks].iter().map(|p| p.alive.0.iter().filter(|a| **a).count()).sum();
        if alive * 4 > self.live * 3 {
            return;
        }
        let is_alive = |paths: &[Paths], i: usize| paths[i / W].alive.0[i % W];
        let (mut front, mut back) = (0, self.live);
        loop {
            while front < back && is_alive(&self.paths, front) {
                front += 1;
            }
            while back > front && !is_alive(&self.paths, back - 1) {
                back -= 1;
            }
            if front >= back {
                break;
            }
            // `front` ended, `back - 1` is live and past it.
            back -= 1;
            let state = self.paths[back / W].get(back % W);
            self.paths[front / W].put(front % W, &state);
            self.paths[back / W].alive.0[back % W] = false;
            front += 1;
        }
        self.live = front;
    }
}
