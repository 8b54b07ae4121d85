//! The renderer's own sample positions: stratified, inside their pixel,
//! and reproducible from (pixel, request, sample index).

use fbksd_procedural::render::{render_image, Sampler, Strata};
use fbksd_procedural::Scene;
use std::collections::HashSet;

const ALL: u8 = 0x7f;

#[test]
fn samples_are_stratified_per_pixel_in_every_dimension() {
    let sampler = Sampler::new(64, 32, 3);
    for spp in [1u64, 4, 9, 16, 64] {
        let k = (spp as f64).sqrt() as u64;
        let strata = Strata::new(spp);
        for (x, y) in [(0, 0), (17, 5), (63, 31)] {
            let pixel = sampler.pixel(x, y);
            let samples: Vec<[f64; 7]> = (0..spp).map(|s| sampler.pixel_sample(&pixel, &strata, s, ALL)).collect();
            let cells = |dx: usize, dy: usize| -> HashSet<(u64, u64)> {
                samples.iter().map(|p| ((p[dx].fract() * k as f64) as u64, (p[dy].fract() * k as f64) as u64)).collect()
            };
            assert_eq!(cells(0, 1).len() as u64, spp, "image strata, spp {spp}");
            assert_eq!(cells(2, 3).len() as u64, spp, "lens strata, spp {spp}");
            assert_eq!(cells(5, 6).len() as u64, spp, "light strata, spp {spp}");
            // Every 1-D projection is stratified into spp intervals (multi-jittered).
            for d in [0, 1, 2, 3, 4, 5, 6] {
                let strata: HashSet<u64> = samples.iter().map(|p| (p[d].fract() * spp as f64) as u64).collect();
                assert_eq!(strata.len() as u64, spp, "dimension {d}, spp {spp}");
            }
            for p in &samples {
                assert!(p[0].floor() == x as f64 && p[1].floor() == y as f64, "{p:?} outside pixel ({x}, {y})");
                assert!(p[2..].iter().all(|v| (0.0..1.0).contains(v)), "{p:?}");
            }
        }
    }
}

/// Regression: with spp not a perfect square, the last cells of the grid
/// were never sampled (IMAGE_Y never reached the bottom of the pixel at 2,
/// 8 or 32 spp), and sub-cell positions sat on a fixed pattern. Every spp
/// must now cover the pixel uniformly, in 1-D and on a fine 2-D grid.
#[test]
fn samples_cover_the_pixel_uniformly_at_every_spp() {
    for spp in [2u64, 3, 4, 8, 16, 32] {
        let strata = Strata::new(spp);
        let sampler = Sampler::new(400, 100, 0);
        let mut histogram = [[0u64; 8]; 8];
        let (mut sum_x, mut sum_y, mut n) = (0.0, 0.0, 0u64);
        for y in 0..100 {
            for x in 0..400 {
                let pixel = sampler.pixel(x, y);
                for s in 0..spp {
                    for (d0, d1) in [(0, 1), (2, 3), (5, 6)] {
                        let p = sampler.pixel_sample(&pixel, &strata, s, ALL);
                        let (u, v) = (p[d0].fract(), p[d1].fract());
                        histogram[(u * 8.0) as usize][(v * 8.0) as usize] += 1;
                        if d0 == 0 {
                            sum_x += u;
                            sum_y += v;
                            n += 1;
                        }
                    }
                }
            }
        }
        assert!(
            (sum_x / n as f64 - 0.5).abs() < 0.01 && (sum_y / n as f64 - 0.5).abs() < 0.01,
            "spp {spp}: mean ({}, {})",
            sum_x / n as f64,
            sum_y / n as f64
        );
        let expected = (3 * n) as f64 / 64.0;
        for row in histogram {
            for count in row {
                assert!((count as f64 - expected).abs() < 0.1 * expected, "spp {spp}: {histogram:?}");
            }
        }
    }
}

#[test]
fn the_same_seed_gives_the_same_samples_and_another_request_others() {
    let strata = Strata::new(16);
    let a = Sampler::new(8, 8, 0);
    let b = Sampler::new(8, 8, 1);
    let pa = a.pixel(3, 4);
    let pb = b.pixel(3, 4);
    for s in 0..16 {
        assert_eq!(a.pixel_sample(&pa, &strata, s, ALL), a.pixel_sample(&a.pixel(3, 4), &strata, s, ALL));
        assert_ne!(a.pixel_sample(&pa, &strata, s, ALL), b.pixel_sample(&pb, &strata, s, ALL));
    }
    assert_eq!(a.free_sample(99), Sampler::new(8, 8, 0).free_sample(99));
    let scene = Scene::parse("t", "width := 16; height := 8;\n#\nCOLOR_R := sin(IMAGE_X * IMAGE_Y) + LENS_U;").unwrap();
    assert_eq!(render_image(&scene, 7, 5).unwrap(), render_image(&scene, 7, 5).unwrap());
    assert_ne!(render_image(&scene, 7, 5).unwrap(), render_image(&scene, 7, 6).unwrap());
}

#[test]
fn drawing_only_some_dimensions_does_not_change_them() {
    let strata = Strata::new(9);
    let sampler = Sampler::new(10, 10, 2);
    let pixel = sampler.pixel(1, 2);
    for s in 0..9 {
        let all = sampler.pixel_sample(&pixel, &strata, s, ALL);
        let time_only = sampler.pixel_sample(&pixel, &strata, s, 1 << 4);
        assert_eq!(all[4], time_only[4]);
        assert_eq!(time_only[0], 0.0);
    }
}
