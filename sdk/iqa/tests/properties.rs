//! Metric values worked out by hand, the properties every metric must have,
//! and the extremes a benchmark meets: NaN/Inf, black references, exact
//! matches, constant and tiny images, huge HDR values, large images.

use fbksd_iqa::image::Image;
use fbksd_iqa::{evaluate, IqaError, Metric};

fn img(w: u32, h: u32, f: impl Fn(u32, u32, usize) -> f32) -> Image {
    let mut rgb = Vec::new();
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                rgb.push(f(x, y, c));
            }
        }
    }
    Image::new(w, h, rgb)
}

fn value(m: Metric, r: &Image, t: &Image) -> f64 {
    evaluate(m, r, t).unwrap_or_else(|e| panic!("{}: {e}", m.acronym())).value
}

#[test]
fn hand_computed_values() {
    // One pixel of three differs by 0.25 in red (exact in f32): squared
    // error 0.0625 over 9 channel values.
    let r = img(3, 1, |_, _, _| 0.5);
    let t = img(3, 1, |x, _, c| if x == 1 && c == 0 { 0.75 } else { 0.5 });
    assert!((value(Metric::Mse, &r, &t) - 0.0625 / 9.0).abs() < 1e-15);
    // Relative: 0.0625 / (0.25 + 0.01) over 9.
    assert!((value(Metric::RelMse, &r, &t) - 0.0625 / 0.26 / 9.0).abs() < 1e-15);
    // SMAPE: 0.25 / (0.75 + 0.5 + 0.01) over 9.
    assert!((value(Metric::Smape, &r, &t) - 0.25 / 1.26 / 9.0).abs() < 1e-15);
    // PSNR: black against white in every channel is a full-range error: 0 dB.
    let black = img(2, 2, |_, _, _| 0.0);
    let white = img(2, 2, |_, _, _| 1.0);
    assert!(value(Metric::Psnr, &black, &white).abs() < 1e-9);
    // …and values above 1 tone-map to 255 (the original let them exceed it).
    assert!(value(Metric::Psnr, &black, &img(2, 2, |_, _, _| 50.0)).abs() < 1e-9);
    // SSIM of two constant images: (2μxμy + C1) / (μx² + μy² + C1), μ in 8-bit units.
    let (mx, my) = (255.0 * 0.5f64.powf(1.0 / 2.4) * 1.055 - 0.055 * 255.0, 0.0);
    let want = (2.0 * mx * my + 6.5025) / (mx * mx + my * my + 6.5025);
    let grey = img(16, 16, |_, _, _| 0.5);
    assert!((value(Metric::Ssim, &grey, &img(16, 16, |_, _, _| 0.0)) - want).abs() < 1e-4);
}

#[test]
fn an_image_against_itself_is_perfect() {
    let a = img(40, 30, |x, y, c| ((x * 7 + y * 3 + c as u32) % 11) as f32 / 5.0);
    for m in Metric::ALL {
        let v = value(m, &a, &a);
        let perfect = match m {
            Metric::Psnr => 100.0,
            Metric::Ssim => 1.0,
            _ => 0.0,
        };
        assert!((v - perfect).abs() < 1e-6, "{}: {v}", m.acronym());
    }
}

#[test]
fn symmetric_metrics_are_symmetric() {
    let a = img(24, 20, |x, y, c| ((x + 2 * y + c as u32) % 9) as f32 / 9.0);
    let b = img(24, 20, |x, y, c| ((3 * x + y + 2 * c as u32) % 7) as f32 / 7.0);
    for m in [Metric::Mse, Metric::Psnr, Metric::Ssim, Metric::Smape] {
        assert!((value(m, &a, &b) - value(m, &b, &a)).abs() < 1e-6, "{}", m.acronym());
    }
    // Relative MSE divides by the reference: not symmetric, on purpose.
    assert!((value(Metric::RelMse, &a, &b) - value(Metric::RelMse, &b, &a)).abs() > 1e-3);
}

