//! Tiles: the unit in which samples move through the ring.
//!
//! A tile is either a rectangle of pixels with `spp` samples each (SPP
//! requests) or a run of `count` samples at positions the renderer (or the
//! technique, for INPUT parameters) chose (count requests). Inside a slot the
//! samples are contiguous, `sample_size` floats each; in a pixel tile, sample
//! `s` of pixel `(x, y)` starts at float
//! `(((y − y0) · (x1 − x0) + (x − x0)) · spp + s) · sample_size`,
//! the same order as the original FBKSD.

use serde::{Deserialize, Serialize};

/// A half-open rectangle of pixels: `x0 ≤ x < x1`, `y0 ≤ y < y1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct TileRect {
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// One past the last column.
    pub x1: u32,
    /// One past the last row.
    pub y1: u32,
}

impl TileRect {
    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.x1.saturating_sub(self.x0)
    }
    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.y1.saturating_sub(self.y0)
    }
    /// Number of pixels.
    pub fn pixels(&self) -> u64 {
        self.width() as u64 * self.height() as u64
    }
    /// Whether the rectangle is non-empty and inside a `width × height` image.
    pub fn is_inside(&self, width: u32, height: u32) -> bool {
        self.x0 < self.x1 && self.y0 < self.y1 && self.x1 <= width && self.y1 <= height
    }
}

/// The samples of one slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Tile {
    /// `spp` samples for every pixel of a rectangle.
    Pixels {
        /// The pixels.
        #[serde(flatten)]
        rect: TileRect,
        /// Samples per pixel in this tile.
        spp: u32,
    },
    /// `count` samples anywhere in the image.
    Samples {
        /// Number of samples.
        count: u64,
    },
}

impl Tile {
    /// Number of samples in the tile.
    pub fn sample_count(&self) -> u64 {
        match self {
            Tile::Pixels { rect, spp } => rect.pixels() * *spp as u64,
            Tile::Samples { count } => *count,
        }
    }

    /// Index (in samples) of sample `s` of pixel `(x, y)` in a pixel tile.
    #[inline]
    pub fn sample_index(rect: &TileRect, spp: u32, x: u32, y: u32, s: u32) -> usize {
        (((y - rect.y0) as usize * rect.width() as usize + (x - rect.x0) as usize) * spp as usize) + s as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_index_matches_the_original_order() {
        let rect = TileRect { x0: 16, y0: 32, x1: 32, y1: 48 };
        // ((y−by)·tileW + (x−bx))·spp + s
        assert_eq!(Tile::sample_index(&rect, 4, 16, 32, 0), 0);
        assert_eq!(Tile::sample_index(&rect, 4, 16, 32, 3), 3);
        assert_eq!(Tile::sample_index(&rect, 4, 17, 32, 0), 4);
        assert_eq!(Tile::sample_index(&rect, 4, 16, 33, 1), 16 * 4 + 1);
        assert_eq!(Tile::Pixels { rect, spp: 4 }.sample_count(), 16 * 16 * 4);
    }

    #[test]
    fn rect_bounds() {
        let r = TileRect { x0: 0, y0: 0, x1: 4, y1: 4 };
        assert!(r.is_inside(4, 4) && !r.is_inside(3, 4));
        assert!(!TileRect { x0: 2, y0: 0, x1: 2, y1: 1 }.is_inside(4, 4));
    }
}
