//! `fbksd results page` as a researcher uses it: benchmark a small scene,
//! compute the metrics, write the viewer folder and open its index.html
//! from file:// in Chromium, where it shows the result's own pixels.

use fbksd_browser::Browser;
use fbksd_tests::{bin, scene_meta};
use std::process::Command;
use std::time::Duration;

fn fbksd(args: &[&str]) -> String {
    let o = Command::new(bin("fbksd")).args(args).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "fbksd {args:?}: {err}");
    err
}

fn srgb_byte(linear: f32) -> u8 {
    (fbksd_iqa::image::srgb(linear) * 255.0 + 0.5) as u8
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_static_viewer_opens_from_file_and_shows_the_exact_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scenes/ramp");
    std::fs::create_dir_all(&scene).unwrap();
    std::fs::write(scene.join("ramp.expr"), "width := 24;\nheight := 16;\n#\nvar v := IMAGE_X / width * LIGHT_X * 2;\nCOLOR_R := v; COLOR_G := v * 0.5; COLOR_B := 1 - v;\n").unwrap();
    scene_meta(&scene, "ramp", "ramp.expr", "procedural", &[1, 8], 24, 16);
    let out = Command::new(bin("fbksd-procedural")).arg("reference").arg(&scene).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let results = dir.path().join("results");
    let (r, s) = (results.to_str().unwrap(), dir.path().join("scenes"));
    let s = s.to_str().unwrap();
    fbksd(&["run", "-t", &bin("box-filter"), "-s", scene.to_str().unwrap(), "--results", r]);
    fbksd(&["results", "compute", "--results", r, "--scenes", s]);
    let said = fbksd(&["results", "page", "--results", r, "--scenes", s]);
    let index = results.join("page/index.html");
    assert!(said.contains(&format!("file://{}", index.display())), "{said}");

    let browser = Browser::start().await;
    browser.goto(&format!("file://{}#scene=ramp&spp=8", index.display())).await;
    browser
        .wait_for("the result at 8 spp", "document.querySelector('canvas.main').dataset.shown", Duration::from_secs(20))
        .await;
    browser
        .wait_for(
            "both crops",
            "document.querySelectorAll('canvas.crop[data-centre]').length === 2",
            Duration::from_secs(20),
        )
        .await;
    browser.eval("document.querySelector('.viewer-bar').scrollIntoView({ block: 'start' });").await;

    // What is on screen at pixel (17, 5) is the EXR's value there, tone mapped.
    let (w, _, rgb) = fbksd_iqa::image::read_exr(&results.join("box-filter/ramp/8_0.exr")).unwrap();
    let (x, y) = (17u32, 5u32);
    let at = browser.eval(&format!("return FBKSD.viewer.comparison.screenOf({x}, {y});")).await;
    let zoom = at["zoom"].as_f64().unwrap();
    let shot = browser.screenshot().await;
    let seen = shot
        .get_pixel((at["x"].as_f64().unwrap() + zoom / 2.0) as u32, (at["y"].as_f64().unwrap() + zoom / 2.0) as u32);
    let k = ((y * w + x) * 3) as usize;
    assert_eq!(&seen.0[..3], &[srgb_byte(rgb[k]), srgb_byte(rgb[k + 1]), srgb_byte(rgb[k + 2])]);

    // The chart has the technique's line; the costs table its two runs.
    let lines = browser.eval("return document.querySelectorAll('svg.chart g.series').length;").await;
    assert_eq!(lines, 1);
    let costs = browser.text("table.costs").await;
    assert_eq!(costs.matches("box-filter").count(), 2, "{costs}");
    browser.close().await;
}
