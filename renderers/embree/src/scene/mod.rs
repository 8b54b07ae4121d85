//! A loaded scene: camera, shapes, materials, lights and the Embree BVH,
//! with ray queries that return shading-ready surface points.

pub mod camera;
pub mod environment;
pub mod light;
pub mod material;
pub mod shape;
pub mod texture;

use crate::embree::{Bvh, EmbreeError, Query};
use crate::integrator::Segment;
use crate::math::Vec3;
use camera::{Camera, Ray};
use fbksd_core::SceneInfo;
use light::Light;
use material::Material;
use shape::{Shape, SurfaceHit};

/// Embree's query records for [`Scene::intersect_all`] and
/// [`Scene::occluded_all`], kept between batches.
#[derive(Debug, Default)]
pub struct QueryBuffers {
    queries: Vec<Query>,
    hits: Vec<Option<crate::embree::RayHit>>,
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
    bvh: Bvh,
}

impl Scene {
    /// A scene of these parts (see the fields), with its BVH and light distribution built.
    pub fn build(
        name: String,
        camera: Camera,
        max_depth: u32,
        shapes: Vec<Shape>,
        materials: Vec<Material>,
        lights: Vec<Light>,
        transform_times: [f32; 2],
    ) -> Result<Scene, EmbreeError> {
        let primitives: Vec<_> = shapes.iter().map(|s| s.geometry.primitives()).collect();
        let bvh = Bvh::build(&primitives)?;
        drop(primitives);
        let mut extent = 0f32;
        for s in &shapes {
            let mut grow = |p: [f32; 3], r: f32| extent = extent.max(p[0].abs().max(p[1].abs()).max(p[2].abs()) + r);
            match &s.geometry {
                shape::Geometry::Mesh { positions, .. } => positions.iter().flatten().for_each(|p| grow(*p, 0.0)),
                shape::Geometry::Sphere { steps, .. } => steps.iter().for_each(|s| grow([s[0], s[1], s[2]], s[3])),
                shape::Geometry::Curves { points, .. } => {
                    points.iter().flatten().for_each(|p| grow([p[0], p[1], p[2]], p[3]))
                }
            }
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
        let light_cdf = light_pmf
            .iter()
            .map(|p| {
                acc += p;
                acc
            })
            .collect();
        Ok(Scene {
            name,
            camera,
            max_depth,
            shapes,
            materials,
            lights,
            environment,
            light_pmf,
            light_cdf,
            transform_times,
            has_motion,
            extent,
            bvh,
        })
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

    /// The closest surface along each ray (unbounded), in one batch to Embree.
    pub fn intersect_all(&self, rays: &[Ray], buffers: &mut QueryBuffers, hits: &mut Vec<Option<SurfaceHit>>) {
        let queries = &mut buffers.queries;
        queries.clear();
        queries.extend(rays.iter().map(|ray| Query {
            org: ray.origin.to_array(),
            dir: ray.dir.to_array(),
            tnear: 0.0,
            tfar: f32::INFINITY,
            time: self.embree_time(ray.time),
        }));
        self.bvh.intersect_batch(queries, &mut buffers.hits);
        hits.clear();
        hits.extend(rays.iter().zip(queries.iter()).zip(&buffers.hits).map(|((ray, query), hit)| {
            let hit = hit.as_ref()?;
            Some(self.shapes[hit.geometry as usize].geometry.surface(
                hit,
                ray.origin,
                ray.dir,
                query.time,
                hit.geometry,
            ))
        }));
    }

    /// Whether anything blocks each segment, in one batch to Embree.
    pub fn occluded_all(&self, segments: &[Segment], buffers: &mut QueryBuffers, occluded: &mut Vec<bool>) {
        let queries = &mut buffers.queries;
        queries.clear();
        queries.extend(segments.iter().map(|s| Query {
            org: s.ray.origin.to_array(),
            dir: s.ray.dir.to_array(),
            tnear: 0.0,
            tfar: s.t_max,
            time: self.embree_time(s.ray.time),
        }));
        self.bvh.occluded_batch(queries, occluded);
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
