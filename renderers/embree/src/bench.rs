//! `fbksd-embree bench`: samples and rays per second, one thread and all
//! cores, best of three runs each.

use crate::render::render_image;
use std::path::Path;
use std::time::Instant;

/// Times each scene and prints one line per scene.
pub fn run(scenes: &[std::path::PathBuf], spp: u64, out_dir: Option<&Path>) -> anyhow::Result<()> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    for path in scenes {
        let scene = crate::pbrt::load(path)?;
        let samples = scene.width() as f64 * scene.height() as f64 * spp as f64;
        let mut line = format!(
            "{:<24} {}×{} × {spp} spp, max depth {}:",
            scene.name,
            scene.width(),
            scene.height(),
            scene.max_depth
        );
        for threads in [1, cores] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
            let runs = if threads == 1 { 1 } else { 3 };
            let mut best = f64::INFINITY;
            let mut rays = 0;
            for i in 0..runs {
                let t = Instant::now();
                let image = pool.install(|| render_image(&scene, spp, i));
                best = best.min(t.elapsed().as_secs_f64());
                rays = image.rays;
                if let (Some(dir), true) = (out_dir, threads == cores && i == 0) {
                    std::fs::create_dir_all(dir)?;
                    fbksd_iqa::image::write_exr(
                        &dir.join(format!("{}.exr", scene.name)),
                        scene.width(),
                        scene.height(),
                        &image.rgb,
                    )?;
                }
            }
            line += &format!(
                "  {threads} thread{}: {:.2} M samples/s, {:.1} M rays/s",
                if threads == 1 { "" } else { "s" },
                samples / best / 1e6,
                rays as f64 / best / 1e6
            );
        }
        println!("{line}");
    }
    println!("(all features off: colour only; {cores} cores; best of 3 on all cores, 1 run on one thread)");
    Ok(())
}

/// Writes a scene made of diffuse triangle meshes, mesh area lights and a
/// pinhole camera as binary PLY files plus `scene.json`, which
/// `bench/mitsuba_bench.py` turns into the same scene for Mitsuba 3, and
/// `scene.xml`, the same as a Mitsuba scene file (for `fbksd-mitsuba`).
pub fn export_for_mitsuba(path: &Path, dir: &Path) -> anyhow::Result<()> {
    use crate::scene::light::Light;
    use crate::scene::material::Material;
    use crate::scene::shape::Geometry;
    use anyhow::bail;
    let scene = crate::pbrt::load(path)?;
    std::fs::create_dir_all(dir)?;
    if scene.camera.has_dof() || scene.has_motion || scene.has_instances() {
        bail!("export: only pinhole cameras and static scenes without instances");
    }
    let mut shapes = Vec::new();
    for (i, shape) in scene.shapes.iter().enumerate() {
        let Geometry::Mesh { positions, indices, .. } = &shape.geometry else {
            bail!("export: shape {i} is not a mesh")
        };
        let Material::Diffuse { reflectance } = &scene.materials[shape.material as usize] else {
            bail!("export: shape {i} is not diffuse")
        };
        let reflectance = reflectance.constant().ok_or_else(|| anyhow::anyhow!("export: shape {i} is textured"))?;
        let mut ply = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
            positions[0].len(),
            indices.len()
        )
        .into_bytes();
        for p in &positions[0] {
            p.iter().for_each(|v| ply.extend(v.to_le_bytes()));
        }
        for t in indices {
            ply.push(3);
            t.iter().for_each(|v| ply.extend((*v as i32).to_le_bytes()));
        }
        let file = format!("shape{i}.ply");
        std::fs::write(dir.join(&file), ply)?;
        let emitter = match shape.light.map(|l| &scene.lights[l as usize]) {
            Some(Light::Mesh { radiance, two_sided: false, .. }) => Some(radiance.to_array()),
            None => None,
            Some(_) => bail!("export: shape {i}'s light is not a one-sided mesh light"),
        };
        shapes.push(serde_json::json!({"ply": file, "reflectance": reflectance.to_array(), "emitter": emitter}));
    }
    let c = &scene.camera;
    let fov = 2.0 * c.tan_half_fov.atan().to_degrees();
    let json = serde_json::json!({
        "width": c.width, "height": c.height, "fov": fov, "max_depth": scene.max_depth,
        "camera_to_world": [c.camera_to_world.rows[0], c.camera_to_world.rows[1], c.camera_to_world.rows[2], [0.0, 0.0, 0.0, 1.0]],
        "shapes": shapes,
    });
    std::fs::write(dir.join("scene.json"), serde_json::to_vec_pretty(&json)?)?;
    std::fs::write(dir.join("scene.xml"), mitsuba_xml(&scene, &shapes))?;
    Ok(())
}

