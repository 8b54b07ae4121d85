//! Vectors, frames and 4×4 transforms.
//!
//! Shading runs in `f32` ([`Vec3`]); scene transforms are composed in `f64`
//! ([`Transform`]) so long chains of directives lose no precision.

use std::ops::{Add, AddAssign, Div, Index, Mul, MulAssign, Neg, Sub};

/// A 3-vector (point, direction, normal or RGB colour).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vec3 {
    /// x, or red.
    pub x: f32,
    /// y, or green.
    pub y: f32,
    /// z, or blue.
    pub z: f32,
}

/// Shorthand constructor.
#[inline(always)]
pub const fn vec3(x: f32, y: f32, z: f32) -> Vec3 {
    Vec3 { x, y, z }
}

impl Vec3 {
    /// (0, 0, 0).
    pub const ZERO: Vec3 = vec3(0.0, 0.0, 0.0);
    /// (1, 1, 1).
    pub const ONE: Vec3 = vec3(1.0, 1.0, 1.0);

    /// All components `v`.
    #[inline(always)]
    pub const fn splat(v: f32) -> Vec3 {
        vec3(v, v, v)
    }
    /// From an array.
    #[inline(always)]
    pub fn from_array(a: [f32; 3]) -> Vec3 {
        vec3(a[0], a[1], a[2])
    }
    /// As an array.
    #[inline(always)]
    pub fn to_array(self) -> [f32; 3] {
        [self.x, self.y, self.z]
    }
    /// Dot product.
    #[inline(always)]
    pub fn dot(self, o: Vec3) -> f32 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// Cross product.
    #[inline(always)]
    pub fn cross(self, o: Vec3) -> Vec3 {
        vec3(self.y * o.z - self.z * o.y, self.z * o.x - self.x * o.z, self.x * o.y - self.y * o.x)
    }
    /// Squared length.
    #[inline(always)]
    pub fn length_squared(self) -> f32 {
        self.dot(self)
    }
    /// Length.
    #[inline(always)]
    pub fn length(self) -> f32 {
        self.length_squared().sqrt()
    }
    /// Unit vector along `self` (zero stays zero rather than becoming NaN).
    #[inline(always)]
    pub fn normalize(self) -> Vec3 {
        let l = self.length();
        if l > 0.0 {
            self * (1.0 / l)
        } else {
            Vec3::ZERO
        }
    }
    /// Largest component.
    #[inline(always)]
    pub fn max_component(self) -> f32 {
        self.x.max(self.y).max(self.z)
    }
    /// Mean of the components.
    #[inline(always)]
    pub fn average(self) -> f32 {
        (self.x + self.y + self.z) * (1.0 / 3.0)
    }
    /// Whether every component is finite.
    #[inline(always)]
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }
    /// Whether every component is zero.
    #[inline(always)]
    pub fn is_black(self) -> bool {
        self.x == 0.0 && self.y == 0.0 && self.z == 0.0
    }
    /// Component-wise map.
    #[inline(always)]
    pub fn map(self, f: impl Fn(f32) -> f32) -> Vec3 {
        vec3(f(self.x), f(self.y), f(self.z))
    }
    /// Linear interpolation to `o` by `t`.
    #[inline(always)]
    pub fn lerp(self, o: Vec3, t: f32) -> Vec3 {
        self * (1.0 - t) + o * t
    }
    /// `self` flipped, if needed, into the hemisphere of `n`.
    #[inline(always)]
    pub fn face_forward(self, n: Vec3) -> Vec3 {
        if self.dot(n) < 0.0 {
            -self
        } else {
            self
        }
    }
}

