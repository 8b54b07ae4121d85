//! The perspective camera of pbrt-v4: field of view on the shorter image
//! axis, a thin lens (depth of field) and a shutter interval.

use crate::lanes::{F32s, Vec3s};
use crate::math::{sin_cos_quarter, vec3, Affine, Vec3};

/// A perspective camera with a thin lens.
#[derive(Debug, Clone)]
pub struct Camera {
    /// Camera space → world (pbrt's camera transform has no projective part).
    pub camera_to_world: Affine,
    /// Image size in pixels.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// tan(fov / 2), fov on the shorter axis.
    pub tan_half_fov: f32,
    /// Screen window: x range and y range (pbrt's `screenwindow`).
    pub screen: [f32; 4],
    /// Lens radius (0: pinhole).
    pub lens_radius: f32,
    /// Distance to the plane in focus.
    pub focal_distance: f32,
    /// Shutter open and close times.
    pub shutter: [f32; 2],
}

/// A ray in world space.
#[derive(Debug, Clone, Copy, Default)]
pub struct Ray {
    /// Origin.
    pub origin: Vec3,
    /// Unit direction.
    pub dir: Vec3,
    /// Scene time.
    pub time: f32,
}

impl Camera {
    /// pbrt's default screen window for an image of `width × height`.
    pub fn default_screen(width: u32, height: u32) -> [f32; 4] {
        let aspect = width as f32 / height as f32;
        if aspect > 1.0 {
            [-aspect, aspect, -1.0, 1.0]
        } else {
            [-1.0, 1.0, -1.0 / aspect, 1.0 / aspect]
        }
    }

    /// Whether the lens has an area (depth of field).
    pub fn has_dof(&self) -> bool {
        self.lens_radius > 0.0
    }

    /// The ray through raster position (`x`, `y`) (pixels, y down), lens
    /// position `lens` ∈ [0, 1)², at shutter fraction `time` ∈ [0, 1).
    pub fn ray(&self, x: f32, y: f32, lens: [f32; 2], time: f32) -> Ray {
        let [x0, x1, y0, y1] = self.screen;
        let sx = x0 + (x / self.width as f32) * (x1 - x0);
        let sy = y1 - (y / self.height as f32) * (y1 - y0);
        let p_camera = vec3(sx * self.tan_half_fov, sy * self.tan_half_fov, 1.0);
        let mut origin = Vec3::ZERO;
        let mut dir = p_camera.normalize();
        if self.lens_radius > 0.0 {
            let (lx, ly) = concentric_disk(lens);
            let p_lens = vec3(lx * self.lens_radius, ly * self.lens_radius, 0.0);
            let focus = dir * (self.focal_distance / dir.z);
            origin = p_lens;
            dir = (focus - p_lens).normalize();
        }
        let time = self.shutter[0] + time * (self.shutter[1] - self.shutter[0]);
        Ray { origin: self.camera_to_world.point(origin), dir: self.camera_to_world.vector(dir).normalize(), time }
    }
}

impl Camera {
    /// [`Camera::ray`] in lanes: the rays' origins, directions and times.
    #[inline(always)]
    pub fn rays_lanes(&self, x: F32s, y: F32s, lens: [F32s; 2], time: F32s) -> (Vec3s, Vec3s, F32s) {
        let [x0, x1, y0, y1] = self.screen;
        let sx = x0 + (x / self.width as f32) * (x1 - x0);
        let sy = y1 - (y / self.height as f32) * (y1 - y0);
        let p_camera = Vec3s::new(sx * self.tan_half_fov, sy * self.tan_half_fov, F32s::splat(1.0));
        let (mut origin, mut dir) = (Vec3s::ZERO, p_camera.normalize());
        if self.lens_radius > 0.0 {
            let (lx, ly) = concentric_disk_lanes(lens);
            let p_lens = Vec3s::new(lx * self.lens_radius, ly * self.lens_radius, F32s::splat(0.0));
            let focus = dir * (self.focal_distance / dir.z);
            origin = p_lens;
            dir = (focus - p_lens).normalize();
        }
        let time = self.shutter[0] + time * (self.shutter[1] - self.shutter[0]);
        (self.camera_to_world.point_lanes(origin), self.camera_to_world.vector_lanes(dir).normalize(), time)
    }
}

/// Shirley–Chiu concentric mapping of the square to the unit disk. The
/// angle is π/4·(b/a) in one half of the square and π/2 − π/4·(a/b) in the
/// other; both are taken through [`sin_cos_quarter`] of the quarter angle
/// (swapping sine and cosine in the second half), without a branch, so the
/// integrator's lanes vectorise it.
#[inline(always)]
pub fn concentric_disk(u: [f32; 2]) -> (f32, f32) {
    let (a, b) = (2.0 * u[0] - 1.0, 2.0 * u[1] - 1.0);
    let wide = a.abs() > b.abs();
    let (r, ratio) = if wide { (a, b / a) } else { (b, a / b) };
    let (sin, cos) = sin_cos_quarter(std::f32::consts::FRAC_PI_4 * ratio);
    let (x, y) = if wide { (r * cos, r * sin) } else { (r * sin, r * cos) };
    // The centre (0/0 above) maps to itself.
    if a == 0.0 && b == 0.0 {
        (0.0, 0.0)
    } else {
        (x, y)
    }
}

