//! The calibration workload: a fixed piece of work a runner times at start
//! and after every job, so that each result says how fast its runner was
//! when it was measured.
//!
//! The work is what techniques do most: passes of a separable filter over a
//! float image and a tone curve with `exp` and `ln` per pixel, on one
//! thread, about 50 ms. It is timed in the calling thread's CPU time (the
//! measure the equal-time cost uses) and in wall time; the median of
//! [`REPEATS`] runs is kept with its spread, from the fastest of [`ROUNDS`]
//! rounds. A runner whose CPU time for it
//! moves has become another machine (a different CPU, its frequency
//! capped, a busy sibling hyper-thread); a CPU quota or a busy machine
//! moves only the wall time.

use serde::Serialize;
use std::time::Instant;

/// The workload's name and version: calibrations compare only under one.
pub const WORKLOAD: &str = "fbksd-calibration-1";
/// Runs timed per round.
pub const REPEATS: usize = 5;
/// Rounds per calibration; the fastest is kept (see [`measure`]).
pub const ROUNDS: usize = 3;
const SIDE: usize = 256;
const RADIUS: usize = 3;
const PASSES: usize = 4;

/// One calibration: the workload's median times and their spread.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Calibration {
    /// [`WORKLOAD`].
    pub workload: String,
    /// Median CPU time of one run, in ms.
    pub cpu_ms: f64,
    /// Coefficient of variation of the CPU times, in percent.
    pub cpu_cv_percent: f64,
    /// Median wall time of one run, in ms.
    pub wall_ms: f64,
    /// Runs timed.
    pub runs: usize,
    /// When it was measured, Unix seconds.
    pub measured_at: i64,
}

/// Measures a calibration ([`measure`]) on a thread of its own pinned to
/// `cpus` (the runner's cores, where its jobs run; unpinned where the
/// kernel refuses). It blocks for half a second or so: call it off
/// async threads.
pub fn measure_on(cpus: &[usize]) -> Calibration {
    let cpus = cpus.to_vec();
    std::thread::spawn(move || {
        pin_to(&cpus);
        measure()
    })
    .join()
    .unwrap_or_else(|e| std::panic::resume_unwind(e))
}

fn pin_to(cpus: &[usize]) {
    // SAFETY: cpu_set_t is plain data; CPU_SET stays within it (cores
    // beyond CPU_SETSIZE are skipped); sched_setaffinity reads it and
    // pins the calling thread (pid 0) only.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        for &cpu in cpus.iter().filter(|&&c| c < libc::CPU_SETSIZE as usize) {
            libc::CPU_SET(cpu, &mut set);
        }
        if !cpus.is_empty() && libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) != 0 {
            tracing::warn!("calibration: could not pin to cores {cpus:?}: {}", std::io::Error::last_os_error());
        }
    }
}

/// Seconds since `measured_at` (Unix seconds).
pub fn age_seconds(measured_at: i64) -> i64 {
    unix_now() - measured_at
}

fn unix_now() -> i64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs() as i64)
}

/// Times [`ROUNDS`] rounds of the workload on the calling thread and
/// keeps the fastest round's: a transient (the thread moved to a cold core,
/// an interrupt storm) only ever slows a round, and it slowed one median of
/// five by up to 12 % in 1 run of 20 on an idle 2-core VM, while a runner
/// that has really become slower is slow in every round.
pub fn measure() -> Calibration {
    workload(); // warms the caches and the allocator
    (0..ROUNDS).map(|_| round()).min_by(|a, b| a.cpu_ms.total_cmp(&b.cpu_ms)).expect("ROUNDS > 0")
}

/// Times the workload [`REPEATS`] times on the calling thread.
fn round() -> Calibration {
    let mut cpu = Vec::with_capacity(REPEATS);
    let mut wall = Vec::with_capacity(REPEATS);
    for _ in 0..REPEATS {
        let (cpu_start, wall_start) = (thread_cpu_ms(), Instant::now());
        std::hint::black_box(workload());
        cpu.push(thread_cpu_ms() - cpu_start);
        wall.push(wall_start.elapsed().as_secs_f64() * 1e3);
    }
    let mean = cpu.iter().sum::<f64>() / cpu.len() as f64;
    let variance = cpu.iter().map(|c| (c - mean).powi(2)).sum::<f64>() / (cpu.len() - 1) as f64;
    Calibration {
        workload: WORKLOAD.to_string(),
        cpu_ms: median(&mut cpu),
        cpu_cv_percent: if mean > 0.0 { 100.0 * variance.sqrt() / mean } else { 0.0 },
        wall_ms: median(&mut wall),
        runs: REPEATS,
        measured_at: unix_now(),
    }
}

/// The workload; returns a checksum of its image, so that none of it can
/// be optimised away (and so a test can see it is the same work each time).
pub fn workload() -> f64 {
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut image: Vec<f32> = (0..SIDE * SIDE * 3)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        })
        .collect();
    let mut scratch = vec![0.0f32; image.len()];
    let weight = 1.0 / (2 * RADIUS + 1) as f32;
    for _ in 0..PASSES {
        // Rows, then columns: each output a mean of its 7 neighbours, clamped at the borders.
        for (stride, along) in [(3, SIDE * 3), (SIDE * 3, 3)] {
            for line in 0..SIDE {
                for channel in 0..3 {
                    let base = line * along + channel;
                    for i in 0..SIDE {
                        let mut sum = 0.0;
                        for k in 0..=2 * RADIUS {
                            let j = (i + k).saturating_sub(RADIUS).min(SIDE - 1);
                            sum += image[base + j * stride];
                        }
                        scratch[base + i * stride] = sum * weight;
                    }
                }
            }
            std::mem::swap(&mut image, &mut scratch);
        }
        for v in &mut image {
            *v = (1.0 - (-4.0 * *v).exp()) + 0.1 * (1.0 + *v).ln();
        }
    }
    image.iter().map(|&v| f64::from(v)).sum()
}

fn thread_cpu_ms() -> f64 {
    let mut now = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes one timespec, which `now` is.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut now) };
    now.tv_sec as f64 * 1e3 + now.tv_nsec as f64 / 1e6
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        (values[n / 2 - 1] + values[n / 2]) / 2.0
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_workload_is_the_same_work_every_time_and_its_times_are_positive() {
        assert_eq!(super::workload().to_bits(), super::workload().to_bits());
        // Pinned to core 0 (every machine has one), as a runner pins it to its cores.
        let calibration = super::measure_on(&[0]);
        assert_eq!(calibration.workload, super::WORKLOAD);
        assert_eq!(calibration.runs, super::REPEATS);
        assert!(calibration.cpu_ms > 0.0 && calibration.wall_ms > 0.0, "{calibration:?}");
        // On one thread with nothing to wait for, CPU time cannot exceed wall time by much.
        assert!(calibration.cpu_ms <= calibration.wall_ms * 1.05 + 1.0, "{calibration:?}");
    }
}
