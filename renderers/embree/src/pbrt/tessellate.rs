//! Shapes that Embree has no primitive for, as triangle meshes in object
//! space: pbrt's `disk` and `cylinder` (finely tessellated, with the exact
//! normals at the vertices), `bilinearmesh` (planar patches exactly, others
//! on a grid) and `loopsubdiv` (Loop's subdivision surface, "Smooth
//! Subdivision Surfaces Based on Triangles", 1987, taken to its limit
//! positions).

use crate::math::{vec3, Vec3};
use std::collections::HashMap;
use std::f32::consts::PI;

/// A triangle mesh in object space.
#[derive(Debug, Clone, Default)]
pub struct TriMesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Triangles, counter-clockwise about the outward normal.
    pub indices: Vec<[u32; 3]>,
    /// Vertex normals, when the surface is curved.
    pub normals: Option<Vec<Vec3>>,
    /// Texture coordinates, pbrt's parameterisation of the shape.
    pub uvs: Option<Vec<[f32; 2]>>,
}

/// Segments of a full circle: the area of the polygon is within 1e-4 of the circle's.
const SEGMENTS: usize = 512;

fn segments(phi_max: f32) -> usize {
    ((SEGMENTS as f32 * phi_max / (2.0 * PI)).ceil() as usize).max(4)
}

/// pbrt's disk: radius `radius` (a hole of `inner`) at z = `height`, facing +z, up to `phi_max` radians.
pub fn disk(height: f32, radius: f32, inner: f32, phi_max: f32) -> TriMesh {
    let n = segments(phi_max);
    let mut m = TriMesh { uvs: Some(Vec::new()), ..TriMesh::default() };
    let uvs = m.uvs.as_mut().expect("set above");
    for i in 0..=n {
        let phi = phi_max * i as f32 / n as f32;
        let (s, c) = phi.sin_cos();
        for (r, v) in [(radius, 0.0), (inner, 1.0)] {
            m.positions.push(vec3(r * c, r * s, height));
            uvs.push([i as f32 / n as f32, v]);
        }
    }
    for i in 0..n as u32 {
        let (outer0, inner0, outer1, inner1) = (2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3);
        m.indices.push([outer0, outer1, inner1]);
        if inner > 0.0 {
            m.indices.push([outer0, inner1, inner0]);
        }
    }
    m
}

/// pbrt's cylinder: radius `radius` about the z axis from `z0` to `z1`, facing outwards, up to `phi_max`.
pub fn cylinder(radius: f32, z0: f32, z1: f32, phi_max: f32) -> TriMesh {
    let n = segments(phi_max);
    let mut m = TriMesh { normals: Some(Vec::new()), uvs: Some(Vec::new()), ..TriMesh::default() };
    let (normals, uvs) = (m.normals.as_mut().expect("set above"), m.uvs.as_mut().expect("set above"));
    for i in 0..=n {
        let phi = phi_max * i as f32 / n as f32;
        let (s, c) = phi.sin_cos();
        for (z, v) in [(z0, 0.0), (z1, 1.0)] {
            m.positions.push(vec3(radius * c, radius * s, z));
            normals.push(vec3(c, s, 0.0));
            uvs.push([i as f32 / n as f32, v]);
        }
    }
    for i in 0..n as u32 {
        let (a, d, b, c) = (2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3);
        m.indices.push([a, b, c]);
        m.indices.push([a, c, d]);
    }
    m
}

