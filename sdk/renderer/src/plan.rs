//! Splitting a request into tiles that fit the ring's slots.

use fbksd_core::{Tile, TileRect};

/// Tiles for a request of `spp` samples per pixel plus `remaining` free
/// samples on a `width × height` image, each holding at most `pipe_size`
/// samples.
///
/// Pixel tiles start as `tile_size`-sided squares, shrink when a square
/// would not fit a slot (high spp), and grow while they stay well below a
/// slot and there remain at least eight tiles per thread (low spp: fewer,
/// larger hand-offs). Free samples come in chunks of up to `pipe_size`, split
/// so every thread has one.
pub fn plan_tiles(
    width: u32,
    height: u32,
    spp: u64,
    remaining: u64,
    tile_size: u32,
    pipe_size: u64,
    threads: usize,
) -> Vec<Tile> {
    let mut tiles = Vec::new();
    let threads = threads.max(1) as u64;
    if spp > 0 && width > 0 && height > 0 {
        let max_pixels = (pipe_size / spp).max(1);
        let side = tile_size.max(1) as u64;
        let (mut tw, mut th) = (side, side);
        if tw * th > max_pixels {
            tw = tw.min(max_pixels);
            th = (max_pixels / tw).max(1);
        } else {
            let count = |w: u64, h: u64| (width as u64).div_ceil(w) * (height as u64).div_ceil(h);
            while 4 * tw * th <= max_pixels / 2 && count(2 * tw, 2 * th) >= 8 * threads {
                tw *= 2;
                th *= 2;
            }
        }
        let (tw, th) = (tw.min(width as u64) as u32, th.min(height as u64) as u32);
        let spp = spp as u32;
        for y0 in (0..height).step_by(th as usize) {
            for x0 in (0..width).step_by(tw as usize) {
                let rect = TileRect { x0, y0, x1: (x0 + tw).min(width), y1: (y0 + th).min(height) };
                tiles.push(Tile::Pixels { rect, spp });
            }
        }
    }
    if remaining > 0 {
        let chunk = remaining.div_ceil(threads).clamp(1, pipe_size.max(1));
        let mut left = remaining;
        while left > 0 {
            let count = left.min(chunk);
            tiles.push(Tile::Samples { count });
            left -= count;
        }
    }
    tiles
}

#[cfg(test)]
mod tests {
    use super::*;

    fn total(tiles: &[Tile]) -> u64 {
        tiles.iter().map(Tile::sample_count).sum()
    }

    #[test]
    fn covers_every_pixel_exactly_once() {
        for &(w, h, spp, pipe) in
            &[(37u32, 23u32, 3u64, 1000u64), (1, 1, 1, 1), (64, 64, 4096, 4096), (500, 500, 1, 1 << 20)]
        {
            let tiles = plan_tiles(w, h, spp, 0, 16, pipe, 2);
            let mut seen = vec![0u32; (w * h) as usize];
            for t in &tiles {
                let Tile::Pixels { rect, spp: s } = t else { panic!() };
                assert_eq!(*s as u64, spp);
                assert!(t.sample_count() <= pipe, "{t:?} exceeds pipe {pipe}");
                for y in rect.y0..rect.y1 {
                    for x in rect.x0..rect.x1 {
                        seen[(y * w + x) as usize] += 1;
                    }
                }
            }
            assert!(seen.iter().all(|&c| c == 1), "{w}x{h} spp {spp}");
        }
    }

    #[test]
    fn low_spp_tiles_grow_but_keep_parallelism() {
        let tiles = plan_tiles(1920, 1080, 1, 0, 16, 1 << 20, 2);
        assert!(tiles.len() >= 16 && tiles.len() < (1920 / 16) * (1080 / 16), "{}", tiles.len());
    }

    #[test]
    fn free_samples_come_in_chunks_within_the_pipe() {
        let tiles = plan_tiles(10, 10, 0, 1_000_001, 16, 65536, 2);
        assert_eq!(total(&tiles), 1_000_001);
        assert!(tiles.iter().all(|t| t.sample_count() <= 65536));
        let tiles = plan_tiles(10, 10, 2, 7, 16, 65536, 2);
        assert_eq!(total(&tiles), 207);
    }
}