impl Add for Vec3 {
    type Output = Vec3;
    #[inline(always)]
    fn add(self, o: Vec3) -> Vec3 {
        vec3(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}
impl AddAssign for Vec3 {
    #[inline(always)]
    fn add_assign(&mut self, o: Vec3) {
        *self = *self + o;
    }
}
impl Sub for Vec3 {
    type Output = Vec3;
    #[inline(always)]
    fn sub(self, o: Vec3) -> Vec3 {
        vec3(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}
impl Mul<f32> for Vec3 {
    type Output = Vec3;
    #[inline(always)]
    fn mul(self, s: f32) -> Vec3 {
        vec3(self.x * s, self.y * s, self.z * s)
    }
}
impl Mul<Vec3> for Vec3 {
    type Output = Vec3;
    #[inline(always)]
    fn mul(self, o: Vec3) -> Vec3 {
        vec3(self.x * o.x, self.y * o.y, self.z * o.z)
    }
}
impl MulAssign<Vec3> for Vec3 {
    #[inline(always)]
    fn mul_assign(&mut self, o: Vec3) {
        *self = *self * o;
    }
}
impl MulAssign<f32> for Vec3 {
    #[inline(always)]
    fn mul_assign(&mut self, s: f32) {
        *self = *self * s;
    }
}
impl Div<f32> for Vec3 {
    type Output = Vec3;
    #[inline(always)]
    fn div(self, s: f32) -> Vec3 {
        self * (1.0 / s)
    }
}
impl Neg for Vec3 {
    type Output = Vec3;
    #[inline(always)]
    fn neg(self) -> Vec3 {
        vec3(-self.x, -self.y, -self.z)
    }
}
impl Index<usize> for Vec3 {
    type Output = f32;
    #[inline(always)]
    fn index(&self, i: usize) -> &f32 {
        match i {
            0 => &self.x,
            1 => &self.y,
            _ => &self.z,
        }
    }
}

/// sin x and cos x for |x| ≤ π/4, by their Taylor series to the x⁹ and x¹⁰
/// terms (the first omitted terms are below 2·10⁻⁹, under f32's rounding).
/// Our own rather than libm's: it vectorises in the integrator's lanes, and
/// it gives the same bits on every CPU (glibc picks an FMA variant of
/// `sincosf` by the CPU it runs on).
#[inline(always)]
pub fn sin_cos_quarter(x: f32) -> (f32, f32) {
    let x2 = x * x;
    let sin = x + x * x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362_880.0))));
    let cos =
        1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40_320.0 + x2 * (-1.0 / 3_628_800.0)))));
    (sin, cos)
}

/// An orthonormal basis around a normal: local z is the normal.
#[derive(Debug, Clone, Copy)]
pub struct Frame {
    /// Tangent.
    pub s: Vec3,
    /// Bitangent.
    pub t: Vec3,
    /// Normal.
    pub n: Vec3,
}

impl Frame {
    /// A frame around unit `n` (Duff et al., "Building an orthonormal basis, revisited").
    #[inline]
    pub fn from_normal(n: Vec3) -> Frame {
        let sign = 1f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        Frame { s: vec3(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x), t: vec3(b, sign + n.y * n.y * a, -n.y), n }
    }
    /// World to local.
    #[inline(always)]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        vec3(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }
    /// Local to world.
    #[inline(always)]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// An affine transform with its inverse (row-major 4×4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    /// The matrix.
    pub m: [[f64; 4]; 4],
    /// Its inverse.
    pub inv: [[f64; 4]; 4],
}

const IDENTITY: [[f64; 4]; 4] =
    [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

fn mat_mul(a: &[[f64; 4]; 4], b: &[[f64; 4]; 4]) -> [[f64; 4]; 4] {
    let mut r = [[0.0; 4]; 4];
    for (i, row) in r.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..4).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    r
}

fn transpose(m: &[[f64; 4]; 4]) -> [[f64; 4]; 4] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[j][i]))
}

/// Inverse by Gauss–Jordan elimination with partial pivoting; `None` when singular.
fn invert(m: &[[f64; 4]; 4]) -> Option<[[f64; 4]; 4]> {
    let mut a = *m;
    let mut inv = IDENTITY;
    for c in 0..4 {
        let p = (c..4).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() < 1e-300 {
            return None;
        }
        a.swap(c, p);
        inv.swap(c, p);
        let d = 1.0 / a[c][c];
        for j in 0..4 {
            a[c][j] *= d;
            inv[c][j] *= d;
        }
        for r in 0..4 {
            if r != c {
                let f = a[r][c];
                for j in 0..4 {
                    a[r][j] -= f * a[c][j];
                    inv[r][j] -= f * inv[c][j];
                }
            }
        }
    }
    Some(inv)
}

