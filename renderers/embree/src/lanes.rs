//! Values in lanes: [`W`] of a kind processed together, one per path of a
//! chunk, for the integrator's SIMD passes: floats ([`F32s`]), integers
//! ([`U32s`]), masks ([`Mask`]), vectors ([`Vec3s`]) and shading frames
//! ([`Frames`]); and the instruction sets the passes are compiled for
//! ([`Isa`]).
//!
//! Each operation is written lane by lane on a fixed-size array, with no
//! branch; inlined into a function compiled for AVX-512 or AVX2, the
//! compiler turns each into one vector instruction (or a few). A lane's
//! arithmetic is exactly its scalar counterpart's (the same operations in
//! the same order, nothing fused), so a value computed in lanes has the
//! bits [`crate::math`] would give it; the tests beside each lane twin of
//! a shading function check that. A scalar function without branches can
//! also be applied lane by lane with [`F32s::from_fn`] and still vectorises.

use crate::math::{vec3, Affine, Frame, Vec3};
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

/// Lanes: one Embree packet's rays.
pub const W: usize = crate::embree::LANES;

/// `[f(0), …, f(W − 1)]`, always inlined (the standard `from_fn` and
/// `map` are not, and out of line they stop the lanes from vectorising).
#[inline(always)]
pub fn each<T: Copy + Default>(mut f: impl FnMut(usize) -> T) -> [T; W] {
    let mut lanes = [T::default(); W];
    for (k, lane) in lanes.iter_mut().enumerate() {
        *lane = f(k);
    }
    lanes
}

/// The instruction sets the integrator's lanes are compiled for (each
/// gives the same values), and that Embree's kernels can be asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Isa {
    /// AVX-512 (F, DQ, VL, BW): a chunk in one register per field, and the
    /// dimension hashes' 64-bit multiplies in one instruction.
    Avx512,
    /// AVX2 (with FMA enabled; nothing is fused, so the values are the same).
    Avx2,
    /// What every CPU of the architecture has.
    Baseline,
}

impl Isa {
    /// The instruction sets this CPU has, best first.
    pub fn available() -> Vec<Isa> {
        [Isa::Avx512, Isa::Avx2, Isa::Baseline].into_iter().filter(|isa| isa.supported()).collect()
    }

    /// Whether this CPU has the instruction set.
    pub fn supported(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            use std::is_x86_feature_detected as has;
            match self {
                Isa::Avx512 => has!("avx512f") && has!("avx512dq") && has!("avx512vl") && has!("avx512bw"),
                Isa::Avx2 => has!("avx2") && has!("fma"),
                Isa::Baseline => true,
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            self == Isa::Baseline
        }
    }

    /// The best instruction set this CPU has, or the one `FBKSD_EMBREE_ISA`
    /// names (see [`Isa::from_env`]).
    pub fn best() -> Isa {
        static BEST: std::sync::OnceLock<Isa> = std::sync::OnceLock::new();
        *BEST.get_or_init(|| match Isa::from_env() {
            Some(isa) if isa.supported() => isa,
            Some(isa) => {
                eprintln!("fbksd-embree: this CPU lacks {isa:?} (FBKSD_EMBREE_ISA); using its best");
                Isa::available()[0]
            }
            None => Isa::available()[0],
        })
    }

    /// The instruction set `FBKSD_EMBREE_ISA` names (`avx512`, `avx2` or
    /// `baseline`), if it is set: the lanes and Embree's kernels are then
    /// those instead of the CPU's best, for tests and comparisons. Another
    /// name is reported and ignored.
    pub fn from_env() -> Option<Isa> {
        let name = std::env::var("FBKSD_EMBREE_ISA").ok()?;
        match name.as_str() {
            "avx512" => Some(Isa::Avx512),
            "avx2" => Some(Isa::Avx2),
            "baseline" => Some(Isa::Baseline),
            _ => {
                eprintln!("fbksd-embree: FBKSD_EMBREE_ISA={name:?} is none of avx512, avx2, baseline; ignored");
                None
            }
        }
    }

    /// Embree's name of the instruction set (its device option `isa`).
    pub fn embree_name(self) -> &'static str {
        match self {
            Isa::Avx512 => "avx512",
            Isa::Avx2 => "avx2",
            Isa::Baseline => "sse2",
        }
    }
}

/// W floats.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C, align(64))]
pub struct F32s(pub [f32; W]);

