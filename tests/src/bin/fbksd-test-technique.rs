//! A technique with many behaviours, chosen by its first argument, for the
//! end-to-end tests: well-behaved scenarios that check every delivered
//! sample against the analytic renderer's formulas (exiting non-zero on any
//! mismatch), and misbehaviours the manager must contain.

use anyhow::{bail, ensure, Context};
use fbksd_analytic_renderer::features;
use fbksd_client::{BenchmarkClient, ElementIo, ErrorKind, Feature, RandomParameter, SampleLayout, Spp};
use fbksd_core::layout::Element;
use fbksd_core::protocol::{read_frame, write_frame, FromTechnique, Hello, Role, ToTechnique};
use std::os::unix::net::UnixStream;

fn main() -> anyhow::Result<()> {
    let mode = std::env::args().nth(1).context("usage: fbksd-test-technique <mode>")?;
    match mode.as_str() {
        "all-elements" => all_elements(),
        "exact-budget" => exact_budget(),
        "over-budget" => over_budget(),
        "input-spp" => input_spp(),
        "input-count" => input_count(),
        "crash" => {
            let _client = BenchmarkClient::connect()?;
            std::process::abort()
        }
        "hang" => {
            let _client = BenchmarkClient::connect()?;
            loop {
                std::thread::sleep(std::time::Duration::from_secs(3600));
            }
        }
        "no-result" => {
            let mut client = BenchmarkClient::connect()?;
            client.set_sample_layout(&SampleLayout::new().with("COLOR_R"))?;
            client.evaluate_samples(Spp(1), |_| {})?;
            Ok(())
        }
        "nan-result" => {
            let mut client = BenchmarkClient::connect()?;
            client.result_buffer()[4] = f32::NAN;
            client.send_result()?;
            Ok(())
        }
        "no-token" => {
            // Connects as if it were some other process: no session token.
            let dir = fbksd_core::rendezvous::from_env().context("no rendezvous")?;
            let mut stream = UnixStream::connect(fbksd_core::rendezvous::control_socket(&dir))?;
            write_frame(&mut stream, &Hello { session: None, ..Hello::new(Role::Technique) })?;
            let answer: Option<ToTechnique> = read_frame(&mut stream)?;
            eprintln!("manager answered: {answer:?}");
            Ok(())
        }
        "wrong-size" => raw_session(FromTechnique::SendResult { width: 1, height: 1, channels: 3 }),
        "duplicate-layout" => raw_session(FromTechnique::SetLayout {
            layout: SampleLayout::new().with("COLOR_R").with("COLOR_G").with("COLOR_R"),
        }),
        "denormals-and-negatives" => {
            // A legitimate image of odd floats: denormals, negatives, huge and zero values.
            let mut client = BenchmarkClient::connect()?;
            client.set_sample_layout(&SampleLayout::new().with("COLOR_R"))?;
            client.evaluate_samples(Spp(1), |_| {})?;
            let odd = [1e-40f32, -1.0, 3e38, 0.0, -0.0, f32::MIN_POSITIVE / 4.0];
            for (i, v) in client.result_buffer().iter_mut().enumerate() {
                *v = odd[i % odd.len()];
            }
            client.send_result()?;
            Ok(())
        }
        "idle-while-waiting" => waits_for_samples(None),
        "burn-while-waiting" => waits_for_samples(Some(Work::Burn)),
        "sleep-before-request" => waits_for_samples(Some(Work::SleepFirst)),
        "burn-in-child" => waits_for_samples(Some(Work::Child)),
        "burn-before-hello" => {
            burn_a_second();
            waits_for_samples(None)
        }
        "burn-cpu" => {
            burn_a_second();
            Ok(())
        }
        "box-filter" => box_filter(false, extra_work()?, 0.0),
        "box-filter-doubled" => box_filter(true, extra_work()?, 0.0),
        "box-filter-jittered" => {
            let jitter = std::env::args().nth(2).context("box-filter-jittered <jitter>")?;
            box_filter(false, 0, jitter.parse().context("box-filter-jittered <jitter>: a number, e.g. 0.01")?)
        }
        other => bail!("unknown mode {other:?}"),
    }
}

