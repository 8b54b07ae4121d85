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
#[inline]
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

/// A keyed pseudo-random permutation of `0..n`: `i ↦ permute(i, n, key)`
/// is a bijection of `0..n` for every key, and different keys give
/// unrelated permutations.
///
/// Three rounds of steps each invertible on the smallest power-of-two range
/// holding `n` (xor and add of a round key, multiplication by an odd
/// number, xor with a right shift), each round keyed by its own hash of the
/// key (also in the multiplier, so keys do not merely relabel one
/// permutation); repeated until the value falls below `n` (cycle walking:
/// the orbit of `i` returns below `n`, in under two passes on average).
#[inline]
pub fn permute(i: u64, n: u64, key: u64) -> u64 {
    Permutation::new(n, key).apply(i)
}

/// [`permute`] for one `(n, key)`, its round keys hashed once.
#[derive(Debug, Clone, Copy, Default)]
struct Permutation {
    n: u64,
    mask: u64,
    shifts: (u32, u32),
    /// Per round: the key xor-ed in, the odd multiplier, the key added.
    rounds: [(u64, u64, u64); 3],
}

impl Permutation {
    #[inline(always)]
    fn new(n: u64, key: u64) -> Permutation {
        if n <= 1 {
            return Permutation { n, ..Default::default() };
        }
        let bits = 64 - (n - 1).leading_zeros();
        let keys = [mix(key), mix(key ^ 0x5851_F42D_4C95_7F2D), mix(key ^ 0x1405_7B7E_F767_814F)];
        Permutation {
            n,
            mask: u64::MAX >> (64 - bits),
            shifts: ((bits / 2).max(1), (bits / 3).max(1)),
            rounds: keys.map(|k| (k, (k >> 21) | 1, k >> 43)),
        }
    }

    /// [`Permutation::apply`] to each value of `values` in place. Below 2³²
    /// values (every budget under 2³² spp) the rounds run in 32-bit lanes:
    /// the same values, since every step keeps only the low `bits` bits;
    /// lanes that fall outside `0..n` take further rounds together.
    #[inline(always)]
    fn apply_all(&self, values: &mut [u64]) {
        const LANES: usize = 64;
        if self.n <= 1 {
            values.fill(0);
            return;
        }
        if self.mask > u32::MAX as u64 || values.len() > LANES {
            values.iter_mut().for_each(|v| *v = self.apply(*v));
            return;
        }
        let (n, rounds) = (self.n, self.rounds_u32());
        let round = |v: u32| self.rounds_in_u32(v, &rounds);
        let mut lanes = [0u32; LANES];
        let lanes = &mut lanes[..values.len()];
        for (l, v) in lanes.iter_mut().zip(values.iter()) {
            *l = round((*v & self.mask) as u32);
        }
        // Checked before each further round: for a power-of-two `n` (most
        // budgets) no lane is ever outside.
        while lanes.iter().fold(false, |any, &l| any | (l as u64 >= n)) {
            for l in lanes.iter_mut() {
                let next = round(*l);
                *l = if *l as u64 >= n { next } else { *l };
            }
        }
        for (v, l) in values.iter_mut().zip(lanes.iter()) {
            *v = *l as u64;
        }
    }

    /// The round keys in 32 bits, for [`Permutation::rounds_in_u32`].
    #[inline(always)]
    fn rounds_u32(&self) -> [(u32, u32, u32); 3] {
        self.rounds.map(|(x, m, a)| (x as u32, m as u32, a as u32))
    }

    /// One pass of the three rounds of [`Permutation::apply`] in 32 bits,
    /// for a mask below 2³² (the same values: every step keeps only the
    /// low `bits` bits).
    #[inline(always)]
    fn rounds_in_u32(&self, mut v: u32, rounds: &[(u32, u32, u32); 3]) -> u32 {
        let (mask, (s1, s2)) = (self.mask as u32, self.shifts);
        for &(xor, multiply, add) in rounds {
            v = (v ^ xor) & mask;
            v = v.wrapping_mul(multiply) & mask;
            v ^= v >> s1;
            v = v.wrapping_add(add) & mask;
            v = v.wrapping_mul(0x6935_FA69_0929_EB3F_u64 as u32) & mask;
            v ^= v >> s2;
        }
        v
    }

