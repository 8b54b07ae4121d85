//! `fbksd iqa`: the built-in metrics as commands, in the external-metric
//! interface (`<metric> [--value-file f] [--map-file f.png] ref test`, the
//! value as JSON on stdout), and their benchmark.

use anyhow::{bail, Context};
use clap::Subcommand;
use fbksd_iqa::image::Image;
use fbksd_iqa::{evaluate, Metric, ValueRecord};
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
    /// Reference image (OpenEXR).
    reference: PathBuf,
    /// Test image (OpenEXR).
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
    let reference = Image::read(&args.reference).with_context(|| format!("reference {}", args.reference.display()))?;
    let test = Image::read(&args.test).with_context(|| format!("test image {}", args.test.display()))?;
    let e = evaluate(metric, &reference, &test)?;
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

fn bench(size: u32) -> anyhow::Result<()> {
    // A smooth HDR-ish reference and a noisy test image, deterministic.
    let n = size as usize;
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
    };
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
    }
    Ok(())
}