/// What a technique does besides asking for samples.
enum Work {
    /// Burns a second of CPU in another thread, starting as it asks for samples.
    Burn,
    /// Sleeps a second before its request.
    SleepFirst,
    /// Runs a child process that burns a second of CPU, and waits for it.
    Child,
}

/// Burns a second of this thread's CPU (not of wall time: on a busy machine
/// the burn takes longer, and the charge must still be a second).
fn burn_a_second() -> u64 {
    let mut x = 1u64;
    while thread_cpu_seconds() < 1.0 {
        for _ in 0..100_000 {
            x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
        }
    }
    x
}

/// The box filters' optional second argument: rounds of arithmetic on each
/// sample, to give the technique weight beside the renderer (0 by default).
fn extra_work() -> anyhow::Result<u32> {
    std::env::args().nth(2).map_or(Ok(0), |n| n.parse().context("box-filter [rounds of work per sample]"))
}

/// A box filter (each pixel the mean of its samples) that also does
/// `rounds` of arithmetic per sample; `doubled`, the same program with a
/// busy loop that doubles its work: before sending its result it burns as
/// much CPU again as it has used since its hello. With a `jitter`, the
/// image is scaled by 1 + jitter · u, u one of seven steps in [−1, 1]
/// picked by the first sample of pixel (0, 0): a box filter off by an amount that
/// changes from seed to seed, for errors too close to call on three seeds.
fn box_filter(doubled: bool, rounds: u32, jitter: f64) -> anyhow::Result<()> {
    let mut client = BenchmarkClient::connect()?;
    let since_hello = process_cpu_seconds();
    let width = client.scene_info().get::<i64>("width")? as usize;
    let spp = client.scene_info().get::<i64>("max_spp")? as u64;
    client.set_sample_layout(&SampleLayout::new().with("COLOR_R").with("COLOR_G").with("COLOR_B"))?;
    let mut sums = vec![0f64; client.result_buffer().len()];
    let mut first_sample = None;
    client.evaluate_samples(Spp(spp), |tile| {
        // Pixel (0, 0)'s: tiles may come in any order.
        if (tile.begin_x(), tile.begin_y()) == (0, 0) {
            first_sample = Some(tile.sample(0, 0, 0)[0]);
        }
        for y in tile.begin_y()..tile.end_y() {
            for x in tile.begin_x()..tile.end_x() {
                let pixel = (y as usize * width + x as usize) * 3;
                for s in 0..tile.spp() {
                    for (c, v) in tile.sample(x, y, s)[..3].iter().enumerate() {
                        let mut v = *v as f64;
                        for _ in 0..rounds {
                            v = std::hint::black_box(v * 1.0000001 + 1e-12) - 1e-12;
                        }
                        sums[pixel + c] += v;
                    }
                }
            }
        }
    })?;
    let step = (first_sample.unwrap_or(0.0) as f64 * 1000.0).floor().rem_euclid(7.0);
    let scale = 1.0 + jitter * (step - 3.0) / 3.0;
    for (out, sum) in client.result_buffer().iter_mut().zip(&sums) {
        *out = (scale * sum / spp as f64) as f32;
    }
    if doubled {
        let until = 2.0 * process_cpu_seconds() - since_hello;
        let mut x = 1u64;
        while process_cpu_seconds() < until {
            for _ in 0..1000 {
                x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
            }
        }
    }
    client.send_result()?;
    Ok(())
}

/// CPU time of this process so far, every thread, to the nanosecond.
fn process_cpu_seconds() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes one timespec.
    unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