    #[inline(always)]
    fn apply(&self, i: u64) -> u64 {
        if self.n <= 1 {
            return 0;
        }
        let (mask, (s1, s2)) = (self.mask, self.shifts);
        let mut v = i & mask;
        loop {
            for (xor, multiply, add) in self.rounds {
                v = (v ^ xor) & mask;
                v = v.wrapping_mul(multiply) & mask;
                v ^= v >> s1;
                v = v.wrapping_add(add) & mask;
                v = v.wrapping_mul(0x6935_FA69_0929_EB3F) & mask;
                v ^= v >> s2;
            }
            if v < self.n {
                return v;
            }
        }
    }
}

/// Up to this many lines (k ≤ 16, up to 256 spp) a pixel's line
/// permutations are made once per pixel, as tables of bytes.
const FEW_LINES: usize = 16;

/// Every line's permutation of `0..k`, [`permute`]`(position, k, key ^
/// mix(line))`, into `table[line · k + position]`, for k ≤ [`FEW_LINES`].
/// A line's positions run their rounds together in one vector of 32-bit
/// lanes (as in [`Permutation::apply_all`]); the lines are independent, so
/// the processor overlaps them.
#[inline(always)]
fn line_permutations(strata: &Strata, key: u64, table: &mut [u8]) {
    let k = strata.k as usize;
    debug_assert!(k <= FEW_LINES && table.len() == k * k);
    if k <= 1 {
        table.fill(0);
        return;
    }
    let n = strata.k as u32;
    for (line, out) in table.chunks_exact_mut(k).enumerate() {
        let permutation = Permutation::new(strata.k, key ^ strata.line_hashes[line]);
        let keys = permutation.rounds_u32();
        let rounds = |values: &[u32; FEW_LINES], out: &mut [u32; FEW_LINES]| {
            for (o, v) in out.iter_mut().zip(values) {
                *o = permutation.rounds_in_u32(*v, &keys);
            }
        };
        // Lanes past k are never read.
        let mut values = [0u32; FEW_LINES];
        rounds(&std::array::from_fn(|position| position as u32), &mut values);
        // Every lane compared, not up to the first outside one: one vector compare.
        let outside =
            |values: &[u32; FEW_LINES]| (0..FEW_LINES).fold(false, |any, i| any | ((i < k) & (values[i] >= n)));
        while outside(&values) {
            let mut next = [0u32; FEW_LINES];
            rounds(&values, &mut next);
            for (v, w) in values.iter_mut().zip(next) {
                *v = if *v >= n { w } else { *v };
            }
        }
        // Narrowed as a whole vector, then the line's k bytes copied.
        let bytes = values.map(|v| v as u8);
        out.copy_from_slice(&bytes[..k]);
    }
}

/// Draws the random parameters of samples.
#[derive(Debug, Clone, Copy)]
pub struct Sampler {
    width: u32,
    height: u32,
    request: u64,
}

/// What the sampler derives once per spp: the stratification grid side.
#[derive(Debug, Clone, Copy)]
pub struct Strata {
    spp: u64,
    inv_spp: f64,
    k: u64,
    inv_k: f64,
    by_k: Divisor,
    cells: u64,
    /// `mix(line)` of the first lines, for their permutations' keys.
    line_hashes: [u64; FEW_LINES],
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
            k,
            inv_k: 1.0 / k as f64,
            by_k: Divisor::new(k),
            cells: k * k,
            line_hashes: std::array::from_fn(|line| mix(line as u64)),
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
    /// Keys of the time permutation and of the three pairs' cell permutations.
    time_key: u64,
    cell_keys: [u64; 3],
    /// Per pair and axis, the key of the sub-position permutations.
    line_keys: [[u64; 2]; 3],
}

impl Sampler {
    /// A sampler for one request of a session.
    pub fn new(width: u32, height: u32, request: u64) -> Self {
        Sampler { width, height, request }
    }

    /// The per-pixel state of pixel `(x, y)`.
    #[inline]
    pub fn pixel(&self, x: u32, y: u32) -> PixelSeed {
        let index = (y as u64) * self.width as u64 + x as u64;
        let seed = mix(index ^ mix(self.request.wrapping_add(0x5EED)));
        let key = |d: u64| mix(seed ^ (d << 40));
        PixelSeed {
            x,
            y,
            seed,
            time_key: key(3),
            cell_keys: [key(4), key(5), key(6)],
            line_keys: std::array::from_fn(|p| std::array::from_fn(|axis| key(p as u64 * 2 + axis as u64 + 7))),
        }
    }

