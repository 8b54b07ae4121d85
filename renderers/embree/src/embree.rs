//! A small safe layer over Embree 3 (Debian's `libembree-dev`): a device, a
//! scene of triangle meshes, spheres and Bézier curves with optional linear
//! motion (two time steps) and single-level instances of prototype scenes,
//! and intersection and occlusion queries traced in packets of 16 lanes,
//! which the integrator fills straight from its own lanes.
//!
//! Hand-written rather than a binding crate: the renderer uses a dozen
//! entry points, and the crates on the registry target other Embree
//! versions or wrap far more than this needs. The struct layouts below are
//! those of Embree 3.13 with `RTC_MAX_INSTANCE_LEVEL_COUNT` 1 and
//! `RTC_MIN_WIDTH` 0 (checked against the installed `rtcore_config.h` by a
//! test).

use std::ffi::c_void;
use std::ptr::NonNull;

pub use sys::{Hit16 as HitLanes, Ray16 as RayPacket, RayHit16 as HitPacket, INVALID_ID};

mod sys {
    use std::ffi::{c_char, c_int, c_uint, c_void};

    pub type Device = *mut c_void;
    pub type Scene = *mut c_void;
    pub type Geometry = *mut c_void;

    pub const GEOMETRY_TRIANGLE: c_uint = 0;
    pub const GEOMETRY_ROUND_BEZIER_CURVE: c_uint = 24;
    pub const GEOMETRY_FLAT_BEZIER_CURVE: c_uint = 25;
    pub const GEOMETRY_SPHERE_POINT: c_uint = 50;
    pub const GEOMETRY_INSTANCE: c_uint = 121;
    pub const FORMAT_FLOAT3X4_ROW_MAJOR: c_uint = 0x9134;
    pub const BUFFER_INDEX: c_uint = 0;
    pub const BUFFER_VERTEX: c_uint = 1;
    pub const FORMAT_UINT: c_uint = 0x5001;
    pub const FORMAT_UINT3: c_uint = 0x5003;
    pub const FORMAT_FLOAT3: c_uint = 0x9003;
    pub const FORMAT_FLOAT4: c_uint = 0x9004;
    pub const SCENE_FLAG_ROBUST: c_uint = 1 << 2;
    pub const CONTEXT_FLAG_COHERENT: c_uint = 1;
    pub const BUILD_QUALITY_HIGH: c_uint = 2;
    /// The geometry or instance id of no hit.
    pub const INVALID_ID: c_uint = u32::MAX;

    /// Sixteen rays in Embree's layout (`RTCRay16`): lane `k` of each field
    /// is ray `k`'s. `tfar` is −∞ after an occlusion query found a blocker.
    #[allow(missing_docs)]
    #[repr(C, align(64))]
    #[derive(Debug, Clone, Copy, Default)]
    pub struct Ray16 {
        pub org_x: [f32; 16],
        pub org_y: [f32; 16],
        pub org_z: [f32; 16],
        pub tnear: [f32; 16],
        pub dir_x: [f32; 16],
        pub dir_y: [f32; 16],
        pub dir_z: [f32; 16],
        pub time: [f32; 16],
        pub tfar: [f32; 16],
        pub mask: [c_uint; 16],
        pub id: [c_uint; 16],
        pub flags: [c_uint; 16],
    }

    /// What sixteen rays hit, in Embree's layout (`RTCHit16`): `geom_id` is
    /// `INVALID_ID` for a ray that hit nothing.
    #[allow(missing_docs)]
    #[repr(C, align(64))]
    #[derive(Debug, Clone, Copy, Default)]
    pub struct Hit16 {
        pub ng_x: [f32; 16],
        pub ng_y: [f32; 16],
        pub ng_z: [f32; 16],
        pub u: [f32; 16],
        pub v: [f32; 16],
        pub prim_id: [c_uint; 16],
        pub geom_id: [c_uint; 16],
        pub inst_id: [[c_uint; 16]; 1],
    }

    /// Sixteen rays and their hits (`RTCRayHit16`): `tfar` becomes the hit distance.
    #[allow(missing_docs)]
    #[repr(C, align(64))]
    #[derive(Debug, Clone, Copy, Default)]
    pub struct RayHit16 {
        pub ray: Ray16,
        pub hit: Hit16,
    }

