//! Sample positions for renderers: the first seven dimensions of a sample
//! (the random parameters), stratified per pixel, and further dimensions
//! (a path's bounces) hashed from the same seed.
//!
//! Every value is a pure function of (image size, request, pixel, sample
//! index, spp, dimension), so any sample can be replayed. The pairs
//! IMAGE_X/IMAGE_Y, LENS_U/LENS_V and LIGHT_X/LIGHT_Y are multi-jittered on a
//! ⌈√spp⌉² grid (uniform in 2-D for any spp; for square spp one sample per
//! cell and per 1-D interval), TIME in `spp` strata; each pair goes through
//! its own per-pixel permutation so dimensions are not correlated. Free
//! samples (count requests) are uniform over the image.

/// SplitMix64 finaliser.
pub fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

const TWO_TO_MINUS_32: f64 = 1.0 / 4_294_967_296.0;

/// A uniform value in [0, 1) from a hash (53 bits).
pub fn uniform(h: u64) -> f64 {
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
    /// The samples per pixel these strata are for.
    pub fn spp(&self) -> u64 {
        self.spp
    }

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
    /// The pixel.
    pub x: u32,
    /// The pixel's row.
    pub y: u32,
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

/// Dimensions past the seven random parameters, for one sample: `get(d)`
/// is uniform in [0, 1) and depends only on the sample and `d`.
#[derive(Debug, Clone, Copy)]
pub struct Dimensions {
    seed: u64,
}

impl Dimensions {
    /// The extra dimensions of sample `s` of a pixel.
    #[inline]
    pub fn of_pixel_sample(pixel: &PixelSeed, s: u64) -> Self {
        Dimensions { seed: mix(pixel.seed ^ mix(s ^ 0xD1B5_4A32_D192_ED03)) }
    }

    /// The extra dimensions of free sample `index` of a request.
    #[inline]
    pub fn of_free_sample(sampler: &Sampler, index: u64) -> Self {
        Dimensions { seed: mix(mix(u64::MAX - sampler.request) ^ mix(index ^ 0x8CB9_2BA7_2F3D_8DD7)) }
    }

    /// Dimension `d` (any number; the caller numbers its own).
    #[inline(always)]
    pub fn get(&self, d: u32) -> f32 {
        let h = mix(self.seed.wrapping_add((d as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)));
        // 24 bits: exactly representable, strictly below 1.
        (h >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }
}

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
