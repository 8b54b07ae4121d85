//! Evaluating samples for the protocol: drawing the random parameters the
//! technique did not give, tracing paths, writing the layout's elements;
//! and in-process rendering for references and benchmarks.

use crate::integrator::{Batch, Position, SampleValues, Wanted};
use crate::scene::Scene;
use fbksd_core::layout::{Element, ElementIo};
use fbksd_core::{CompiledLayout, Feature, Tile};
use fbksd_renderer::sampler::{Dimensions, PixelSeed, Sampler, Strata};
use fbksd_renderer::Evaluation;
use std::sync::atomic::{AtomicU64, Ordering};

/// Where each layout element comes from, resolved once per session.
#[derive(Debug, Clone)]
pub struct Bindings {
    /// Per layout element: what to write (None: an INPUT parameter, left alone).
    outputs: Vec<Option<Source>>,
    /// Per random parameter: the layout offset of an INPUT value.
    inputs: [Option<usize>; 7],
    /// What the integrator must compute.
    pub wanted: Wanted,
}

#[derive(Debug, Clone, Copy)]
enum Source {
    Parameter(usize),
    Feature(Feature, u8),
}

impl Bindings {
    /// Binds a layout.
    pub fn new(layout: &CompiledLayout) -> Bindings {
        use Feature::*;
        let inputs = layout.input_offsets();
        let mut wanted = Wanted { roughness_threshold: layout.roughness_threshold(), ..Wanted::default() };
        let outputs = layout
            .elements()
            .iter()
            .map(|(element, io)| match element {
                Element::Parameter(_) if *io == ElementIo::Input => None,
                Element::Parameter(p) => Some(Source::Parameter(p.index())),
                Element::Feature(f, n) => {
                    match f {
                        ColorR | ColorG | ColorB => wanted.radiance = true,
                        DirectLightR | DirectLightG | DirectLightB => wanted.direct = true,
                        DiffuseColorR | DiffuseColorG | DiffuseColorB => {
                            wanted.radiance = true;
                            wanted.diffuse = true;
                        }
                        _ => wanted.geometry = true,
                    }
                    Some(Source::Feature(*f, *n))
                }
            })
            .collect();
        Bindings { outputs, inputs, wanted }
    }
}

fn feature(v: &SampleValues, f: Feature, n: u8) -> f32 {
    use Feature::*;
    let h = &v.hits[(n as usize).min(1)];
    let ns = &v.non_specular;
    match f {
        ColorR => v.color.x,
        ColorG => v.color.y,
        ColorB => v.color.z,
        DirectLightR => v.direct.x,
        DirectLightG => v.direct.y,
        DirectLightB => v.direct.z,
        Depth => v.depth,
        WorldX => h.world.x,
        WorldY => h.world.y,
        WorldZ => h.world.z,
        NormalX => h.normal.x,
        NormalY => h.normal.y,
        NormalZ => h.normal.z,
        TextureColorR => h.albedo.x,
        TextureColorG => h.albedo.y,
        TextureColorB => h.albedo.z,
        WorldXNs => ns.world.x,
        WorldYNs => ns.world.y,
        WorldZNs => ns.world.z,
        NormalXNs => ns.normal.x,
        NormalYNs => ns.normal.y,
        NormalZNs => ns.normal.z,
        TextureColorRNs => ns.albedo.x,
        TextureColorGNs => ns.albedo.y,
        TextureColorBNs => ns.albedo.z,
        DiffuseColorR => v.diffuse.x,
        DiffuseColorG => v.diffuse.y,
        DiffuseColorB => v.diffuse.z,
    }
}

/// A sample's place: pixel `(x, y)` sample `s` of `spp`, or free sample `index`.
#[derive(Debug, Clone, Copy)]
pub enum Place {
    /// A pixel sample.
    Pixel {
        /// Column.
        x: u32,
        /// Row.
        y: u32,
        /// Sample index in the pixel.
        s: u64,
        /// Samples per pixel of the request.
        spp: u64,
    },
    /// A sample anywhere on the image (count requests).
    Free {
        /// Index within the request.
        index: u64,
    },
}

/// Draws positions for a run of places, caching per-pixel state.
struct Drawer<'a> {
    sampler: &'a Sampler,
    /// Parameters to draw: those the scene uses or the layout outputs.
    /// Each parameter's value does not depend on which others are drawn.
    needed: u8,
    strata: Strata,
    pixel: Option<PixelSeed>,
}

