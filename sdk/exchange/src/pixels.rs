//! The viewer's pixel files (`.fbpx`): an image's exact 32-bit float
//! values, made small for the wire. Browsers cannot read OpenEXR, and a
//! tone-mapped PNG would lose what the viewer's exposure control and pixel
//! inspector need, so the runner and `fbksd results page` write one of
//! these beside each result image and reference.
//!
//! A file is the gzip of:
//!
//! ```text
//! "FBPX"  u32 version (1)  u32 width  u32 height  u32 channels     (little-endian)
//! byte plane 0, byte plane 1, byte plane 2, byte plane 3
//! ```
//!
//! The floats are taken channel by channel (all R, then all G, then all B),
//! rows top to bottom, and byte plane `k` holds byte `k` of every float's
//! little-endian bits. Splitting the bytes puts the slowly varying sign and
//! exponent bytes together, which deflate then shrinks well; the browser
//! undoes it with `DecompressionStream("gzip")` and no library.

use std::io::{Read, Write};

/// The magic bytes that open a decompressed pixel file.
pub const MAGIC: &[u8; 4] = b"FBPX";
/// The format's version.
pub const VERSION: u32 = 1;
/// Extension of pixel files.
pub const EXTENSION: &str = "fbpx";
const HEADER_BYTES: usize = 20;

/// The name under which a runner uploads, with a job's files, the pixel
/// file of reference `sha256:<hex>` (`references/<hex>.fbpx`) or of a
/// feature buffer made with it (`buffer`, one of
/// [`crate::scenes::FEATURE_BUFFERS`]: `references/<hex>.<buffer>.fbpx`),
/// when the server lacks it; the server keeps it under the same name.
pub fn uploaded_reference_name(reference_hash: &str, buffer: Option<&str>) -> Option<String> {
    let hex = reference_hash.strip_prefix("sha256:")?;
    if hex.len() != 64 || !hex.chars().all(|c| c.is_ascii_hexdigit()) {
        return None;
    }
    match buffer {
        None => Some(format!("references/{hex}.{EXTENSION}")),
        Some(b) if crate::scenes::FEATURE_BUFFERS.contains(&b) => Some(format!("references/{hex}.{b}.{EXTENSION}")),
        Some(_) => None,
    }
}

/// Pixel files larger than this are refused when read (64 Mpixel RGB).
const MAX_FLOATS: usize = 3 << 26;

/// Encodes interleaved pixels (`channels` floats per pixel, rows top to
/// bottom) as a pixel file.
pub fn encode(width: u32, height: u32, channels: u32, interleaved: &[f32]) -> Vec<u8> {
    let n = width as usize * height as usize * channels as usize;
    assert_eq!(interleaved.len(), n, "pixel count does not match {width}×{height}×{channels}");
    let pixels = width as usize * height as usize;
    let c = channels as usize;
    let mut raw = Vec::with_capacity(HEADER_BYTES + 4 * n);
    raw.extend_from_slice(MAGIC);
    for v in [VERSION, width, height, channels] {
        raw.extend_from_slice(&v.to_le_bytes());
    }
    // Plane (byte, channel) at `(byte · c + channel) · pixels`, each filled
    // in its own pass: a strided read and a shift per byte, where one pass
    // scattering every byte cost a division per value.
    raw.resize(HEADER_BYTES + 4 * n, 0);
    if pixels > 0 {
        for (k, plane) in raw[HEADER_BYTES..].chunks_exact_mut(pixels).enumerate() {
            let (shift, channel) = (8 * (k / c), k % c);
            for (b, pixel) in plane.iter_mut().zip(interleaved.chunks_exact(c)) {
                *b = (pixel[channel].to_bits() >> shift) as u8;
            }
        }
    }
    // The fastest level: the low mantissa bytes of rendered images are
    // noise that no level compresses, and level 6 took four times as long
    // for files 2 % smaller (`fbksd bench metrics`).
    let mut gz = flate2::write::GzEncoder::new(Vec::with_capacity(n), flate2::Compression::fast());
    gz.write_all(&raw).expect("writing to memory");
    gz.finish().expect("writing to memory")
}

/// A decoded pixel file.
#[derive(Debug, Clone, PartialEq)]
pub struct Pixels {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Floats per pixel.
    pub channels: u32,
    /// Interleaved values, rows top to bottom.
    pub values: Vec<f32>,
}