/// CPU time of the calling thread (user + system, from /proc, in 10 ms ticks).
fn thread_cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").unwrap_or_default();
    // Fields after the command's closing parenthesis: utime and stime are the 12th and 13th.
    let fields: Vec<&str> = stat.rsplit_once(')').map_or("", |(_, rest)| rest).split_whitespace().collect();
    let ticks: f64 = fields.get(11..13).map_or(0.0, |f| f.iter().filter_map(|v| v.parse::<f64>().ok()).sum());
    ticks / 100.0
}

/// Asks for 1 spp (from a slow renderer) and sends the samples' mean, doing
/// `work` too; the manager must charge the work, not the waiting.
fn waits_for_samples(work: Option<Work>) -> anyhow::Result<()> {
    let mut client = BenchmarkClient::connect()?;
    client.set_sample_layout(&SampleLayout::new().with("COLOR_R"))?;
    let burner = match work {
        Some(Work::Burn) => Some(std::thread::spawn(burn_a_second)),
        Some(Work::Child) => {
            let mut child = std::process::Command::new(std::env::current_exe()?).arg("burn-cpu").spawn()?;
            Some(std::thread::spawn(move || {
                let status = child.wait().expect("the child is waited for");
                assert!(status.success(), "the burning child failed: {status}");
                0
            }))
        }
        Some(Work::SleepFirst) => {
            std::thread::sleep(std::time::Duration::from_secs(1));
            None
        }
        None => None,
    };
    let mut sum = 0.0;
    client.evaluate_samples(Spp(1), |tile| sum += tile.data().iter().map(|v| *v as f64).sum::<f64>())?;
    if let Some(b) = burner {
        b.join().expect("the burner ends");
    }
    let value = sum as f32;
    client.result_buffer().iter_mut().for_each(|v| *v = value);
    client.send_result()?;
    Ok(())
}

/// Speaks the protocol directly, to send what the client library never would.
fn raw_session(message: FromTechnique) -> anyhow::Result<()> {
    let dir = fbksd_core::rendezvous::from_env().context("no rendezvous")?;
    let mut stream = UnixStream::connect(fbksd_core::rendezvous::control_socket(&dir))?;
    write_frame(&mut stream, &Hello::new(Role::Technique))?;
    let _welcome: Option<ToTechnique> = read_frame(&mut stream)?;
    write_frame(&mut stream, &message)?;
    let answer: Option<ToTechnique> = read_frame(&mut stream)?;
    eprintln!("manager answered: {answer:?}");
    Ok(())
}

fn full_layout() -> SampleLayout {
    let mut layout = SampleLayout::new().with_roughness_threshold(0.25);
    for f in Feature::ALL.iter().rev() {
        layout = layout.with(f.name());
        if f.is_numbered() {
            layout = layout.with_number(f.name(), 1);
        }
    }
    for p in RandomParameter::ALL {
        layout = layout.with(p.name());
    }
    layout
}

/// Checks one sample against the analytic formulas; returns its params.
fn check_sample(sample: &[f32], layout: &fbksd_core::CompiledLayout, w: u32, h: u32) -> anyhow::Result<[f32; 7]> {
    let mut params = [0f32; 7];
    for p in RandomParameter::ALL {
        let i = layout.parameter_offset(*p).context("layout lacks a parameter")?;
        params[p.index()] = sample[i];
    }
    let (x, y) = (params[0], params[1]);
    ensure!(x >= 0.0 && x < w as f32 && y >= 0.0 && y < h as f32, "IMAGE_X/Y ({x}, {y}) outside the image");
    for p in &params[2..] {
        ensure!((0.0..1.0).contains(p), "parameter {p} outside [0, 1)");
    }
    for (i, (element, _)) in layout.elements().iter().enumerate() {
        if let Element::Feature(f, n) = element {
            let want = features(*f, *n, &params, w, h, layout.roughness_threshold());
            ensure!(
                sample[i] == want,
                "{element} at offset {i} is {} but should be {want} (params {params:?})",
                sample[i]
            );
        }
    }
    Ok(params)
}

