//! Our metrics against independent implementations run by python3 on the
//! same pixels: scikit-image (SSIM, PSNR, MSE) and NVIDIA's flip-evaluator
//! (LDR- and HDR-ꟻLIP). `deploy/setup.sh` installs
//! them (`pip install numpy scikit-image flip-evaluator`).

use fbksd_iqa::image::Image;
use fbksd_iqa::{evaluate, Metric};
use std::io::Write;
use std::process::Command;

/// A smooth HDR-ish reference (some values above 1) and a noisy, biased test.
fn pair(w: u32, h: u32, seed: u64) -> (Image, Image) {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let mut r = Vec::new();
    let mut t = Vec::new();
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                let v = 0.6 + 0.5 * ((x as f64 * 0.11 + c as f64).sin() * (y as f64 * 0.07).cos());
                r.push(v as f32);
                t.push((v * 0.95 + 0.3 * noise()).max(0.0) as f32);
            }
        }
    }
    (Image::new(w, h, r), Image::new(w, h, t))
}

/// Runs `script` with the two images as `ref` and `test` (H×W×3 float32
/// numpy arrays) and returns what it prints.
fn python(reference: &Image, test: &Image, script: &str) -> f64 {
    let dir = tempfile::tempdir().unwrap();
    for (name, img) in [("ref", reference), ("test", test)] {
        let bytes: Vec<u8> = img.rgb.iter().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::File::create(dir.path().join(name)).unwrap().write_all(&bytes).unwrap();
    }
    let prelude = format!(
        "import numpy as np\n\
         shape = ({}, {}, 3)\n\
         ref = np.fromfile('{d}/ref', dtype='<f4').reshape(shape)\n\
         test = np.fromfile('{d}/test', dtype='<f4').reshape(shape)\n\
         def tone_map(v):\n\
         \x20   v = np.clip(np.nan_to_num(v.astype(np.float64), nan=0.0), 0.0, 1.0)\n\
         \x20   return 255.0 * np.where(v <= 0.0031308, v * 12.92, 1.055 * v ** (1 / 2.4) - 0.055)\n",
        reference.height,
        reference.width,
        d = dir.path().display()
    );
    let out = Command::new("python3").arg("-c").arg(format!("{prelude}{script}")).output().expect("python3");
    assert!(
        out.status.success(),
        "python failed (run deploy/setup.sh to install numpy, scikit-image and flip-evaluator): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).trim().parse().unwrap()
}

#[test]
fn ssim_equals_scikit_image() {
    // An 11 × 11 image has a single full window: f32 filtering error is not
    // averaged away there, so it gets 1e−5; ordinary images agree to 2e−6.
    for (w, h, seed, tolerance) in [(64, 48, 1, 2e-6), (11, 11, 2, 1e-5), (131, 97, 3, 2e-6)] {
        let (r, t) = pair(w, h, seed);
        let ours = evaluate(Metric::Ssim, &r, &t).unwrap().value;
        let theirs = python(
            &r,
            &t,
            "from skimage.metrics import structural_similarity as s\n\
             print(s(tone_map(ref), tone_map(test), data_range=255, gaussian_weights=True, sigma=1.5, use_sample_covariance=False, channel_axis=2))",
        );
        assert!((ours - theirs).abs() < tolerance, "{w}×{h}: ours {ours}, scikit-image {theirs}");
    }
}

#[test]
fn psnr_and_mse_equal_scikit_image() {
    let (r, t) = pair(40, 30, 4);
    let psnr = python(
        &r,
        &t,
        "from skimage.metrics import peak_signal_noise_ratio as p\nprint(p(tone_map(ref), tone_map(test), data_range=255))",
    );
    let ours = evaluate(Metric::Psnr, &r, &t).unwrap().value;
    assert!((ours - psnr).abs() < 1e-6, "ours {ours}, scikit-image {psnr}");
    let mse = python(&r, &t, "from skimage.metrics import mean_squared_error as m\nprint(m(ref.astype(np.float64), test.astype(np.float64)))");
    assert!((evaluate(Metric::Mse, &r, &t).unwrap().value - mse).abs() < 1e-12);
}

#[test]
fn flip_equals_nvidias_flip_evaluator() {
    for (w, h, seed) in [(64, 48, 5), (23, 17, 6)] {
        let (r, t) = pair(w, h, seed);
        let ldr = evaluate(Metric::Flip, &r, &t).unwrap();
        let theirs = python(
            &r,
            &t,
            "import flip_evaluator as f\n_, m, _ = f.evaluate(ref, test, 'LDR', inputsRGB=False, applyMagma=False)\nprint(m)",
        );
        assert!((ldr.value - theirs).abs() < 1e-5, "LDR {w}×{h}: ours {}, flip-evaluator {theirs}", ldr.value);
        let hdr = evaluate(Metric::HdrFlip, &r, &t).unwrap();
        let theirs = python(
            &r,
            &t,
            "import flip_evaluator as f\n_, m, _ = f.evaluate(ref, test, 'HDR', applyMagma=False)\nprint(m)",
        );
        assert!((hdr.value - theirs).abs() < 1e-5, "HDR {w}×{h}: ours {}, flip-evaluator {theirs}", hdr.value);
        assert!(hdr.value > 0.0 && ldr.value > 0.0);
    }
}
