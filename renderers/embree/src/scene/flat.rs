//! Flat tables of a scene's common cases, which the wavefront integrator
//! reads lane by lane inside its SIMD loops: the triangles of static,
//! top-level meshes with face normals ([`PlainTriangle`]), constant diffuse
//! materials, and small mesh lights ([`FlatLight`]). A lane whose hit,
//! material or light is not one of these finds it marked so and is shaded
//! by the general code; both give the same values (the same formulas, in
//! the same order).

use crate::lanes::{each, F32s, Mask, U32s, Vec3s};
use crate::math::Vec3;
use crate::scene::light::{
    area_sample, area_sample_lanes, remap, triangle_point, triangle_point_lanes, Light, LightSample, LightSamples,
};
use crate::scene::material::Material;
use crate::scene::shape::{Geometry, Shape};
use crate::scene::texture::Texture;

/// "None" in the tables' index columns.
pub const NONE: u32 = u32::MAX;

/// The most lights, or triangles of one mesh light, chosen among in lanes:
/// a choice is a count of the cumulative sums below the random number, over
/// this many entries.
pub const SMALL: usize = 16;

/// A table that is never empty, so that a lane can read any index (a lane
/// whose value will not be used reads the last entry) without a bounds
/// check, which would keep its loop from being vectorised.
#[derive(Debug, Clone)]
pub struct Table<T>(Vec<T>);

impl<T: Copy> Table<T> {
    fn new(mut items: Vec<T>, filler: T) -> Self {
        if items.is_empty() {
            items.push(filler);
        }
        Table(items)
    }

    /// Entry `i`, or the last entry when `i` is past the end.
    #[inline(always)]
    pub fn at(&self, i: u32) -> T {
        let i = (i as usize).min(self.0.len() - 1);
        // SAFETY: the table is never empty (see `new`), so `i` is in bounds.
        unsafe { *self.0.get_unchecked(i) }
    }
}

/// A triangle of a plain mesh: its vertices and its unit geometric normal,
/// oriented as the shape says (the shading normal is the same).
#[derive(Debug, Clone, Copy, Default)]
pub struct PlainTriangle {
    /// The vertices.
    pub p: [Vec3; 3],
    /// The oriented unit normal.
    pub ng: Vec3,
}

/// A light as lanes sample it: a mesh light of at most [`SMALL`] triangles
/// without vertex normals (`plain`), with its triangles' cumulative areas
/// padded with ∞; any other light is not `plain`.
#[derive(Debug, Clone, Copy)]
pub struct FlatLight {
    /// Whether lanes sample it (the fields below are set only then).
    pub plain: bool,
    /// Its first triangle in [`Flat::light_triangles`].
    pub first: u32,
    /// How many triangles.
    pub count: u32,
    /// Cumulative areas, normalised to end at 1, then ∞.
    pub cdf: [f32; SMALL],
    /// 1 / total area.
    pub inv_area: f32,
    /// Emitted radiance.
    pub radiance: Vec3,
    /// Emits on both sides.
    pub two_sided: bool,
}

impl FlatLight {
    /// [`Light::sample`] of the plain mesh light this is, with the same
    /// values: the triangle is chosen by counting the cumulative areas at
    /// most `u[0]`, which is where a binary search ends, without a loop of
    /// its own.
    #[inline(always)]
    pub fn sample(&self, triangles: &Table<LightTriangle>, p: Vec3, u: [f32; 2]) -> Option<LightSample> {
        let below: u32 = self.cdf.iter().map(|c| (*c <= u[0]) as u32).sum();
        let k = (below.min(self.count.saturating_sub(1)) as usize).min(SMALL - 1);
        let lo = if k == 0 { 0.0 } else { self.cdf[k.saturating_sub(1)] };
        let t = triangles.at(self.first + k as u32);
        let (point, _) = triangle_point(t.p0, t.e1, t.e2, [remap(u[0], lo, self.cdf[k]), u[1]]);
        area_sample(p, point, t.n, self.inv_area, self.radiance, self.two_sided)
    }

