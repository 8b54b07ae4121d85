//! A loaded scene: camera, shapes, materials, lights and the Embree BVH,
//! with ray queries that return shading-ready surface points.

pub mod camera;
pub mod environment;
pub mod flat;
pub mod light;
pub mod material;
pub mod shape;
pub mod texture;

use crate::embree::{Bvh, EmbreeError, HitPacket, Placement, RayHit, RayPacket, Valid};
use crate::lanes::{F32s, Vec3s};
use crate::math::Vec3;
use crate::math::{Affine, Transform};
use camera::{Camera, Ray};
use fbksd_core::SceneInfo;
use light::Light;
use material::{Bump, Material};
use shape::{Shape, SurfaceHit};

/// A bound on |p| over `shapes`' points (radii included).
fn bound(shapes: &[Shape]) -> f32 {
    let mut extent = 0f32;
    for s in shapes {
        let mut grow = |p: [f32; 3], r: f32| extent = extent.max(p[0].abs().max(p[1].abs()).max(p[2].abs()) + r);
        match &s.geometry {
            shape::Geometry::Mesh { positions, .. } => positions.iter().flatten().for_each(|p| grow(*p, 0.0)),
            shape::Geometry::Sphere { steps, .. } => steps.iter().for_each(|s| grow([s[0], s[1], s[2]], s[3])),
            shape::Geometry::Curves { points, .. } => {
                points.iter().flatten().for_each(|p| grow([p[0], p[1], p[2]], p[3]))
            }
        }
    }
    extent
}

/// Everything the integrator needs.
pub struct Scene {
    /// A name for messages (the file stem).
    pub name: String,
    /// The camera (and image size).
    pub camera: Camera,
    /// Longest path, in bounces (pbrt's `maxdepth`).
    pub max_depth: u32,
    /// Shapes; shape `i` is Embree geometry `i`.
    pub shapes: Vec<Shape>,
    /// Materials.
    pub materials: Vec<Material>,
    /// Each material's bump or normal map.
    pub bumps: Vec<Option<Bump>>,
    /// Lights.
    pub lights: Vec<Light>,
    /// The environment light, if any (index into `lights`).
    pub environment: Option<u32>,
    /// Light selection probabilities, and their cumulative sums.
    light_pmf: Vec<f32>,
    light_cdf: Vec<f32>,
    /// Scene times of the two motion steps (pbrt's `TransformTimes`).
    pub transform_times: [f32; 2],
    /// Whether anything moves during the shutter.
    pub has_motion: bool,
    /// A bound on |p| over the scene, for ray offsets.
    pub extent: f32,
    /// Placed copies of objects (pbrt's `ObjectInstance`).
    instances: Vec<Instance>,
    /// Each object's shapes, a range of `shapes` after the top-level ones.
    objects: Vec<std::ops::Range<u32>>,
    /// The common cases as flat tables, for the integrator's lanes.
    pub flat: flat::Flat,
    bvh: Bvh,
}

/// What a scene is built from (see [`Scene`]'s fields).
pub struct Parts {
    /// A name for messages.
    pub name: String,
    /// The camera.
    pub camera: Camera,
    /// Longest path, in bounces.
    pub max_depth: u32,
    /// Top-level shapes, then the objects' shapes (see [`Instancing`]).
    pub shapes: Vec<Shape>,
    /// Materials.
    pub materials: Vec<Material>,
    /// Each material's bump or normal map.
    pub bumps: Vec<Option<Bump>>,
    /// Lights.
    pub lights: Vec<Light>,
    /// Scene times of the two motion steps.
    pub transform_times: [f32; 2],
    /// Objects and their placements.
    pub instancing: Instancing,
}

/// Objects and their placements (pbrt's `ObjectBegin` and `ObjectInstance`).
#[derive(Debug, Default)]
pub struct Instancing {
    /// Each object's shapes: a range of the scene's shapes, all after the
    /// top-level shapes (which Embree sees directly).
    pub objects: Vec<std::ops::Range<u32>>,
    /// (object, object to world) per instance.
    pub placements: Vec<(u32, Transform)>,
}

