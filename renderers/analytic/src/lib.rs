//! A deterministic analytic renderer: every layout element is a closed-form
//! function of the sample's random parameters, so tests can check each
//! delivered sample exactly, and the transport benchmark has a renderer
//! that costs nothing but writing memory.
//!
//! Scene file (JSON):
//! `{"width": 64, "height": 48, "pattern": "analytic", "tile_size": 16}`;
//! `pattern` is `analytic` (default: see [`features`]) or `constant` (every
//! sample is the same, for the transport benchmark).
//!
//! Random parameters the renderer draws itself are stratified per pixel and
//! seeded from (pixel, sample index, dimension) — see [`draw`] — so any run
//! is reproducible. Test faults: `--fault crash-at-spp=N` aborts when a
//! request asks N spp, `--fault short` delivers one tile too few,
//! `--fault hang` never delivers, `--fault exit-at-start` exits with code 3,
//! `--fault hang-layout` never answers a layout, `--fault duplicate` sends
//! the first tile twice and never the second.
#![deny(missing_docs)]

use fbksd_core::layout::{Element, ElementIo};
use fbksd_core::{CompiledLayout, Feature, RandomParameter, SceneInfo, Tile};
use fbksd_renderer::{Evaluation, RenderingServer};
use serde::Deserialize;
use std::path::Path;

/// The analytic scene.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `analytic` or `constant`.
    #[serde(default = "default_pattern")]
    pub pattern: Pattern,
    /// Tile side in pixels.
    #[serde(default = "default_tile")]
    pub tile_size: u32,
}

/// What the samples hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Pattern {
    /// Every element a closed-form function of the random parameters.
    Analytic,
    /// Every sample identical (transport benchmark).
    Constant,
}

fn default_pattern() -> Pattern {
    Pattern::Analytic
}
fn default_tile() -> u32 {
    16
}

impl Scene {
    /// Reads a scene file.
    pub fn load(path: &Path) -> Result<Scene, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let scene: Scene = serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
        if scene.width == 0 || scene.height == 0 {
            return Err(format!("{}: width and height must be positive", path.display()));
        }
        Ok(scene)
    }

    /// The scene info this renderer reports.
    pub fn info(&self) -> SceneInfo {
        let mut info = SceneInfo::new();
        info.set("width", self.width)
            .set("height", self.height)
            .set("has_motion_blur", true)
            .set("has_dof", true)
            .set("shutter_open", 0.0)
            .set("shutter_close", 1.0)
            .set("renderer", "analytic");
        info
    }
}

/// Deliberate failures, for tests of the manager.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// Abort the process when a request asks this many spp.
    CrashAtSpp(u64),
    /// Deliver one tile fewer than asked.
    Short,
    /// Never deliver anything.
    Hang,
    /// Exit with code 3 before connecting.
    ExitAtStart,
    /// Never answer a layout.
    HangLayout,
    /// Deliver the first tile twice instead of the second.
    Duplicate,
    /// Take this many milliseconds before rendering each request (a slow
    /// renderer, for the tests of what a technique does while it waits).
    SlowMs(u64),
}

impl Fault {
    /// Parses `crash-at-spp=N`, `slow-ms=N`, `short`, `hang`, `exit-at-start`,
    /// `hang-layout` or `duplicate`.
    pub fn parse(s: &str) -> Result<Fault, String> {
        match s {
            "short" => Ok(Fault::Short),
            "hang" => Ok(Fault::Hang),
            "exit-at-start" => Ok(Fault::ExitAtStart),
            "hang-layout" => Ok(Fault::HangLayout),
            "duplicate" => Ok(Fault::Duplicate),
            _ => s
                .strip_prefix("crash-at-spp=")
                .and_then(|n| n.parse().ok())
                .map(Fault::CrashAtSpp)
                .or_else(|| s.strip_prefix("slow-ms=").and_then(|n| n.parse().ok()).map(Fault::SlowMs))
                .ok_or_else(|| {
                    format!(
                        "unknown fault {s:?} (crash-at-spp=N, slow-ms=N, short, hang, exit-at-start, hang-layout, duplicate)"
                    )
                }),
        }
    }
}

