//! The environments hold what `fbksd_exchange::environments` (and so the
//! `/environments` page, README and the build hints) says they hold: every
//! package at its listed version, every listed header and module present,
//! and OpenEXR reachable under OpenEXR 2's names as 2.x-era builds ask.
//! Prints each image's size.

mod common;

use common::*;
use fbksd_exchange::environments::Source;
use fbksd_exchange::technique::Environment;
use std::process::Command;

/// Runs `script` in a throw-away container of `image` without network; its output.
fn in_image(image: &str, script: &str) -> Result<String, String> {
    let out = Command::new("docker")
        .args(["run", "--rm", "--network", "none", "--entrypoint", "sh", image, "-c", script])
        .output()
        .unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    if out.status.success() {
        Ok(String::from_utf8_lossy(&out.stdout).trim().to_string())
    } else {
        Err(text)
    }
}

#[test]
fn each_environment_holds_what_its_page_lists() {
    let manifest: serde_json::Value = serde_json::from_slice(&std::fs::read(images()).unwrap()).unwrap();
    for env in Environment::ALL {
        let image = manifest[env.as_str()].as_str().unwrap();
        // One container per environment: a line per installed version, and
        // every listed header or module that is not there.
        let mut script = String::new();
        for package in env.packages() {
            match package.source {
                Source::Debian(name) => {
                    script += &format!("echo \"{name} $(dpkg-query -W -f '${{Version}}' {name})\"\n")
                }
                Source::Wheel(name) => {
                    script += &format!(
                    "echo \"{name} $(python3 -c \"import importlib.metadata as m; print(m.version('{name}'))\")\"\n"
                )
                }
                Source::Fbksd => {}
            }
            for header in package.headers {
                script += &format!(
                    "found=; for d in /usr/include /usr/local/include /usr/include/OpenEXR /usr/include/Imath \
                     /usr/include/opencv4 /usr/include/eigen3 /usr/lib/gcc/x86_64-linux-gnu/12/include; do \
                     [ -e \"$d/{header}\" ] && found=1; done; [ -n \"$found\" ] || echo \"missing header {header}\"\n"
                );
            }
            for module in package.modules {
                script += &format!("python3 -c 'import {module}' 2>/dev/null || echo \"missing module {module}\"\n");
            }
        }
        let report = in_image(image, &script).unwrap_or_else(|e| panic!("{image}: {e}"));
        let missing: Vec<&str> = report.lines().filter(|l| l.starts_with("missing ")).collect();
        assert!(missing.is_empty(), "{}: {missing:?} in {image}", env.as_str());
        for package in env.packages() {
            let (Source::Debian(name) | Source::Wheel(name)) = package.source else { continue };
            let installed = report
                .lines()
                .find_map(|l| l.strip_prefix(&format!("{name} ")))
                .unwrap_or_else(|| panic!("{name} not reported: {report}"));
            // The upstream part: no epoch (`4:`), compared as a prefix.
            let installed = installed.rsplit(':').next().unwrap_or(installed);
            assert!(
                installed.starts_with(package.version),
                "{}: {} is listed at {} but {image} has {installed}",
                env.as_str(),
                package.name,
                package.version
            );
        }
        let size = Command::new("docker").args(["image", "inspect", "--format", "{{.Size}}", image]).output().unwrap();
        let bytes: u64 = String::from_utf8_lossy(&size.stdout).trim().parse().unwrap();
        eprintln!("FIGURE environment {}: image {image} is {:.0} MB", env.as_str(), bytes as f64 / 1e6);
    }

    // A 2.x-era build without CMake: OpenEXR 2's include directory and library names, and OpenMP.
    let cpp = manifest["cpp"].as_str().unwrap();
    let source = r#"#include <ImfRgbaFile.h>
#include <ImfArray.h>
#include <half.h>
#include <omp.h>
int main() {
    Imf::Array2D<Imf::Rgba> p(1, 1);
    p[0][0] = Imf::Rgba(half(0.5f), half(0.25f), half(1.f), half(1.f));
    { Imf::RgbaOutputFile f("/tmp/x.exr", 1, 1, Imf::WRITE_RGBA); f.setFrameBuffer(&p[0][0], 1, 1); f.writePixels(1); }
    Imf::RgbaInputFile f("/tmp/x.exr");
    return float(p[0][0].g) == 0.25f && omp_get_max_threads() > 0 ? 0 : 1;
}"#;
    let built = in_image(
        cpp,
        &format!(
            "cd /tmp && cat > x.cpp <<'EOF'\n{source}\nEOF\n\
             g++ -fopenmp -I/usr/include/OpenEXR x.cpp -o x -lIlmImf -lHalf -lIex && ./x && echo ran"
        ),
    );
    assert_eq!(built.as_deref(), Ok("ran"), "{built:?}");
}
