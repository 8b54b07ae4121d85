//! Box filter: each pixel is the mean of its samples. The simplest denoiser,
//! and the first example of the FBKSD Rust API.
//!
//! `FBKSD_BOX_EXTRA_FEATURES=1` also requests the eleven geometric features
//! (14 floats per sample) without using them: the transport benchmark uses
//! it to move realistic sample sizes through a real technique.

use fbksd_client::{BenchmarkClient, SampleLayout, Spp};

fn main() -> anyhow::Result<()> {
    // STEP 1: connect and read the scene.
    let mut client = BenchmarkClient::from_args(std::env::args())?;
    let info = client.scene_info();
    let width = info.get::<i64>("width")? as usize;
    let height = info.get::<i64>("height")? as usize;
    let spp = info.get::<i64>("max_spp")? as u64;

    // STEP 2: the sample layout: colour only (plus ballast when benchmarking).
    let mut layout = SampleLayout::new().with("COLOR_R").with("COLOR_G").with("COLOR_B");
    if std::env::var_os("FBKSD_BOX_EXTRA_FEATURES").is_some() {
        for name in ["DEPTH", "WORLD_X", "WORLD_Y", "WORLD_Z", "NORMAL_X", "NORMAL_Y", "NORMAL_Z"] {
            layout = layout.with(name);
        }
        for name in ["TEXTURE_COLOR_R", "TEXTURE_COLOR_G", "TEXTURE_COLOR_B", "DIRECT_LIGHT_R"] {
            layout = layout.with(name);
        }
    }
    client.set_sample_layout(&layout)?;

    // STEP 3: request the whole budget and sum each pixel's samples.
    let mut sums = vec![0f64; width * height * 3];
    let size = client.sample_size();
    client.evaluate_samples(Spp(spp), |tile| {
        // A tile's samples are stored pixel by pixel, each pixel's samples
        // together: walk them in storage order.
        let tile_width = (tile.end_x() - tile.begin_x()) as usize;
        let per_pixel = tile.spp() as usize * size;
        for (i, samples) in tile.data().chunks_exact(per_pixel).enumerate() {
            let (x, y) = (tile.begin_x() as usize + i % tile_width, tile.begin_y() as usize + i / tile_width);
            let pixel = &mut sums[(y * width + x) * 3..][..3];
            for sample in samples.chunks_exact(size) {
                pixel[0] += sample[0] as f64;
                pixel[1] += sample[1] as f64;
                pixel[2] += sample[2] as f64;
            }
        }
    })?;

    // STEP 4: reconstruct: the mean of each pixel.
    let inv = 1.0 / spp as f64;
    for (out, sum) in client.result_buffer().iter_mut().zip(&sums) {
        *out = (sum * inv) as f32;
    }

    // STEP 5: send the result.
    client.send_result()?;
    Ok(())
}