/// pbrt's bilinear patches: corners (p00, p10, p01, p11) per patch, with
/// optional per-vertex normals and uvs. A planar patch is two triangles
/// (exactly its surface); a curved one, a grid of `grid × grid` cells.
pub fn bilinear(
    p: &[Vec3],
    patches: &[[u32; 4]],
    normals: Option<&[Vec3]>,
    uvs: Option<&[[f32; 2]]>,
    grid: usize,
) -> TriMesh {
    let mut m = TriMesh {
        positions: p.to_vec(),
        normals: normals.map(<[Vec3]>::to_vec),
        // pbrt's default parameterisation: (u, v) of the patch at each corner.
        uvs: Some(uvs.map_or_else(|| vec![[0.0; 2]; p.len()], <[[f32; 2]]>::to_vec)),
        ..TriMesh::default()
    };
    let default_uv = uvs.is_none();
    for patch in patches {
        let [a, b, c, d] = *patch;
        let [p00, p10, p01, p11] = patch.map(|i| p[i as usize]);
        let n = (p10 - p00).cross(p01 - p00);
        let size = (p10 - p00).length().max((p01 - p00).length()).max(f32::MIN_POSITIVE);
        let planar = n.length() > 0.0 && (n.normalize().dot(p11 - p00)).abs() <= 1e-5 * size;
        if planar && !default_uv {
            m.indices.push([a, b, d]);
            m.indices.push([a, d, c]);
            continue;
        }
        // A grid of new vertices, evaluated on the patch.
        let k = if planar { 1 } else { grid };
        let first = m.positions.len() as u32;
        let lerp4 = |q: [Vec3; 4], u: f32, v: f32| {
            (q[0] * (1.0 - u) + q[1] * u) * (1.0 - v) + (q[2] * (1.0 - u) + q[3] * u) * v
        };
        for j in 0..=k {
            for i in 0..=k {
                let (u, v) = (i as f32 / k as f32, j as f32 / k as f32);
                m.positions.push(lerp4([p00, p10, p01, p11], u, v));
                if let (Some(out), Some(ns)) = (m.normals.as_mut(), normals) {
                    out.push(lerp4(patch.map(|i| ns[i as usize]), u, v).normalize());
                }
                let uv = match uvs {
                    Some(t) => {
                        let q = patch.map(|i| t[i as usize]);
                        let at = |c: usize| {
                            (q[0][c] * (1.0 - u) + q[1][c] * u) * (1.0 - v) + (q[2][c] * (1.0 - u) + q[3][c] * u) * v
                        };
                        [at(0), at(1)]
                    }
                    None => [u, v],
                };
                m.uvs.as_mut().expect("set above").push(uv);
            }
        }
        let at = |i: usize, j: usize| first + (j * (k + 1) + i) as u32;
        for j in 0..k {
            for i in 0..k {
                m.indices.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                m.indices.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
    }
    m
}

/// The edges of a triangle mesh: for each (low, high) vertex pair, the
/// vertices opposite it in the triangles that share it.
fn edges(tris: &[[u32; 3]]) -> HashMap<(u32, u32), Vec<u32>> {
    let mut edges: HashMap<(u32, u32), Vec<u32>> = HashMap::with_capacity(tris.len() * 3 / 2);
    for t in tris {
        for k in 0..3 {
            let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            edges.entry((a.min(b), a.max(b))).or_default().push(c);
        }
    }
    edges
}

/// Each vertex's neighbours, and its neighbours along boundary edges
/// (edges with one triangle, or more than two).
fn rings(n: usize, edges: &HashMap<(u32, u32), Vec<u32>>) -> (Vec<Vec<u32>>, Vec<Vec<u32>>) {
    let (mut all, mut boundary) = (vec![Vec::new(); n], vec![Vec::new(); n]);
    for (&(a, b), opposite) in edges {
        all[a as usize].push(b);
        all[b as usize].push(a);
        if opposite.len() != 2 {
            boundary[a as usize].push(b);
            boundary[b as usize].push(a);
        }
    }
    (all, boundary)
}

/// Loop's weight for a vertex of valence `n`.
fn beta(n: usize) -> f32 {
    if n == 3 {
        3.0 / 16.0
    } else {
        3.0 / (8.0 * n as f32)
    }
}

/// One step of Loop subdivision: every triangle becomes four.
fn subdivide(p: &[Vec3], tris: &[[u32; 3]]) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let edges = edges(tris);
    let (all, boundary) = rings(p.len(), &edges);
    let sum = |vs: &[u32]| vs.iter().fold(Vec3::ZERO, |s, v| s + p[*v as usize]);
    // The old vertices, moved.
    let mut out: Vec<Vec3> = (0..p.len())
        .map(|v| match boundary[v].as_slice() {
            [] => {
                let n = all[v].len();
                if n == 0 {
                    return p[v];
                }
                let b = beta(n);
                p[v] * (1.0 - n as f32 * b) + sum(&all[v]) * b
            }
            [a, c] => p[v] * 0.75 + (p[*a as usize] + p[*c as usize]) * 0.125,
            // A corner or a non-manifold vertex stays put.
            _ => p[v],
        })
        .collect();
    // A new vertex on each edge.
    let mut midpoint = HashMap::with_capacity(edges.len());
    for (&(a, b), opposite) in &edges {
        let q = match opposite.as_slice() {
            [c, d] => (p[a as usize] + p[b as usize]) * 0.375 + (p[*c as usize] + p[*d as usize]) * 0.125,
            _ => (p[a as usize] + p[b as usize]) * 0.5,
        };
        midpoint.insert((a, b), out.len() as u32);
        out.push(q);
    }
    let mid = |a: u32, b: u32| midpoint[&(a.min(b), a.max(b))];
    let mut new_tris = Vec::with_capacity(tris.len() * 4);
    for &[a, b, c] in tris {
        let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
        new_tris.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
    }
    (out, new_tris)
}

/// pbrt's `loopsubdiv`: `levels` steps of Loop subdivision, then every
/// vertex moved to its limit position; smooth normals from the faces.
pub fn loop_subdivision(p: &[Vec3], tris: &[[u32; 3]], levels: u32) -> TriMesh {
    let (mut positions, mut indices) = (p.to_vec(), tris.to_vec());
    for _ in 0..levels {
        (positions, indices) = subdivide(&positions, &indices);
    }
    let (all, boundary) = rings(positions.len(), &edges(&indices));
    let sum = |vs: &[u32]| vs.iter().fold(Vec3::ZERO, |s, v| s + positions[*v as usize]);
    let limit: Vec<Vec3> = (0..positions.len())
        .map(|v| match boundary[v].as_slice() {
            [] if !all[v].is_empty() => {
                let n = all[v].len() as f32;
                let chi = 1.0 / (3.0 / (8.0 * beta(all[v].len())) + n);
                positions[v] * (1.0 - n * chi) + sum(&all[v]) * chi
            }
            [a, c] => positions[v] * 0.6 + (positions[*a as usize] + positions[*c as usize]) * 0.2,
            _ => positions[v],
        })
        .collect();
    // Area-weighted face normals, summed at the vertices.
    let mut normals = vec![Vec3::ZERO; limit.len()];
    for t in &indices {
        let [a, b, c] = t.map(|i| limit[i as usize]);
        let n = (b - a).cross(c - a);
        for i in t {
            normals[*i as usize] += n;
        }
    }
    let normals = normals.into_iter().map(Vec3::normalize).collect();
    TriMesh { positions: limit, indices, normals: Some(normals), uvs: None }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area(m: &TriMesh) -> f64 {
        m.indices
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| m.positions[i as usize]);
                ((b - a).cross(c - a).length() * 0.5) as f64
            })
            .sum()
    }

    #[test]
    fn a_disk_and_a_cylinder_have_their_area_and_face_outwards() {
        let d = disk(0.5, 2.0, 0.0, 2.0 * PI);
        assert!((area(&d) / (PI as f64 * 4.0) - 1.0).abs() < 1e-4, "{}", area(&d));
        let [a, b, c] = d.indices[7].map(|i| d.positions[i as usize]);
        assert!((b - a).cross(c - a).z > 0.0, "a disk faces +z");
        let ring = disk(0.0, 2.0, 1.0, PI);
        assert!((area(&ring) / (PI as f64 * 3.0 / 2.0) - 1.0).abs() < 1e-4, "{}", area(&ring));
        let cyl = cylinder(1.5, -1.0, 2.0, 2.0 * PI);
        assert!((area(&cyl) / (2.0 * PI as f64 * 1.5 * 3.0) - 1.0).abs() < 1e-4, "{}", area(&cyl));
        let [a, b, c] = cyl.indices[0].map(|i| cyl.positions[i as usize]);
        let outward = (a + b + c) * (1.0 / 3.0);
        assert!((b - a).cross(c - a).dot(vec3(outward.x, outward.y, 0.0)) > 0.0, "a cylinder faces outwards");
    }

    #[test]
    fn bilinear_patches_planar_as_two_triangles_curved_on_a_grid() {
        let p = [vec3(0.0, 0.0, 0.0), vec3(2.0, 0.0, 0.0), vec3(0.0, 1.0, 0.0), vec3(2.0, 1.0, 0.0)];
        let uv = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]];
        let flat = bilinear(&p, &[[0, 1, 2, 3]], None, Some(&uv), 8);
        assert_eq!(flat.indices.len(), 2);
        assert!((area(&flat) - 2.0).abs() < 1e-6);
        // A saddle: z = u·v over the unit square; its area is ∫∫ √(1 + u² + v²) ≈ 1.2808.
        let saddle = [vec3(0.0, 0.0, 0.0), vec3(1.0, 0.0, 0.0), vec3(0.0, 1.0, 0.0), vec3(1.0, 1.0, 1.0)];
        let curved = bilinear(&saddle, &[[0, 1, 2, 3]], None, None, 32);
        assert_eq!(curved.indices.len(), 2 * 32 * 32);
        assert!((area(&curved) - 1.280_789).abs() < 1e-3, "{}", area(&curved));
        // The grid follows the 4 given vertices; its last vertex is the patch's (1, 1).
        assert_eq!(curved.uvs.as_ref().unwrap()[4 + 32 * 33 + 32], [1.0, 1.0]);
    }

    #[test]
    fn loop_subdivision_converges_to_a_smooth_closed_surface() {
        // An octahedron: its limit surface is a smooth blob inside it, symmetric about the origin.
        let p = [
            vec3(1.0, 0.0, 0.0),
            vec3(-1.0, 0.0, 0.0),
            vec3(0.0, 1.0, 0.0),
            vec3(0.0, -1.0, 0.0),
            vec3(0.0, 0.0, 1.0),
            vec3(0.0, 0.0, -1.0),
        ];
        let t = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
        let m = loop_subdivision(&p, &t, 4);
        assert_eq!(m.indices.len(), 8 * 4usize.pow(4));
        let radii: Vec<f32> = m.positions.iter().map(|q| q.length()).collect();
        let (lo, hi) = radii.iter().fold((f32::MAX, 0f32), |(l, h), r| (l.min(*r), h.max(*r)));
        assert!(lo > 0.4 && hi < 0.75 && hi / lo < 1.35, "a rounded blob: radii {lo}..{hi}");
        // Normals point outwards, nearly along the position.
        let normals = m.normals.as_ref().unwrap();
        assert!(m.positions.iter().zip(normals).all(|(q, n)| n.dot(q.normalize()) > 0.9));
        let flat = loop_subdivision(
            &[vec3(0.0, 0.0, 0.0), vec3(1.0, 0.0, 0.0), vec3(1.0, 1.0, 0.0), vec3(0.0, 1.0, 0.0)],
            &[[0, 1, 2], [0, 2, 3]],
            3,
        );
        // An open flat mesh stays flat and inside its outline (the boundary
        // is smoothed as a B-spline curve, corners included, as in pbrt).
        assert!(flat.positions.iter().all(|q| q.z == 0.0 && (0.0..=1.0).contains(&q.x) && (0.0..=1.0).contains(&q.y)));
    }
}
