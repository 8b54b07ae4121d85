//! The results directory: images, per-run logs and a machine-readable index.
//!
//! ```text
//! <results>/index.json                              every run, one entry each
//! <results>/<technique>/<scene>/<spp>_0.exr         result image (32-bit float, scanline)
//! <results>/<technique>/<scene>/<spp>_0_log.json    the run's RunRecord
//! <results>/<technique>/<scene>/<spp>_0_technique.log   the technique's stdout and stderr
//! <results>/renderer-logs/<scene>.log               the renderer's stdout and stderr
//! ```
//!
//! File names follow the original FBKSD (`<spp>_0.exr`, `<spp>_0_log.json`).
//! The index is rewritten atomically after every run, so an interrupted
//! benchmark keeps every finished run.

use crate::record::{RunRecord, RunStatus};
use serde::{Deserialize, Serialize};
use std::io;
use std::path::{Path, PathBuf};

/// Name of the index file.
pub const INDEX_FILE: &str = "index.json";
/// Format tag of the index.
pub const INDEX_FORMAT: &str = "fbksd-results";
/// Version of the index format.
pub const INDEX_VERSION: u32 = 1;

/// One run in the index.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IndexEntry {
    /// Technique name.
    pub technique: String,
    /// Scene name.
    pub scene: String,
    /// Budget in samples per pixel.
    pub spp: u64,
    /// Typed status.
    pub status: RunStatus,
    /// Why (empty for ok).
    pub message: String,
    /// The run's log, relative to the results directory.
    pub log: String,
    /// The result image, relative to the results directory.
    pub image: Option<String>,
    /// Technique time in ms.
    pub technique_ms: f64,
    /// Render time in ms.
    pub render_ms: f64,
    /// Samples used.
    pub used_samples: u64,
}

/// The index file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResultsIndex {
    /// Always [`INDEX_FORMAT`].
    pub format: String,
    /// Always [`INDEX_VERSION`].
    pub version: u32,
    /// Runs, sorted by technique, scene and spp.
    pub runs: Vec<IndexEntry>,
}

impl Default for ResultsIndex {
    fn default() -> Self {
        ResultsIndex {
            format: INDEX_FORMAT.into(),
            version: INDEX_VERSION,
            runs: Vec::new(),
        }
    }
}

/// A results directory.
#[derive(Debug, Clone)]
pub struct ResultsDir {
    root: PathBuf,
}

impl ResultsDir {
    /// Opens (creating if needed) a results directory.
    pub fn create(root: &Path) -> io::Result<Self> {
        std::fs::create_dir_all(root)?;
        Ok(ResultsDir {
            root: root.to_path_buf(),
        })
    }

    /// The directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The directory of one technique on one scene (created).
    pub fn run_dir(&self, technique: &str, scene: &str) -> io::Result<PathBuf> {
        let dir = self.root.join(technique).join(scene);
        std::fs::create_dir_all(&dir)?;
        Ok(dir)
    }

    /// Path of a renderer's log for a scene.
    pub fn renderer_log(&self, scene: &str) -> io::Result<PathBuf> {
        let dir = self.root.join("renderer-logs");
        std::fs::create_dir_all(&dir)?;
        Ok(dir.join(format!("{scene}.log")))
    }

    /// Reads the index (an empty one when there is none yet).
    pub fn read_index(&self) -> io::Result<ResultsIndex> {
        let path = self.root.join(INDEX_FILE);
        match std::fs::read(&path) {
            Ok(bytes) => serde_json::from_slice(&bytes).map_err(|e| {
                io::Error::new(
                    io::ErrorKind::InvalidData,
                    format!("{}: {e}", path.display()),
                )
            }),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(ResultsIndex::default()),
            Err(e) => Err(e),
        }
    }