    /// The parameters in `needed` (bit `d` = dimension `d`) of sample `s`
    /// of a pixel; the others are left 0.
    ///
    /// Each pair (IMAGE, LENS, LIGHT) is multi-jittered: sample `s` takes
    /// cell `π(s)` of a k × k grid, π a random permutation of the k² cells
    /// (all cells once when spp = k²; otherwise a random subset), and inside
    /// its cell the sub-column and sub-row come from random permutations per
    /// column and per row, so the 2-D distribution is uniform and, for
    /// square spp, each 1-D projection has one sample in each of k²
    /// intervals. TIME has one sample in each of spp intervals. Every pair
    /// and TIME have their own independent permutations (per pixel and
    /// request), so the dimensions are independent of each other: an
    /// estimate converges to the integral over all of them, whatever the
    /// request.
    #[inline(always)]
    pub fn pixel_sample(&self, pixel: &PixelSeed, strata: &Strata, s: u64, needed: u8) -> [f64; 7] {
        let u = |d: u64| uniform(mix(pixel.seed ^ (s << 4 | d)));
        let inv_k = strata.inv_k;
        let below_one = |v: f64| v.min(1.0 - f64::EPSILON);
        let pair = |which: usize, d: u64| {
            let cell = permute(s, strata.cells, pixel.cell_keys[which]);
            let (row, column) = strata.by_k.div_mod(cell);
            // Sub-column of the sample in its cell: a random permutation of
            // the rows of its column (one per column); likewise the sub-row.
            let shuffle = |axis: usize, line: u64, position: u64| {
                permute(position, strata.k, pixel.line_keys[which][axis] ^ mix(line))
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
            let stratum = permute(s, strata.spp, pixel.time_key);
            p[4] = below_one((stratum as i64 as f64 + u(4)) * strata.inv_spp);
        }
        if has(5) || has(6) {
            (p[5], p[6]) = pair(2, 5);
        }
        p
    }

    /// Samples `s0..s0 + out.len()` of a pixel: the values of
    /// [`Sampler::pixel_sample`], computed stage by stage across up to 64
    /// samples at once. One sample is a chain of dependent permutation
    /// rounds that waits on itself; a stage's samples are independent, so
    /// the processor overlaps them.
    pub fn pixel_samples(&self, pixel: &PixelSeed, strata: &Strata, s0: u64, needed: u8, out: &mut [[f64; 7]]) {
        /// [`Sampler::pixel_samples_in`] compiled for `$features`.
        #[cfg(target_arch = "x86_64")]
        macro_rules! compiled_for {
            ($name:ident, $features:literal) => {
                /// # Safety
                /// The CPU must support the features.
                #[target_feature(enable = $features)]
                unsafe fn $name(
                    s: &Sampler,
                    p: &PixelSeed,
                    strata: &Strata,
                    s0: u64,
                    needed: u8,
                    out: &mut [[f64; 7]],
                ) {
                    s.pixel_samples_in(p, strata, s0, needed, out)
                }
            };
        }
        // The values are the same in every build: integer lanes, and IEEE
        // doubles with no fused multiply-add (Rust never fuses on its own).
        // AVX-512 first: its DQ extension multiplies 64-bit lanes and turns
        // them into doubles in one instruction each, which AVX2 emulates or
        // does lane by lane (the hashes are 64-bit multiplies).
        #[cfg(target_arch = "x86_64")]
        {
            use std::is_x86_feature_detected as has;
            compiled_for!(avx512, "avx512f,avx512dq,avx512vl");
            compiled_for!(avx2, "avx2");
            if has!("avx512f") && has!("avx512dq") && has!("avx512vl") {
                // SAFETY: the features were just detected.
                return unsafe { avx512(self, pixel, strata, s0, needed, out) };
            }
            if has!("avx2") {
                // SAFETY: the feature was just detected.
                return unsafe { avx2(self, pixel, strata, s0, needed, out) };
            }
        }
        self.pixel_samples_in(pixel, strata, s0, needed, out)
    }

    /// [`Sampler::pixel_samples`], compiled into each instruction set's build.
    #[inline(always)]
    fn pixel_samples_in(&self, pixel: &PixelSeed, strata: &Strata, s0: u64, needed: u8, out: &mut [[f64; 7]]) {
        const BATCH: usize = 64;
        let has = |d: usize| needed & (1 << d) != 0;
        let below_one = |v: f64| v.min(1.0 - f64::EPSILON);
        let inv_k = strata.inv_k;
        // The line permutations of a pixel as tables, made once when there
        // are few lines (up to 256 spp; their values fit a byte).
        let k = strata.k as usize;
        let mut tables = [[0u8; FEW_LINES * FEW_LINES]; 2];
        for (first, out) in (s0..).step_by(BATCH).zip(out.chunks_mut(BATCH)) {
            let n = out.len();
            out.iter_mut().for_each(|p| *p = [0.0; 7]);
            for (which, d) in [(0usize, 0u64), (1, 2), (2, 5)] {
                if !(has(d as usize) || has(d as usize + 1)) {
                    continue;
                }
                let cells = Permutation::new(strata.cells, pixel.cell_keys[which]);
                let (mut rows, mut columns) = ([0u64; BATCH], [0u64; BATCH]);
                for (i, c) in columns.iter_mut().take(n).enumerate() {
                    *c = first + i as u64;
                }
                cells.apply_all(&mut columns[..n]);
                for i in 0..n {
                    (rows[i], columns[i]) = strata.by_k.div_mod(columns[i]);
                }
                // Sub-column of each sample in its cell from its column's
                // permutation of rows; likewise the sub-row.
                let keyed = k <= FEW_LINES;
                if keyed {
                    // Each line's whole permutation: table[axis][line · k + position].
                    for (axis, table) in tables.iter_mut().enumerate() {
                        line_permutations(strata, pixel.line_keys[which][axis], &mut table[..k * k]);
                    }
                }
                // Stage by stage over the samples, each stage a loop of
                // independent lanes: the sub-positions, the jitter hashes,
                // then the coordinates.
                let (mut sub_x, mut sub_y) = ([0u64; BATCH], [0u64; BATCH]);
                if keyed {
                    for i in 0..n {
                        let (column, row) = (columns[i] as usize, rows[i] as usize);
                        (sub_x[i], sub_y[i]) = (tables[0][column * k + row] as u64, tables[1][row * k + column] as u64);
                    }
                } else {
                    let key = |axis: usize, line: u64| pixel.line_keys[which][axis] ^ mix(line);
                    for i in 0..n {
                        let (column, row) = (columns[i], rows[i]);
                        (sub_x[i], sub_y[i]) =
                            (permute(row, strata.k, key(0, column)), permute(column, strata.k, key(1, row)));
                    }
                }
                let mut hashes = [0u64; BATCH];
                for (i, h) in hashes[..n].iter_mut().enumerate() {
                    *h = mix(pixel.seed ^ ((first + i as u64) << 4 | d));
                }
                let (mut xs, mut ys) = ([0f64; BATCH], [0f64; BATCH]);
                for i in 0..n {
                    // One hash gives both jitters (32 bits each).
                    let h = hashes[i];
                    let (ux, uy) =
                        ((h >> 32) as i64 as f64 * TWO_TO_MINUS_32, (h & 0xFFFF_FFFF) as i64 as f64 * TWO_TO_MINUS_32);
                    let (c, r) = (columns[i] as i64 as f64, rows[i] as i64 as f64);
                    let (sx, sy) = (sub_x[i] as i64 as f64, sub_y[i] as i64 as f64);
                    (xs[i], ys[i]) =
                        (below_one((c + (sx + ux) * inv_k) * inv_k), below_one((r + (sy + uy) * inv_k) * inv_k));
                }
                let (px, py) = (pixel.x as f64, pixel.y as f64);
                for (p, (x, y)) in out.iter_mut().zip(xs.into_iter().zip(ys)) {
                    match which {
                        0 => (p[0], p[1]) = (px + x, py + y),
                        1 => (p[2], p[3]) = (x, y),
                        _ => (p[5], p[6]) = (x, y),
                    }
                }
            }
            if has(4) {
                let mut strata_of = [0u64; BATCH];
                for (i, t) in strata_of.iter_mut().take(n).enumerate() {
                    *t = first + i as u64;
                }
                Permutation::new(strata.spp, pixel.time_key).apply_all(&mut strata_of[..n]);
                for (i, p) in out.iter_mut().enumerate() {
                    let s = first + i as u64;
                    let u = uniform(mix(pixel.seed ^ (s << 4 | 4)));
                    p[4] = below_one((strata_of[i] as i64 as f64 + u) * strata.inv_spp);
                }
            }
        }
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

    /// The dimensions of the sample whose key is `key` (see [`Dimensions::key`]):
    /// a renderer that keeps its paths' keys in lanes rebuilds them here.
    #[inline(always)]
    pub fn from_key(key: u64) -> Self {
        Dimensions { seed: key }
    }

    /// The 64-bit key every dimension is hashed from: a renderer with its
    /// own random numbers (Mitsuba's, through `fbksd.renderer`) derives
    /// them from it, so each sample stays a pure function of its indices.
    #[inline]
    pub fn key(&self) -> u64 {
        self.seed
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

    #[test]
    fn samples_in_batches_are_the_samples_one_at_a_time() {
        let sampler = Sampler::new(37, 23, 5);
        // Budgets square and not, more lines than a batch (k = 71), batches
        // starting mid-pixel, and every subset of the pairs and TIME.
        for spp in [64u64, 1, 2, 3, 5, 16, 17, 100, 256, 257, 5000] {
            let strata = Strata::new(spp);
            for needed in [0x7Fu8, 0b11, 0b1_0000, 0b110_0000, 0b1100, 0b1_0011] {
                for (x, y) in [(0, 0), (36, 22), (7, 11)] {
                    let pixel = sampler.pixel(x, y);
                    for (s0, count) in [(0, spp), (spp / 3, spp - spp / 3), (spp - 1, 1)] {
                        let mut batch = vec![[0.0; 7]; count.min(300) as usize];
                        sampler.pixel_samples(&pixel, &strata, s0, needed, &mut batch);
                        for (i, b) in batch.iter().enumerate() {
                            let s = s0 + i as u64;
                            let one = sampler.pixel_sample(&pixel, &strata, s, needed);
                            assert_eq!(
                                one.map(f64::to_bits),
                                b.map(f64::to_bits),
                                "spp {spp}, {needed:#b}, ({x}, {y}), s {s}"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn permute_is_a_bijection_for_every_size_and_key() {
        for n in [1u64, 2, 3, 5, 16, 17, 100, 1024, 1025, 4096] {
            for key in [0u64, 1, 0xDEAD_BEEF, u64::MAX] {
                let mut seen = vec![false; n as usize];
                for i in 0..n {
                    let v = permute(i, n, key) as usize;
                    assert!(!seen[v], "n {n} key {key}: {v} twice");
                    seen[v] = true;
                }
            }
        }
        let a: Vec<u64> = (0..64).map(|i| permute(i, 64, 1)).collect();
        let b: Vec<u64> = (0..64).map(|i| permute(i, 64, 2)).collect();
        assert_ne!(a, b, "different keys give different orders");
    }

    // Regression: the pairs' cells were (a·s + bᵢ) mod k² with one
    // multiplier a for every pair, so within a pixel the lens (and light)
    // position was the image position plus a fixed offset: an estimate of
    // a function of both converged, per request, to a wrong value (the
    // depth-of-field references stopped improving with more samples).
    #[test]
    fn every_pair_of_dimensions_is_independent_within_a_pixel() {
        let spp = 1024;
        let strata = Strata::new(spp);
        for request in 0..4 {
            let sampler = Sampler::new(8, 8, request);
            for (px, py) in [(0, 0), (3, 5), (7, 7)] {
                let pixel = sampler.pixel(px, py);
                let points: Vec<[f64; 7]> = (0..spp).map(|s| sampler.pixel_sample(&pixel, &strata, s, 0x7F)).collect();
                let frac = |p: &[f64; 7], d: usize| if d < 2 { p[d].fract() } else { p[d] };
                for a in 0..7 {
                    for b in a + 1..7 {
                        // E[(A − B)²] = 1/6 for independent uniforms.
                        let m = points.iter().map(|p| (frac(p, a) - frac(p, b)).powi(2)).sum::<f64>() / spp as f64;
                        assert!(
                            (m - 1.0 / 6.0).abs() < 0.02,
                            "request {request}, pixel ({px}, {py}), dims {a}/{b}: {m}"
                        );
                    }
                }
            }
        }
    }
}
