//! Shapes as the renderer keeps them: the data Embree intersects plus what
//! shading needs (normals, texture coordinates, orientation), and the
//! surface point a hit describes.

use crate::embree::{Primitives, RayHit};
use crate::math::{vec3, Vec3};

/// The geometry of one shape; each holds one or two time steps (linear motion).
#[derive(Debug, Clone)]
pub enum Geometry {
    /// A triangle mesh.
    Mesh {
        /// World-space vertex positions, per time step.
        positions: Vec<Vec<[f32; 3]>>,
        /// Vertex indices.
        indices: Vec<[u32; 3]>,
        /// World-space shading normals per time step, if the mesh has them.
        normals: Option<Vec<Vec<Vec3>>>,
        /// Texture coordinates per vertex.
        uvs: Option<Vec<[f32; 2]>>,
        /// pbrt's ReverseOrientation xor a handedness-swapping transform.
        flip: bool,
    },
    /// One sphere: (centre, radius) per time step.
    Sphere {
        /// (x, y, z, r) per time step.
        steps: Vec<[f32; 4]>,
        /// World → object rotation (for texture coordinates).
        to_object: crate::math::Transform,
        /// Normals point inwards.
        flip: bool,
    },
    /// Cubic Bézier curves (hair): control points (x, y, z, radius) per
    /// time step, and each segment's first control point.
    Curves {
        /// Control points per time step.
        points: Vec<Vec<[f32; 4]>>,
        /// First control point of each segment.
        first: Vec<u32>,
        /// Tubes (`cylinder`) rather than ribbons facing the ray (`flat`).
        round: bool,
    },
}

/// A shape: geometry, material, and the area light it carries, if any.
#[derive(Debug, Clone)]
pub struct Shape {
    /// Its geometry.
    pub geometry: Geometry,
    /// Index into the scene's materials.
    pub material: u32,
    /// Index into the scene's lights, when the shape emits.
    pub light: Option<u32>,
}

/// A point on a surface, in world space.
#[derive(Debug, Clone, Copy)]
pub struct SurfaceHit {
    /// Position.
    pub p: Vec3,
    /// Unit geometric normal, oriented as the shape says (outward unless flipped).
    pub ng: Vec3,
    /// Unit shading normal, on the same side as `ng`.
    pub ns: Vec3,
    /// Texture coordinates.
    pub uv: [f32; 2],
    /// Distance from the ray origin.
    pub t: f32,
    /// The instance it was found in (an index of the scene's instances), if any.
    pub instance: Option<u32>,
    /// Which shape.
    pub shape: u32,
    /// Which primitive of it.
    pub primitive: u32,
}

