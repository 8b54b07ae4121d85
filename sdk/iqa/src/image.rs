//! Images: 32-bit float RGB in memory, OpenEXR on disk, sRGB previews.

use std::io;
use std::path::Path;

/// A linear RGB float image, scanline order, 3 floats per pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width × height × 3` values.
    pub rgb: Vec<f32>,
}

impl Image {
    /// An image from its pixels (panics if the size does not match).
    pub fn new(width: u32, height: u32, rgb: Vec<f32>) -> Image {
        assert_eq!(rgb.len(), width as usize * height as usize * 3, "image size");
        Image { width, height, rgb }
    }

    /// Reads an OpenEXR file in full 32-bit float, or an 8-bit PNG (by its
    /// `.png` extension) as sRGB decoded to linear, as ꟻLIP's own tool does
    /// for LDR images.
    pub fn read(path: &Path) -> io::Result<Image> {
        let png = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("png"));
        let (width, height, rgb) = if png { read_png(path)? } else { read_exr(path)? };
        Ok(Image { width, height, rgb })
    }

    /// Number of pixels.
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The image as the results viewer's pixel file ([`fbksd_exchange::pixels`]).
    pub fn pixels_file(&self) -> Vec<u8> {
        fbksd_exchange::pixels::encode(self.width, self.height, 3, &self.rgb)
    }
}

/// Writes a `width × height` RGB float image as a 32-bit float, scanline,
/// ZIP-compressed OpenEXR file (readable by tinyexr-based tools).
pub fn write_exr(path: &Path, width: u32, height: u32, rgb: &[f32]) -> io::Result<()> {
    use exr::prelude::*;
    assert_eq!(rgb.len(), width as usize * height as usize * 3, "image size");
    let w = width as usize;
    let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
        let i = (y * w + x) * 3;
        (rgb[i], rgb[i + 1], rgb[i + 2])
    });
    Image::from_encoded_channels((w, height as usize), Encoding::SMALL_LOSSLESS, channels)
        .write()
        .to_file(path)
        .map_err(|e| io::Error::other(format!("{}: {e}", path.display())))
}

/// The sRGB transfer function of a linear value, clamped to [0, 1]; NaN
/// becomes 0.
pub fn srgb(linear: f32) -> f32 {
    let v = if linear.is_nan() { 0.0 } else { linear.clamp(0.0, 1.0) };
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Writes an 8-bit sRGB PNG preview of a linear RGB float image
/// (`exposure` in stops is applied first).
pub fn write_png_preview(path: &Path, width: u32, height: u32, rgb: &[f32], exposure: f32) -> io::Result<()> {
    let scale = 2f32.powf(exposure);
    let bytes: Vec<u8> = rgb.iter().map(|v| (srgb(v * scale) * 255.0 + 0.5) as u8).collect();
    image::RgbImage::from_raw(width, height, bytes)
        .ok_or_else(|| io::Error::other("image size mismatch"))?
        .save(path)
        .map_err(|e| io::Error::other(format!("{}: {e}", path.display())))
}

/// Reads the first RGB(A) layer of an OpenEXR file as 32-bit floats
/// (whatever the file's sample type): `(width, height, rgb)`.
pub fn read_exr(path: &Path) -> io::Result<(u32, u32, Vec<f32>)> {
    use exr::prelude::*;
    let image = read_first_rgba_layer_from_file(
        path,
        |size: Vec2<usize>, _: &RgbaChannels| (size.0, vec![0f32; size.0 * size.1 * 3]),
        |(w, pixels): &mut (usize, Vec<f32>), Vec2(x, y): Vec2<usize>, (r, g, b, _a): (f32, f32, f32, f32)| {
            let i = (y * *w + x) * 3;
            pixels[i..i + 3].copy_from_slice(&[r, g, b]);
        },
    )
    .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, format!("{}: {e}", path.display())))?;
    let size = image.layer_data.size;
    Ok((size.0 as u32, size.1 as u32, image.layer_data.channel_data.pixels.1))
}

/// Reads a PNG as 8-bit sRGB, decoded to linear RGB (alpha dropped).
pub fn read_png(path: &Path) -> io::Result<(u32, u32, Vec<f32>)> {
    let image = ::image::open(path)
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, format!("{}: {e}", path.display())))?
        .into_rgb8();
    let linear: [f32; 256] = std::array::from_fn(|b| {
        let c = b as f32 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    });
    let (width, height) = image.dimensions();
    Ok((width, height, image.into_raw().into_iter().map(|b| linear[b as usize]).collect()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exr_round_trip_is_exact_in_f32() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.exr");
        let rgb: Vec<f32> = (0..5 * 3 * 3).map(|i| i as f32 * 0.1234567 + 1e-7).collect();
        write_exr(&path, 5, 3, &rgb).unwrap();
        let (w, h, back) = read_exr(&path).unwrap();
        assert_eq!((w, h), (5, 3));
        assert_eq!(back, rgb);
    }

    #[test]
    fn png_reads_as_linear_srgb() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        ::image::RgbImage::from_raw(2, 1, vec![0, 128, 255, 10, 20, 30]).unwrap().save(&path).unwrap();
        let image = Image::read(&path).unwrap();
        assert_eq!((image.width, image.height), (2, 1));
        assert_eq!(image.rgb[0], 0.0);
        assert!((image.rgb[1] - 0.215_861).abs() < 1e-5, "{}", image.rgb[1]);
        assert_eq!(image.rgb[2], 1.0);
    }
}