/// One placed object: its transforms, as the hit point needs them.
#[derive(Debug, Clone)]
struct Instance {
    object: u32,
    to_world: Affine,
    to_object: Affine,
}

impl Instance {
    /// A normal from object to world space (by the inverse transpose).
    fn normal(&self, n: Vec3) -> Vec3 {
        let m = &self.to_object.rows;
        Vec3 {
            x: m[0][0] * n.x + m[1][0] * n.y + m[2][0] * n.z,
            y: m[0][1] * n.x + m[1][1] * n.y + m[2][1] * n.z,
            z: m[0][2] * n.x + m[1][2] * n.y + m[2][2] * n.z,
        }
        .normalize()
    }

    /// A hit found in object space, in world space (the distance is the same).
    fn to_world(&self, mut hit: SurfaceHit) -> SurfaceHit {
        hit.p = self.to_world.point(hit.p);
        hit.ng = self.normal(hit.ng);
        hit.ns = self.normal(hit.ns);
        hit
    }
}

impl Scene {
    /// A scene of these parts, with its BVH and light distribution built.
    pub fn build(parts: Parts) -> Result<Scene, EmbreeError> {
        let Parts { name, camera, max_depth, shapes, materials, bumps, lights, transform_times, instancing } = parts;
        let Instancing { objects, placements } = instancing;
        let top_level = objects.first().map_or(shapes.len(), |r| r.start as usize);
        let primitives: Vec<_> = shapes[..top_level].iter().map(|s| s.geometry.primitives()).collect();
        let prototypes: Vec<Vec<_>> = objects
            .iter()
            .map(|r| shapes[r.start as usize..r.end as usize].iter().map(|s| s.geometry.primitives()).collect())
            .collect();
        let embree_placements: Vec<Placement> = placements
            .iter()
            .map(|(object, t)| Placement { prototype: *object, transform: Affine::new(t).rows })
            .collect();
        let bvh = Bvh::build(&primitives, &prototypes, &embree_placements)?;
        drop((primitives, prototypes));
        // A bound on |p|: the top-level shapes', then each instance's: its
        // object's bound (about the object's origin) moved and stretched into place.
        let mut extent = bound(&shapes[..top_level]);
        let instances: Vec<Instance> = placements
            .iter()
            .map(|(object, t)| Instance {
                object: *object,
                to_world: Affine::new(t),
                to_object: Affine::new(&t.inverse()),
            })
            .collect();
        let object_bounds: Vec<f32> =
            objects.iter().map(|r| bound(&shapes[r.start as usize..r.end as usize])).collect();
        for i in &instances {
            let centre = i.to_world.point(Vec3::ZERO);
            let axis = |k: usize| i.to_world.vector(Vec3::from_array(std::array::from_fn(|j| (j == k) as u8 as f32)));
            let stretch = (0..3).map(|k| axis(k).length()).fold(0f32, f32::max);
            let reach = object_bounds[i.object as usize] * 3f32.sqrt() * stretch;
            extent = extent.max(centre.x.abs().max(centre.y.abs()).max(centre.z.abs()) + reach);
        }
        let has_motion = shapes.iter().any(|s| s.geometry.moves()) && camera.shutter[0] != camera.shutter[1];
        let environment = lights.iter().position(Light::is_environment).map(|i| i as u32);
        // Choose lights by power, mixed with a uniform choice so no light is starved.
        let area_of = |i: usize| shapes.iter().find(|s| s.light == Some(i as u32)).map_or(0.0, |s| s.geometry.area());
        let powers: Vec<f32> =
            lights.iter().enumerate().map(|(i, l)| l.power(area_of(i), extent.max(1e-6)).max(0.0)).collect();
        let total: f32 = powers.iter().sum();
        let n = lights.len() as f32;
        let light_pmf: Vec<f32> = powers
            .iter()
            .map(|p| if total > 0.0 && total.is_finite() { 0.9 * p / total + 0.1 / n } else { 1.0 / n })
            .collect();
        let mut acc = 0.0;
        let light_cdf: Vec<f32> = light_pmf
            .iter()
            .map(|p| {
                acc += p;
                acc
            })
            .collect();
        let flat = flat::Flat::new(&shapes, top_level, &materials, &bumps, &lights, &light_pmf, &light_cdf);
        Ok(Scene {
            name,
            camera,
            max_depth,
            shapes,
            materials,
            bumps,
            lights,
            environment,
            light_pmf,
            light_cdf,
            transform_times,
            has_motion,
            extent,
            instances,
            objects,
            flat,
            bvh,
        })
    }