fn dims(client: &BenchmarkClient) -> anyhow::Result<(u32, u32, u64)> {
    let info = client.scene_info();
    Ok((info.get::<i64>("width")? as u32, info.get::<i64>("height")? as u32, info.get::<i64>("max_spp")? as u64))
}

/// Every layout element, SPP requests: each sample is checked, each pixel
/// must get exactly its samples inside its own area, and the result is the
/// box filter of the colour.
fn all_elements() -> anyhow::Result<()> {
    let mut client = BenchmarkClient::connect()?;
    let (w, h, spp) = dims(&client)?;
    let layout = full_layout();
    let compiled = layout.compile()?;
    client.set_sample_layout(&layout)?;
    let mut counts = vec![0u32; (w * h) as usize];
    let mut sums = vec![0f64; (w * h * 3) as usize];
    let mut error = None;
    client.evaluate_samples(Spp(spp), |tile| {
        for y in tile.begin_y()..tile.end_y() {
            for x in tile.begin_x()..tile.end_x() {
                for s in 0..tile.spp() {
                    let sample = tile.sample(x, y, s);
                    match check_sample(sample, &compiled, w, h) {
                        Ok(p) if p[0].floor() as u32 == x && p[1].floor() as u32 == y => {}
                        Ok(p) => error = Some(format!("sample of pixel ({x}, {y}) lies at ({}, {})", p[0], p[1])),
                        Err(e) => error = Some(e.to_string()),
                    }
                    let i = (y * w + x) as usize;
                    counts[i] += 1;
                    for c in 0..3 {
                        sums[i * 3 + c] += sample[compiled.feature_offset(Feature::ALL[c], 0).unwrap()] as f64;
                    }
                }
            }
        }
    })?;
    if let Some(e) = error {
        bail!(e);
    }
    ensure!(counts.iter().all(|&c| c as u64 == spp), "some pixel did not get exactly {spp} samples");
    ensure!(client.remaining_samples() == 0, "budget not spent");
    for (o, s) in client.result_buffer().iter_mut().zip(&sums) {
        *o = (s / spp as f64) as f32;
    }
    client.send_result()?;
    Ok(())
}

/// The budget spent in three requests of different kinds, exactly.
fn exact_budget() -> anyhow::Result<()> {
    let mut client = BenchmarkClient::connect()?;
    let (w, h, spp) = dims(&client)?;
    ensure!(spp >= 3, "needs a budget of at least 3 spp");
    let pixels = (w * h) as u64;
    let layout = full_layout();
    let compiled = layout.compile()?;
    client.set_sample_layout(&layout)?;
    let mut seen = 0u64;
    client.evaluate_samples(Spp(spp - 2), |tile| seen += tile.len())?;
    let size = client.sample_size();
    let mut check = |data: &[f32]| -> anyhow::Result<()> {
        for sample in data.chunks_exact(size) {
            check_sample(sample, &compiled, w, h)?;
            seen += 1;
        }
        Ok(())
    };
    let mut error = None;
    // More than a pixel's worth so the count splits into spp + remainder, then the rest.
    for count in [pixels + 7, pixels - 7] {
        client.evaluate_sample_count(count, |d| {
            if let Err(e) = check(d) {
                error = Some(e);
            }
        })?;
    }
    if let Some(e) = error {
        return Err(e);
    }
    ensure!(seen == spp * pixels, "saw {seen} samples, budget {}", spp * pixels);
    ensure!(client.remaining_samples() == 0, "remaining {}", client.remaining_samples());
    client.send_result()?;
    Ok(())
}

/// Spends the budget, then asks for one sample more: the manager must refuse.
fn over_budget() -> anyhow::Result<()> {
    let mut client = BenchmarkClient::connect()?;
    let (_, _, spp) = dims(&client)?;
    client.set_sample_layout(&SampleLayout::new().with("COLOR_R"))?;
    client.evaluate_samples(Spp(spp), |_| {})?;
    match client.evaluate_sample_count(1, |_| {}) {
        Err(fbksd_client::ClientError::Refused { kind: ErrorKind::OverBudget, message }) => {
            eprintln!("refused as expected: {message}");
            std::process::exit(0)
        }
        other => bail!("expected an over-budget refusal, got {other:?}"),
    }
}

