//! Evaluating samples: drawing random parameters, running the program on
//! batches of 64, writing the layout's elements.
//!
//! Sample positions the technique does not give (no INPUT parameters) are
//! drawn by [`fbksd_renderer::sampler`], stratified per pixel and seeded
//! from (pixel, request, sample index, dimension), so a run is
//! reproducible. Free samples (count requests) are uniform over the image.

use crate::program::{Machine, Program, LANES};
use crate::scene::Scene;
use fbksd_core::layout::{Element, ElementIo};
use fbksd_core::{CompiledLayout, Feature, RandomParameter, Tile};
pub use fbksd_renderer::sampler::{PixelSeed, Sampler, Strata};
use fbksd_renderer::Evaluation;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// Where each layout element comes from, resolved once per session.
#[derive(Debug, Clone)]
pub struct Bindings {
    /// Per layout element: what to write (None: INPUT, leave alone).
    outputs: Vec<Option<Source>>,
    /// Per random parameter: the layout offset of an INPUT value.
    inputs: [Option<usize>; 7],
    /// Dimensions to draw: read by the program or written to the layout.
    needed: u8,
}

#[derive(Debug, Clone, Copy)]
enum Source {
    Parameter(usize),
    Slot(usize),
    Zero,
}

impl Bindings {
    /// Binds a (specialised) program to a layout.
    pub fn new(program: &Program, layout: &CompiledLayout) -> Bindings {
        let inputs = layout.input_offsets();
        let outputs = layout
            .elements()
            .iter()
            .map(|(element, io)| match element {
                Element::Parameter(_) if *io == ElementIo::Input => None,
                Element::Parameter(p) => Some(Source::Parameter(p.index())),
                Element::Feature(f, n) => Some(program.feature_slot(*f, *n).map_or(Source::Zero, Source::Slot)),
            })
            .collect();
        let mut needed = 0u8;
        for p in RandomParameter::ALL {
            let output = layout.parameter_offset(*p).is_some() && !layout.is_input(*p);
            if (program.uses(*p) || output) && inputs[p.index()].is_none() {
                needed |= 1 << p.index();
            }
        }
        Bindings { outputs, inputs, needed }
    }
}

/// Non-finite values seen in one request.
#[derive(Default)]
pub struct NonFinite {
    count: AtomicU64,
    first: Mutex<Option<String>>,
}

impl NonFinite {
    fn record(&self, what: impl FnOnce() -> String) {
        if self.count.fetch_add(1, Ordering::Relaxed) == 0 {
            *self.first.lock().unwrap() = Some(what());
        }
    }
    /// `(count, description of the first)`.
    pub fn report(&self) -> Option<(u64, String)> {
        let n = self.count.load(Ordering::Relaxed);
        (n > 0).then(|| (n, self.first.lock().unwrap().clone().unwrap_or_default()))
    }
}

/// Where a sample lies: pixel `(x, y)` sample `s` of `spp`, or free sample `index`.
#[derive(Clone, Copy)]
enum Position {
    Pixel { x: u32, y: u32, s: u64, spp: u64 },
    Free { index: u64 },
}

/// Fills `samples` (each `layout.sample_size()` floats) at `positions`.
#[allow(clippy::too_many_arguments)]
fn fill(
    machine: &mut Machine<'_>,
    scene: &Scene,
    bindings: &Bindings,
    layout: &CompiledLayout,
    sampler: &Sampler,
    samples: &mut [f32],
    positions: &mut dyn Iterator<Item = Position>,
    problems: &NonFinite,
) -> Result<(), String> {
    let size = layout.sample_size();
    let count = samples.len() / size;
    let (strata, pixel) = (&mut Strata::new(1), &mut None::<PixelSeed>);
    let mut params = [[0.0f64; 7]; LANES];
    let mut where_ = [Position::Free { index: 0 }; LANES];
    for batch_start in (0..count).step_by(LANES) {
        let n = (count - batch_start).min(LANES);
        for lane in 0..n {
            let pos = positions.next().expect("a position per sample");
            where_[lane] = pos;
            let mut p = match pos {
                Position::Pixel { x, y, s, spp } => {
                    if strata.spp() != spp.max(1) {
                        *strata = Strata::new(spp);
                    }
                    if pixel.as_ref().is_none_or(|px: &PixelSeed| (px.x, px.y) != (x, y)) {
                        *pixel = Some(sampler.pixel(x, y));
                    }
                    sampler.pixel_sample(pixel.as_ref().unwrap(), strata, s, bindings.needed)
                }
                Position::Free { index } => sampler.free_sample(index),
            };
            let sample = &samples[(batch_start + lane) * size..][..size];
            for (d, input) in bindings.inputs.iter().enumerate() {
                if let Some(i) = input {
                    p[d] = sample[*i] as f64;
                }
            }
            params[lane] = p;
        }
        machine.run_samples(&params[..n]).map_err(|e| scene.runtime_error(e.pos, &e.message))?;
        for (i, source) in bindings.outputs.iter().enumerate() {
            let Some(source) = source else { continue };
            for lane in 0..n {
                let v = match source {
                    Source::Parameter(d) => params[lane][*d],
                    Source::Slot(s) => machine.slot(*s)[lane],
                    Source::Zero => 0.0,
                };
                let v32 = v as f32;
                if !v32.is_finite() {
                    problems.record(|| describe(where_[lane], layout, i, v));
                }
                samples[(batch_start + lane) * size + i] = v32;
            }
        }
    }
    Ok(())
}