/// W unsigned integers (indices).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(C, align(64))]
pub struct U32s(pub [u32; W]);

/// W truths.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Mask(pub [bool; W]);

/// W vectors, one float lane per component.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vec3s {
    /// x, or red.
    pub x: F32s,
    /// y, or green.
    pub y: F32s,
    /// z, or blue.
    pub z: F32s,
}

/// W orthonormal frames (see [`Frame`]).
#[derive(Debug, Clone, Copy)]
pub struct Frames {
    /// Tangent.
    pub s: Vec3s,
    /// Bitangent.
    pub t: Vec3s,
    /// Normal.
    pub n: Vec3s,
}

macro_rules! lanewise {
    ($ty:ident, $elem:ty, $($trait:ident $method:ident $op:tt),*) => {$(
        impl $trait for $ty {
            type Output = $ty;
            #[inline(always)]
            fn $method(self, o: $ty) -> $ty {
                $ty(each(|k| self.0[k] $op o.0[k]))
            }
        }
        impl $trait<$elem> for $ty {
            type Output = $ty;
            #[inline(always)]
            fn $method(self, o: $elem) -> $ty {
                $ty(each(|k| self.0[k] $op o))
            }
        }
    )*};
}

lanewise!(F32s, f32, Add add +, Sub sub -, Mul mul *, Div div /);

impl Neg for F32s {
    type Output = F32s;
    #[inline(always)]
    fn neg(self) -> F32s {
        self.map(|v| -v)
    }
}

impl F32s {
    /// Every lane `v`.
    #[inline(always)]
    pub fn splat(v: f32) -> F32s {
        F32s([v; W])
    }

    /// Lane `k` is `f(k)`.
    #[inline(always)]
    pub fn from_fn(f: impl FnMut(usize) -> f32) -> F32s {
        F32s(each(f))
    }

    /// `f` of each lane.
    #[inline(always)]
    pub fn map(self, f: impl Fn(f32) -> f32) -> F32s {
        F32s(each(|k| f(self.0[k])))
    }

    /// `f` of each pair of lanes.
    #[inline(always)]
    pub fn zip(self, o: F32s, f: impl Fn(f32, f32) -> f32) -> F32s {
        F32s(each(|k| f(self.0[k], o.0[k])))
    }

    #[inline(always)]
    fn test(self, o: F32s, f: impl Fn(f32, f32) -> bool) -> Mask {
        Mask(each(|k| f(self.0[k], o.0[k])))
    }

    /// Square roots.
    #[inline(always)]
    pub fn sqrt(self) -> F32s {
        self.map(f32::sqrt)
    }

    /// Absolute values.
    #[inline(always)]
    pub fn abs(self) -> F32s {
        self.map(f32::abs)
    }

    /// As [`f32::max`] (a NaN lane takes the other value).
    #[inline(always)]
    pub fn max(self, o: F32s) -> F32s {
        self.zip(o, f32::max)
    }

    /// As [`f32::min`].
    #[inline(always)]
    pub fn min(self, o: F32s) -> F32s {
        self.zip(o, f32::min)
    }

    /// Lanes below `o`'s.
    #[inline(always)]
    pub fn lt(self, o: F32s) -> Mask {
        self.test(o, |a, b| a < b)
    }

    /// Lanes at most `o`'s.
    #[inline(always)]
    pub fn le(self, o: F32s) -> Mask {
        self.test(o, |a, b| a <= b)
    }

    /// Lanes above `o`'s.
    #[inline(always)]
    pub fn gt(self, o: F32s) -> Mask {
        self.test(o, |a, b| a > b)
    }

    /// Lanes at least `o`'s.
    #[inline(always)]
    pub fn ge(self, o: F32s) -> Mask {
        self.test(o, |a, b| a >= b)
    }

    /// Lanes equal to `o`'s.
    #[inline(always)]
    pub fn eq(self, o: F32s) -> Mask {
        self.test(o, |a, b| a == b)
    }

    /// Infinite lanes.
    #[inline(always)]
    pub fn is_infinite(self) -> Mask {
        Mask(each(|k| self.0[k].is_infinite()))
    }

    /// Lanes neither infinite nor NaN.
    #[inline(always)]
    pub fn is_finite(self) -> Mask {
        Mask(each(|k| self.0[k].is_finite()))
    }

    /// `a` in the lanes of `m`, `b` in the others.
    #[inline(always)]
    pub fn select(m: Mask, a: F32s, b: F32s) -> F32s {
        F32s(each(|k| if m.0[k] { a.0[k] } else { b.0[k] }))
    }
}

