//! The integrator's SIMD lanes against its general code, and its builds
//! for each instruction set against each other: the samples of every
//! production scene, with colour alone and with every feature, have the
//! same bits whichever way they are shaded.

use fbksd_embree::integrator::{Batch, Isa, Position, SampleValues, Wanted};
use fbksd_embree::scene::Scene;
use fbksd_renderer::sampler::{mix, Dimensions};
use std::path::PathBuf;

fn production_scenes() -> Vec<PathBuf> {
    let pool = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/production");
    let mut scenes: Vec<PathBuf> =
        std::fs::read_dir(pool).unwrap().map(|e| e.unwrap().path().join("small.pbrt")).filter(|p| p.exists()).collect();
    scenes.sort();
    assert!(scenes.len() >= 10, "{scenes:?}");
    scenes
}

/// `n` samples anywhere on the image, each with its own key.
fn starts(scene: &Scene, n: u64) -> Vec<(Position, Dimensions)> {
    let u = |i: u64, d: u64| (mix(i * 8 + d) >> 40) as f32 / (1u64 << 24) as f32;
    (0..n)
        .map(|i| {
            let position = Position {
                image_x: u(i, 0) * scene.width() as f32,
                image_y: u(i, 1) * scene.height() as f32,
                lens: [u(i, 2), u(i, 3)],
                time: u(i, 4),
                light: [u(i, 5), u(i, 6)],
            };
            (position, Dimensions::from_key(mix(i ^ 0xF00D)))
        })
        .collect()
}

/// Every value of a sample, as bits.
fn bits(v: &SampleValues) -> Vec<u32> {
    let mut vectors =
        vec![v.color, v.direct, v.diffuse, v.non_specular.world, v.non_specular.normal, v.non_specular.albedo];
    for h in &v.hits {
        vectors.extend([h.world, h.normal, h.albedo]);
    }
    let mut bits: Vec<u32> = vectors.iter().flat_map(|v| [v.x, v.y, v.z]).map(f32::to_bits).collect();
    bits.extend([v.depth.to_bits(), v.rays, v.repaired as u32]);
    bits
}

fn trace(isa: Isa, scene: &Scene, wanted: &Wanted) -> Vec<Vec<u32>> {
    // 300 samples: many full chunks of lanes, and a partial one.
    Batch::default().trace_with(isa, scene, starts(scene, 300), wanted).map(bits).collect()
}

#[test]
fn lanes_general_code_and_every_instruction_set_give_the_same_bits() {
    let colour = Wanted { radiance: true, ..Wanted::default() };
    let everything = Wanted { radiance: true, direct: true, geometry: true, diffuse: true, roughness_threshold: 0.1 };
    let features = Wanted { geometry: true, direct: true, ..Wanted::default() };
    let isas = Isa::available();
    for path in production_scenes() {
        let lanes = fbksd_embree::pbrt::load(&path).unwrap();
        let general = fbksd_embree::pbrt::load(&path).unwrap().with_general_shading();
        for wanted in [colour, everything, features] {
            let expected = trace(Isa::Baseline, &general, &wanted);
            assert!(expected.iter().any(|v| v[..3].iter().any(|c| *c != 0)), "{path:?}: something is seen");
            for isa in &isas {
                for (scene, how) in [(&lanes, "lanes"), (&general, "general code")] {
                    let got = trace(*isa, scene, &wanted);
                    let differ = got.iter().zip(&expected).filter(|(a, b)| a != b).count();
                    if let Some(i) = got.iter().zip(&expected).position(|(a, b)| a != b) {
                        let floats = |v: &[u32]| v.iter().map(|b| f32::from_bits(*b)).collect::<Vec<_>>();
                        panic!(
                            "{path:?}, {wanted:?}, {isa:?}, {how}: {differ} samples differ; sample {i}: {:?}, expected {:?}",
                            floats(&got[i]),
                            floats(&expected[i])
                        );
                    }
                }
            }
        }
    }
}

/// A regression test: with Embree's AVX2 kernels (any CPU without
/// AVX-512), a masked-off lane of a packet holding a NaN made Embree abort
/// the render on its check that every lane is a well-formed ray. Each
/// instruction set renders, and agrees with the CPU's best up to Embree's
/// own rounding.
#[test]
fn every_instruction_set_renders_a_scene_as_the_cpus_best_does() {
    let dir = tempfile::tempdir().unwrap();
    let cpu = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let isas: Vec<&str> = ["avx512", "avx2", "baseline"]
        .into_iter()
        .filter(|isa| match *isa {
            "avx512" => cpu.contains(" avx512bw") && cpu.contains(" avx512dq") && cpu.contains(" avx512vl"),
            "avx2" => cpu.contains(" avx2") && cpu.contains(" fma"),
            _ => true,
        })
        .collect();
    // Hair's curves are intersected by Embree's own kernels, whose SSE2 and
    // AVX2 versions differ in the last bits (FMA), and its thin-hair paths
    // are chaotic: an ulp decides some hits, so paths diverge. On an AMD
    // EPYC (AVX2), SSE2 against AVX2 moved a quarter of hair's pixels and
    // its mean by 1.1e-4, a fortieth of the render's own noise (standard
    // error of the mean 4.7e-3): hair is held to 1e-3, the rest to 1e-4.
    for (scene, tolerance) in [("cornell-box", 1e-4), ("glossy-spheres", 1e-4), ("hair", 1e-3)] {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join(format!("../../scenes/production/{scene}/small.pbrt"));
        let render = |isa: Option<&str>| {
            let out = dir.path().join(format!("{scene}-{}.exr", isa.unwrap_or("best")));
            let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_fbksd-embree"));
            command.arg("render").arg(&path).args(["--spp", "4", "--out"]).arg(&out);
            if let Some(isa) = isa {
                command.env("FBKSD_EMBREE_ISA", isa);
            }
            let result = command.output().unwrap();
            assert!(result.status.success(), "{scene} on {isa:?}: {}", String::from_utf8_lossy(&result.stderr));
            fbksd_iqa::image::read_exr(&out).unwrap().2
        };
        let best = render(None);
        let mean = |v: &[f32]| v.iter().map(|x| *x as f64).sum::<f64>() / v.len() as f64;
        for isa in &isas {
            let image = render(Some(isa));
            assert!(image.iter().all(|v| v.is_finite()), "{scene} on {isa}");
            let (a, b) = (mean(&best), mean(&image));
            assert!((a - b).abs() <= tolerance * a, "{scene} on {isa}: mean {b} against {a}");
        }
    }
}