    /// Adds (or replaces) a run in the index.
    pub fn record(
        &self,
        record: &RunRecord,
        log_path: &Path,
        image_path: Option<&Path>,
    ) -> io::Result<()> {
        let rel = |p: &Path| {
            p.strip_prefix(&self.root)
                .unwrap_or(p)
                .to_string_lossy()
                .into_owned()
        };
        let entry = IndexEntry {
            technique: record.technique.clone(),
            scene: record.scene.clone(),
            spp: record.spp_budget,
            status: record.status,
            message: record.message.clone(),
            log: rel(log_path),
            image: image_path.map(rel),
            technique_ms: record.times.technique_ms,
            render_ms: record.times.render_ms,
            used_samples: record.used_samples,
        };
        let mut index = self.read_index()?;
        index.runs.retain(|r| {
            (&r.technique, &r.scene, r.spp) != (&entry.technique, &entry.scene, entry.spp)
        });
        index.runs.push(entry);
        index
            .runs
            .sort_by(|a, b| (&a.technique, &a.scene, a.spp).cmp(&(&b.technique, &b.scene, b.spp)));
        write_json_atomically(&self.root.join(INDEX_FILE), &index)
    }
}

/// Writes JSON to a temporary file and renames it into place.
pub fn write_json_atomically<T: Serialize>(path: &Path, value: &T) -> io::Result<()> {
    let tmp = path.with_extension("json.tmp");
    std::fs::write(
        &tmp,
        serde_json::to_vec_pretty(value).map_err(io::Error::other)?,
    )?;
    std::fs::rename(tmp, path)
}

/// Turns a name into a safe single path component (letters, digits, `-_.`).
pub fn path_safe_name(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    match s.trim_start_matches('.') {
        "" => "unnamed".into(),
        t => t.to_string(),
    }
}

/// Writes a `width × height` RGB float image as a 32-bit float, scanline,
/// ZIP-compressed OpenEXR file (readable by tinyexr-based tools).
pub fn write_exr(path: &Path, width: u32, height: u32, rgb: &[f32]) -> io::Result<()> {
    use exr::prelude::*;
    assert_eq!(
        rgb.len(),
        width as usize * height as usize * 3,
        "image size"
    );
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
    let v = if linear.is_nan() {
        0.0
    } else {
        linear.clamp(0.0, 1.0)
    };
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Writes an 8-bit sRGB PNG preview of a linear RGB float image
/// (`exposure` in stops is applied first).
pub fn write_png_preview(
    path: &Path,
    width: u32,
    height: u32,
    rgb: &[f32],
    exposure: f32,
) -> io::Result<()> {
    let scale = 2f32.powf(exposure);
    let bytes: Vec<u8> = rgb
        .iter()
        .map(|v| (srgb(v * scale) * 255.0 + 0.5) as u8)
        .collect();
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
        |(w, pixels): &mut (usize, Vec<f32>),
         Vec2(x, y): Vec2<usize>,
         (r, g, b, _a): (f32, f32, f32, f32)| {
            let i = (y * *w + x) * 3;
            pixels[i..i + 3].copy_from_slice(&[r, g, b]);
        },
    )
    .map_err(|e| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("{}: {e}", path.display()),
        )
    })?;
    let size = image.layer_data.size;
    Ok((
        size.0 as u32,
        size.1 as u32,
        image.layer_data.channel_data.pixels.1,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exr_round_trip_is_exact_in_f32() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.exr");
        let rgb: Vec<f32> = (0..5 * 3 * 3)
            .map(|i| i as f32 * 0.1234567 + 1e-7)
            .collect();
        write_exr(&path, 5, 3, &rgb).unwrap();
        let (w, h, back) = read_exr(&path).unwrap();
        assert_eq!((w, h), (5, 3));
        assert_eq!(back, rgb);
    }

    #[test]
    fn names_become_path_components() {
        assert_eq!(path_safe_name("box filter/v2"), "box_filter_v2");
        assert_eq!(path_safe_name(".."), "unnamed");
        assert_eq!(path_safe_name("ok-1.2_x"), "ok-1.2_x");
    }
}