fn describe(pos: Position, layout: &CompiledLayout, element: usize, v: f64) -> String {
    let what = layout.elements()[element].0;
    match pos {
        Position::Pixel { x, y, s, .. } => format!("{what} = {v} at pixel ({x}, {y}) sample {s}"),
        Position::Free { index } => format!("{what} = {v} at free sample {index}"),
    }
}

/// Renders one request of the protocol.
pub fn evaluate(scene: &Scene, program: &Program, eval: &Evaluation) -> Result<(), String> {
    use rayon::prelude::*;
    let layout = eval.layout();
    let bindings = Bindings::new(program, layout);
    let sampler = Sampler::new(scene.width, scene.height, eval.request);
    let problems = NonFinite::default();
    eval.plan_with_free_starts().par_iter().try_for_each_init(
        || Machine::new(program),
        |machine, &(tile, first)| -> Result<(), String> {
            let mut pipe = eval.pipe(tile).map_err(|e| e.to_string())?;
            let mut positions: Box<dyn Iterator<Item = Position>> = match tile {
                Tile::Pixels { rect, spp } => Box::new((rect.y0..rect.y1).flat_map(move |y| {
                    (rect.x0..rect.x1)
                        .flat_map(move |x| (0..spp as u64).map(move |s| Position::Pixel { x, y, s, spp: spp as u64 }))
                })),
                Tile::Samples { count } => Box::new((first..first + count).map(|index| Position::Free { index })),
            };
            fill(machine, scene, &bindings, layout, &sampler, pipe.raw(), &mut positions, &problems)?;
            pipe.finish().map_err(|e| e.to_string())
        },
    )?;
    if let Some((n, first)) = problems.report() {
        // Delivered as computed (a renderer must not hide a scene's NaN), and said loudly.
        eprintln!("{}: warning: {n} NaN or infinite values in request {}; first: {first}", scene.name, eval.request);
    }
    Ok(())
}

/// Renders the box-filtered colour image at `spp` samples per pixel on the
/// current rayon pool, accumulating in f64 (references, benchmarks).
pub fn render_image(scene: &Scene, spp: u64, request: u64) -> Result<Vec<f32>, String> {
    render_features(scene, spp, request, &[(Feature::ColorR, 0), (Feature::ColorG, 0), (Feature::ColorB, 0)])
}

/// Renders the per-pixel box-filtered mean of each `wanted` feature at
/// `spp` samples per pixel (`wanted.len()` values per pixel, 0 for a
/// feature the scene never assigns).
pub fn render_features(scene: &Scene, spp: u64, request: u64, wanted: &[(Feature, u8)]) -> Result<Vec<f32>, String> {
    use rayon::prelude::*;
    let program = scene.program.specialise(wanted);
    let slots: Vec<Option<usize>> = wanted.iter().map(|(f, n)| program.feature_slot(*f, *n)).collect();
    let sampler = Sampler::new(scene.width, scene.height, request);
    let needed = RandomParameter::ALL.iter().filter(|p| program.uses(**p)).fold(0u8, |m, p| m | 1 << p.index());
    let (w, h) = (scene.width as usize, scene.height as usize);
    let channels = wanted.len();
    let mut image = vec![0f32; w * h * channels];
    image.par_chunks_mut(w * channels).enumerate().try_for_each_init(
        || Machine::new(&program),
        |machine, (y, row)| -> Result<(), String> {
            let mut sums = vec![0f64; w * channels];
            let mut params = [[0.0f64; 7]; LANES];
            let strata = Strata::new(spp);
            let mut pixel = sampler.pixel(0, y as u32);
            let (mut x, mut s) = (0u32, 0u64);
            let mut columns = [0usize; LANES];
            let total = w as u64 * spp;
            let mut index = 0u64;
            while index < total {
                let n = ((total - index) as usize).min(LANES);
                let mut filled = 0;
                while filled < n {
                    if s == spp {
                        s = 0;
                        x += 1;
                        pixel = sampler.pixel(x, y as u32);
                    }
                    let m = (n - filled).min((spp - s) as usize);
                    sampler.pixel_samples(&pixel, &strata, s, needed, &mut params[filled..filled + m]);
                    columns[filled..filled + m].fill(x as usize * channels);
                    s += m as u64;
                    filled += m;
                }
                machine.run_samples(&params[..n]).map_err(|e| scene.runtime_error(e.pos, &e.message))?;
                for (c, slot) in slots.iter().enumerate() {
                    let Some(slot) = slot else { continue };
                    let lanes = machine.slot(*slot);
                    for (lane, v) in lanes.iter().enumerate().take(n) {
                        sums[columns[lane] + c] += v;
                    }
                }
                index += n as u64;
            }
            for (o, s) in row.iter_mut().zip(&sums) {
                *o = (s / spp as f64) as f32;
            }
            Ok(())
        },
    )?;
    Ok(image)
}

/// Bumped whenever sample positions change, so cached references are rebuilt.
pub const SAMPLER_VERSION: u32 = 3;