impl U32s {
    /// Every lane `v`.
    #[inline(always)]
    pub fn splat(v: u32) -> U32s {
        U32s([v; W])
    }

    /// Lane `k` is `f(k)`.
    #[inline(always)]
    pub fn from_fn(f: impl FnMut(usize) -> u32) -> U32s {
        U32s(each(f))
    }

    /// Lanes equal to `o`'s.
    #[inline(always)]
    pub fn eq(self, o: U32s) -> Mask {
        Mask(each(|k| self.0[k] == o.0[k]))
    }

    /// The smaller of each pair of lanes.
    #[inline(always)]
    pub fn min(self, o: U32s) -> U32s {
        U32s(each(|k| self.0[k].min(o.0[k])))
    }

    /// Sums, wrapping.
    #[inline(always)]
    pub fn wrapping_add(self, o: U32s) -> U32s {
        U32s(each(|k| self.0[k].wrapping_add(o.0[k])))
    }

    /// `a` in the lanes of `m`, `b` in the others.
    #[inline(always)]
    pub fn select(m: Mask, a: U32s, b: U32s) -> U32s {
        U32s(each(|k| if m.0[k] { a.0[k] } else { b.0[k] }))
    }
}

impl Mask {
    /// Every lane `v`.
    #[inline(always)]
    pub fn splat(v: bool) -> Mask {
        Mask([v; W])
    }

    /// Lane `k` is `f(k)`.
    #[inline(always)]
    pub fn from_fn(f: impl FnMut(usize) -> bool) -> Mask {
        Mask(each(f))
    }

    /// Whether any lane is set.
    #[inline(always)]
    pub fn any(self) -> bool {
        self.0.iter().any(|m| *m)
    }

    /// The lanes set, in order.
    #[inline(always)]
    pub fn lanes(self) -> impl Iterator<Item = usize> {
        let mut bits = self.0.iter().rev().fold(0u32, |bits, m| bits << 1 | *m as u32);
        std::iter::from_fn(move || {
            let k = bits.trailing_zeros() as usize;
            bits &= bits.wrapping_sub(1);
            (k < W).then_some(k)
        })
    }

    /// 1 in the lanes set, 0 elsewhere.
    #[inline(always)]
    pub fn count(self) -> U32s {
        U32s(each(|k| self.0[k] as u32))
    }
}

impl BitAnd for Mask {
    type Output = Mask;
    #[inline(always)]
    fn bitand(self, o: Mask) -> Mask {
        Mask(each(|k| self.0[k] & o.0[k]))
    }
}

impl BitAnd<bool> for Mask {
    type Output = Mask;
    #[inline(always)]
    fn bitand(self, o: bool) -> Mask {
        Mask(each(|k| self.0[k] & o))
    }
}

impl BitOr for Mask {
    type Output = Mask;
    #[inline(always)]
    fn bitor(self, o: Mask) -> Mask {
        Mask(each(|k| self.0[k] | o.0[k]))
    }
}

impl BitOr<bool> for Mask {
    type Output = Mask;
    #[inline(always)]
    fn bitor(self, o: bool) -> Mask {
        Mask(each(|k| self.0[k] | o))
    }
}

impl Not for Mask {
    type Output = Mask;
    #[inline(always)]
    fn not(self) -> Mask {
        Mask(each(|k| !self.0[k]))
    }
}

impl Vec3s {
    /// (0, 0, 0) in every lane.
    pub const ZERO: Vec3s = Vec3s { x: F32s([0.0; W]), y: F32s([0.0; W]), z: F32s([0.0; W]) };

    /// From components.
    #[inline(always)]
    pub fn new(x: F32s, y: F32s, z: F32s) -> Vec3s {
        Vec3s { x, y, z }
    }

    /// Every lane `v`.
    #[inline(always)]
    pub fn splat(v: Vec3) -> Vec3s {
        Vec3s::new(F32s::splat(v.x), F32s::splat(v.y), F32s::splat(v.z))
    }

    /// Lane `k` is `f(k)` (called once per component: a gather from a
    /// table is three gathers, not a table of structures built first).
    #[inline(always)]
    pub fn from_fn(f: impl Fn(usize) -> Vec3) -> Vec3s {
        let v: [Vec3; W] = each(f);
        Vec3s::new(F32s::from_fn(|k| v[k].x), F32s::from_fn(|k| v[k].y), F32s::from_fn(|k| v[k].z))
    }

