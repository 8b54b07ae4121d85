//! Textures bound to material parameters: constants, image maps (EXR or
//! PNG), checkerboards and products, looked up at a surface's (u, v).

use crate::math::{vec3, Vec3};
use std::path::Path;
use std::sync::Arc;

/// Pixels of an image texture, linear RGB, row 0 at the top.
#[derive(Debug)]
pub struct ImageData {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Row-major linear RGB.
    pub pixels: Vec<Vec3>,
}

/// How lookups outside [0, 1) behave.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wrap {
    /// Tile the image.
    Repeat,
    /// Extend the edge pixels.
    Clamp,
    /// Black outside.
    Black,
}

/// pbrt's (u, v) mapping: `s = su·u + du`, `t = sv·v + dv`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UvMapping {
    /// u scale.
    pub su: f32,
    /// v scale.
    pub sv: f32,
    /// u offset.
    pub du: f32,
    /// v offset.
    pub dv: f32,
}

impl Default for UvMapping {
    fn default() -> Self {
        UvMapping { su: 1.0, sv: 1.0, du: 0.0, dv: 0.0 }
    }
}

impl UvMapping {
    fn map(&self, uv: [f32; 2]) -> [f32; 2] {
        [self.su * uv[0] + self.du, self.sv * uv[1] + self.dv]
    }
}

/// A texture: an RGB value per (u, v). Float textures hold equal components.
#[derive(Debug, Clone)]
pub enum Texture {
    /// The same value everywhere.
    Constant(Vec3),
    /// A bilinearly filtered image.
    Image {
        /// The pixels.
        image: Arc<ImageData>,
        /// (u, v) → (s, t).
        mapping: UvMapping,
        /// Factor applied to every value.
        scale: f32,
        /// `1 − value` instead of the value.
        invert: bool,
        /// Outside [0, 1).
        wrap: Wrap,
    },
    /// Two textures alternating on a unit grid in (s, t).
    Checkerboard {
        /// (u, v) → (s, t).
        mapping: UvMapping,
        /// Where ⌊s⌋ + ⌊t⌋ is even.
        even: Arc<Texture>,
        /// Where it is odd.
        odd: Arc<Texture>,
    },
    /// The product of two textures.
    Scale(Arc<Texture>, Arc<Texture>),
}

impl Texture {
    /// The value at `uv`.
    pub fn eval(&self, uv: [f32; 2]) -> Vec3 {
        match self {
            Texture::Constant(v) => *v,
            Texture::Image { image, mapping, scale, invert, wrap } => {
                let [s, t] = mapping.map(uv);
                // pbrt-v4 flips t: image row 0 is the top, t = 0 the bottom.
                let v = bilinear(image, s, 1.0 - t, *wrap) * *scale;
                if *invert {
                    (Vec3::ONE - v).map(|c| c.max(0.0))
                } else {
                    v
                }
            }
            Texture::Checkerboard { mapping, even, odd } => {
                let [s, t] = mapping.map(uv);
                if (s.floor() as i64 + t.floor() as i64) & 1 == 0 {
                    even.eval(uv)
                } else {
                    odd.eval(uv)
                }
            }
            Texture::Scale(a, b) => a.eval(uv) * b.eval(uv),
        }
    }

    /// The value when it does not vary.
    pub fn constant(&self) -> Option<Vec3> {
        match self {
            Texture::Constant(v) => Some(*v),
            _ => None,
        }
    }

    /// The value as a float texture (its first component).
    #[inline]
    pub fn eval_float(&self, uv: [f32; 2]) -> f32 {
        self.eval(uv).x
    }
}

pub(crate) fn bilinear(image: &ImageData, s: f32, t: f32, wrap: Wrap) -> Vec3 {
    let (w, h) = (image.width as i64, image.height as i64);
    let x = s * w as f32 - 0.5;
    let y = t * h as f32 - 0.5;
    if !x.is_finite() || !y.is_finite() {
        return Vec3::ZERO;
    }
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let texel = |xi: i64, yi: i64| -> Vec3 {
        let (xi, yi) = match wrap {
            Wrap::Repeat => (xi.rem_euclid(w), yi.rem_euclid(h)),
            Wrap::Clamp => (xi.clamp(0, w - 1), yi.clamp(0, h - 1)),
            Wrap::Black => {
                if xi < 0 || yi < 0 || xi >= w || yi >= h {
                    return Vec3::ZERO;
                }
                (xi, yi)
            }
        };
        image.pixels[(yi * w + xi) as usize]
    };
    let (x0, y0) = (x0 as i64, y0 as i64);
    (texel(x0, y0) * (1.0 - fx) + texel(x0 + 1, y0) * fx) * (1.0 - fy)
        + (texel(x0, y0 + 1) * (1.0 - fx) + texel(x0 + 1, y0 + 1) * fx) * fy
}

/// How 8-bit image values map to linear values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Encoding {
    /// The sRGB transfer curve (pbrt's default for 8-bit images).
    Srgb,
    /// Values / 255.
    Linear,
    /// `(v / 255)^γ`.
    Gamma(f32),
}

/// Reads an image texture: OpenEXR (linear) or PNG (decoded by `encoding`).
pub fn read_image(path: &Path, encoding: Encoding) -> Result<ImageData, String> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    match ext.as_str() {
        "exr" => {
            let (width, height, rgb) =
                fbksd_iqa::image::read_exr(path).map_err(|e| format!("{}: {e}", path.display()))?;
            let pixels = rgb.chunks_exact(3).map(|c| vec3(c[0], c[1], c[2])).collect();
            Ok(ImageData { width: width as usize, height: height as usize, pixels })
        }
        "png" => {
            let img = image::open(path).map_err(|e| format!("{}: {e}", path.display()))?.to_rgb8();
            let decode = |v: u8| {
                let c = v as f32 / 255.0;
                match encoding {
                    Encoding::Linear => c,
                    Encoding::Gamma(g) => c.powf(g),
                    Encoding::Srgb => {
                        if c <= 0.04045 {
                            c / 12.92
                        } else {
                            ((c + 0.055) / 1.055).powf(2.4)
                        }
                    }
                }
            };
            let pixels = img.pixels().map(|p| vec3(decode(p[0]), decode(p[1]), decode(p[2]))).collect();
            Ok(ImageData { width: img.width() as usize, height: img.height() as usize, pixels })
        }
        _ => Err(format!("{}: unsupported image format (use .exr or .png)", path.display())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checkerboard_alternates_and_images_filter_bilinearly() {
        let c = Texture::Checkerboard {
            mapping: UvMapping { su: 2.0, sv: 2.0, ..Default::default() },
            even: Arc::new(Texture::Constant(Vec3::ZERO)),
            odd: Arc::new(Texture::Constant(Vec3::ONE)),
        };
        assert_eq!(c.eval([0.1, 0.1]), Vec3::ZERO);
        assert_eq!(c.eval([0.6, 0.1]), Vec3::ONE);
        assert_eq!(c.eval([0.6, 0.6]), Vec3::ZERO);
        let image = Arc::new(ImageData { width: 2, height: 1, pixels: vec![Vec3::ZERO, Vec3::ONE] });
        let t = Texture::Image { image, mapping: UvMapping::default(), scale: 1.0, invert: false, wrap: Wrap::Clamp };
        assert_eq!(t.eval([0.25, 0.5]).x, 0.0);
        assert!((t.eval([0.5, 0.5]).x - 0.5).abs() < 1e-6);
        assert_eq!(t.eval([0.75, 0.5]).x, 1.0);
    }
}
