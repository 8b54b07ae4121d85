//! Helpers for scene-level tests: scenes written as pbrt text into a
//! temporary directory, and samples evaluated in-process exactly as the
//! protocol path evaluates them.
#![allow(dead_code)]

use fbksd_core::{CompiledLayout, SampleLayout};
use fbksd_embree::render::{fill, Bindings, Place, Repairs};
use fbksd_embree::scene::Scene;
use fbksd_renderer::sampler::Sampler;
use std::path::PathBuf;

/// A scene from pbrt text (plus extra files), loaded.
pub fn scene(text: &str, files: &[(&str, &[u8])]) -> Result<Scene, String> {
    let dir = tempfile::tempdir().unwrap();
    for (name, data) in files {
        std::fs::write(dir.path().join(name), data).unwrap();
    }
    let path = dir.path().join("scene.pbrt");
    std::fs::write(&path, text).unwrap();
    fbksd_embree::pbrt::load(&path).map_err(|e| e.to_string())
}

/// A scene from pbrt text, loaded, with the warnings of its load as text.
pub fn scene_with_warnings(text: &str) -> Result<(Scene, Vec<String>), String> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.pbrt");
    std::fs::write(&path, text).unwrap();
    let (scene, warnings) = fbksd_embree::pbrt::load_with_warnings(&path).map_err(|e| e.to_string())?;
    Ok((scene, warnings.iter().map(|w| w.to_string()).collect()))
}

/// The file name the error messages use for [`scene`]'s main file.
pub fn main_file() -> PathBuf {
    PathBuf::from("scene.pbrt")
}

/// A scene header: a camera at the origin looking down +z, `w × h`, and `maxdepth`.
pub fn header(w: u32, h: u32, fov: f32, max_depth: u32) -> String {
    format!(
        "LookAt 0 0 0  0 0 1  0 1 0\nCamera \"perspective\" \"float fov\" [{fov}]\nFilm \"rgb\" \"integer xresolution\" [{w}] \"integer yresolution\" [{h}]\nIntegrator \"path\" \"integer maxdepth\" [{max_depth}]\nWorldBegin\n"
    )
}

/// A layout from element names.
pub fn layout(names: &[&str]) -> CompiledLayout {
    let mut l = SampleLayout::new();
    for n in names {
        l = l.with(n);
    }
    l.compile().unwrap()
}

/// All samples of request `request` at `spp` per pixel, pixel by pixel.
pub fn samples(scene: &Scene, layout: &CompiledLayout, spp: u64, request: u64) -> (Vec<f32>, u64) {
    let (w, h) = (scene.width(), scene.height());
    let mut out = vec![0f32; (w * h) as usize * spp as usize * layout.sample_size()];
    let places =
        (0..h).flat_map(move |y| (0..w).flat_map(move |x| (0..spp).map(move |s| Place::Pixel { x, y, s, spp })));
    let repairs = Repairs::default();
    fill(scene, &Bindings::new(layout), layout, &Sampler::new(w, h, request), &mut out, places, &repairs);
    (out, repairs.count())
}

/// Rays traced to evaluate every sample of request 0 at `spp`.
pub fn rays(scene: &Scene, layout: &CompiledLayout, spp: u64) -> u64 {
    let (w, h) = (scene.width(), scene.height());
    let mut out = vec![0f32; (w * h) as usize * spp as usize * layout.sample_size()];
    let places =
        (0..h).flat_map(move |y| (0..w).flat_map(move |x| (0..spp).map(move |s| Place::Pixel { x, y, s, spp })));
    fill(scene, &Bindings::new(layout), layout, &Sampler::new(w, h, 0), &mut out, places, &Repairs::default())
}

/// Pixel means of element `e` (offset in the layout).
pub fn pixel_means(scene: &Scene, data: &[f32], layout: &CompiledLayout, spp: u64, e: usize) -> Vec<f64> {
    let size = layout.sample_size();
    let n = (scene.width() * scene.height()) as usize;
    (0..n)
        .map(|p| (0..spp as usize).map(|s| data[(p * spp as usize + s) * size + e] as f64).sum::<f64>() / spp as f64)
        .collect()
}
