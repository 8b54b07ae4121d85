//! Speed and size of the results viewer, in headless Chromium on loopback:
//! a private page beside 9 published techniques, one 512×512 scene at
//! 4, 16 and 64 spp.
//!
//! `cargo bench -p fbksd-server --bench viewer`
//!
//! Prints the time from navigation to the first image on screen, the time
//! to switch the shown image, the exposure and the spp (median of 5), the
//! time to draw one panned frame, and the bytes the view transferred
//! against the raw EXR files of the same images.

#[path = "../tests/common/mod.rs"]
mod common;

use common::{push, spawn, technique_repository, Db, FakeRunner};
use fbksd_browser::Browser;
use reqwest::Method;
use std::time::Duration;

const SIZE: u32 = 512;
const SPPS: [u64; 3] = [4, 16, 64];
const TECHNIQUES: usize = 10;

fn reference(_: usize) -> Vec<f32> {
    (0..SIZE * SIZE * 3)
        .map(|i| {
            let p = i / 3;
            let (x, y) = ((p % SIZE) as f32 / SIZE as f32, (p / SIZE) as f32 / SIZE as f32);
            0.2 + 0.6 * (6.0 * x).sin().abs() * y + 0.1 * (i % 3) as f32
        })
        .collect()
}

/// The reference plus noise of a Monte Carlo estimate at `spp` (a fixed
/// pseudo-random sequence per technique).
fn noisy(technique: usize, spp: u64) -> Vec<f32> {
    let mut state = 0x9e37_79b9_7f4a_7c15u64 ^ (technique as u64 * 7919 + spp);
    let sigma = 0.4 / (spp as f32).sqrt() * (1.0 + technique as f32 / 10.0);
    reference(0)
        .into_iter()
        .map(|v| {
            state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            let u = (state >> 40) as f32 / (1u64 << 24) as f32;
            (v + sigma * (2.0 * u - 1.0) * 1.7).max(0.0)
        })
        .collect()
}