#[test]
fn every_metric_gets_worse_as_noise_grows() {
    let reference = img(48, 40, |x, y, c| 0.3 + 0.2 * ((x as f32 * 0.2 + c as f32).sin() * (y as f32 * 0.15).cos()));
    let noisy = |amount: f32| {
        img(48, 40, |x, y, c| {
            let n = (((x * 7919 + y * 104729 + c as u32 * 1299709) % 1000) as f32 / 1000.0 - 0.5) * amount;
            reference.rgb[((y * 48 + x) * 3) as usize + c] + n
        })
    };
    for m in Metric::ALL {
        let values: Vec<f64> = [0.02, 0.1, 0.3].iter().map(|a| value(m, &reference, &noisy(*a))).collect();
        let worse = |a: f64, b: f64| if m.info().lower_is_better { b > a } else { b < a };
        assert!(worse(values[0], values[1]) && worse(values[1], values[2]), "{}: {values:?}", m.acronym());
    }
}

#[test]
fn nan_and_infinity_are_counted_not_averaged() {
    let r = img(8, 8, |_, _, _| 0.5);
    let mut t = img(8, 8, |_, _, _| 0.625);
    t.rgb[0] = f32::NAN;
    t.rgb[10] = f32::INFINITY;
    let mut r2 = r.clone();
    r2.rgb[30] = f32::NEG_INFINITY;
    for m in Metric::ALL {
        let e = evaluate(m, &r2, &t).unwrap();
        assert!(e.value.is_finite(), "{}: {}", m.acronym(), e.value);
        assert_eq!((e.nonfinite_reference, e.nonfinite_test), (1, 2), "{}", m.acronym());
    }
    // The finite pixels decide the pixelwise means: 61 pixels off by 0.125.
    assert!((value(Metric::Mse, &r2, &t) - 0.015625).abs() < 1e-15);
    let all_nan = img(2, 2, |_, _, _| f32::NAN);
    assert!(matches!(evaluate(Metric::Mse, &r, &all_nan.clone()), Err(IqaError::SizeMismatch(..))));
    assert!(matches!(evaluate(Metric::Mse, &img(2, 2, |_, _, _| 0.5), &all_nan), Err(IqaError::NothingFinite(0, 4))));
}

#[test]
fn black_references_and_exact_matches() {
    let black = img(6, 6, |_, _, _| 0.0);
    let dim = img(6, 6, |_, _, _| 0.125);
    // rMSE on black: 0.125² / (0 + 0.01), finite.
    assert!((value(Metric::RelMse, &black, &dim) - 1.5625).abs() < 1e-12);
    assert!((value(Metric::Smape, &black, &dim) - 0.125 / 0.135).abs() < 1e-12);
    assert_eq!(value(Metric::Psnr, &black, &black), 100.0);
    // HDR-FLIP of an all-black reference (the reference implementation stops there).
    assert!(value(Metric::HdrFlip, &black, &dim) > 0.0);
    assert_eq!(value(Metric::HdrFlip, &black, &black), 0.0);
}

#[test]
fn tiny_constant_and_huge_images() {
    // Smaller than the 11 × 11 SSIM window: every pixel counts.
    let a = img(3, 2, |x, _, _| x as f32 * 0.3);
    let b = img(3, 2, |x, _, _| x as f32 * 0.25);
    let s = value(Metric::Ssim, &a, &b);
    assert!(s > 0.0 && s < 1.0, "{s}");
    for m in Metric::ALL {
        assert!(value(m, &a, &b).is_finite(), "{}", m.acronym());
        assert!(value(m, &img(1, 1, |_, _, _| 0.2), &img(1, 1, |_, _, _| 0.3)).is_finite(), "{} on 1×1", m.acronym());
    }
    // Huge HDR values do not overflow the f64 sums.
    let huge = img(4, 4, |_, _, _| 1e30);
    let mse = value(Metric::Mse, &img(4, 4, |_, _, _| 0.0), &huge);
    assert!((mse / 1e60 - 1.0).abs() < 1e-6, "{mse}");
    assert!(value(Metric::HdrFlip, &huge, &img(4, 4, |_, _, _| 1e29)).is_finite());
}