fn input_layout() -> SampleLayout {
    let mut layout = SampleLayout::new();
    for p in RandomParameter::ALL {
        layout = layout.with_io(p.name(), ElementIo::Input);
    }
    layout.with("COLOR_R").with("COLOR_G").with("COLOR_B").with("DEPTH").with_number("NORMAL_Z", 1).with("WORLD_Z_NS")
}

/// A deterministic position for sample `s` of pixel `(x, y)`.
fn my_params(x: u32, y: u32, s: u32) -> [f32; 7] {
    let u = |k: u32| ((x * 7 + y * 13 + s * 31 + k * 17) % 97) as f32 / 97.0;
    [x as f32 + u(0), y as f32 + u(1), u(2), u(3), u(4), u(5), u(6)]
}

/// INPUT parameters written per pixel; the renderer must use them.
fn input_spp() -> anyhow::Result<()> {
    let mut client = BenchmarkClient::connect()?;
    let (w, h, spp) = dims(&client)?;
    let layout = input_layout();
    let compiled = layout.compile()?;
    client.set_sample_layout(&layout)?;
    let mut error = None;
    let mut consumed = 0u64;
    client.evaluate_input_samples(
        Spp(spp),
        |tile| {
            for y in tile.begin_y()..tile.end_y() {
                for x in tile.begin_x()..tile.end_x() {
                    for s in 0..tile.spp() {
                        tile.sample_mut(x, y, s)[..7].copy_from_slice(&my_params(x, y, s));
                    }
                }
            }
        },
        |tile| {
            for y in tile.begin_y()..tile.end_y() {
                for x in tile.begin_x()..tile.end_x() {
                    for s in 0..tile.spp() {
                        consumed += 1;
                        let sample = tile.sample(x, y, s);
                        if sample[..7] != my_params(x, y, s) {
                            error = Some(format!("INPUT parameters of ({x}, {y}, {s}) were overwritten"));
                        } else if let Err(e) = check_sample(sample, &compiled, w, h) {
                            error = Some(e.to_string());
                        }
                    }
                }
            }
        },
    )?;
    if let Some(e) = error {
        bail!(e);
    }
    ensure!(consumed == spp * (w * h) as u64, "consumed {consumed}");
    client.send_result()?;
    Ok(())
}

/// INPUT parameters for free samples (count request), all in one corner pixel.
fn input_count() -> anyhow::Result<()> {
    let mut client = BenchmarkClient::connect()?;
    let (w, h, spp) = dims(&client)?;
    let layout = input_layout();
    let compiled = layout.compile()?;
    client.set_sample_layout(&layout)?;
    let size = client.sample_size();
    let total = spp * (w * h) as u64;
    let mut produced = 0u32;
    let mut consumed = 0u32;
    let mut error = None;
    client.evaluate_input_sample_count(
        total,
        |data| {
            for sample in data.chunks_exact_mut(size) {
                sample[..7].copy_from_slice(&my_params(0, 0, produced));
                produced += 1;
            }
        },
        |data| {
            for sample in data.chunks_exact(size) {
                if sample[0] >= 1.0 || sample[1] >= 1.0 {
                    error = Some(format!("sample {consumed} not where the technique put it: {:?}", &sample[..2]));
                }
                if let Err(e) = check_sample(sample, &compiled, w, h) {
                    error = Some(e.to_string());
                }
                consumed += 1;
            }
        },
    )?;
    if let Some(e) = error {
        bail!(e);
    }
    ensure!(
        consumed as u64 == total && produced as u64 == total,
        "produced {produced}, consumed {consumed} of {total}"
    );
    client.send_result()?;
    Ok(())
}