    #[repr(C)]
    pub struct IntersectContext {
        pub flags: c_uint,
        pub filter: *const c_void,
        pub inst_id: [c_uint; 1],
    }

    #[link(name = "embree3")]
    extern "C" {
        pub fn rtcNewDevice(config: *const c_char) -> Device;
        pub fn rtcReleaseDevice(device: Device);
        pub fn rtcGetDeviceError(device: Device) -> c_uint;
        pub fn rtcNewScene(device: Device) -> Scene;
        pub fn rtcReleaseScene(scene: Scene);
        pub fn rtcSetSceneFlags(scene: Scene, flags: c_uint);
        pub fn rtcSetSceneBuildQuality(scene: Scene, quality: c_uint);
        pub fn rtcCommitScene(scene: Scene);
        pub fn rtcNewGeometry(device: Device, kind: c_uint) -> Geometry;
        pub fn rtcReleaseGeometry(geometry: Geometry);
        pub fn rtcSetGeometryTimeStepCount(geometry: Geometry, count: c_uint);
        pub fn rtcSetNewGeometryBuffer(
            geometry: Geometry,
            kind: c_uint,
            slot: c_uint,
            format: c_uint,
            stride: usize,
            count: usize,
        ) -> *mut c_void;
        pub fn rtcCommitGeometry(geometry: Geometry);
        pub fn rtcAttachGeometry(scene: Scene, geometry: Geometry) -> c_uint;
        pub fn rtcSetGeometryInstancedScene(geometry: Geometry, scene: Scene);
        pub fn rtcSetGeometryTransform(geometry: Geometry, step: c_uint, format: c_uint, xfm: *const c_void);
        pub fn rtcIntersect16(valid: *const c_int, scene: Scene, context: *mut IntersectContext, rayhit: *mut RayHit16);
        pub fn rtcOccluded16(valid: *const c_int, scene: Scene, context: *mut IntersectContext, ray: *mut Ray16);
    }
}

/// An Embree error, with the call that raised it.
#[derive(Debug, thiserror::Error)]
#[error("Embree error {code} in {call}")]
pub struct EmbreeError {
    code: u32,
    call: &'static str,
}

/// The shape of one geometry's primitives; each holds one slice per time
/// step (two for linear motion).
#[derive(Debug, Clone)]
pub enum Primitives<'a> {
    /// Triangles.
    Triangles {
        /// Vertex positions per time step.
        positions: Vec<&'a [[f32; 3]]>,
        /// Vertex indices.
        indices: &'a [[u32; 3]],
    },
    /// Spheres.
    Spheres {
        /// (centre, radius) per time step.
        spheres: Vec<&'a [[f32; 4]]>,
    },
    /// Cubic Bézier curves.
    Curves {
        /// Control points (x, y, z, radius) per time step.
        points: Vec<&'a [[f32; 4]]>,
        /// The first control point of each segment.
        first_point: &'a [u32],
        /// Tubes; otherwise ribbons facing the ray.
        round: bool,
    },
}

/// A committed scene, ready for rays from many threads.
pub struct Bvh {
    device: NonNull<c_void>,
    scene: NonNull<c_void>,
    /// The scenes that instances place (pbrt's `ObjectBegin` objects).
    prototypes: Vec<NonNull<c_void>>,
    /// Geometries of the top-level scene before the instances.
    geometry_count: u32,
}

/// An instance of a prototype: which, and where (object to world, the
/// rows of a 3 × 4 matrix).
#[derive(Debug, Clone, Copy)]
pub struct Placement {
    /// Index into the prototypes given to [`Bvh::build`].
    pub prototype: u32,
    /// Object to world.
    pub transform: [[f32; 4]; 3],
}

// SAFETY: Embree documents a committed scene as safe to query concurrently,
// and the device as thread-safe.
unsafe impl Send for Bvh {}
unsafe impl Sync for Bvh {}

impl Drop for Bvh {
    fn drop(&mut self) {
        // SAFETY: both handles were created by this struct and are released once.
        unsafe {
            sys::rtcReleaseScene(self.scene.as_ptr());
            for p in &self.prototypes {
                sys::rtcReleaseScene(p.as_ptr());
            }
            sys::rtcReleaseDevice(self.device.as_ptr());
        }
    }
}