/// [`concentric_disk`] in lanes.
#[inline(always)]
pub fn concentric_disk_lanes(u: [F32s; 2]) -> (F32s, F32s) {
    let (a, b) = (u[0] * 2.0 - F32s::splat(1.0), u[1] * 2.0 - F32s::splat(1.0));
    let wide = a.abs().gt(b.abs());
    let (r, ratio) = (F32s::select(wide, a, b), F32s::select(wide, b / a, a / b));
    let theta = ratio * std::f32::consts::FRAC_PI_4;
    let (sin, cos) =
        (F32s::from_fn(|k| sin_cos_quarter(theta.0[k]).0), F32s::from_fn(|k| sin_cos_quarter(theta.0[k]).1));
    let (x, y) = (F32s::select(wide, r * cos, r * sin), F32s::select(wide, r * sin, r * cos));
    let zero = F32s::splat(0.0);
    let centre = a.eq(zero) & b.eq(zero);
    (F32s::select(centre, zero, x), F32s::select(centre, zero, y))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lanes::tests::{same, same3, Values};

    #[test]
    fn camera_rays_in_lanes_have_the_scalar_bits() {
        let mut values = Values::new(3);
        for lens_radius in [0.0, 0.25] {
            let camera = Camera {
                camera_to_world: Affine { rows: [[0.8, 0.0, 0.6, 1.0], [0.0, 1.0, 0.0, -2.0], [-0.6, 0.0, 0.8, 3.0]] },
                width: 640,
                height: 480,
                tan_half_fov: 0.4,
                screen: Camera::default_screen(640, 480),
                lens_radius,
                focal_distance: 5.0,
                shutter: [0.25, 0.75],
            };
            for _ in 0..200 {
                let (x, y) =
                    (values.lanes().map(|v| (v.abs() * 640.0).min(639.9)), values.lanes().map(|v| v.abs() * 480.0));
                let (lens, time) =
                    ([values.lanes().map(f32::abs), values.lanes().map(f32::abs)], values.lanes().map(f32::abs));
                let (origin, dir, t) = camera.rays_lanes(x, y, lens, time);
                for k in 0..crate::lanes::W {
                    let ray = camera.ray(x.0[k], y.0[k], [lens[0].0[k], lens[1].0[k]], time.0[k]);
                    assert!(same3(origin.lane(k), ray.origin) && same3(dir.lane(k), ray.dir) && same(t.0[k], ray.time));
                }
            }
        }
    }

    #[test]
    fn the_concentric_mapping_in_lanes_has_the_scalar_bits() {
        let mut values = Values::new(2);
        for _ in 0..2000 {
            // Points of the square, its centre and edges, and values outside it.
            let u = [values.lanes().map(|v| if v.abs() < 0.3 { 0.5 } else { v }), values.lanes()];
            let (x, y) = concentric_disk_lanes(u);
            for k in 0..crate::lanes::W {
                let (sx, sy) = concentric_disk([u[0].0[k], u[1].0[k]]);
                assert!(same(x.0[k], sx) && same(y.0[k], sy), "{:?}", [u[0].0[k], u[1].0[k]]);
            }
        }
    }

    #[test]
    fn the_concentric_mapping_agrees_with_its_trigonometric_form() {
        // The disk point at radius r and angle φ as Shirley and Chiu give it, with libm's cos and sin.
        let exact = |u: [f32; 2]| {
            let (a, b) = (2.0 * u[0] as f64 - 1.0, 2.0 * u[1] as f64 - 1.0);
            let (r, phi) = if a.abs() > b.abs() {
                (a, std::f64::consts::FRAC_PI_4 * (b / a))
            } else {
                (b, std::f64::consts::FRAC_PI_2 - std::f64::consts::FRAC_PI_4 * (a / b))
            };
            (r * phi.cos(), r * phi.sin())
        };
        let n = 301;
        for i in 0..n {
            for j in 0..n {
                let u = [i as f32 / (n - 1) as f32, j as f32 / (n - 1) as f32];
                let (x, y) = concentric_disk(u);
                if u == [0.5, 0.5] {
                    assert_eq!((x, y), (0.0, 0.0));
                    continue;
                }
                let (ex, ey) = exact(u);
                assert!((x as f64 - ex).abs() < 3e-7 && (y as f64 - ey).abs() < 3e-7, "{u:?}: {x} {y} vs {ex} {ey}");
            }
        }
    }
}