impl Default for Transform {
    fn default() -> Self {
        Transform::IDENTITY
    }
}

impl Transform {
    /// The identity.
    pub const IDENTITY: Transform = Transform { m: IDENTITY, inv: IDENTITY };

    /// From a row-major matrix; `None` when it is singular.
    pub fn from_matrix(m: [[f64; 4]; 4]) -> Option<Transform> {
        Some(Transform { m, inv: invert(&m)? })
    }
    /// A translation.
    pub fn translate(d: [f64; 3]) -> Transform {
        let mut m = IDENTITY;
        let mut inv = IDENTITY;
        for i in 0..3 {
            m[i][3] = d[i];
            inv[i][3] = -d[i];
        }
        Transform { m, inv }
    }
    /// A scale; `None` when a factor is zero.
    pub fn scale(s: [f64; 3]) -> Option<Transform> {
        let mut m = IDENTITY;
        for i in 0..3 {
            m[i][i] = s[i];
        }
        Transform::from_matrix(m)
    }
    /// A rotation by `degrees` about `axis` (pbrt's `Rotate`).
    pub fn rotate(degrees: f64, axis: [f64; 3]) -> Option<Transform> {
        let len = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
        if len == 0.0 || !len.is_finite() {
            return None;
        }
        let [x, y, z] = axis.map(|v| v / len);
        let (s, c) = degrees.to_radians().sin_cos();
        let m = [
            [x * x + (1.0 - x * x) * c, x * y * (1.0 - c) - z * s, x * z * (1.0 - c) + y * s, 0.0],
            [x * y * (1.0 - c) + z * s, y * y + (1.0 - y * y) * c, y * z * (1.0 - c) - x * s, 0.0],
            [x * z * (1.0 - c) - y * s, y * z * (1.0 - c) + x * s, z * z + (1.0 - z * z) * c, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        Some(Transform { m, inv: transpose(&m) })
    }
    /// pbrt's `LookAt`: the world-to-camera transform; `None` when `up` is parallel to the view.
    pub fn look_at(eye: [f64; 3], target: [f64; 3], up: [f64; 3]) -> Option<Transform> {
        let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
        };
        let norm = |a: [f64; 3]| {
            let l = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
            (l > 0.0 && l.is_finite()).then(|| a.map(|v| v / l))
        };
        let dir = norm(sub(target, eye))?;
        let right = norm(cross(norm(up)?, dir))?;
        let new_up = cross(dir, right);
        let camera_to_world = [
            [right[0], new_up[0], dir[0], eye[0]],
            [right[1], new_up[1], dir[1], eye[1]],
            [right[2], new_up[2], dir[2], eye[2]],
            [0.0, 0.0, 0.0, 1.0],
        ];
        Transform::from_matrix(camera_to_world).map(|t| t.inverse())
    }
    /// The inverse transform.
    pub fn inverse(&self) -> Transform {
        Transform { m: self.inv, inv: self.m }
    }
    /// `self ∘ o` (apply `o` first).
    pub fn compose(&self, o: &Transform) -> Transform {
        Transform { m: mat_mul(&self.m, &o.m), inv: mat_mul(&o.inv, &self.inv) }
    }
    /// Applies to a point.
    pub fn point(&self, p: Vec3) -> Vec3 {
        let m = &self.m;
        let (x, y, z) = (p.x as f64, p.y as f64, p.z as f64);
        let w = m[3][0] * x + m[3][1] * y + m[3][2] * z + m[3][3];
        let r = |i: usize| ((m[i][0] * x + m[i][1] * y + m[i][2] * z + m[i][3]) / w) as f32;
        vec3(r(0), r(1), r(2))
    }
    /// Applies to a direction.
    pub fn vector(&self, v: Vec3) -> Vec3 {
        let m = &self.m;
        let (x, y, z) = (v.x as f64, v.y as f64, v.z as f64);
        let r = |i: usize| (m[i][0] * x + m[i][1] * y + m[i][2] * z) as f32;
        vec3(r(0), r(1), r(2))
    }
    /// Applies to a normal (by the inverse transpose).
    pub fn normal(&self, n: Vec3) -> Vec3 {
        let m = &self.inv;
        let (x, y, z) = (n.x as f64, n.y as f64, n.z as f64);
        let r = |i: usize| (m[0][i] * x + m[1][i] * y + m[2][i] * z) as f32;
        vec3(r(0), r(1), r(2))
    }
    /// Whether the transform flips handedness (pbrt then flips normals).
    pub fn swaps_handedness(&self) -> bool {
        let m = &self.m;
        let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        det < 0.0
    }
    /// The uniform scale factor, if the linear part is a rotation times a uniform scale.
    pub fn uniform_scale(&self) -> Option<f64> {
        let m = &self.m;
        let col = |j: usize| (m[0][j] * m[0][j] + m[1][j] * m[1][j] + m[2][j] * m[2][j]).sqrt();
        let (a, b, c) = (col(0), col(1), col(2));
        let close = |u: f64, v: f64| (u - v).abs() <= 1e-6 * u.max(v);
        let dot = |i: usize, j: usize| (m[0][i] * m[0][j] + m[1][i] * m[1][j] + m[2][i] * m[2][j]) / (col(i) * col(j));
        (close(a, b) && close(b, c) && dot(0, 1).abs() < 1e-6 && dot(0, 2).abs() < 1e-6 && dot(1, 2).abs() < 1e-6)
            .then_some(a)
    }
    /// Whether this is the identity.
    pub fn is_identity(&self) -> bool {
        self.m == IDENTITY
    }
}

/// An affine transform in `f32`, for hot paths (the camera): the top three
/// rows of a [`Transform`]'s matrix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Affine {
    /// Rows of the 3 × 4 matrix.
    pub rows: [[f32; 4]; 3],
}