    /// The scene with every path shaded by the general code rather than in
    /// SIMD lanes (the values are the same; for comparisons).
    pub fn with_general_shading(mut self) -> Scene {
        self.flat = self.flat.without_plain_cases();
        self
    }

    /// Whether the scene places objects by instancing.
    pub fn has_instances(&self) -> bool {
        !self.instances.is_empty()
    }

    /// Image width.
    pub fn width(&self) -> u32 {
        self.camera.width
    }

    /// Image height.
    pub fn height(&self) -> u32 {
        self.camera.height
    }

    /// Embree's time ∈ [0, 1] for scene time `t`.
    #[inline]
    pub fn embree_time(&self, t: f32) -> f32 {
        let [a, b] = self.transform_times;
        if b > a {
            ((t - a) / (b - a)).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// How far to offset a ray leaving `p`: relative to the scene's size,
    /// so very large and very small scenes both avoid self-intersection.
    #[inline]
    pub fn epsilon(&self, p: Vec3) -> f32 {
        let scale = p.x.abs().max(p.y.abs()).max(p.z.abs()).max(self.extent * 1e-3);
        scale * 2e-5 + f32::MIN_POSITIVE
    }

    /// [`Scene::embree_time`] in lanes.
    #[inline(always)]
    pub fn embree_time_lanes(&self, t: F32s) -> F32s {
        let [a, b] = self.transform_times;
        if b > a {
            ((t - F32s::splat(a)) / (b - a)).map(|v| v.clamp(0.0, 1.0))
        } else {
            F32s::splat(0.0)
        }
    }

    /// [`Scene::epsilon`] in lanes.
    #[inline(always)]
    pub fn epsilon_lanes(&self, p: Vec3s) -> F32s {
        let scale = p.x.abs().max(p.y.abs()).max(p.z.abs()).max(F32s::splat(self.extent * 1e-3));
        scale * 2e-5 + F32s::splat(f32::MIN_POSITIVE)
    }

    /// Finds the closest hit of each valid lane of `packet`, `coherent` rays or not (see [`Bvh::intersect`]).
    #[inline]
    pub fn intersect(&self, valid: &Valid, packet: &mut HitPacket, coherent: bool) {
        self.bvh.intersect(valid, packet, coherent);
    }

    /// Tests each valid lane of `packet` for a blocker (see [`Bvh::occluded`]).
    #[inline]
    pub fn occluded(&self, valid: &Valid, packet: &mut RayPacket) {
        self.bvh.occluded(valid, packet);
    }

    /// Lane `k`'s hit in `packet` after [`Scene::intersect`], if any.
    #[inline]
    pub fn hit(&self, packet: &HitPacket, k: usize) -> Option<RayHit> {
        self.bvh.hit(packet, k)
    }

    /// The surface point of Embree's `hit` of `ray`.
    pub fn surface(&self, hit: &RayHit, ray: &Ray) -> SurfaceHit {
        let time = self.embree_time(ray.time);
        match hit.instance {
            None => self.shapes[hit.geometry as usize].geometry.surface(hit, ray.origin, ray.dir, time, hit.geometry),
            Some(k) => {
                // Found in the object's own space: the ray is taken there, the hit brought back.
                let instance = &self.instances[k as usize];
                let shape = self.objects[instance.object as usize].start + hit.geometry;
                let (origin, dir) = (instance.to_object.point(ray.origin), instance.to_object.vector(ray.dir));
                let local = self.shapes[shape as usize].geometry.surface(hit, origin, dir, time, shape);
                SurfaceHit { instance: Some(k), ..instance.to_world(local) }
            }
        }
    }

    /// ∂p/∂u and ∂p/∂v at a hit (see [`shape::Geometry::tangents`]), in world space.
    pub fn tangents(&self, hit: &SurfaceHit, time: f32) -> (Vec3, Vec3) {
        let geometry = &self.shapes[hit.shape as usize].geometry;
        let time = self.embree_time(time);
        match hit.instance {
            None => geometry.tangents(hit.primitive, hit.p, time),
            Some(k) => {
                let instance = &self.instances[k as usize];
                let (dpdu, dpdv) = geometry.tangents(hit.primitive, instance.to_object.point(hit.p), time);
                (instance.to_world.vector(dpdu), instance.to_world.vector(dpdv))
            }
        }
    }

    /// The material at a hit seen from `wo`: `index`, or for a mix the
    /// material it picks there. The pick is a hash of the point and the
    /// direction (as pbrt's), so a sample replays, and is the second
    /// material with probability `amount`.
    pub fn material_at(&self, mut index: u32, hit: &SurfaceHit, wo: Vec3) -> u32 {
        // Named materials are defined before use, so a chain of mixes ends.
        while let Material::Mix { materials, amount } = &self.materials[index as usize] {
            let a = amount.eval_float(hit.uv);
            let bits = [hit.p.x, hit.p.y, hit.p.z, wo.x, wo.y, wo.z]
                .iter()
                .fold(index as u64, |h, v| fbksd_renderer::sampler::mix(h ^ v.to_bits() as u64));
            let u = (bits >> 40) as f32 / (1u64 << 24) as f32;
            index = if a <= 0.0 {
                materials[0]
            } else if a >= 1.0 || u < a {
                materials[1]
            } else {
                materials[0]
            };
        }
        index
    }

    /// Picks a light with `u` ∈ [0, 1): (index, probability).
    #[inline]
    pub fn choose_light(&self, u: f32) -> Option<(u32, f32)> {
        if self.lights.is_empty() {
            return None;
        }
        let i = self.light_cdf.partition_point(|c| *c <= u).min(self.lights.len() - 1);
        Some((i as u32, self.light_pmf[i]))
    }

    /// The probability of choosing light `i`.
    #[inline]
    pub fn light_probability(&self, i: u32) -> f32 {
        self.light_pmf[i as usize]
    }

    /// The random parameters the scene depends on, as a bit mask by
    /// [`fbksd_core::RandomParameter::index`]: the image always, the lens
    /// with depth of field, time with motion, the light pair with lights.
    pub fn used_parameters(&self) -> u8 {
        let mut mask = 0b11;
        if self.camera.has_dof() {
            mask |= 0b1100;
        }
        if self.has_motion {
            mask |= 0b1_0000;
        }
        if !self.lights.is_empty() {
            mask |= 0b110_0000;
        }
        mask
    }

    /// The scene info sent to techniques.
    pub fn info(&self) -> SceneInfo {
        let mut used = vec!["IMAGE_X", "IMAGE_Y"];
        if self.camera.has_dof() {
            used.extend(["LENS_U", "LENS_V"]);
        }
        if self.has_motion {
            used.push("TIME");
        }
        if !self.lights.is_empty() {
            used.extend(["LIGHT_X", "LIGHT_Y"]);
        }
        let mut info = SceneInfo::new();
        info.set("width", self.width())
            .set("height", self.height())
            .set("max_depth", self.max_depth as i64)
            .set("has_dof", self.camera.has_dof())
            .set("has_motion_blur", self.has_motion)
            .set("has_area_lights", self.lights.iter().any(|l| !l.is_environment()))
            .set("has_environment_light", self.environment.is_some())
            .set("shutter_open", self.camera.shutter[0] as f64)
            .set("shutter_close", self.camera.shutter[1] as f64)
            .set("random_parameters", used.join(","))
            .set("renderer", "embree");
        info
    }
}
