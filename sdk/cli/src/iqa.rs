//! `fbksd iqa`: the built-in metrics as commands, in the external-metric
//! interface (`<metric> [--value-file f] [--map-file f.png] ref test`, the
//! value as JSON on stdout), and their benchmark.

use anyhow::{bail, Context};
use clap::Subcommand;
use fbksd_iqa::image::Image;
use fbksd_iqa::{evaluate, evaluate_against, Metric, Reference, ValueRecord};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Subcommand)]
pub enum IqaCommand {
    /// List the built-in metrics (as IQA info.json objects).
    List,
    /// Time every metric on a 1024×1024 pair, on one thread and on all cores.
    Bench {
        /// Image side.
        #[arg(long, default_value_t = 1024)]
        size: u32,
    },
    /// Compute one metric: `fbksd iqa <METRIC> [--value-file f] [--map-file m.png] <reference.exr> <test.exr>`.
    #[command(external_subcommand)]
    Metric(Vec<String>),
}

#[derive(clap::Parser)]
#[command(no_binary_name = true)]
struct MetricArgs {
    /// Metric acronym (MSE, rMSE, PSNR, SSIM, SMAPE, FLIP, HDR-FLIP).
    metric: String,
    /// Also write the value as JSON here.
    #[arg(long)]
    value_file: Option<PathBuf>,
    /// Write the error map (PNG) here.
    #[arg(long)]
    map_file: Option<PathBuf>,
    /// Reference image (OpenEXR, or an 8-bit sRGB PNG).
    reference: PathBuf,
    /// Test image (OpenEXR, or an 8-bit sRGB PNG).
    test: PathBuf,
}

pub fn iqa(command: IqaCommand) -> anyhow::Result<()> {
    match command {
        IqaCommand::List => {
            let infos: Vec<_> = Metric::ALL.iter().map(|m| m.info()).collect();
            println!("{}", serde_json::to_string_pretty(&infos)?);
            Ok(())
        }
        IqaCommand::Bench { size } => bench(size),
        IqaCommand::Metric(argv) => {
            let args = <MetricArgs as clap::Parser>::try_parse_from(argv).map_err(|e| anyhow::anyhow!("{e}"))?;
            one(args)
        }
    }
}

fn one(args: MetricArgs) -> anyhow::Result<()> {
    let Some(metric) = Metric::from_acronym(&args.metric) else {
        let known: Vec<_> = Metric::ALL.iter().map(|m| m.acronym()).collect();
        bail!("unknown metric {:?} (known: {})", args.metric, known.join(", "));
    };
    // The reference is prepared while the test image decodes.
    let (reference, test) = rayon::join(
        || {
            let reference = Reference::new(Image::read(&args.reference)?);
            reference.prepare(metric);
            Ok::<_, std::io::Error>(reference)
        },
        || Image::read(&args.test),
    );
    let reference = reference.with_context(|| format!("reference {}", args.reference.display()))?;
    let test = test.with_context(|| format!("test image {}", args.test.display()))?;
    let e = evaluate_against(metric, &reference, &test)?;
    let record = ValueRecord {
        metric: metric.acronym().into(),
        value: e.value,
        nonfinite_reference: e.nonfinite_reference,
        nonfinite_test: e.nonfinite_test,
    };
    let json = serde_json::to_string(&record)?;
    if let Some(f) = &args.value_file {
        std::fs::write(f, &json).with_context(|| format!("{}", f.display()))?;
    }
    if let (Some(f), Some(map)) = (&args.map_file, &e.map) {
        map.write_png(f)?;
    }
    if e.nonfinite_reference + e.nonfinite_test > 0 {
        eprintln!(
            "warning: {} reference and {} test pixels hold NaN or infinity and were left out (see the crate docs)",
            e.nonfinite_reference, e.nonfinite_test
        );
    }
    println!("{json}");
    Ok(())
}

/// Deterministic noise in [−0.5, 0.5) (xorshift64) for the benchmarks' images.
pub(crate) fn noise(seed: u64) -> impl FnMut() -> f32 {
    let mut state = seed;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
    }
}