impl Affine {
    /// From a transform whose last row is (0, 0, 0, 1).
    pub fn new(t: &Transform) -> Affine {
        Affine { rows: std::array::from_fn(|i| std::array::from_fn(|j| t.m[i][j] as f32)) }
    }
    /// Applies to a point.
    #[inline(always)]
    pub fn point(&self, p: Vec3) -> Vec3 {
        let r = |i: usize| self.rows[i][0] * p.x + self.rows[i][1] * p.y + self.rows[i][2] * p.z + self.rows[i][3];
        vec3(r(0), r(1), r(2))
    }
    /// Applies to a direction.
    #[inline(always)]
    pub fn vector(&self, v: Vec3) -> Vec3 {
        let r = |i: usize| self.rows[i][0] * v.x + self.rows[i][1] * v.y + self.rows[i][2] * v.z;
        vec3(r(0), r(1), r(2))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_orthonormal_for_every_normal_including_the_poles() {
        for n in [vec3(0.0, 0.0, 1.0), vec3(0.0, 0.0, -1.0), vec3(1.0, 2.0, -3.0).normalize(), vec3(0.0, 1.0, 0.0)] {
            let f = Frame::from_normal(n);
            for (a, b) in [(f.s, f.t), (f.s, f.n), (f.t, f.n)] {
                assert!(a.dot(b).abs() < 1e-6);
            }
            let v = vec3(0.3, -0.4, 0.5);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-6);
        }
    }

    #[test]
    fn transforms_compose_and_invert() {
        let t = Transform::translate([1.0, 2.0, 3.0])
            .compose(&Transform::rotate(30.0, [0.0, 1.0, 1.0]).unwrap())
            .compose(&Transform::scale([2.0, 2.0, 2.0]).unwrap());
        let p = vec3(0.5, -1.0, 4.0);
        assert!((t.inverse().point(t.point(p)) - p).length() < 1e-5);
        assert_eq!(t.uniform_scale().map(|s| (s * 1e6).round() / 1e6), Some(2.0));
        assert!(Transform::scale([1.0, 0.0, 1.0]).is_none());
        assert!(Transform::scale([-1.0, 1.0, 1.0]).unwrap().swaps_handedness());
    }
}