    /// [`FlatLight::sample`] in lanes, all of this light: the triangle is
    /// chosen among its own, without gathering.
    #[inline(always)]
    pub fn sample_lanes(&self, triangles: &Table<LightTriangle>, p: Vec3s, u: [F32s; 2]) -> LightSamples {
        let count = (self.count as usize).clamp(1, SMALL);
        let cdf = &self.cdf[..count];
        let below = cdf.iter().fold(U32s::splat(0), |n, c| n.wrapping_add(F32s::splat(*c).le(u[0]).count()));
        let k = below.min(U32s::splat(count as u32 - 1));
        let (mut lo, mut hi) = (F32s::splat(0.0), F32s::splat(0.0));
        let mut t = [Vec3s::ZERO; 4];
        for (j, c) in cdf.iter().enumerate() {
            let this = k.eq(U32s::splat(j as u32));
            lo = F32s::select(this, F32s::splat(if j == 0 { 0.0 } else { cdf[j - 1] }), lo);
            hi = F32s::select(this, F32s::splat(*c), hi);
            let triangle = triangles.at(self.first + j as u32);
            for (corner, v) in t.iter_mut().zip([triangle.p0, triangle.e1, triangle.e2, triangle.n]) {
                *corner = Vec3s::select(this, Vec3s::splat(v), *corner);
            }
        }
        let u0 = F32s::from_fn(|l| remap(u[0].0[l], lo.0[l], hi.0[l]));
        let point = triangle_point_lanes(t[0], t[1], t[2], [u0, u[1]]);
        area_sample_lanes(
            p,
            point,
            t[3],
            F32s::splat(self.inv_area),
            Vec3s::splat(self.radiance),
            Mask::splat(self.two_sided),
        )
    }

    const OTHER: FlatLight = FlatLight {
        plain: false,
        first: 0,
        count: 0,
        cdf: [f32::INFINITY; SMALL],
        inv_area: 0.0,
        radiance: Vec3::ZERO,
        two_sided: false,
    };
}

/// The lights of a chunk's lanes, one [`FlatLight`] per lane.
#[derive(Debug, Clone, Copy)]
pub struct FlatLights {
    /// Lanes whose light is plain.
    pub plain: Mask,
    first: U32s,
    count: U32s,
    cdf: [F32s; SMALL],
    inv_area: F32s,
    radiance: Vec3s,
    two_sided: Mask,
}

impl FlatLights {
    /// `light` in every lane.
    #[inline(always)]
    pub fn splat(light: &FlatLight) -> FlatLights {
        FlatLights {
            plain: Mask::splat(light.plain),
            first: U32s::splat(light.first),
            count: U32s::splat(light.count),
            cdf: each(|j| F32s::splat(light.cdf[j])),
            inv_area: F32s::splat(light.inv_area),
            radiance: Vec3s::splat(light.radiance),
            two_sided: Mask::splat(light.two_sided),
        }
    }

    /// Light `lights[i]` in the lane of each `i`.
    #[inline(always)]
    pub fn gather(lights: &Table<FlatLight>, i: U32s) -> FlatLights {
        let light = |k: usize| lights.at(i.0[k]);
        FlatLights {
            plain: Mask::from_fn(|k| light(k).plain),
            first: U32s::from_fn(|k| light(k).first),
            count: U32s::from_fn(|k| light(k).count),
            cdf: each(|j| F32s::from_fn(|k| light(k).cdf[j])),
            inv_area: F32s::from_fn(|k| light(k).inv_area),
            radiance: Vec3s::from_fn(|k| light(k).radiance),
            two_sided: Mask::from_fn(|k| light(k).two_sided),
        }
    }

    /// [`FlatLight::sample`] in lanes (valid in the `plain` lanes).
    #[inline(always)]
    pub fn sample(&self, triangles: &Table<LightTriangle>, p: Vec3s, u: [F32s; 2]) -> LightSamples {
        let below = self.cdf.iter().fold(U32s::splat(0), |n, c| n.wrapping_add(c.le(u[0]).count()));
        let last = U32s::from_fn(|k| self.count.0[k].saturating_sub(1));
        let k = below.min(last).min(U32s::splat(SMALL as u32 - 1));
        // The cumulative areas before and at the chosen triangle.
        let (mut lo, mut hi) = (F32s::splat(0.0), F32s::splat(0.0));
        for (j, c) in self.cdf.iter().enumerate() {
            lo = F32s::select(k.eq(U32s::splat(j as u32 + 1)), *c, lo);
            hi = F32s::select(k.eq(U32s::splat(j as u32)), *c, hi);
        }
        let u0 = F32s::from_fn(|l| remap(u[0].0[l], lo.0[l], hi.0[l]));
        let index = self.first.wrapping_add(k);
        let corner = |f: fn(&LightTriangle) -> Vec3| Vec3s::from_fn(|l| f(&triangles.at(index.0[l])));
        let point = triangle_point_lanes(corner(|t| t.p0), corner(|t| t.e1), corner(|t| t.e2), [u0, u[1]]);
        area_sample_lanes(p, point, corner(|t| t.n), self.inv_area, self.radiance, self.two_sided)
    }
}

