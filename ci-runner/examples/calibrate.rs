//! How much a runner's calibration moves between measurements: prints this
//! machine's runner class and N calibrations (default 20), each as a
//! runner measures it (pinned to `CPUS`, default all cores), then their
//! median, range and CV. The server's drift limit (5 %) must stand well
//! above this spread.
//!
//!     cargo run --release -p fbksd-ci --example calibrate -- [N] [CPUS]

use fbksd_ci::calibration::measure_on;
use fbksd_ci::machine::{cpus_of, Machine};

fn main() {
    let mut args = std::env::args().skip(1);
    let n: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(20);
    let cpuset = args.next();
    let machine = Machine::probe(cpuset.as_deref(), None);
    println!("class: {}", machine.class);
    let cpus = cpus_of(&machine.cpuset).unwrap_or_default();
    let mut medians = Vec::with_capacity(n);
    for i in 0..n {
        let c = measure_on(&cpus);
        println!(
            "{i:>3}: {:.2} ms CPU (CV of its {} runs {:.1} %), {:.2} ms wall",
            c.cpu_ms, c.runs, c.cpu_cv_percent, c.wall_ms
        );
        medians.push(c.cpu_ms);
    }
    let spread = fbksd_exchange::stats::Spread::of(&medians).expect("at least one calibration");
    println!(
        "{n} calibrations: median {:.2} ms, {:.2}–{:.2} ms (largest / median − 1: {:+.1} %, smallest: {:+.1} %), CV {:.2} %",
        spread.median,
        spread.min,
        spread.max,
        100.0 * (spread.max / spread.median - 1.0),
        100.0 * (spread.min / spread.median - 1.0),
        100.0 * spread.cv
    );
}
