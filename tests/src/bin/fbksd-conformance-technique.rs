//! The conformance technique, Rust edition: runs one scenario and dumps
//! every tile it receives, so tests can check that the Rust, C++ and Python
//! clients deliver the same samples bit for bit. Its twins are
//! `tests/conformance/conformance.cpp` and `conformance.py`; the three must
//! stay line-for-line equivalent.
//!
//! `FBKSD_CONFORMANCE=spp|count|input-spp|input-count` picks the scenario,
//! `FBKSD_CONFORMANCE_OUT` the dump file. The layout holds every element
//! (all random parameters, every feature, the second intersection of the
//! numbered ones); the input scenarios make all random parameters INPUT and
//! write them from the formulas in [`params`]. Dump records, little-endian:
//! `u32 begin_x, end_x, begin_y, end_y, spp, sample_size; u64 count;` then
//! `count × sample_size` f32.

use fbksd_client::{BenchmarkClient, ElementIo, Feature, RandomParameter, SampleLayout, Spp};
use std::io::Write;

const NUMBERED: [&str; 9] = [
    "WORLD_X",
    "WORLD_Y",
    "WORLD_Z",
    "NORMAL_X",
    "NORMAL_Y",
    "NORMAL_Z",
    "TEXTURE_COLOR_R",
    "TEXTURE_COLOR_G",
    "TEXTURE_COLOR_B",
];

/// The seven random parameters of sample `s` of pixel `(x, y)`: exact
/// binary fractions, so every language computes the same floats.
fn params(x: u64, y: u64, s: u64) -> [f32; 7] {
    [
        x as f32 + ((s % 4) as f32 + 0.5) / 4.0,
        y as f32 + (((3 * s) % 8) as f32 + 0.5) / 8.0,
        ((x + 3 * y + s) % 8) as f32 / 8.0,
        ((x + s) % 4) as f32 / 4.0,
        ((y + 5 * s) % 16) as f32 / 16.0,
        (s % 2) as f32 / 2.0,
        ((x * y + s) % 32) as f32 / 32.0,
    ]
}

struct Dump(std::io::BufWriter<std::fs::File>);

impl Dump {
    fn record(&mut self, rect: [u32; 4], spp: u32, size: usize, data: &[f32]) {
        let mut head = Vec::with_capacity(32);
        for v in [rect[0], rect[1], rect[2], rect[3], spp, size as u32] {
            head.extend_from_slice(&v.to_le_bytes());
        }
        head.extend_from_slice(&((data.len() / size) as u64).to_le_bytes());
        self.0.write_all(&head).unwrap();
        for v in data {
            self.0.write_all(&v.to_le_bytes()).unwrap();
        }
    }
}

fn main() -> anyhow::Result<()> {
    let scenario = std::env::var("FBKSD_CONFORMANCE")?;
    let out = std::env::var("FBKSD_CONFORMANCE_OUT")?;
    let input = scenario.starts_with("input-");
    let mut client = BenchmarkClient::from_args(std::env::args())?;
    let info = client.scene_info().clone();
    let (w, h) = (info.get::<i64>("width")? as u64, info.get::<i64>("height")? as u64);
    let max_spp = info.get::<i64>("max_spp")? as u64;

    let io = if input { ElementIo::Input } else { ElementIo::Output };
    let mut layout = SampleLayout::new();
    for p in RandomParameter::ALL {
        layout = layout.with_io(p.name(), io);
    }
    for f in Feature::ALL {
        layout = layout.with(f.name());
    }
    for name in NUMBERED {
        layout = layout.with_number(name, 1);
    }
    client.set_sample_layout(&layout)?;
    let size = client.sample_size();
    let mut dump = Dump(std::io::BufWriter::new(std::fs::File::create(out)?));

    match scenario.as_str() {
        "spp" => {
            for spp in [1, max_spp - 1] {
                client.evaluate_samples(Spp(spp), |t| {
                    dump.record([t.begin_x(), t.end_x(), t.begin_y(), t.end_y()], t.spp(), size, t.data())
                })?;
            }
        }
        "count" => {
            for count in [w * h + 7, max_spp * w * h - (w * h + 7)] {
                client.evaluate_sample_count(count, |data| dump.record([0; 4], 0, size, data))?;
            }
        }
        "input-spp" => {
            client.evaluate_input_samples(
                Spp(max_spp),
                |t| {
                    for y in t.begin_y()..t.end_y() {
                        for x in t.begin_x()..t.end_x() {
                            for s in 0..t.spp() {
                                let p = params(x as u64, y as u64, s as u64);
                                t.sample_mut(x, y, s)[..7].copy_from_slice(&p);
                            }
                        }
                    }
                },
                |t| dump.record([t.begin_x(), t.end_x(), t.begin_y(), t.end_y()], t.spp(), size, t.data()),
            )?;
        }
        "input-count" => {
            let mut k = 0u64;
            client.evaluate_input_sample_count(
                max_spp * w * h,
                |data| {
                    for sample in data.chunks_mut(size) {
                        let p = params(k % w, (k / w) % h, k / (w * h));
                        sample[..7].copy_from_slice(&p);
                        k += 1;
                    }
                },
                |data| dump.record([0; 4], 0, size, data),
            )?;
        }
        other => anyhow::bail!("unknown scenario {other:?}"),
    }
    dump.0.flush()?;
    client.send_result()?;
    Ok(())
}