/// A triangle of a plain mesh light: a vertex, two edges, the emitting side's unit normal.
#[derive(Debug, Clone, Copy, Default)]
pub struct LightTriangle {
    /// First vertex.
    pub p0: Vec3,
    /// Second vertex − first.
    pub e1: Vec3,
    /// Third vertex − first.
    pub e2: Vec3,
    /// Unit normal of the emitting side.
    pub n: Vec3,
}

/// The tables (see the module documentation).
#[derive(Debug, Clone)]
pub struct Flat {
    /// Per shape: the index in `triangles` of its first triangle when it is
    /// a plain mesh (top-level, static, without vertex normals or texture
    /// coordinates, no degenerate triangle), else [`NONE`].
    pub first_triangle: Table<u32>,
    /// The plain meshes' triangles.
    pub triangles: Table<PlainTriangle>,
    /// Per shape: its material.
    pub shape_material: Table<u32>,
    /// Per shape: its light, or [`NONE`].
    pub shape_light: Table<u32>,
    /// Per material: whether it is a constant diffuse material without a
    /// bump map, and if so its reflectance (clamped as [`Material::bsdf`]
    /// clamps it).
    pub diffuse: Table<bool>,
    /// See `diffuse`.
    pub reflectance: Table<Vec3>,
    /// The lights' cumulative selection probabilities, padded with ∞, when
    /// there are at most [`SMALL`] lights.
    pub light_cdf: Option<[f32; SMALL]>,
    /// Per light: its selection probability.
    pub light_pmf: Table<f32>,
    /// Per light: how lanes sample it.
    pub lights: Table<FlatLight>,
    /// The plain mesh lights' triangles.
    pub light_triangles: Table<LightTriangle>,
}

impl Flat {
    /// The tables of a scene's parts; `top_level` shapes are those Embree sees directly.
    pub fn new(
        shapes: &[Shape],
        top_level: usize,
        materials: &[Material],
        bumps: &[Option<crate::scene::material::Bump>],
        lights: &[Light],
        light_pmf: &[f32],
        light_cdf: &[f32],
    ) -> Flat {
        let mut triangles = Vec::new();
        let first_triangle = shapes
            .iter()
            .enumerate()
            .map(|(i, shape)| match plain_triangles(&shape.geometry) {
                Some(t) if i < top_level => {
                    let first = triangles.len() as u32;
                    triangles.extend(t);
                    first
                }
                _ => NONE,
            })
            .collect();
        let diffuse: Vec<Option<Vec3>> = materials
            .iter()
            .zip(bumps)
            .map(|(m, bump)| match (m, bump) {
                (Material::Diffuse { reflectance }, None) => match reflectance.as_ref() {
                    Texture::Constant(_) => match m.bsdf([0.0, 0.0]) {
                        crate::bsdf::Bsdf::Diffuse(d) => Some(d.reflectance),
                        _ => None,
                    },
                    _ => None,
                },
                _ => None,
            })
            .collect();
        let mut light_triangles = Vec::new();
        let flat_lights = lights
            .iter()
            .map(|light| match light {
                Light::Mesh { triangles, cdf, area, radiance, two_sided, .. }
                    if triangles.len() <= SMALL && triangles.iter().all(|t| t.vertex_normals.is_none()) =>
                {
                    let first = light_triangles.len() as u32;
                    light_triangles.extend(triangles.iter().map(|t| LightTriangle {
                        p0: t.p0,
                        e1: t.e1,
                        e2: t.e2,
                        n: t.n,
                    }));
                    FlatLight {
                        plain: true,
                        first,
                        count: triangles.len() as u32,
                        cdf: padded(cdf),
                        inv_area: 1.0 / area,
                        radiance: *radiance,
                        two_sided: *two_sided,
                    }
                }
                _ => FlatLight::OTHER,
            })
            .collect();
        Flat {
            first_triangle: Table::new(first_triangle, NONE),
            triangles: Table::new(triangles, PlainTriangle::default()),
            shape_material: Table::new(shapes.iter().map(|s| s.material).collect(), 0),
            shape_light: Table::new(shapes.iter().map(|s| s.light.unwrap_or(NONE)).collect(), NONE),
            reflectance: Table::new(diffuse.iter().map(|d| d.unwrap_or(Vec3::ZERO)).collect(), Vec3::ZERO),
            diffuse: Table::new(diffuse.iter().map(Option::is_some).collect(), false),
            light_cdf: (light_cdf.len() <= SMALL).then(|| padded(light_cdf)),
            light_pmf: Table::new(light_pmf.to_vec(), 0.0),
            lights: Table::new(flat_lights, FlatLight::OTHER),
            light_triangles: Table::new(light_triangles, LightTriangle::default()),
        }
    }
}