    /// Lane `k`.
    #[inline(always)]
    pub fn lane(&self, k: usize) -> Vec3 {
        vec3(self.x.0[k], self.y.0[k], self.z.0[k])
    }

    /// Sets lane `k`.
    #[inline(always)]
    pub fn set_lane(&mut self, k: usize, v: Vec3) {
        (self.x.0[k], self.y.0[k], self.z.0[k]) = (v.x, v.y, v.z);
    }

    /// As [`Vec3::dot`].
    #[inline(always)]
    pub fn dot(self, o: Vec3s) -> F32s {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    /// As [`Vec3::length_squared`].
    #[inline(always)]
    pub fn length_squared(self) -> F32s {
        self.dot(self)
    }

    /// As [`Vec3::normalize`] (zero stays zero).
    #[inline(always)]
    pub fn normalize(self) -> Vec3s {
        let l = self.length_squared().sqrt();
        Vec3s::select(l.gt(F32s::splat(0.0)), self * (F32s::splat(1.0) / l), Vec3s::ZERO)
    }

    /// As [`Vec3::max_component`].
    #[inline(always)]
    pub fn max_component(self) -> F32s {
        self.x.max(self.y).max(self.z)
    }

    /// As [`Vec3::is_black`].
    #[inline(always)]
    pub fn is_black(self) -> Mask {
        let zero = F32s::splat(0.0);
        self.x.eq(zero) & self.y.eq(zero) & self.z.eq(zero)
    }

    /// As [`Vec3::is_finite`].
    #[inline(always)]
    pub fn is_finite(self) -> Mask {
        self.x.is_finite() & self.y.is_finite() & self.z.is_finite()
    }

    /// `a` in the lanes of `m`, `b` in the others.
    #[inline(always)]
    pub fn select(m: Mask, a: Vec3s, b: Vec3s) -> Vec3s {
        Vec3s::new(F32s::select(m, a.x, b.x), F32s::select(m, a.y, b.y), F32s::select(m, a.z, b.z))
    }
}

impl Add for Vec3s {
    type Output = Vec3s;
    #[inline(always)]
    fn add(self, o: Vec3s) -> Vec3s {
        Vec3s::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}

impl Sub for Vec3s {
    type Output = Vec3s;
    #[inline(always)]
    fn sub(self, o: Vec3s) -> Vec3s {
        Vec3s::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}

impl Mul for Vec3s {
    type Output = Vec3s;
    #[inline(always)]
    fn mul(self, o: Vec3s) -> Vec3s {
        Vec3s::new(self.x * o.x, self.y * o.y, self.z * o.z)
    }
}

impl Mul<F32s> for Vec3s {
    type Output = Vec3s;
    #[inline(always)]
    fn mul(self, s: F32s) -> Vec3s {
        Vec3s::new(self.x * s, self.y * s, self.z * s)
    }
}

impl Mul<f32> for Vec3s {
    type Output = Vec3s;
    #[inline(always)]
    fn mul(self, s: f32) -> Vec3s {
        Vec3s::new(self.x * s, self.y * s, self.z * s)
    }
}

impl Neg for Vec3s {
    type Output = Vec3s;
    #[inline(always)]
    fn neg(self) -> Vec3s {
        Vec3s::new(-self.x, -self.y, -self.z)
    }
}

impl Affine {
    /// [`Affine::point`] in lanes.
    #[inline(always)]
    pub fn point_lanes(&self, p: Vec3s) -> Vec3s {
        let r = |i: usize| p.x * self.rows[i][0] + p.y * self.rows[i][1] + p.z * self.rows[i][2] + self.rows[i][3];
        Vec3s::new(r(0), r(1), r(2))
    }