/// The same scene as a Mitsuba 3 XML file (for `fbksd-mitsuba`): the camera
/// (pbrt's x points right on the image, Mitsuba's left, hence the mirror),
/// a box filter, the path tracer at the same depth (Mitsuba counts the
/// camera's first hit as a vertex) with Russian roulette where pbrt starts it.
fn mitsuba_xml(scene: &crate::scene::Scene, shapes: &[serde_json::Value]) -> String {
    let c = &scene.camera;
    let r = &c.camera_to_world.rows;
    let matrix: Vec<String> = (0..3)
        .flat_map(|i| (0..4).map(move |j| if j == 0 { -r[i][j] } else { r[i][j] }))
        .chain([0.0, 0.0, 0.0, 1.0])
        .map(|v| v.to_string())
        .collect();
    let rgb = |v: &serde_json::Value| {
        v.as_array().map_or(String::new(), |a| a.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(", "))
    };
    let mut xml = format!(
        "<scene version=\"3.0.0\">\n  <integrator type=\"path\"><integer name=\"max_depth\" value=\"{}\"/><integer name=\"rr_depth\" value=\"2\"/></integrator>\n  <sensor type=\"perspective\">\n    <float name=\"fov\" value=\"{}\"/><string name=\"fov_axis\" value=\"smaller\"/>\n    <transform name=\"to_world\"><matrix value=\"{}\"/></transform>\n    <film type=\"hdrfilm\"><integer name=\"width\" value=\"{}\"/><integer name=\"height\" value=\"{}\"/><string name=\"pixel_format\" value=\"rgb\"/><rfilter type=\"box\"/></film>\n  </sensor>\n",
        scene.max_depth + 1,
        2.0 * c.tan_half_fov.atan().to_degrees(),
        matrix.join(" "),
        c.width,
        c.height
    );
    for s in shapes {
        xml += &format!(
            "  <shape type=\"ply\"><string name=\"filename\" value=\"{}\"/><boolean name=\"face_normals\" value=\"true\"/>\n    <bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"{}\"/></bsdf>\n",
            s["ply"].as_str().unwrap_or_default(),
            rgb(&s["reflectance"])
        );
        if !s["emitter"].is_null() {
            xml += &format!(
                "    <emitter type=\"area\"><rgb name=\"radiance\" value=\"{}\"/></emitter>\n",
                rgb(&s["emitter"])
            );
        }
        xml += "  </shape>\n";
    }
    xml + "</scene>\n"
}

/// How far two renderings of one scene agree beyond their noise: the
/// per-channel means, and the largest relative difference of block means
/// (blocks of `block × block` pixels average the noise away).
pub fn compare(a: &Path, b: &Path, block: usize) -> anyhow::Result<String> {
    let (wa, ha, pa) = fbksd_iqa::image::read_exr(a)?;
    let (wb, hb, pb) = fbksd_iqa::image::read_exr(b)?;
    anyhow::ensure!((wa, ha) == (wb, hb), "sizes differ: {wa}×{ha} and {wb}×{hb}");
    let (w, h) = (wa as usize, ha as usize);
    let mean = |p: &[f32], c: usize| p.iter().skip(c).step_by(3).map(|v| *v as f64).sum::<f64>() / (w * h) as f64;
    let means: Vec<(f64, f64)> = (0..3).map(|c| (mean(&pa, c), mean(&pb, c))).collect();
    let (bw, bh) = (w / block, h / block);
    let block_mean = |p: &[f32], bx: usize, by: usize| {
        let mut s = 0f64;
        for y in by * block..(by + 1) * block {
            for x in bx * block..(bx + 1) * block {
                s += (p[(y * w + x) * 3] + p[(y * w + x) * 3 + 1] + p[(y * w + x) * 3 + 2]) as f64;
            }
        }
        s / (block * block * 3) as f64
    };
    let (mut worst, mut sum) = (0f64, 0f64);
    for by in 0..bh {
        for bx in 0..bw {
            let (x, y) = (block_mean(&pa, bx, by), block_mean(&pb, bx, by));
            let d = (x - y).abs() / x.abs().max(y.abs()).max(1e-3);
            worst = worst.max(d);
            sum += d;
        }
    }
    let channels: Vec<String> =
        means.iter().map(|(x, y)| format!("{x:.4} vs {y:.4} ({:+.2}%)", 100.0 * (y - x) / x.abs().max(1e-9))).collect();
    Ok(format!(
        "channel means {}; {block}×{block} block means differ by {:.2}% on average, {:.2}% at most",
        channels.join(", "),
        100.0 * sum / (bw * bh) as f64,
        100.0 * worst
    ))
}
