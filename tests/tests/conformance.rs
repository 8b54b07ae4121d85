//! Conformance of the three client bindings: the same scenarios (samples
//! per pixel, sample counts, INPUT samples per pixel and by count, with a
//! layout holding every element) run through the Rust, C++ and Python
//! editions of the conformance technique against the analytic renderer, and
//! every sample each receives is the same, bit for bit.

use fbksd_tests::{analytic_scene, bin, compile_cpp, python_path};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

const W: u32 = 23;
const H: u32 = 17;
const SPP: u64 = 5;
/// Every element: 7 random parameters, 28 features, 9 second intersections.
const SAMPLE_SIZE: usize = 44;

/// The samples of one dump: pixel samples by (x, y, index within the
/// pixel's samples of that request, request), and free samples sorted.
#[derive(Debug, PartialEq, Default)]
struct Received {
    pixels: BTreeMap<(u32, u32, u32, u32), Vec<u32>>,
    free: Vec<Vec<u32>>,
}

fn parse(bytes: &[u8]) -> Received {
    fn take<'a>(rest: &mut &'a [u8], n: usize) -> &'a [u8] {
        let (s, tail) = rest.split_at(n);
        *rest = tail;
        s
    }
    let mut rest = bytes;
    let u32s = |s: &[u8]| s.chunks(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect::<Vec<_>>();
    let mut received = Received::default();
    // Pixel tiles of one request arrive before the next request's.
    let mut request = 0;
    let mut last_spp = None;
    while !rest.is_empty() {
        let head = u32s(take(&mut rest, 24));
        let count = u64::from_le_bytes(take(&mut rest, 8).try_into().unwrap()) as usize;
        let (bx, ex, by, ey, spp, size) = (head[0], head[1], head[2], head[3], head[4], head[5] as usize);
        assert_eq!(size, SAMPLE_SIZE);
        let data = u32s(take(&mut rest, count * size * 4));
        if spp == 0 {
            received.free.extend(data.chunks(size).map(<[u32]>::to_vec));
            continue;
        }
        if last_spp.is_some_and(|s| s != spp) {
            request += 1;
        }
        last_spp = Some(spp);
        assert_eq!(count as u32, (ex - bx) * (ey - by) * spp);
        let mut samples = data.chunks(size);
        for y in by..ey {
            for x in bx..ex {
                for s in 0..spp {
                    let old = received.pixels.insert((x, y, s, request), samples.next().unwrap().to_vec());
                    assert!(old.is_none(), "pixel ({x}, {y}) sample {s} delivered twice");
                }
            }
        }
    }
    received.free.sort();
    received
}

fn conformance(scenario: &str) {
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let cpp = compile_cpp(&[&root.join("conformance/conformance.cpp")], &dir.path().join("conformance-cpp"));
    let scene = analytic_scene(dir.path(), "conformance", W, H);
    let dumps = dir.path().join("dumps");
    std::fs::create_dir(&dumps).unwrap();
    let mut techniques = Vec::new();
    for (name, command) in [
        ("rust", bin("fbksd-conformance-technique")),
        ("cpp", cpp.display().to_string()),
        ("python", root.join("conformance/conformance.py").display().to_string()),
    ] {
        // Each edition dumps to the file named after it: a wrapper sets the name.
        let wrapper = dir.path().join(format!("{name}.sh"));
        std::fs::write(
            &wrapper,
            format!("#!/bin/sh\nFBKSD_CONFORMANCE_OUT={}/{name}.bin exec {command}\n", dumps.display()),
        )
        .unwrap();
        std::fs::set_permissions(&wrapper, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
        techniques.extend(["-t".to_string(), format!("{name}={}", wrapper.display())]);
    }
    let output = Command::new(bin("fbksd"))
        .arg("run")
        .args(&techniques)
        .args(["-r", &bin("fbksd-analytic-renderer"), "-s", scene.to_str().unwrap()])
        .args(["--spp", &SPP.to_string(), "--results", dir.path().join("results").to_str().unwrap()])
        .env("FBKSD_CONFORMANCE", scenario)
        .env("PYTHONPATH", python_path())
        .output()
        .unwrap();
    assert!(output.status.success(), "{scenario}: {}", String::from_utf8_lossy(&output.stderr));

    let read = |name: &str| parse(&std::fs::read(dumps.join(format!("{name}.bin"))).unwrap());
    let rust = read("rust");
    let pixels = (W * H) as u64;
    match scenario {
        "spp" | "input-spp" => {
            assert_eq!(rust.pixels.len() as u64, SPP * pixels, "{scenario}: every pixel sample once");
            assert!(rust.free.is_empty());
        }
        _ => {
            assert_eq!(rust.free.len() as u64, SPP * pixels, "{scenario}: every requested sample");
            assert!(rust.pixels.is_empty());
        }
    }
    if scenario.starts_with("input-") {
        // The renderer saw the technique's parameters: IMAGE_X of the first sample of pixel (x, y) is x + 1/8.
        if let Some(first) = rust.pixels.get(&(3, 2, 0, 0)) {
            assert_eq!(f32::from_bits(first[0]), 3.125);
        }
    }
    for other in ["cpp", "python"] {
        let theirs = read(other);
        assert!(theirs == rust, "{scenario}: the {other} client received other samples than the Rust client");
    }
}

#[test]
fn samples_per_pixel_are_identical_in_rust_cpp_and_python() {
    conformance("spp");
}

#[test]
fn sample_counts_are_identical_in_rust_cpp_and_python() {
    conformance("count");
}

#[test]
fn input_samples_per_pixel_are_identical_in_rust_cpp_and_python() {
    conformance("input-spp");
}

#[test]
fn input_sample_counts_are_identical_in_rust_cpp_and_python() {
    conformance("input-count");
}