fn bench(size: u32) -> anyhow::Result<()> {
    // A smooth HDR-ish reference and a noisy test image, deterministic.
    let n = size as usize;
    let mut noise = noise(0x2545_F491_4F6C_DD1D);
    let mut r = Vec::with_capacity(n * n * 3);
    let mut t = Vec::with_capacity(n * n * 3);
    for y in 0..n {
        for x in 0..n {
            for c in 0..3 {
                let v = 0.5 + 0.45 * ((x as f32 * 0.013 + c as f32).sin() * (y as f32 * 0.021).cos());
                r.push(v);
                t.push((v + 0.2 * noise()).max(0.0));
            }
        }
    }
    let (r, t) = (Image::new(size, size, r), Image::new(size, size, t));
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    println!("{size}×{size} pair, best of 3 (ms):");
    println!("{:<10} {:>12} {:>12} {:>12}", "metric", "1 thread", format!("{cores} threads"), "value");
    let mut ssim_times = None;
    for metric in Metric::ALL {
        let mut times = Vec::new();
        let mut value = 0.0;
        for threads in [1, cores] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
            let best = (0..3)
                .map(|_| {
                    let start = Instant::now();
                    value = pool.install(|| evaluate(metric, &r, &t)).map(|e| e.value)?;
                    Ok(start.elapsed().as_secs_f64() * 1e3)
                })
                .collect::<anyhow::Result<Vec<f64>>>()?
                .into_iter()
                .fold(f64::INFINITY, f64::min);
            times.push(best);
        }
        println!("{:<10} {:>12.1} {:>12.1} {:>12.6}", metric.acronym(), times[0], times[1], value);
        if metric == Metric::Ssim {
            ssim_times = Some((times[0], value));
        }
    }
    match against_flip_evaluator(&r, &t) {
        Ok(lines) => lines.iter().for_each(|l| println!("{l}")),
        Err(e) => println!("(flip-evaluator not measured: {e})"),
    }
    if let Some((ours, value)) = ssim_times {
        match scikit_image_ssim(&r, &t) {
            Ok((theirs, their_value)) => println!(
                "scikit-image SSIM on the same pair, 1 thread: {:.1} ms (value {their_value:.6}): ours is {:.1}× faster, values differ by {:.1e}",
                theirs,
                theirs / ours,
                (their_value - value).abs()
            ),
            Err(e) => println!("(scikit-image not measured: {e})"),
        }
    }
    Ok(())
}