/// SplitMix64: a good 64-bit mix, enough for reproducible test randomness.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A uniform number in [0, 1) from (stream, sample, dimension).
pub fn uniform(stream: u64, sample: u64, dimension: u64) -> f32 {
    let h = mix(mix(mix(stream) ^ sample) ^ dimension);
    (h >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

/// The renderer's own value of random parameter `p` for sample `s` of pixel
/// `(x, y)` (IMAGE_X stratified in spp strata, the rest uniform).
/// For free samples pass `pixel = None` and the request's sample index.
pub fn draw(
    p: RandomParameter,
    width: u32,
    height: u32,
    pixel: Option<(u32, u32)>,
    s: u64,
    spp: u64,
    request: u64,
) -> f32 {
    let dim = p.index() as u64;
    match pixel {
        Some((x, y)) => {
            let stream = (y as u64 * width as u64 + x as u64) << 8 | (request & 0xff);
            let u = uniform(stream, s, dim);
            match p {
                // Stratified along x, uniform along y: unbiased for any spp.
                RandomParameter::ImageX => x as f32 + ((s as f32 + u) / spp.max(1) as f32).min(0.999_999_9),
                RandomParameter::ImageY => y as f32 + u.min(0.999_999_9),
                _ => u,
            }
        }
        None => {
            let u = uniform(u64::MAX - request, s, dim);
            match p {
                RandomParameter::ImageX => (u * width as f32).min(width as f32 - 1e-3),
                RandomParameter::ImageY => (u * height as f32).min(height as f32 - 1e-3),
                _ => u,
            }
        }
    }
}

/// The value of every feature for a sample with random parameters
/// `params` (indexed by [`RandomParameter::index`]):
///
/// - COLOR = ((⌊IMAGE_X⌋ + ½)/width, (⌊IMAGE_Y⌋ + ½)/height, TIME): the red
///   and green channels are constant per pixel, so a box filter recovers them
///   exactly; blue is noisy with mean ½.
/// - DIRECT_LIGHT = COLOR / 2; DEPTH = 1 + LENS_U.
/// - WORLD[n] = (IMAGE_X, IMAGE_Y, TIME) + n; NORMAL[n] = (LENS_V, LIGHT_X,
///   LIGHT_Y) + 10n; TEXTURE_COLOR[n] = COLOR · (n + 1).
/// - each `_NS` feature = its number-0 feature + 100.
/// - DIFFUSE_COLOR = COLOR · roughness threshold.
pub fn features(f: Feature, number: u8, params: &[f32; 7], width: u32, height: u32, threshold: f32) -> f32 {
    use Feature::*;
    let [ix, iy, lu, lv, t, lx, ly] = *params;
    let color = [(ix.floor() + 0.5) / width as f32, (iy.floor() + 0.5) / height as f32, t];
    let n = number as f32;
    match f {
        ColorR | ColorG | ColorB => color[f as usize - ColorR as usize],
        DirectLightR | DirectLightG | DirectLightB => color[f as usize - DirectLightR as usize] / 2.0,
        Depth => 1.0 + lu,
        WorldX => ix + n,
        WorldY => iy + n,
        WorldZ => t + n,
        NormalX => lv + 10.0 * n,
        NormalY => lx + 10.0 * n,
        NormalZ => ly + 10.0 * n,
        TextureColorR | TextureColorG | TextureColorB => color[f as usize - TextureColorR as usize] * (n + 1.0),
        WorldXNs => ix + 100.0,
        WorldYNs => iy + 100.0,
        WorldZNs => t + 100.0,
        NormalXNs => lv + 100.0,
        NormalYNs => lx + 100.0,
        NormalZNs => ly + 100.0,
        TextureColorRNs | TextureColorGNs | TextureColorBNs => color[f as usize - TextureColorRNs as usize] + 100.0,
        DiffuseColorR | DiffuseColorG | DiffuseColorB => color[f as usize - DiffuseColorR as usize] * threshold,
    }
}

/// Fills one sample: random parameters (the technique's for INPUT ones),
/// then every feature of the layout.
fn fill_sample(
    raw: &mut [f32],
    layout: &CompiledLayout,
    scene: &Scene,
    pixel: Option<(u32, u32)>,
    s: u64,
    spp: u64,
    request: u64,
) {
    let mut params = [0f32; 7];
    for p in RandomParameter::ALL {
        params[p.index()] = match layout.parameter_offset(*p) {
            Some(i) if layout.is_input(*p) => raw[i],
            _ => draw(*p, scene.width, scene.height, pixel, s, spp, request),
        };
    }
    for (i, (element, io)) in layout.elements().iter().enumerate() {
        raw[i] = match element {
            Element::Parameter(p) if *io == ElementIo::Input => continue,
            Element::Parameter(p) => params[p.index()],
            Element::Feature(f, n) => {
                features(*f, *n, &params, scene.width, scene.height, layout.roughness_threshold())
            }
        };
    }
}

/// Renders one request.
pub fn evaluate(
    scene: &Scene,
    fault: Option<Fault>,
    eval: &Evaluation,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    use rayon::prelude::*;
    match fault {
        Some(Fault::CrashAtSpp(n)) if n == eval.spp => std::process::abort(),
        Some(Fault::Hang) => loop {
            std::thread::sleep(std::time::Duration::from_secs(3600));
        },
        Some(Fault::SlowMs(ms)) => std::thread::sleep(std::time::Duration::from_millis(ms)),
        _ => {}
    }
    let mut plan = eval.plan();
    if fault == Some(Fault::Short) {
        plan.pop();
    }
    if fault == Some(Fault::Duplicate) && plan.len() > 1 {
        plan[1] = plan[0];
    }
    let layout = eval.layout();
    let size = layout.sample_size();
    // The constant pattern: one template sample copied everywhere.
    let template: Vec<f32> = (0..size).map(|i| i as f32 * 0.25).collect();
    let free_offsets = {
        let mut acc = 0u64;
        plan.iter()
            .map(|t| {
                let start = acc;
                if let Tile::Samples { count } = t {
                    acc += count;
                }
                start
            })
            .collect::<Vec<_>>()
    };
    plan.par_iter().zip(free_offsets).try_for_each(|(tile, first)| {
        let mut pipe = eval.pipe(*tile)?;
        if scene.pattern == Pattern::Constant {
            for chunk in pipe.raw().chunks_exact_mut(size) {
                chunk.copy_from_slice(&template);
            }
            return pipe.finish();
        }
        match *tile {
            Tile::Pixels { rect, spp } => {
                for y in rect.y0..rect.y1 {
                    for x in rect.x0..rect.x1 {
                        for s in 0..spp {
                            let mut buffer = pipe.pixel_sample(x, y, s);
                            fill_sample(buffer.raw(), layout, scene, Some((x, y)), s as u64, spp as u64, eval.request);
                        }
                    }
                }
            }
            Tile::Samples { count } => {
                for i in 0..count {
                    let mut buffer = pipe.sample(i);
                    fill_sample(buffer.raw(), layout, scene, None, first + i, 0, eval.request);
                }
            }
        }
        pipe.finish()
    })?;
    Ok(())
}

/// Serves `scene` to the manager until it finishes.
pub fn serve(scene: Scene, fault: Option<Fault>) -> Result<(), fbksd_renderer::RendererError> {
    let info = scene.info();
    let tile = scene.tile_size;
    RenderingServer::new()
        .on_get_tile_size(move || tile)
        .on_get_scene_info(move || info.clone())
        .on_set_parameters(move |_| {
            while fault == Some(Fault::HangLayout) {
                std::thread::sleep(std::time::Duration::from_secs(3600));
            }
            Ok(())
        })
        .on_evaluate_samples(move |eval| evaluate(&scene, fault, eval))
        .run()
}