/// What a ray hit: distance, geometry, primitive, Embree's (u, v) and the
/// unnormalised geometric normal.
#[derive(Debug, Clone, Copy)]
pub struct RayHit {
    /// Distance along the (unnormalised) direction.
    pub t: f32,
    /// The geometry, in the order given to [`Bvh::build`].
    pub geometry: u32,
    /// The primitive within it.
    pub primitive: u32,
    /// Barycentric (triangles) or curve parameter.
    pub uv: [f32; 2],
    /// Geometric normal, not normalised.
    pub ng: [f32; 3],
    /// The instance hit (an index into the placements given to
    /// [`Bvh::build`]); `geometry` then numbers the prototype's geometries.
    pub instance: Option<u32>,
}

fn check(device: sys::Device, call: &'static str) -> Result<(), EmbreeError> {
    // SAFETY: device is a live device handle.
    let code = unsafe { sys::rtcGetDeviceError(device) };
    if code == 0 {
        Ok(())
    } else {
        Err(EmbreeError { code, call })
    }
}

/// Fills a new Embree buffer from a slice.
///
/// # Safety
/// `geometry` is a live geometry; `T` matches `format` and `stride`.
unsafe fn fill_buffer<T: Copy>(geometry: sys::Geometry, kind: u32, slot: u32, format: u32, data: &[T]) -> *mut c_void {
    // Embree reads 16 bytes past the last vertex; a new buffer is padded for that.
    // SAFETY: per the contract above.
    let ptr = unsafe {
        sys::rtcSetNewGeometryBuffer(geometry, kind, slot, format, std::mem::size_of::<T>(), data.len().max(1))
    };
    if !ptr.is_null() {
        // SAFETY: Embree allocated at least data.len() items of this stride.
        unsafe { std::ptr::copy_nonoverlapping(data.as_ptr(), ptr as *mut T, data.len()) };
    }
    ptr
}

