//! The perspective camera of pbrt-v4: field of view on the shorter image
//! axis, a thin lens (depth of field) and a shutter interval.

use crate::math::{vec3, Affine, Vec3};

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
#[derive(Debug, Clone, Copy)]
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

/// Shirley–Chiu concentric mapping of the square to the unit disk.
pub fn concentric_disk(u: [f32; 2]) -> (f32, f32) {
    let (a, b) = (2.0 * u[0] - 1.0, 2.0 * u[1] - 1.0);
    if a == 0.0 && b == 0.0 {
        return (0.0, 0.0);
    }
    let (r, phi) = if a.abs() > b.abs() {
        (a, std::f32::consts::FRAC_PI_4 * (b / a))
    } else {
        (b, std::f32::consts::FRAC_PI_2 - std::f32::consts::FRAC_PI_4 * (a / b))
    };
    (r * phi.cos(), r * phi.sin())
}
