//! Views of one tile of samples, as the technique's callbacks see them.

use fbksd_core::{Tile, TileRect};

/// Geometry shared by both views. Free-sample tiles (count requests) have
/// no pixels: their rectangle is empty and `spp` is 0.
#[derive(Clone, Copy)]
struct Geometry {
    rect: TileRect,
    spp: u32,
    count: u64,
    sample_size: usize,
}

impl Geometry {
    fn new(tile: Tile, sample_size: usize) -> Self {
        match tile {
            Tile::Pixels { rect, spp } => Geometry { rect, spp, count: tile.sample_count(), sample_size },
            Tile::Samples { count } => {
                Geometry { rect: TileRect { x0: 0, y0: 0, x1: 0, y1: 0 }, spp: 0, count, sample_size }
            }
        }
    }

    #[inline]
    fn range(&self, x: u32, y: u32, s: u32) -> std::ops::Range<usize> {
        debug_assert!(x >= self.rect.x0 && x < self.rect.x1 && y >= self.rect.y0 && y < self.rect.y1 && s < self.spp);
        let start = Tile::sample_index(&self.rect, self.spp, x, y, s) * self.sample_size;
        start..start + self.sample_size
    }
}

macro_rules! geometry_accessors {
    () => {
        /// First column (inclusive).
        pub fn begin_x(&self) -> u32 {
            self.g.rect.x0
        }
        /// Last column (exclusive).
        pub fn end_x(&self) -> u32 {
            self.g.rect.x1
        }
        /// First row (inclusive).
        pub fn begin_y(&self) -> u32 {
            self.g.rect.y0
        }
        /// Last row (exclusive).
        pub fn end_y(&self) -> u32 {
            self.g.rect.y1
        }
        /// Samples per pixel in this tile.
        pub fn spp(&self) -> u32 {
            self.g.spp
        }
        /// Number of samples in this tile.
        pub fn len(&self) -> u64 {
            self.g.count
        }
        /// Whether the tile has no samples.
        pub fn is_empty(&self) -> bool {
            self.g.count == 0
        }
        /// Floats per sample.
        pub fn sample_size(&self) -> usize {
            self.g.sample_size
        }
    };
}

/// A tile of rendered samples (read-only).
pub struct BufferTile<'a> {
    g: Geometry,
    data: &'a [f32],
}

impl<'a> BufferTile<'a> {
    pub(crate) fn new(tile: Tile, data: &'a [f32], sample_size: usize) -> Self {
        BufferTile { g: Geometry::new(tile, sample_size), data }
    }

    geometry_accessors!();

    /// Sample `s` of pixel `(x, y)` (the C++ `tile(x, y, s)`).
    #[inline]
    pub fn sample(&self, x: u32, y: u32, s: u32) -> &[f32] {
        &self.data[self.g.range(x, y, s)]
    }

    /// All samples of the tile, contiguous, in pixel-then-sample order.
    pub fn data(&self) -> &[f32] {
        self.data
    }
}

/// A tile whose INPUT parameters the technique writes.
pub struct BufferTileMut<'a> {
    g: Geometry,
    data: &'a mut [f32],
}

impl<'a> BufferTileMut<'a> {
    pub(crate) fn new(tile: Tile, data: &'a mut [f32], sample_size: usize) -> Self {
        BufferTileMut { g: Geometry::new(tile, sample_size), data }
    }

    geometry_accessors!();

    /// Sample `s` of pixel `(x, y)`, writable.
    #[inline]
    pub fn sample_mut(&mut self, x: u32, y: u32, s: u32) -> &mut [f32] {
        let r = self.g.range(x, y, s);
        &mut self.data[r]
    }

    /// All samples of the tile, writable.
    pub fn data_mut(&mut self) -> &mut [f32] {
        self.data
    }
}