/// Decodes a pixel file; the error says what is wrong with it.
pub fn decode(file: &[u8]) -> Result<Pixels, String> {
    let mut raw = Vec::new();
    flate2::read::GzDecoder::new(file)
        .take((HEADER_BYTES + 4 * MAX_FLOATS) as u64 + 1)
        .read_to_end(&mut raw)
        .map_err(|e| format!("not a gzip stream: {e}"))?;
    if raw.len() < HEADER_BYTES || &raw[..4] != MAGIC {
        return Err("not an FBKSD pixel file (no FBPX header)".into());
    }
    let word = |i: usize| u32::from_le_bytes(raw[4 + 4 * i..8 + 4 * i].try_into().unwrap());
    let (version, width, height, channels) = (word(0), word(1), word(2), word(3));
    if version != VERSION {
        return Err(format!("pixel file version {version}; this program reads version {VERSION}"));
    }
    let n = (width as usize).saturating_mul(height as usize).saturating_mul(channels as usize);
    if n > MAX_FLOATS || raw.len() != HEADER_BYTES + 4 * n {
        return Err(format!("{width}×{height}×{channels} pixels do not match the file's {} bytes", raw.len()));
    }
    let planes = &raw[HEADER_BYTES..];
    let (pixels, c) = (width as usize * height as usize, channels as usize);
    let mut values = vec![0f32; n];
    for (p, value) in values.iter_mut().enumerate() {
        // Planar index of interleaved value p.
        let planar = (p % c) * pixels + p / c;
        let bytes = [planes[planar], planes[n + planar], planes[2 * n + planar], planes[3 * n + planar]];
        *value = f32::from_bits(u32::from_le_bytes(bytes));
    }
    Ok(Pixels { width, height, channels, values })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_buffer_is_stored_beside_its_reference_and_only_known_names_are() {
        let hash = format!("sha256:{}", "ab".repeat(32));
        let hex = "ab".repeat(32);
        assert_eq!(uploaded_reference_name(&hash, None), Some(format!("references/{hex}.fbpx")));
        assert_eq!(uploaded_reference_name(&hash, Some("albedo")), Some(format!("references/{hex}.albedo.fbpx")));
        // A name from a request never becomes a path of its own.
        assert_eq!(uploaded_reference_name(&hash, Some("../../etc")), None);
        assert_eq!(uploaded_reference_name("sha256:12", Some("depth")), None);
    }

    #[test]
    fn pixels_survive_the_round_trip_bit_for_bit() {
        let values: Vec<f32> = (0..4 * 3 * 3).map(|i| (i as f32 * 0.37).sin() * 1e3_f32.powi(i % 3) - 1.0).collect();
        let mut values = values;
        values[5] = f32::MIN_POSITIVE / 4.0; // a subnormal
        values[7] = -0.0;
        let file = encode(4, 3, 3, &values);
        let back = decode(&file).unwrap();
        assert_eq!((back.width, back.height, back.channels), (4, 3, 3));
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back.values), bits(&values));
        // The layout the viewer reads: byte `b` of channel `c` of pixel `p`
        // at `(b · 3 + c) · 12 + p` after the header.
        let mut raw = Vec::new();
        flate2::read::GzDecoder::new(&file[..]).read_to_end(&mut raw).unwrap();
        for (i, v) in values.iter().enumerate() {
            let (p, c) = (i / 3, i % 3);
            for (b, byte) in v.to_le_bytes().into_iter().enumerate() {
                assert_eq!(raw[HEADER_BYTES + (b * 3 + c) * 12 + p], byte, "byte {b} of value {i}");
            }
        }
    }

    #[test]
    fn a_smooth_image_compresses_well_below_its_float_size() {
        let (w, h) = (256u32, 256u32);
        let values: Vec<f32> =
            (0..w * h * 3).map(|i| ((i / 3) % w) as f32 / w as f32 + ((i / 3) / w) as f32 / h as f32).collect();
        let file = encode(w, h, 3, &values);
        assert!(file.len() < values.len() * 4 / 2, "{} bytes", file.len());
    }

    #[test]
    fn damaged_files_are_refused_with_a_reason() {
        assert!(decode(b"not gzip").unwrap_err().contains("gzip"));
        let mut file = encode(2, 2, 3, &[1.0; 12]);
        let raw = {
            let mut raw = Vec::new();
            flate2::read::GzDecoder::new(&file[..]).read_to_end(&mut raw).unwrap();
            raw
        };
        let mut short = raw.clone();
        short.truncate(raw.len() - 4);
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        gz.write_all(&short).unwrap();
        file = gz.finish().unwrap();
        assert!(decode(&file).unwrap_err().contains("do not match"));
    }
}