/// Times `fbksd iqa` and NVIDIA's `flip` (flip-evaluator) as processes on
/// the same files, best of 3 wall times each: HDR-ꟻLIP on the pair scaled
/// to an HDR range (OpenEXR), LDR-ꟻLIP on its 8-bit sRGB PNGs.
fn against_flip_evaluator(r: &Image, t: &Image) -> anyhow::Result<Vec<String>> {
    use fbksd_iqa::image::{srgb, write_exr};
    let dir = tempfile::tempdir()?;
    let path = |name: &str| dir.path().join(name);
    let (w, h) = (r.width, r.height);
    for (name, img) in [("ref", r), ("test", t)] {
        let hdr: Vec<f32> = img.rgb.iter().map(|v| 4.0 * v).collect();
        write_exr(&path(&format!("{name}-hdr.exr")), w, h, &hdr)?;
        let bytes: Vec<u8> = img.rgb.iter().map(|v| (srgb(*v) * 255.0).round() as u8).collect();
        image::RgbImage::from_raw(w, h, bytes).context("png size")?.save(path(&format!("{name}.png")))?;
    }
    let best_of_3 = |command: &mut std::process::Command| -> anyhow::Result<(f64, String)> {
        let mut best = (f64::INFINITY, String::new());
        for _ in 0..3 {
            let start = Instant::now();
            let out = command.output().with_context(|| format!("{command:?}"))?;
            let seconds = start.elapsed().as_secs_f64();
            if !out.status.success() {
                bail!("{command:?}: {}", String::from_utf8_lossy(&out.stderr).trim());
            }
            if seconds < best.0 {
                best = (seconds, String::from_utf8_lossy(&out.stdout).into_owned());
            }
        }
        Ok(best)
    };
    let ours_exe = std::env::current_exe()?;
    let mut lines = vec![format!("as processes on {w}×{h} files, best of 3 wall times:")];
    for (metric, suffix) in [("HDR-FLIP", "-hdr.exr"), ("FLIP", ".png")] {
        let (ours, ours_out) = best_of_3(std::process::Command::new(&ours_exe).args([
            "iqa".as_ref(),
            metric.as_ref(),
            path(&format!("ref{suffix}")).as_os_str(),
            path(&format!("test{suffix}")).as_os_str(),
        ]))?;
        let ours_value = serde_json::from_str::<ValueRecord>(ours_out.trim())?.value;
        let (theirs, theirs_out) = best_of_3(
            std::process::Command::new("flip")
                .arg("-r")
                .arg(path(&format!("ref{suffix}")))
                .arg("-t")
                .arg(path(&format!("test{suffix}")))
                .args(["-nerm", "-nexm", "-v", "1"])
                .current_dir(dir.path()),
        )?;
        let theirs_value = theirs_out
            .lines()
            .find_map(|l| l.trim().strip_prefix("Mean:").map(|v| v.trim().parse::<f64>()))
            .context("flip printed no mean")??;
        lines.push(format!(
            "{metric:<9} fbksd iqa {:.0} ms, flip-evaluator {:.0} ms: {:.1}× faster; values {ours_value:.6} and {theirs_value:.6} (differ by {:.1e})",
            ours * 1e3,
            theirs * 1e3,
            theirs / ours,
            (ours_value - theirs_value).abs()
        ));
    }
    Ok(lines)
}

/// Times scikit-image's SSIM (best of 3, one thread) on the same tone-mapped pair.
fn scikit_image_ssim(r: &Image, t: &Image) -> anyhow::Result<(f64, f64)> {
    let dir = tempfile::tempdir()?;
    for (name, img) in [("ref", r), ("test", t)] {
        let bytes: Vec<u8> = img.rgb.iter().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::write(dir.path().join(name), bytes)?;
    }
    let script = format!(
        "import numpy as np, time\n\
         from skimage.metrics import structural_similarity as s\n\
         shape = ({h}, {w}, 3)\n\
         def tm(v):\n\
         \x20   v = np.clip(v.astype(np.float64), 0.0, 1.0)\n\
         \x20   return 255.0 * np.where(v <= 0.0031308, v * 12.92, 1.055 * v ** (1 / 2.4) - 0.055)\n\
         a = tm(np.fromfile('{d}/ref', dtype='<f4').reshape(shape))\n\
         b = tm(np.fromfile('{d}/test', dtype='<f4').reshape(shape))\n\
         best = 1e9\n\
         for _ in range(3):\n\
         \x20   t0 = time.perf_counter()\n\
         \x20   v = s(a, b, data_range=255, gaussian_weights=True, sigma=1.5, use_sample_covariance=False, channel_axis=2)\n\
         \x20   best = min(best, time.perf_counter() - t0)\n\
         print(best * 1e3, v)\n",
        h = r.height,
        w = r.width,
        d = dir.path().display()
    );
    let out = std::process::Command::new("python3")
        .arg("-c")
        .arg(script)
        .env("OMP_NUM_THREADS", "1")
        .env("OPENBLAS_NUM_THREADS", "1")
        .output()?;
    if !out.status.success() {
        anyhow::bail!("{}", String::from_utf8_lossy(&out.stderr).lines().last().unwrap_or("python3 failed"));
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let mut parts = text.split_whitespace().map(|p| p.parse::<f64>());
    match (parts.next(), parts.next()) {
        (Some(Ok(ms)), Some(Ok(v))) => Ok((ms, v)),
        _ => anyhow::bail!("unexpected output {text:?}"),
    }
}