impl Geometry {
    /// The primitives handed to Embree.
    pub fn primitives(&self) -> Primitives<'_> {
        match self {
            Geometry::Mesh { positions, indices, .. } => {
                Primitives::Triangles { positions: positions.iter().map(|p| p.as_slice()).collect(), indices }
            }
            Geometry::Sphere { steps, .. } => {
                Primitives::Spheres { spheres: steps.iter().map(std::slice::from_ref).collect() }
            }
            Geometry::Curves { points, first, round } => Primitives::Curves {
                points: points.iter().map(|p| p.as_slice()).collect(),
                first_point: first,
                round: *round,
            },
        }
    }

    /// Whether the shape moves during the shutter.
    pub fn moves(&self) -> bool {
        match self {
            Geometry::Mesh { positions, .. } => positions.len() > 1 && positions[0] != positions[1],
            Geometry::Sphere { steps, .. } => steps.len() > 1 && steps[0] != steps[1],
            Geometry::Curves { points, .. } => points.len() > 1 && points[0] != points[1],
        }
    }

    /// Surface area (at the first time step; lights do not move).
    pub fn area(&self) -> f32 {
        match self {
            Geometry::Mesh { positions, indices, .. } => indices.iter().map(|i| triangle_area(&positions[0], i)).sum(),
            Geometry::Sphere { steps, .. } => 4.0 * std::f32::consts::PI * steps[0][3] * steps[0][3],
            Geometry::Curves { .. } => 0.0,
        }
    }

    /// ∂p/∂u and ∂p/∂v of the texture parameterisation at point `p` of
    /// primitive `primitive` (for bump and normal maps; computed only for
    /// the materials that have them).
    pub fn tangents(&self, primitive: u32, p: Vec3, time: f32) -> (Vec3, Vec3) {
        match self {
            Geometry::Mesh { positions, indices, uvs, .. } => {
                let idx = indices[primitive as usize];
                let vertex = |k: usize| {
                    let i = idx[k] as usize;
                    match positions.len() {
                        1 => Vec3::from_array(positions[0][i]),
                        _ => Vec3::from_array(positions[0][i]).lerp(Vec3::from_array(positions[1][i]), time),
                    }
                };
                let (p0, p1, p2) = (vertex(0), vertex(1), vertex(2));
                let Some(uv) = uvs else {
                    // pbrt's default parameterisation: p = p0 + u(p1 − p0) + v(p2 − p1).
                    return (p1 - p0, p2 - p1);
                };
                let [a, b, c] = idx.map(|i| uv[i as usize]);
                // Solve for ∂p/∂u, ∂p/∂v from the edges and their uv differences.
                let (duv02, duv12) = ([a[0] - c[0], a[1] - c[1]], [b[0] - c[0], b[1] - c[1]]);
                let (dp02, dp12) = (p0 - p2, p1 - p2);
                let det = duv02[0] * duv12[1] - duv02[1] * duv12[0];
                if det.abs() < 1e-12 {
                    let f = crate::math::Frame::from_normal((p1 - p0).cross(p2 - p0).normalize());
                    return (f.to_world(vec3(1.0, 0.0, 0.0)), f.to_world(vec3(0.0, 1.0, 0.0)));
                }
                let inv = 1.0 / det;
                ((dp02 * duv12[1] - dp12 * duv02[1]) * inv, (dp12 * duv02[0] - dp02 * duv12[0]) * inv)
            }
            Geometry::Sphere { steps, to_object, .. } => {
                let s = match steps.len() {
                    1 => steps[0],
                    _ => std::array::from_fn(|i| steps[0][i] + (steps[1][i] - steps[0][i]) * time),
                };
                let (center, radius) = (vec3(s[0], s[1], s[2]), s[3]);
                let n = (p - center).normalize();
                // Around the sphere's axis (u), and along its meridian towards the +z pole (v).
                let axis = to_object.inverse().vector(vec3(0.0, 0.0, 1.0)).normalize();
                let meridian = (axis - n * n.dot(axis)).normalize();
                (axis.cross(p - center) * (2.0 * std::f32::consts::PI), meridian * (std::f32::consts::PI * radius))
            }
            Geometry::Curves { .. } => (Vec3::ZERO, Vec3::ZERO),
        }
    }

    /// The surface point of an Embree hit of a ray from `origin` along `dir` at Embree time `time`.
    pub fn surface(&self, hit: &RayHit, origin: Vec3, dir: Vec3, time: f32, shape: u32) -> SurfaceHit {
        let lerp = |a: [f32; 3], b: [f32; 3]| Vec3::from_array(a).lerp(Vec3::from_array(b), time);
        let (p, ng, ns, uv) = match self {
            Geometry::Mesh { positions, indices, normals, uvs, flip } => {
                let idx = indices[hit.primitive as usize];
                let vertex = |k: usize| {
                    let i = idx[k] as usize;
                    if positions.len() > 1 {
                        lerp(positions[0][i], positions[1][i])
                    } else {
                        Vec3::from_array(positions[0][i])
                    }
                };
                let (p0, p1, p2) = (vertex(0), vertex(1), vertex(2));
                let [b1, b2] = hit.uv;
                let b0 = 1.0 - b1 - b2;
                let p = p0 * b0 + p1 * b1 + p2 * b2;
                let mut ng = (p1 - p0).cross(p2 - p0).normalize();
                if ng == Vec3::ZERO {
                    // A degenerate triangle: Embree's normal is all there is.
                    ng = Vec3::from_array(hit.ng).normalize();
                }
                let ns = match normals {
                    Some(n) => {
                        let normal = |k: usize| {
                            let i = idx[k] as usize;
                            if n.len() > 1 {
                                n[0][i].lerp(n[1][i], time)
                            } else {
                                n[0][i]
                            }
                        };
                        let ns = (normal(0) * b0 + normal(1) * b1 + normal(2) * b2).normalize();
                        if ns == Vec3::ZERO {
                            ng = if *flip { -ng } else { ng };
                            ng
                        } else {
                            // pbrt: the geometric normal follows the shading normal.
                            ng = ng.face_forward(ns);
                            ns
                        }
                    }
                    None => {
                        if *flip {
                            ng = -ng;
                        }
                        ng
                    }
                };
                let uv = match uvs {
                    Some(uv) => {
                        let t = |k: usize| uv[idx[k] as usize];
                        let (a, b, c) = (t(0), t(1), t(2));
                        [a[0] * b0 + b[0] * b1 + c[0] * b2, a[1] * b0 + b[1] * b1 + c[1] * b2]
                    }
                    // pbrt's default parameterisation (0,0), (1,0), (1,1).
                    None => [b1 + b2, b2],
                };
                (p, ng, ns, uv)
            }
            Geometry::Sphere { steps, to_object, flip } => {
                let s = if steps.len() > 1 {
                    let (a, b) = (steps[0], steps[1]);
                    std::array::from_fn(|i| a[i] + (b[i] - a[i]) * time)
                } else {
                    steps[0]
                };
                let center = vec3(s[0], s[1], s[2]);
                let mut n = (origin + dir * hit.t - center).normalize();
                if n == Vec3::ZERO {
                    n = Vec3::from_array(hit.ng).normalize();
                }
                // Re-project onto the sphere: removes the error of origin + t·dir.
                let p = center + n * s[3];
                let local = to_object.vector(n).normalize();
                let phi = local.y.atan2(local.x);
                let phi = if phi < 0.0 { phi + 2.0 * std::f32::consts::PI } else { phi };
                // pbrt-v4: v runs from the −z pole (0) to the +z pole (1).
                let uv =
                    [phi / (2.0 * std::f32::consts::PI), 1.0 - local.z.clamp(-1.0, 1.0).acos() / std::f32::consts::PI];
                let ng = if *flip { -n } else { n };
                (p, ng, ng, uv)
            }
            Geometry::Curves { .. } => {
                let ng = Vec3::from_array(hit.ng).normalize();
                let ng = if ng == Vec3::ZERO { -dir } else { ng };
                (origin + dir * hit.t, ng, ng, hit.uv)
            }
        };
        SurfaceHit { p, ng, ns, uv, t: hit.t, shape, primitive: hit.primitive, instance: None }
    }
}

/// Area of triangle `i` of a vertex list.
pub fn triangle_area(positions: &[[f32; 3]], i: &[u32; 3]) -> f32 {
    let p = |k: usize| Vec3::from_array(positions[i[k] as usize]);
    0.5 * (p(1) - p(0)).cross(p(2) - p(0)).length()
}