    /// [`Affine::vector`] in lanes.
    #[inline(always)]
    pub fn vector_lanes(&self, v: Vec3s) -> Vec3s {
        let r = |i: usize| v.x * self.rows[i][0] + v.y * self.rows[i][1] + v.z * self.rows[i][2];
        Vec3s::new(r(0), r(1), r(2))
    }
}

impl Add<F32s> for f32 {
    type Output = F32s;
    #[inline(always)]
    fn add(self, o: F32s) -> F32s {
        o.map(|v| self + v)
    }
}

impl Sub<F32s> for f32 {
    type Output = F32s;
    #[inline(always)]
    fn sub(self, o: F32s) -> F32s {
        o.map(|v| self - v)
    }
}

impl Mul<F32s> for f32 {
    type Output = F32s;
    #[inline(always)]
    fn mul(self, o: F32s) -> F32s {
        o.map(|v| self * v)
    }
}

impl Div<F32s> for f32 {
    type Output = F32s;
    #[inline(always)]
    fn div(self, o: F32s) -> F32s {
        o.map(|v| self / v)
    }
}

impl Frames {
    /// As [`Frame::from_normal`].
    #[inline(always)]
    pub fn from_normal(n: Vec3s) -> Frames {
        let sign = n.z.map(|z| 1f32.copysign(z));
        let a = F32s::splat(-1.0) / (sign + n.z);
        let b = n.x * n.y * a;
        Frames {
            s: Vec3s::new(F32s::splat(1.0) + sign * n.x * n.x * a, sign * b, -sign * n.x),
            t: Vec3s::new(b, sign + n.y * n.y * a, -n.y),
            n,
        }
    }

    /// As [`Frame::to_local`].
    #[inline(always)]
    pub fn to_local(&self, v: Vec3s) -> Vec3s {
        Vec3s::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    /// As [`Frame::to_world`].
    #[inline(always)]
    pub fn to_world(&self, v: Vec3s) -> Vec3s {
        self.s * v.x + self.t * v.y + self.n * v.z
    }

    /// Lane `k`.
    pub fn lane(&self, k: usize) -> Frame {
        Frame { s: self.s.lane(k), t: self.t.lane(k), n: self.n.lane(k) }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A deterministic stream of test floats: ordinary values, tiny and huge
    /// ones, zeros of both signs, infinities and NaN.
    pub(crate) struct Values(u64);

    impl Values {
        pub(crate) fn new(seed: u64) -> Values {
            Values(seed)
        }

        pub(crate) fn next(&mut self) -> f32 {
            self.0 = fbksd_renderer::sampler::mix(self.0);
            let u = (self.0 >> 40) as f32 / (1u64 << 24) as f32;
            match self.0 & 0xFF {
                0 => 0.0,
                1 => -0.0,
                2 => f32::INFINITY,
                3 => f32::NAN,
                4 => 1e-30 * u,
                5 => 1e30 * u,
                _ => 2.0 * u - 1.0,
            }
        }

        pub(crate) fn lanes(&mut self) -> F32s {
            F32s::from_fn(|_| self.next())
        }

        pub(crate) fn vectors(&mut self) -> Vec3s {
            Vec3s::new(self.lanes(), self.lanes(), self.lanes())
        }
    }

    /// Whether two floats have the same bits (any NaN equals any NaN).
    pub(crate) fn same(a: f32, b: f32) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    pub(crate) fn same3(a: Vec3, b: Vec3) -> bool {
        same(a.x, b.x) && same(a.y, b.y) && same(a.z, b.z)
    }

    #[test]
    fn a_mask_lists_its_lanes_in_order() {
        let m = Mask(each(|k| k % 3 == 1 || k == 15));
        assert_eq!(m.lanes().collect::<Vec<_>>(), [1, 4, 7, 10, 13, 15]);
        assert_eq!(Mask::splat(false).lanes().count(), 0);
        assert_eq!(Mask::splat(true).lanes().count(), W);
    }

    #[test]
    fn frames_and_vectors_in_lanes_have_the_scalar_bits() {
        let mut values = Values::new(1);
        for _ in 0..500 {
            let (n, v) = (values.vectors(), values.vectors());
            // Unit normals, as frames get them, and arbitrary ones.
            let unit = Vec3s::from_fn(|k| n.lane(k).normalize());
            for n in [n, unit] {
                let frames = Frames::from_normal(n);
                let (local, world) = (frames.to_local(v), frames.to_world(v));
                for k in 0..W {
                    let frame = Frame::from_normal(n.lane(k));
                    assert!(same3(local.lane(k), frame.to_local(v.lane(k))), "{:?}", n.lane(k));
                    assert!(same3(world.lane(k), frame.to_world(v.lane(k))), "{:?}", n.lane(k));
                    assert!(same(n.dot(v).0[k], n.lane(k).dot(v.lane(k))));
                    assert!(same(v.max_component().0[k], v.lane(k).max_component()));
                    assert_eq!(v.is_black().0[k], v.lane(k).is_black());
                    assert_eq!(v.is_finite().0[k], v.lane(k).is_finite());
                }
            }
        }
    }
}