#[test]
fn sums_keep_their_precision_on_large_images() {
    // 8 Mpixel with a tiny uniform error: an f32 running sum would drift.
    let (w, h) = (4096, 2048);
    let r = Image::new(w, h, vec![1000.0; (w * h * 3) as usize]);
    let t = Image::new(w, h, vec![1000.0 + 1.0 / 1024.0; (w * h * 3) as usize]);
    let mse = value(Metric::Mse, &r, &t);
    let want = (1.0f64 / 1024.0).powi(2);
    assert!((mse - want).abs() < 1e-12 * want.max(1e-300) + 1e-18, "{mse} vs {want}");
}

#[test]
fn error_maps_use_one_fixed_scale() {
    // The same per-pixel error draws the same colour in maps of different images.
    let r = img(4, 1, |_, _, _| 0.5);
    let small = img(4, 1, |x, _, _| if x == 0 { 0.6 } else { 0.5 });
    let large = img(4, 1, |x, _, _| if x == 0 { 0.6 } else { 3.0 });
    let dir = tempfile::tempdir().unwrap();
    for m in [Metric::Mse, Metric::RelMse, Metric::Smape, Metric::Ssim, Metric::Flip] {
        let (a, b) = (evaluate(m, &r, &small).unwrap().map.unwrap(), evaluate(m, &r, &large).unwrap().map.unwrap());
        let (pa, pb) = (dir.path().join("a.png"), dir.path().join("b.png"));
        a.write_png(&pa).unwrap();
        b.write_png(&pb).unwrap();
        assert_eq!(a.scale, b.scale);
        if m != Metric::Ssim && m != Metric::Flip {
            // Pixel 0 has the same error in both: same colour, whatever else the image holds.
            let (ia, ib) = (image::open(&pa).unwrap().to_rgb8(), image::open(&pb).unwrap().to_rgb8());
            assert_eq!(ia.get_pixel(0, 0), ib.get_pixel(0, 0), "{}", m.acronym());
        }
    }
}

#[test]
fn a_reference_prepared_once_scores_every_test_as_a_fresh_one() {
    use fbksd_iqa::{evaluate_against, Reference};
    let r = img(67, 45, |x, y, c| ((x * 7 + y * 3 + c as u32) % 11) as f32 * 0.4);
    let mut nan_test = img(67, 45, |x, y, c| ((x * 5 + y + c as u32) % 13) as f32 * 0.3);
    nan_test.rgb[100] = f32::NAN;
    let tests = [img(67, 45, |x, y, _| ((x + y) % 5) as f32 * 0.5), nan_test];
    let reference = Reference::new(r.clone());
    for metric in Metric::ALL {
        reference.prepare(metric);
        for t in &tests {
            // Bit for bit (NaN marks a pixel without a value in a map).
            let bits = |e: fbksd_iqa::Evaluation| {
                let map = e.map.map(|m| m.values.iter().map(|v| v.to_bits()).collect::<Vec<u32>>());
                (e.value.to_bits(), map, e.nonfinite_reference, e.nonfinite_test)
            };
            let (prepared, fresh) =
                (evaluate_against(metric, &reference, t).unwrap(), evaluate(metric, &r, t).unwrap());
            assert_eq!(bits(prepared), bits(fresh), "{metric:?}");
        }
    }
}

#[test]
fn flip_maps_do_not_depend_on_the_number_of_threads() {
    // The filters run in bands of rows whose size follows the thread count;
    // bands overlap, and every pixel must come out the same.
    let r = img(131, 200, |x, y, c| (((x * 13) ^ (y * 7)) % 17 + c as u32) as f32 * 0.2);
    let t = img(131, 200, |x, y, c| (((x * 11) ^ (y * 5)) % 19 + c as u32) as f32 * 0.2);
    for metric in [Metric::Flip, Metric::HdrFlip] {
        let maps: Vec<Vec<f32>> = [1, 2, 3]
            .into_iter()
            .map(|threads| {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                pool.install(|| evaluate(metric, &r, &t)).unwrap().map.unwrap().values
            })
            .collect();
        assert!(maps[0].iter().any(|v| *v > 0.0));
        assert_eq!(maps[0], maps[1], "{metric:?}: 1 and 2 threads");
        assert_eq!(maps[0], maps[2], "{metric:?}: 1 and 3 threads");
    }
}
