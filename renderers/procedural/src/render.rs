//! Evaluating samples: drawing random parameters, running the program on
//! batches of 64, writing the layout's elements.
//!
//! Sample positions the technique does not give (no INPUT parameters) are
//! drawn here, stratified per pixel and seeded from (pixel, request, sample
//! index, dimension), so a run is reproducible: the pairs IMAGE_X/IMAGE_Y,
//! LENS_U/LENS_V and LIGHT_X/LIGHT_Y are multi-jittered on a ⌈√spp⌉² grid
//! (uniform in 2-D for any spp; for square spp one sample per cell and per
//! 1-D interval), TIME in `spp` strata; each pair goes through its own
//! per-pixel permutation so dimensions are not correlated. Free samples (count requests) are
//! uniform over the image.

use crate::program::{Machine, Program, LANES};
use crate::scene::Scene;
use fbksd_core::layout::{Element, ElementIo};
use fbksd_core::{CompiledLayout, Feature, RandomParameter, Tile};
use fbksd_renderer::Evaluation;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// SplitMix64 finaliser.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

const TWO_TO_MINUS_32: f64 = 1.0 / 4_294_967_296.0;

fn uniform(h: u64) -> f64 {
    // Through i64: a signed conversion is one instruction, an unsigned one several.
    (h >> 11) as i64 as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Exact division of integers below 2³² by a fixed divisor, as a multiply
/// by a precomputed 64-bit reciprocal `⌈2⁶⁴ / d⌉` (for 32-bit operands the
/// high half of the product is the exact quotient). Wider operands fall back
/// to hardware division.
#[derive(Debug, Clone, Copy)]
struct Divisor {
    d: u64,
    reciprocal: u64,
}

impl Divisor {
    fn new(d: u64) -> Self {
        let d = d.max(1);
        Divisor { d, reciprocal: if d == 1 { 0 } else { u64::MAX / d + 1 } }
    }

    /// `(n / d, n % d)`.
    #[inline(always)]
    fn div_mod(&self, n: u64) -> (u64, u64) {
        if self.d == 1 {
            return (n, 0);
        }
        if n >> 32 == 0 {
            let q = ((self.reciprocal as u128 * n as u128) >> 64) as u64;
            return (q, n - q * self.d);
        }
        // Only above 2²⁶ spp: exact, if slow.
        (n / self.d, n % self.d)
    }
}

/// Small primes for the per-dimension permutations `s ↦ (a·s + b) mod n`.
const PRIMES: [u64; 12] = [7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47];

/// A multiplier coprime with `n`, different per dimension.
fn coprime(n: u64, dimension: usize) -> u64 {
    (0..PRIMES.len()).map(|k| PRIMES[(dimension * 3 + k) % PRIMES.len()]).find(|p| n % p != 0).unwrap_or(1)
}

/// Draws the random parameters of samples.
#[derive(Debug, Clone, Copy)]
pub struct Sampler {
    width: u32,
    height: u32,
    request: u64,
}

/// What the sampler derives once per (request, spp): the stratification
/// grid side and the permutation multipliers.
#[derive(Debug, Clone, Copy)]
pub struct Strata {
    spp: u64,
    inv_spp: f64,
    by_spp: Divisor,
    k: u64,
    inv_k: f64,
    by_k: Divisor,
    by_cells: Divisor,
    cells: u64,
    /// Multipliers of the affine permutations: of `0..spp` (time), of the
    /// k² cells (pairs), of `0..k` (sub-positions in a cell).
    a_time: u64,
    a_cell: u64,
    a_sub: u64,
}

impl Strata {
    /// Strata for `spp` samples per pixel.
    pub fn new(spp: u64) -> Self {
        let spp = spp.max(1);
        let k = (spp as f64).sqrt().ceil().max(1.0) as u64;
        Strata {
            spp,
            inv_spp: 1.0 / spp as f64,
            by_spp: Divisor::new(spp),
            k,
            inv_k: 1.0 / k as f64,
            by_k: Divisor::new(k),
            by_cells: Divisor::new(k * k),
            cells: k * k,
            a_time: coprime(spp, 3),
            a_cell: coprime(k * k, 1),
            a_sub: coprime(k, 2),
        }
    }
}

/// What the sampler derives once per pixel.
#[derive(Debug, Clone, Copy)]
pub struct PixelSeed {
    x: u32,
    y: u32,
    seed: u64,
    /// Random offsets of the time permutation and of the three pairs' cell permutations.
    time_offset: u64,
    cell_offsets: [u64; 3],
    /// Per pair and axis, the random offset of the sub-position shuffles.
    line_offsets: [[u64; 2]; 3],
}

impl Sampler {
    /// A sampler for one request of a session.
    pub fn new(width: u32, height: u32, request: u64) -> Self {
        Sampler { width, height, request }
    }

    /// The per-pixel state of pixel `(x, y)`.
    #[inline]
    pub fn pixel(&self, x: u32, y: u32, strata: &Strata) -> PixelSeed {
        let index = (y as u64) * self.width as u64 + x as u64;
        let seed = mix(index ^ mix(self.request.wrapping_add(0x5EED)));
        let offset = |d: u64, n: u64| mix(seed ^ d) % n;
        PixelSeed {
            x,
            y,
            seed,
            time_offset: offset(3, strata.spp),
            cell_offsets: [offset(4, strata.cells), offset(5, strata.cells), offset(6, strata.cells)],
            // Reduced mod k: the shuffles' operands then stay below 2³² (fast division).
            line_offsets: std::array::from_fn(|p| {
                std::array::from_fn(|axis| mix(seed ^ ((p as u64 * 2 + axis as u64 + 7) << 40)) % strata.k)
            }),
        }
    }

    /// The parameters in `needed` (bit `d` = dimension `d`) of sample `s`
    /// of a pixel; the others are left 0.
    ///
    /// Each pair (IMAGE, LENS, LIGHT) is multi-jittered: sample `s` takes
    /// cell `(a·s + b) mod k²` of a k × k grid (all cells once when spp = k²;
    /// otherwise an evenly spread random subset, each cell equally likely),
    /// and inside its cell the sub-column and sub-row come from random
    /// permutations per column and per row, so the 2-D distribution is
    /// uniform and, for square spp, each 1-D projection has one sample in
    /// each of k² intervals. TIME has one sample in each of spp intervals.
    #[inline(always)]
    pub fn pixel_sample(&self, pixel: &PixelSeed, strata: &Strata, s: u64, needed: u8) -> [f64; 7] {
        let u = |d: u64| uniform(mix(pixel.seed ^ (s << 4 | d)));
        let inv_k = strata.inv_k;
        let below_one = |v: f64| v.min(1.0 - f64::EPSILON);
        let pair = |which: usize, d: u64| {
            let cell = strata.by_cells.div_mod(strata.a_cell * s + pixel.cell_offsets[which]).1;
            let (row, column) = strata.by_k.div_mod(cell);
            // Sub-column of the sample in its cell: a permutation of the rows
            // of its column, shifted by a random per-pixel, per-column offset
            // (an odd stride per line), so it is uniform over pixels; likewise
            // the sub-row.
            let shuffle = |axis: usize, line: u64, position: u64| {
                let offset = pixel.line_offsets[which][axis] + line * 0x9E37;
                strata.by_k.div_mod(strata.a_sub * position + offset).1
            };
            let sub_x = shuffle(0, column, row) as i64 as f64;
            let sub_y = shuffle(1, row, column) as i64 as f64;
            // One hash gives both jitters (32 bits each).
            let h = mix(pixel.seed ^ (s << 4 | d));
            let (ux, uy) =
                ((h >> 32) as i64 as f64 * TWO_TO_MINUS_32, (h & 0xFFFF_FFFF) as i64 as f64 * TWO_TO_MINUS_32);
            let (c, r) = (column as i64 as f64, row as i64 as f64);
            (below_one((c + (sub_x + ux) * inv_k) * inv_k), below_one((r + (sub_y + uy) * inv_k) * inv_k))
        };
        let mut p = [0.0; 7];
        let has = |d: usize| needed & (1 << d) != 0;
        if has(0) || has(1) {
            let (x, y) = pair(0, 0);
            p[0] = pixel.x as f64 + x;
            p[1] = pixel.y as f64 + y;
        }
        if has(2) || has(3) {
            (p[2], p[3]) = pair(1, 2);
        }
        if has(4) {
            let stratum = strata.by_spp.div_mod(strata.a_time * s + pixel.time_offset).1;
            p[4] = below_one((stratum as i64 as f64 + u(4)) * strata.inv_spp);
        }
        if has(5) || has(6) {
            (p[5], p[6]) = pair(2, 5);
        }
        p
    }

    /// All seven parameters of free sample `index` of the request.
    pub fn free_sample(&self, index: u64) -> [f64; 7] {
        let seed = mix(u64::MAX - self.request);
        let u = |d: u64| uniform(mix(seed ^ (index << 4 | d)));
        let mut p = [0.0; 7];
        for (d, v) in p.iter_mut().enumerate() {
            *v = u(d as u64);
        }
        p[0] = (p[0] * self.width as f64).min(self.width as f64 - 1e-9);
        p[1] = (p[1] * self.height as f64).min(self.height as f64 - 1e-9);
        p
    }
}

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
        let mut inputs = [None; 7];
        let outputs = layout
            .elements()
            .iter()
            .enumerate()
            .map(|(i, (element, io))| match element {
                Element::Parameter(p) if *io == ElementIo::Input => {
                    inputs[p.index()] = Some(i);
                    None
                }
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
                    if strata.spp != spp.max(1) {
                        *strata = Strata::new(spp);
                    }
                    if pixel.as_ref().is_none_or(|px: &PixelSeed| (px.x, px.y) != (x, y)) {
                        *pixel = Some(sampler.pixel(x, y, strata));
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
    let plan = eval.plan();
    let mut free_start = 0u64;
    let starts: Vec<u64> = plan
        .iter()
        .map(|t| {
            let start = free_start;
            if let Tile::Samples { count } = t {
                free_start += count;
            }
            start
        })
        .collect();
    plan.par_iter().zip(starts).try_for_each_init(
        || Machine::new(program),
        |machine, (tile, first)| -> Result<(), String> {
            let mut pipe = eval.pipe(*tile).map_err(|e| e.to_string())?;
            let mut positions: Box<dyn Iterator<Item = Position>> = match *tile {
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
    use rayon::prelude::*;
    let wanted = [(Feature::ColorR, 0), (Feature::ColorG, 0), (Feature::ColorB, 0)];
    let program = scene.program.specialise(&wanted);
    let slots: Vec<Option<usize>> = wanted.iter().map(|(f, n)| program.feature_slot(*f, *n)).collect();
    let sampler = Sampler::new(scene.width, scene.height, request);
    let needed = RandomParameter::ALL.iter().filter(|p| program.uses(**p)).fold(0u8, |m, p| m | 1 << p.index());
    let (w, h) = (scene.width as usize, scene.height as usize);
    let mut image = vec![0f32; w * h * 3];
    image.par_chunks_mut(w * 3).enumerate().try_for_each_init(
        || Machine::new(&program),
        |machine, (y, row)| -> Result<(), String> {
            let mut sums = vec![0f64; w * 3];
            let mut params = [[0.0f64; 7]; LANES];
            let strata = Strata::new(spp);
            let mut pixel = sampler.pixel(0, y as u32, &strata);
            let (mut x, mut s) = (0u32, 0u64);
            let mut columns = [0usize; LANES];
            let total = w as u64 * spp;
            let mut index = 0u64;
            while index < total {
                let n = ((total - index) as usize).min(LANES);
                for (p, column) in params.iter_mut().zip(columns.iter_mut()).take(n) {
                    if s == spp {
                        s = 0;
                        x += 1;
                        pixel = sampler.pixel(x, y as u32, &strata);
                    }
                    *p = sampler.pixel_sample(&pixel, &strata, s, needed);
                    *column = x as usize * 3;
                    s += 1;
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
pub const SAMPLER_VERSION: u32 = 2;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_division_is_exact_including_wide_operands() {
        for d in [1u64, 2, 3, 7, 8, 63, 64, 65, 1000, 65536, 4_000_000_007] {
            let by = Divisor::new(d);
            let mut n = 0x9E37_79B9u64;
            for _ in 0..2000 {
                n = mix(n);
                for v in [n & 0xFFFF, n & 0xFFFF_FFFF, n >> 8, d - 1, d, d + 1, u32::MAX as u64] {
                    assert_eq!(by.div_mod(v), (v / d, v % d), "{v} / {d}");
                }
            }
        }
    }
}