fn exr(pixels: &[f32]) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("image.exr");
    fbksd_iqa::image::write_exr(&path, SIZE, SIZE, pixels).unwrap();
    std::fs::read(path).unwrap()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let server = spawn(Db::Sqlite).await;
    let ada = server.user("ada@example.org").await;
    let bob = server.user("bob@example.org").await;
    let runner = FakeRunner::register(&server, "bench").await;
    let scenes = [common::PicturedScene { name: "bench-scene", tags: &["bench"] }];
    let mut sets = Vec::new();
    eprintln!("uploading {TECHNIQUES} techniques × {} budgets at {SIZE}²…", SPPS.len());
    for t in 0..TECHNIQUES {
        let (user, project) = if t == 0 { (&ada, "ada-denoiser".to_string()) } else { (&bob, format!("bob-{t}")) };
        server.create_project(user, &project, "public").await;
        let repo = technique_repository("box-filter-python");
        assert!(push(repo.path(), &server.clone_url(&project, &user.token), &["FBKSD_RUN"]).0);
        let job = runner.claim(5).await.expect("a job");
        let (set, _) = common::upload_pictured(
            &runner,
            &job,
            &common::Pictured {
                technique: &project,
                scenes: &scenes,
                spps: &SPPS,
                size: (SIZE, SIZE),
                reference: &reference,
                image: &|_, spp| noisy(t, spp),
                mse: &|_, spp| 0.01 * (1.0 + t as f64) / spp as f64,
                technique_ms: &|_, spp| (1 + t) as f64 * spp as f64,
                exr: &exr,
            },
        )
        .await;
        if t > 0 {
            bob.api(Method::POST, format!("{}/api/v1/results/{set}/publish", server.url)).send().await.unwrap();
        }
        sets.push(set);
    }
    // What the view shows at 4 spp: every technique's image and the reference, as EXR files.
    let exr_bytes: usize = (0..TECHNIQUES).map(|t| exr(&noisy(t, 4)).len()).sum::<usize>() + exr(&reference(0)).len();
    let raw_bytes = (TECHNIQUES + 1) * (SIZE * SIZE * 3 * 4) as usize;

    let browser = Browser::start().await;
    browser.log_in(&server.url, &ada.email, "a long enough password").await;
    // A warm-up visit (the browser's own start-up is not the page's).
    browser.goto(&format!("{}/results/{}#scene=bench-scene&spp=64", server.url, sets[1])).await;
    browser.wait_for("warm-up", "FBKSD.firstImageMs !== undefined", Duration::from_secs(30)).await;

    browser.goto(&format!("{}/results/{}#scene=bench-scene&spp=4", server.url, sets[0])).await;
    let first = browser.wait_for("the first image", "FBKSD.firstImageMs", Duration::from_secs(30)).await;
    let all_crops = format!("document.querySelectorAll('canvas.crop[data-centre]').length === {}", TECHNIQUES + 1);
    browser.wait_for("every crop", &all_crops, Duration::from_secs(30)).await;
    let transfer = browser
        .eval(
            "const e = performance.getEntriesByType('resource').concat(performance.getEntriesByType('navigation')); \
             const px = e.filter(r => r.name.includes('.fbpx') || r.name.includes('/references/')); \
             return { all: e.reduce((s, r) => s + r.transferSize, 0), pixels: px.reduce((s, r) => s + r.transferSize, 0), \
             files: px.length };",
        )
        .await;

    let timed = |change: &str| {
        format!(
            "const v = FBKSD.viewer; const t = performance.now(); v.set({change}); await v.showing; return performance.now() - t;"
        )
    };
    let mut switch_image = Vec::new();
    let mut switch_exposure = Vec::new();
    let mut switch_spp = Vec::new();
    let keys: Vec<String> = sets.iter().map(|s| format!("'{s}'")).collect();
    for i in 0..5 {
        switch_image.push(browser.eval_async(&timed(&format!("{{ a: {} }}", keys[1 + i]))).await.as_f64().unwrap());
        switch_exposure.push(
            browser.eval_async(&timed(&format!("{{ exposure: {} }}", (i + 1) as f64 * 0.5))).await.as_f64().unwrap(),
        );
    }
    // The first visit of an spp loads its 11 pixel files; later ones are cached.
    let mut first_visits = Vec::new();
    for spp in [16, 64] {
        first_visits.push(browser.eval_async(&timed(&format!("{{ spp: {spp} }}"))).await.as_f64().unwrap());
        browser.wait_for("every crop", &all_crops, Duration::from_secs(30)).await;
    }
    for spp in [4, 16, 64, 4, 16] {
        switch_spp.push(browser.eval_async(&timed(&format!("{{ spp: {spp} }}"))).await.as_f64().unwrap());
    }
    let pan = browser
        .eval("const c = FBKSD.viewer.comparison; const t = performance.now(); for (let i = 0; i < 120; i++) { c.panBy(1, 0); c.draw(); } return (performance.now() - t) / 120;")
        .await
        .as_f64()
        .unwrap();
    browser.close().await;

    let pixels = transfer["pixels"].as_f64().unwrap();
    println!("viewer, {TECHNIQUES} techniques + reference at {SIZE}×{SIZE} (headless Chromium, loopback, 2 cores):");
    println!("  first image on screen: {:.0} ms after navigation", first.as_f64().unwrap());
    println!(
        "  switch image: {:.1} ms   exposure: {:.1} ms   spp: {:.1} ms (medians of 5); spp first visited (its 11 pixel files load): {:.0} and {:.0} ms",
        median(switch_image),
        median(switch_exposure),
        median(switch_spp),
        first_visits[0],
        first_visits[1]
    );
    println!("  one panned frame: {pan:.2} ms ({:.0} frames/s possible)", 1000.0 / pan);
    println!(
        "  transferred for the view: {:.2} MB in all; pixel files {:.2} MB ({} files) against {:.2} MB of ZIP-compressed EXR files ({:.2}×) and {:.2} MB of raw floats ({:.2}×)",
        transfer["all"].as_f64().unwrap() / 1e6,
        pixels / 1e6,
        transfer["files"],
        exr_bytes as f64 / 1e6,
        pixels / exr_bytes as f64,
        raw_bytes as f64 / 1e6,
        pixels / raw_bytes as f64
    );
}