impl Bvh {
    /// Builds a scene of `geometries`; geometry `i` is reported as `i`.
    pub fn build(
        geometries: &[Primitives<'_>],
        prototypes: &[Vec<Primitives<'_>>],
        placements: &[Placement],
    ) -> Result<Bvh, EmbreeError> {
        let robust = std::env::var_os("FBKSD_EMBREE_ROBUST").is_some();
        // Embree's kernels for another instruction set than the CPU's best, when asked (see [`crate::lanes::Isa`]).
        let config = std::ffi::CString::new(
            crate::lanes::Isa::from_env().map_or(String::new(), |isa| format!("isa={}", isa.embree_name())),
        )
        .expect("no NUL in an ISA name");
        // SAFETY: plain constructor calls; every handle is checked and owned below.
        unsafe {
            let device = sys::rtcNewDevice(config.as_ptr());
            let device = NonNull::new(device).ok_or(EmbreeError { code: 1, call: "rtcNewDevice" })?;
            let new_scene = || {
                let scene = NonNull::new(sys::rtcNewScene(device.as_ptr()))
                    .ok_or(EmbreeError { code: 1, call: "rtcNewScene" })?;
                if robust {
                    // Watertight traversal: no ray slips through an edge shared by two triangles.
                    sys::rtcSetSceneFlags(scene.as_ptr(), sys::SCENE_FLAG_ROBUST);
                }
                sys::rtcSetSceneBuildQuality(scene.as_ptr(), sys::BUILD_QUALITY_HIGH);
                Ok::<_, EmbreeError>(scene)
            };
            let scene = new_scene()?;
            let mut bvh = Bvh { device, scene, prototypes: Vec::new(), geometry_count: geometries.len() as u32 };
            for prototype in prototypes {
                let p = new_scene()?;
                bvh.prototypes.push(p);
                for (i, primitives) in prototype.iter().enumerate() {
                    let id = bvh.attach(p, primitives)?;
                    assert_eq!(id as usize, i, "Embree numbers geometries in attachment order");
                }
                sys::rtcCommitScene(p.as_ptr());
                check(device.as_ptr(), "rtcCommitScene")?;
            }
            for (i, primitives) in geometries.iter().enumerate() {
                let id = bvh.attach(scene, primitives)?;
                assert_eq!(id as usize, i, "Embree numbers geometries in attachment order");
            }
            for placement in placements {
                let instance = sys::rtcNewGeometry(device.as_ptr(), sys::GEOMETRY_INSTANCE);
                check(device.as_ptr(), "rtcNewGeometry")?;
                let prototype = bvh.prototypes[placement.prototype as usize];
                sys::rtcSetGeometryInstancedScene(instance, prototype.as_ptr());
                sys::rtcSetGeometryTransform(
                    instance,
                    0,
                    sys::FORMAT_FLOAT3X4_ROW_MAJOR,
                    placement.transform.as_ptr() as *const c_void,
                );
                sys::rtcCommitGeometry(instance);
                sys::rtcAttachGeometry(scene.as_ptr(), instance);
                sys::rtcReleaseGeometry(instance);
                check(device.as_ptr(), "instance")?;
            }
            sys::rtcCommitScene(scene.as_ptr());
            check(device.as_ptr(), "rtcCommitScene")?;
            Ok(bvh)
        }
    }

    fn attach(&self, scene: NonNull<c_void>, primitives: &Primitives<'_>) -> Result<u32, EmbreeError> {
        let device = self.device.as_ptr();
        let (kind, steps) = match primitives {
            Primitives::Triangles { positions, .. } => (sys::GEOMETRY_TRIANGLE, positions.len()),
            Primitives::Spheres { spheres } => (sys::GEOMETRY_SPHERE_POINT, spheres.len()),
            Primitives::Curves { points, round, .. } => {
                (if *round { sys::GEOMETRY_ROUND_BEZIER_CURVE } else { sys::GEOMETRY_FLAT_BEZIER_CURVE }, points.len())
            }
        };
        // SAFETY: the geometry is created here, filled with buffers of the
        // declared formats, committed, attached, then released (the scene
        // keeps its own reference).
        unsafe {
            let geometry = sys::rtcNewGeometry(device, kind);
            check(device, "rtcNewGeometry")?;
            sys::rtcSetGeometryTimeStepCount(geometry, steps as u32);
            match primitives {
                Primitives::Triangles { positions, indices } => {
                    for (slot, p) in positions.iter().enumerate() {
                        fill_buffer(geometry, sys::BUFFER_VERTEX, slot as u32, sys::FORMAT_FLOAT3, pad(p).as_slice());
                    }
                    fill_buffer(geometry, sys::BUFFER_INDEX, 0, sys::FORMAT_UINT3, indices);
                }
                Primitives::Spheres { spheres } => {
                    for (slot, s) in spheres.iter().enumerate() {
                        fill_buffer(geometry, sys::BUFFER_VERTEX, slot as u32, sys::FORMAT_FLOAT4, s);
                    }
                }
                Primitives::Curves { points, first_point, .. } => {
                    for (slot, p) in points.iter().enumerate() {
                        fill_buffer(geometry, sys::BUFFER_VERTEX, slot as u32, sys::FORMAT_FLOAT4, p);
                    }
                    fill_buffer(geometry, sys::BUFFER_INDEX, 0, sys::FORMAT_UINT, first_point);
                }
            }
            check(device, "rtcSetNewGeometryBuffer")?;
            sys::rtcCommitGeometry(geometry);
            let id = sys::rtcAttachGeometry(scene.as_ptr(), geometry);
            sys::rtcReleaseGeometry(geometry);
            check(device, "rtcAttachGeometry")?;
            Ok(id)
        }
    }

    fn context() -> sys::IntersectContext {
        sys::IntersectContext { flags: 0, filter: std::ptr::null(), inst_id: [sys::INVALID_ID] }
    }

    /// Finds the closest hit of each valid lane of `packet` (Embree's
    /// `rtcIntersect16`), even when the rays are incoherent: a packet costs
    /// less per ray than one call each (a third less on the Cornell box,
    /// and shadow rays too). Embree is told when the rays are `coherent`
    /// (camera rays through one pixel: 7 % faster on the Cornell box;
    /// shadow rays are not, even at the first bounce). Read the answers
    /// with [`Bvh::hit`].
    pub fn intersect(&self, valid: &Valid, packet: &mut HitPacket, coherent: bool) {
        packet.ray.clear_masked(valid);
        packet.hit.geom_id = [sys::INVALID_ID; LANES];
        packet.hit.inst_id = [[sys::INVALID_ID; LANES]];
        let mut context = Self::context();
        if coherent {
            context.flags = sys::CONTEXT_FLAG_COHERENT;
        }
        // SAFETY: the scene is committed; the packet and mask have Embree's layout and alignment.
        unsafe { sys::rtcIntersect16(valid.0.as_ptr(), self.scene.as_ptr(), &mut context, packet) };
    }

    /// Tests each valid lane of `packet` for anything between `tnear` and
    /// `tfar` (Embree's `rtcOccluded16`); see [`RayPacket::occluded`].
    pub fn occluded(&self, valid: &Valid, packet: &mut RayPacket) {
        packet.clear_masked(valid);
        let mut context = Self::context();
        // SAFETY: as in intersect.
        unsafe { sys::rtcOccluded16(valid.0.as_ptr(), self.scene.as_ptr(), &mut context, packet) };
    }

    /// Lane `k`'s answer to [`Bvh::intersect`].
    #[inline]
    pub fn hit(&self, packet: &HitPacket, k: usize) -> Option<RayHit> {
        let (ray, hit) = (&packet.ray, &packet.hit);
        let instance = hit.inst_id[0][k];
        (hit.geom_id[k] != sys::INVALID_ID).then(|| RayHit {
            t: ray.tfar[k],
            geometry: hit.geom_id[k],
            primitive: hit.prim_id[k],
            uv: [hit.u[k], hit.v[k]],
            ng: [hit.ng_x[k], hit.ng_y[k], hit.ng_z[k]],
            instance: (instance != sys::INVALID_ID).then(|| instance - self.geometry_count),
        })
    }
}

/// Rays per packet: Embree's widest, which it splits itself on narrower CPUs.
pub const LANES: usize = 16;

/// A packet's lane mask, aligned as Embree requires: −1 traces the lane, 0 leaves it.
#[repr(C, align(64))]
#[derive(Debug, Clone, Copy, Default)]
pub struct Valid(pub [i32; LANES]);

impl RayPacket {
    /// Sets lane `k` to the segment `org + t·dir` for `t` in (`tnear`,
    /// `tfar`) at motion time `time` ∈ [0, 1].
    #[inline(always)]
    pub fn set(&mut self, k: usize, org: [f32; 3], dir: [f32; 3], tnear: f32, tfar: f32, time: f32) {
        [self.org_x[k], self.org_y[k], self.org_z[k]] = org;
        [self.dir_x[k], self.dir_y[k], self.dir_z[k]] = dir;
        self.tnear[k] = tnear;
        self.tfar[k] = tfar;
        self.time[k] = time;
        self.mask[k] = u32::MAX;
        self.flags[k] = 0;
    }

    /// Sets the lanes `valid` masks off to an empty segment: Embree's AVX2
    /// kernels check every lane of a packet for a well-formed ray, and abort
    /// on one masked off that holds a NaN.
    fn clear_masked(&mut self, valid: &Valid) {
        let keep = |v: &mut [f32; LANES]| {
            for (v, valid) in v.iter_mut().zip(valid.0) {
                *v = if valid != 0 { *v } else { 0.0 };
            }
        };
        for field in [
            &mut self.org_x,
            &mut self.org_y,
            &mut self.org_z,
            &mut self.dir_x,
            &mut self.dir_y,
            &mut self.dir_z,
            &mut self.tnear,
            &mut self.tfar,
            &mut self.time,
        ] {
            keep(field);
        }
    }

    /// Whether [`Bvh::occluded`] found lane `k` blocked (Embree sets its `tfar` to −∞).
    #[inline(always)]
    pub fn occluded(&self, k: usize) -> bool {
        self.tfar[k] == f32::NEG_INFINITY
    }
}

/// Triangle vertices padded to 16 bytes' reach: Embree may load a whole
/// SSE vector at the last vertex.
fn pad(p: &[[f32; 3]]) -> Vec<[f32; 3]> {
    let mut v = Vec::with_capacity(p.len() + 1);
    v.extend_from_slice(p);
    v.push([0.0; 3]);
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn struct_layouts_match_embree_3() {
        assert_eq!(std::mem::size_of::<sys::Ray16>(), 12 * 64);
        assert_eq!(std::mem::size_of::<sys::RayHit16>(), 20 * 64);
        let config = std::fs::read_to_string("/usr/include/embree3/rtcore_config.h").unwrap();
        assert!(config.contains("#define RTC_MAX_INSTANCE_LEVEL_COUNT 1"));
        assert!(config.contains("#define EMBREE_MIN_WIDTH 0"));
    }

    /// A segment along +z from `(x, y, 0)`: (x, y, tfar, time).
    type Segment = (f32, f32, f32, f32);

    /// Fills one packet with `segments` (the rest of its lanes masked off).
    fn packet(segments: &[Segment]) -> (Valid, RayPacket) {
        let (mut valid, mut packet) = (Valid([0; LANES]), RayPacket::default());
        for (k, &(x, y, tfar, time)) in segments.iter().enumerate() {
            packet.set(k, [x, y, 0.0], [0.0, 0.0, 1.0], 0.0, tfar, time);
            valid.0[k] = -1;
        }
        (valid, packet)
    }

    fn hits(bvh: &Bvh, segments: &[Segment]) -> Vec<Option<RayHit>> {
        let (valid, ray) = packet(segments);
        let mut packet = HitPacket { ray, hit: HitLanes::default() };
        bvh.intersect(&valid, &mut packet, false);
        (0..segments.len()).map(|k| bvh.hit(&packet, k)).collect()
    }

    fn occluded(bvh: &Bvh, segments: &[Segment]) -> Vec<bool> {
        let (valid, mut packet) = packet(segments);
        bvh.occluded(&valid, &mut packet);
        (0..segments.len()).map(|k| packet.occluded(k)).collect()
    }

    #[test]
    fn a_moving_triangle_is_hit_where_it_is_at_the_ray_time() {
        let at0 = [[0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [0.0, 1.0, 5.0]];
        let at1 = [[10.0, 0.0, 5.0], [11.0, 0.0, 5.0], [10.0, 1.0, 5.0]];
        let indices = [[0u32, 1, 2]];
        let bvh =
            Bvh::build(&[Primitives::Triangles { positions: vec![&at0, &at1], indices: &indices }], &[], &[]).unwrap();
        let found = hits(&bvh, &[(0.2, 0.2, f32::INFINITY, 0.0), (0.2, 0.2, f32::INFINITY, 1.0)]);
        assert!(found[0].is_some_and(|h| (h.t - 5.0).abs() < 1e-5));
        assert!(found[1].is_none());
        assert_eq!(occluded(&bvh, &[(10.2, 0.2, 10.0, 1.0), (10.2, 0.2, 4.0, 1.0)]), [true, false]);
    }

    #[test]
    fn a_packet_answers_each_lane_and_only_its_valid_lanes() {
        // A wall of triangles at z = 5; lanes alternate between hitting it
        // and passing beside it, and the last three are masked off.
        let wall = [[0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [0.0, 1.0, 5.0]];
        let indices = [[0u32, 1, 2]];
        let bvh = Bvh::build(&[Primitives::Triangles { positions: vec![&wall], indices: &indices }], &[], &[]).unwrap();
        let segments: Vec<Segment> =
            (0..13).map(|i| (if i % 3 == 0 { 5.0 } else { 0.1 }, 0.1, f32::INFINITY, 0.0)).collect();
        let (mut valid, ray) = packet(&segments);
        valid.0[13..].fill(0);
        let mut packet = HitPacket { ray, hit: HitLanes::default() };
        // A masked lane's ray would hit the wall: it must not be answered.
        packet.ray.set(14, [0.1, 0.1, 0.0], [0.0, 0.0, 1.0], 0.0, f32::INFINITY, 0.0);
        bvh.intersect(&valid, &mut packet, true);
        for i in 0..LANES {
            match bvh.hit(&packet, i) {
                Some(h) => assert!(i < 13 && i % 3 != 0 && (h.t - 5.0).abs() < 1e-5, "lane {i}: {h:?}"),
                None => assert!(i >= 13 || i % 3 == 0, "lane {i} missed"),
            }
        }
    }
}