impl Flat {
    /// The same tables with nothing plain: every lane is shaded by the general code.
    pub fn without_plain_cases(self) -> Flat {
        Flat {
            first_triangle: Table::new(vec![], NONE),
            diffuse: Table::new(vec![], false),
            lights: Table::new(vec![], FlatLight::OTHER),
            ..self
        }
    }
}

/// At most [`SMALL`] cumulative sums, then ∞.
fn padded(cdf: &[f32]) -> [f32; SMALL] {
    std::array::from_fn(|i| cdf.get(i).copied().unwrap_or(f32::INFINITY))
}

/// A mesh's triangles as [`Geometry::surface`] would see them, when it is
/// plain: one time step, face normals, pbrt's default parameterisation, no
/// degenerate triangle.
fn plain_triangles(geometry: &Geometry) -> Option<Vec<PlainTriangle>> {
    let Geometry::Mesh { positions, indices, normals: None, uvs: None, flip } = geometry else { return None };
    let [positions] = positions.as_slice() else { return None };
    indices
        .iter()
        .map(|idx| {
            let p = idx.map(|i| Vec3::from_array(positions[i as usize]));
            let ng = (p[1] - p[0]).cross(p[2] - p[0]).normalize();
            (ng != Vec3::ZERO).then_some(PlainTriangle { p, ng: if *flip { -ng } else { ng } })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lanes::tests::{same, same3, Values};
    use crate::lanes::W;
    use crate::scene::light::{area_cdf, LightTriangle as MeshTriangle};

    /// A mesh light of `n` triangles of different areas, as the scene has it and as the tables do.
    fn mesh_light(n: u32, two_sided: bool) -> (Light, Flat) {
        let positions: Vec<[f32; 3]> = (0..=n)
            .flat_map(|i| [[i as f32 * 1.5, 2.0, 0.0], [i as f32 * 1.5 + 0.3 * i as f32 + 0.2, 2.5, 1.0]])
            .collect();
        let indices: Vec<[u32; 3]> = (0..n).map(|i| [2 * i, 2 * i + 1, 2 * i + 2]).collect();
        let (cdf, area) = area_cdf(&positions, &indices);
        let triangles = MeshTriangle::of_mesh(&positions, &indices, None, false);
        let light =
            Light::Mesh { shape: 0, triangles, cdf, area, radiance: crate::math::vec3(1.0, 2.0, 3.0), two_sided };
        let flat = Flat::new(&[], 0, &[], &[], std::slice::from_ref(&light), &[1.0], &[1.0]);
        (light, flat)
    }

    #[test]
    fn a_plain_mesh_light_in_lanes_has_the_scalar_bits() {
        let mut values = Values::new(5);
        for (n, two_sided) in [(1, false), (2, true), (5, false), (16, true)] {
            let (light, flat) = mesh_light(n, two_sided);
            let plain = flat.lights.at(0);
            assert!(plain.plain, "{n} triangles");
            for _ in 0..300 {
                let p = values.vectors();
                let u = [values.lanes().map(f32::abs), values.lanes().map(f32::abs)];
                let uniform = plain.sample_lanes(&flat.light_triangles, p, u);
                let gathered = FlatLights::gather(&flat.lights, U32s::splat(0)).sample(&flat.light_triangles, p, u);
                for k in 0..W {
                    let (p, u) = (p.lane(k), [u[0].0[k], u[1].0[k]]);
                    let expected = light.sample(p, u);
                    for (how, got) in [
                        ("one", plain.sample(&flat.light_triangles, p, u)),
                        ("uniform", uniform.lane(k)),
                        ("gathered", gathered.lane(k)),
                    ] {
                        assert_eq!(got.is_some(), expected.is_some(), "{how}, {n} triangles, {p:?} {u:?}");
                        if let (Some(a), Some(b)) = (got, expected) {
                            assert!(
                                same3(a.wi, b.wi)
                                    && same(a.distance, b.distance)
                                    && same3(a.radiance, b.radiance)
                                    && same(a.pdf, b.pdf),
                                "{how}, {n} triangles, {p:?} {u:?}: {a:?} vs {b:?}"
                            );
                        }
                    }
                }
            }
        }
        // More triangles than lanes choose among: not plain.
        assert!(!mesh_light(SMALL as u32 + 1, false).1.lights.at(0).plain);
    }
}