impl Drawer<'_> {
    fn draw(&mut self, place: Place) -> ([f64; 7], Dimensions) {
        match place {
            Place::Pixel { x, y, s, spp } => {
                if self.strata.spp() != spp.max(1) {
                    self.strata = Strata::new(spp);
                    self.pixel = None;
                }
                if self.pixel.as_ref().is_none_or(|p| (p.x, p.y) != (x, y)) {
                    self.pixel = Some(self.sampler.pixel(x, y));
                }
                let pixel = self.pixel.as_ref().expect("set above");
                (self.sampler.pixel_sample(pixel, &self.strata, s, self.needed), Dimensions::of_pixel_sample(pixel, s))
            }
            Place::Free { index } => (self.sampler.free_sample(index), Dimensions::of_free_sample(self.sampler, index)),
        }
    }
}

/// Counts non-finite values replaced in one request (renderer bugs, reported loudly).
#[derive(Default)]
pub struct Repairs(AtomicU64);

impl Repairs {
    /// How many.
    pub fn count(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

fn position(p: &[f64; 7]) -> Position {
    Position {
        image_x: p[0] as f32,
        image_y: p[1] as f32,
        lens: [p[2] as f32, p[3] as f32],
        time: p[4] as f32,
        light: [p[5] as f32, p[6] as f32],
    }
}

/// Paths traced together: enough that the later bounces, after Russian
/// roulette, still hand Embree streams worth batching.
const BATCH: usize = 256;

/// Fills `samples` (each `layout.sample_size()` floats) at `places`; returns rays traced.
pub fn fill(
    scene: &Scene,
    bindings: &Bindings,
    layout: &CompiledLayout,
    sampler: &Sampler,
    samples: &mut [f32],
    places: impl Iterator<Item = Place>,
    repairs: &Repairs,
) -> u64 {
    let size = layout.sample_size();
    let outputs = layout.elements().iter().fold(0u8, |mask, (e, io)| match e {
        Element::Parameter(p) if *io == ElementIo::Output => mask | 1 << p.index(),
        _ => mask,
    });
    let mut drawer = Drawer { sampler, needed: scene.used_parameters() | outputs, strata: Strata::new(1), pixel: None };
    let mut rays = 0u64;
    let mut batch = Batch::default();
    let mut places = places.into_iter();
    let mut drawn: Vec<([f64; 7], Dimensions)> = Vec::with_capacity(BATCH);
    for chunk in samples.chunks_mut(size * BATCH) {
        drawn.clear();
        for (sample, place) in chunk.chunks_exact(size).zip(&mut places) {
            let (mut p, dims) = drawer.draw(place);
            for (d, input) in bindings.inputs.iter().enumerate() {
                if let Some(i) = input {
                    p[d] = sample[*i] as f64;
                }
            }
            drawn.push((p, dims));
        }
        let traced = batch.trace(scene, drawn.iter().map(|(p, dims)| (position(p), *dims)), &bindings.wanted);
        for ((sample, (p, _)), values) in chunk.chunks_exact_mut(size).zip(&drawn).zip(traced) {
            rays += values.rays as u64;
            if values.repaired {
                repairs.0.fetch_add(1, Ordering::Relaxed);
            }
            for (slot, source) in sample.iter_mut().zip(&bindings.outputs) {
                match source {
                    None => {}
                    Some(Source::Parameter(d)) => *slot = p[*d] as f32,
                    Some(Source::Feature(f, n)) => *slot = feature(values, *f, *n),
                }
            }
        }
    }
    rays
}

/// Renders one request of the protocol on all cores.
pub fn evaluate(scene: &Scene, eval: &Evaluation) -> Result<(), String> {
    use rayon::prelude::*;
    let layout = eval.layout();
    let bindings = Bindings::new(layout);
    let sampler = Sampler::new(scene.width(), scene.height(), eval.request);
    let repairs = Repairs::default();
    eval.plan_with_free_starts().par_iter().try_for_each(|&(tile, first)| -> Result<(), String> {
        let mut pipe = eval.pipe(tile).map_err(|e| e.to_string())?;
        match tile {
            Tile::Pixels { rect, spp } => {
                let spp = spp as u64;
                let places = (rect.y0..rect.y1).flat_map(move |y| {
                    (rect.x0..rect.x1).flat_map(move |x| (0..spp).map(move |s| Place::Pixel { x, y, s, spp }))
                });
                fill(scene, &bindings, layout, &sampler, pipe.raw(), places, &repairs);
            }
            Tile::Samples { count } => {
                let places = (first..first + count).map(|index| Place::Free { index });
                fill(scene, &bindings, layout, &sampler, pipe.raw(), places, &repairs);
            }
        }
        pipe.finish().map_err(|e| e.to_string())
    })?;
    if repairs.count() > 0 {
        eprintln!(
            "{}: warning: {} samples had non-finite values replaced by 0 in request {} (a renderer bug)",
            scene.name,
            repairs.count(),
            eval.request
        );
    }
    Ok(())
}

/// A rendered image and what it cost.
#[derive(Debug, Clone)]
pub struct Rendered {
    /// Box-filtered RGB, row-major.
    pub rgb: Vec<f32>,
    /// Rays traced.
    pub rays: u64,
    /// Samples whose values had to be repaired.
    pub repairs: u64,
    /// Whether every sample value was finite before any repair.
    pub all_finite: bool,
}

/// Renders the per-pixel box-filtered mean of three geometric features
/// (first hit, as the protocol gives them) at `spp` stratified samples per
/// pixel: the feature buffers made with a reference.
pub fn render_features(scene: &Scene, spp: u64, request: u64, wanted: [(Feature, u8); 3]) -> Vec<f32> {
    let geometry = Wanted { geometry: true, ..Wanted::default() };
    pixel_means(scene, spp, request, &geometry, |v| wanted.map(|(f, n)| feature(v, f, n))).rgb
}

/// Renders the box-filtered colour image at `spp` stratified samples per
/// pixel on the current rayon pool, accumulating in f64.
pub fn render_image(scene: &Scene, spp: u64, request: u64) -> Rendered {
    let radiance = Wanted { radiance: true, ..Wanted::default() };
    pixel_means(scene, spp, request, &radiance, |v| [v.color.x, v.color.y, v.color.z])
}

/// The per-pixel mean of three values of each sample, traced for `wanted`.
fn pixel_means(
    scene: &Scene,
    spp: u64,
    request: u64,
    wanted: &Wanted,
    values: impl Fn(&SampleValues) -> [f32; 3] + Sync,
) -> Rendered {
    use rayon::prelude::*;
    let (w, h) = (scene.width() as usize, scene.height() as usize);
    let sampler = Sampler::new(scene.width(), scene.height(), request);
    let needed = scene.used_parameters();
    let repairs = Repairs::default();
    let rays = AtomicU64::new(0);
    let mut rgb = vec![0f32; w * h * 3];
    rgb.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        let strata = Strata::new(spp);
        let mut batch = Batch::default();
        let mut drawn = [[0f64; 7]; BATCH];
        // The paths of a batch, and the column of each (a batch spans pixels when spp is low).
        let mut starts: Vec<(Position, Dimensions)> = Vec::with_capacity(BATCH);
        let mut columns: Vec<usize> = Vec::with_capacity(BATCH);
        let mut sums = vec![[0f64; 3]; w];
        let mut row_rays = 0u64;
        let mut flush = |starts: &mut Vec<(Position, Dimensions)>, columns: &mut Vec<usize>| {
            for (&x, v) in columns.iter().zip(batch.trace(scene, starts.drain(..), wanted)) {
                row_rays += v.rays as u64;
                if v.repaired {
                    repairs.0.fetch_add(1, Ordering::Relaxed);
                }
                for (total, value) in sums[x].iter_mut().zip(values(v)) {
                    *total += value as f64;
                }
            }
            columns.clear();
        };
        for x in 0..w {
            let pixel = sampler.pixel(x as u32, y as u32);
            let mut s0 = 0;
            while s0 < spp {
                let n = (spp - s0).min((BATCH - starts.len()) as u64) as usize;
                sampler.pixel_samples(&pixel, &strata, s0, needed, &mut drawn[..n]);
                for (k, p) in drawn[..n].iter().enumerate() {
                    starts.push((position(p), Dimensions::of_pixel_sample(&pixel, s0 + k as u64)));
                    columns.push(x);
                }
                s0 += n as u64;
                if starts.len() == BATCH {
                    flush(&mut starts, &mut columns);
                }
            }
        }
        flush(&mut starts, &mut columns);
        for (x, sum) in sums.iter().enumerate() {
            for c in 0..3 {
                row[x * 3 + c] = (sum[c] / spp as f64) as f32;
            }
        }
        rays.fetch_add(row_rays, Ordering::Relaxed);
    });
    let repairs = repairs.count();
    Rendered { rgb, rays: rays.into_inner(), repairs, all_finite: repairs == 0 }
}
