//! The results viewer in a real browser (Chromium over WebDriver), on a
//! private page with three techniques: what a person sees on screen (the
//! tone-mapped pixel at exposure 0 and +1, the inspector's values, crops
//! that stay on one pixel through zoom and pan, one chart line per
//! technique and an SVG export that opens, a ranking that follows the tag
//! filter), and that a private set's data and images stay its owner's.
//!
//! The runner here is the tests' fake one, uploading pixel files made from
//! known values, so every expected value is computed, not read back.

mod common;

use common::{push, spawn, technique_repository, Db, FakeRunner, TestServer, TestUser};
use fbksd_browser::Browser;
use reqwest::Method;
use std::time::Duration;

const W: u32 = 64;
const H: u32 = 48;
const SPPS: [u64; 3] = [4, 16, 64];

/// The reference of a scene: a smooth HDR gradient.
fn reference(scene: usize) -> Vec<f32> {
    (0..W * H * 3)
        .map(|i| {
            let (p, c) = (i / 3, i % 3);
            let (x, y) = ((p % W) as f32, (p / W) as f32);
            0.05 + 0.9 * x / W as f32 * (1.0 + 0.2 * c as f32) + 0.3 * y / H as f32 + 0.1 * scene as f32
        })
        .collect()
}

/// A technique's result: the reference plus a pattern of its own, smaller
/// at more spp.
fn result(scene: usize, technique: usize, spp: u64) -> Vec<f32> {
    let amplitude = error_of(scene, technique, spp).sqrt() as f32;
    reference(scene)
        .iter()
        .enumerate()
        .map(|(i, v)| v + amplitude * (((i * (7 + technique)) % 13) as f32 / 6.0 - 1.0))
        .collect()
}

/// The MSE a technique is given: per scene a different order, so that the
/// ranking depends on the scenes chosen.
fn error_of(scene: usize, technique: usize, spp: u64) -> f64 {
    let order = [[1.0, 2.0, 3.0], [3.0, 1.0, 2.0]][scene][technique];
    0.01 * order / spp as f64
}

const SCENES: [(&str, &[&str]); 2] = [("sin-bands", &["procedural", "bands"]), ("defocus", &["procedural", "dof"])];
const TECHNIQUES: [&str; 3] = ["ada-filter", "bob-filter", "bob-nlm"];

/// Runs the fake runner through one benchmark job of `technique`; returns
/// the result set's UUID.
async fn benchmark(runner: &FakeRunner, technique: usize) -> String {
    let job = runner.claim(5).await.expect("a benchmark job");
    let scenes: Vec<common::PicturedScene> =
        SCENES.iter().map(|(name, tags)| common::PicturedScene { name, tags }).collect();
    let technique_ms = |_: usize, spp: u64| 2.0 * spp as f64 * (1 + technique) as f64;
    let (set, sent_references) = common::upload_pictured(
        runner,
        &job,
        &common::Pictured {
            technique: TECHNIQUES[technique],
            scenes: &scenes,
            spps: &SPPS,
            size: (W, H),
            reference: &reference,
            image: &|s, spp| result(s, technique, spp),
            mse: &|s, spp| error_of(s, technique, spp),
            technique_ms: &technique_ms,
            exr: &|_| b"an EXR".to_vec(),
        },
    )
    .await;
    // The server keeps one copy of each reference: only the first job sends them.
    assert_eq!(sent_references, if technique == 0 { SCENES.len() } else { 0 });
    set
}

async fn submit(server: &TestServer, user: &TestUser, project: &str) {
    server.create_project(user, project, "public").await;
    let repo = technique_repository("box-filter-python");
    assert!(push(repo.path(), &server.clone_url(project, &user.token), &["FBKSD_RUN"]).0);
}

/// The 8-bit value the SDK's previews give a linear value.
fn srgb_byte(v: f32) -> u8 {
    (fbksd_iqa::image::srgb(v) * 255.0 + 0.5) as u8
}

/// The colour pixel `(x, y)` of an image of this test is given on screen
/// at +1 EV in sRGB.
fn at_plus_one(pixels: &[f32], (x, y): (u32, u32)) -> [u8; 3] {
    let k = ((y * W + x) * 3) as usize;
    [0, 1, 2].map(|c| srgb_byte(2.0 * pixels[k + c]))
}

/// The colour on screen at a viewport point.
fn seen(shot: &image::RgbaImage, x: f64, y: f64) -> [u8; 3] {
    let p = shot.get_pixel(x as u32, y as u32).0;
    [p[0], p[1], p[2]]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_owner_compares_pixels_charts_and_ranks_in_the_viewer() {
    let server = spawn(Db::Sqlite).await;
    let ada = server.user("ada@example.org").await;
    let bob = server.user("bob@example.org").await;
    let runner = FakeRunner::register(&server, "r").await;
    let mut sets = Vec::new();
    for (t, (user, project)) in
        [(&ada, TECHNIQUES[0]), (&bob, TECHNIQUES[1]), (&bob, TECHNIQUES[2])].into_iter().enumerate()
    {
        submit(&server, user, project).await;
        sets.push(benchmark(&runner, t).await);
    }
    // Ada's document is made once per board version: each publish shows in it at once.
    let techniques_beside_ada = || async {
        let doc = ada.browser.get(format!("{}/api/v1/results/{}/viewer", server.url, sets[0])).send().await.unwrap();
        let doc: serde_json::Value = doc.json().await.unwrap();
        doc["techniques"].as_array().unwrap().len()
    };
    assert_eq!(techniques_beside_ada().await, 1, "nothing published yet");
    for (n, set) in sets[1..].iter().enumerate() {
        let published = bob.api(Method::POST, format!("{}/api/v1/results/{set}/publish", server.url)).send().await;
        assert_eq!(published.unwrap().status(), 200);
        assert_eq!(techniques_beside_ada().await, n + 2, "after publishing {set}");
    }
    let adas = &sets[0];

    // Only Ada sees her private set: its document, pixels, maps, logs and references.
    let viewer_doc = format!("{}/api/v1/results/{adas}/viewer", server.url);
    let (status, doc) = common::json_of(ada.browser.get(&viewer_doc).send().await.unwrap()).await;
    assert_eq!(status, 200, "{doc}");
    let own_run = &doc["techniques"][0]["runs"][0];
    let private_urls = [
        viewer_doc.clone(),
        format!("{}{}", server.url, own_run["pixels"].as_str().unwrap()),
        format!("{}{}", server.url, own_run["log"].as_str().unwrap()),
        format!("{}{}", server.url, own_run["error_maps"]["MSE"].as_str().unwrap()),
        format!("{}{}", server.url, doc["scenes"][0]["reference"].as_str().unwrap()),
        format!("{}{}", server.url, doc["scenes"][0]["buffers"]["albedo"].as_str().unwrap()),
        format!("{}/results/{adas}", server.url),
    ];
    for url in &private_urls {
        assert_eq!(ada.browser.get(url).send().await.unwrap().status(), 200, "{url}");
        for (client, who) in [(bob.browser.clone(), "another user"), (reqwest::Client::new(), "anonymous")] {
            assert_eq!(client.get(url).send().await.unwrap().status(), 404, "{who}: {url}");
        }
    }

    // The document travels gzipped; pixel files are gzip already and are sent as they are.
    let gzip = |url: String| {
        let client = ada.browser.clone();
        async move {
            let response = client.get(&url).header("accept-encoding", "gzip").send().await.unwrap();
            response.headers().get("content-encoding").map(|v| v.to_str().unwrap().to_string())
        }
    };
    assert_eq!(gzip(viewer_doc.clone()).await.as_deref(), Some("gzip"), "the viewer's document");
    assert_eq!(
        gzip(format!("{}/static/viewer/viewer.js", server.url)).await.as_deref(),
        Some("gzip"),
        "the viewer's code"
    );
    assert_eq!(gzip(private_urls[1].clone()).await, None, "a pixel file");

    // Ada logs in with the form and opens her private page.
    let browser = Browser::start().await;
    browser.log_in(&server.url, &ada.email, "a long enough password").await;
    browser.goto(&format!("{}/results/{adas}#scene=sin-bands&spp=4", server.url)).await;
    let ada_pixels = format!("/results/{adas}/files/ada-filter/sin-bands/4_0.fbpx");
    browser
        .wait_for("Ada's image at exposure 0", &format!("(document.querySelector('canvas.main').dataset.shown || '').startsWith('{ada_pixels} single 0|srgb|false')"), Duration::from_secs(20))
        .await;

    // A person scrolls to the viewer: the image and the crops then fill the window.

    screenshot(&browser, "viewer-images.png", "h1").await;
    browser.eval("document.querySelector('.viewer-bar').scrollIntoView({ block: 'start' });").await;

    // A known pixel on screen is its value tone mapped, at exposure 0 and +1.
    let (px, py) = (40u32, 30u32);
    let image = result(0, 0, 4);
    let value = |c: u32| image[((py * W + px) * 3 + c) as usize];
    let centre = |b: &serde_json::Value| {
        let zoom = b["zoom"].as_f64().unwrap();
        (b["x"].as_f64().unwrap() + zoom / 2.0, b["y"].as_f64().unwrap() + zoom / 2.0)
    };
    let at = browser.eval(&format!("return FBKSD.viewer.comparison.screenOf({px}, {py});")).await;
    assert!(at["zoom"].as_f64().unwrap() >= 4.0, "a small image is shown magnified: {at}");
    let (sx, sy) = centre(&at);
    let shot = browser.screenshot().await;
    assert_eq!(seen(&shot, sx, sy), [srgb_byte(value(0)), srgb_byte(value(1)), srgb_byte(value(2))], "exposure 0");
    browser.press("]]").await;
    browser
        .wait_for(
            "exposure +1",
            "document.querySelector('canvas.main').dataset.shown.includes(' 1|srgb|')",
            Duration::from_secs(5),
        )
        .await;
    assert_eq!(browser.text("output.exposure").await, "+1 EV");
    let shot = browser.screenshot().await;
    let doubled = |c| srgb_byte(2.0 * value(c));
    assert_eq!(seen(&shot, sx, sy), [doubled(0), doubled(1), doubled(2)], "exposure +1");

    // The inspector shows the file's exact values under the cursor.
    browser.move_mouse(sx, sy).await;
    let inspector = browser
        .wait_for("the inspector", "document.querySelector('.inspector').innerText", Duration::from_secs(5))
        .await;
    let inspector = inspector.as_str().unwrap().to_string();
    assert!(inspector.contains(&format!("{px}, {py}")), "{inspector}");
    let a_values = browser.text(".inspector div:nth-child(2) output").await;
    let shown: Vec<f32> = a_values.split_whitespace().map(|t| t.parse().unwrap()).collect();
    assert_eq!(shown, vec![value(0), value(1), value(2)], "inspector: {inspector}");

    // Every crop (reference and three techniques) is centred on that pixel,
    // and shows that pixel of its own image, through zoom and pan.
    let check_crops = |expected: (u32, u32)| {
        let browser = &browser;
        async move {
            let crops = browser
                .eval("return [...document.querySelectorAll('canvas.crop')].map(c => { const r = c.getBoundingClientRect(); return { centre: c.dataset.centre, scale: Number(c.dataset.scale), x: r.left + c.clientLeft, y: r.top + c.clientTop }; });")
                .await;
            let crops = crops.as_array().unwrap().clone();
            assert_eq!(crops.len(), 4, "reference and three techniques");
            let shot = browser.screenshot().await;
            for (i, crop) in crops.iter().enumerate() {
                assert_eq!(crop["centre"], format!("{},{}", expected.0, expected.1), "crop {i}");
                let scale = crop["scale"].as_f64().unwrap();
                let (x, y) = (crop["x"].as_f64().unwrap() + 16.5 * scale, crop["y"].as_f64().unwrap() + 16.5 * scale);
                let pixels = if i == 0 { reference(0) } else { result(0, i - 1, 4) };
                assert_eq!(seen(&shot, x, y), at_plus_one(&pixels, expected), "crop {i} at {expected:?}");
            }
        }
    };
    check_crops((px, py)).await;
    browser.press("+").await;
    let zoomed = browser.eval("return FBKSD.viewer.comparison.pixelAt(FBKSD.viewer.comparison.pointer.x, FBKSD.viewer.comparison.pointer.y);").await;
    let zoomed = (zoomed["x"].as_u64().unwrap() as u32, zoomed["y"].as_u64().unwrap() as u32);
    tokio::time::sleep(Duration::from_millis(200)).await;
    check_crops(zoomed).await;
    browser.drag((sx, sy), (sx - 3.0 * at["zoom"].as_f64().unwrap() * 2.0, sy)).await;
    let at = browser.eval("return FBKSD.viewer.comparison.screenOf(20, 20);").await;
    let (cx, cy) = centre(&at);
    browser.move_mouse(cx, cy).await;
    tokio::time::sleep(Duration::from_millis(200)).await;
    check_crops((20, 20)).await;

    // Split at the middle: Ada's image left of the line, the reference
    // (image B) right of it; a flip (f) shows B alone, a second one A.
    browser.press("r").await;
    browser.press("s").await;
    browser
        .wait_for(
            "the split view",
            "document.querySelector('canvas.main').dataset.shown.includes(' split ')",
            Duration::from_secs(5),
        )
        .await;
    let canvas = browser.eval("const r = document.querySelector('canvas.main').getBoundingClientRect(); return { left: r.left, width: r.width };").await;
    let split_x = canvas["left"].as_f64().unwrap() + 0.5 * canvas["width"].as_f64().unwrap();
    let shot = browser.screenshot().await;
    let mut sides = [0, 0];
    for x in [2u32, W / 2 - 3, W / 2 + 3, W - 3] {
        let (sx, sy) = centre(&browser.eval(&format!("return FBKSD.viewer.comparison.screenOf({x}, {py});")).await);
        if (sx - split_x).abs() < 2.0 {
            continue;
        }
        let right = sx > split_x;
        sides[right as usize] += 1;
        let pixels = if right { reference(0) } else { result(0, 0, 4) };
        let want = at_plus_one(&pixels, (x, py));
        assert_eq!(seen(&shot, sx, sy), want, "split view at pixel ({x}, {py}), right of the line: {right}");
    }
    assert!(sides[0] > 0 && sides[1] > 0, "pixels on both sides of the split: {sides:?}");
    let sin_bands = doc["scenes"].as_array().unwrap().iter().find(|s| s["name"] == "sin-bands").unwrap().clone();
    let reference_pixels = sin_bands["reference"].as_str().unwrap().to_string();
    browser.press("f").await;
    browser
        .wait_for(
            "the flip to B",
            &format!("document.querySelector('canvas.main').dataset.shown.startsWith('{reference_pixels} flip ')"),
            Duration::from_secs(5),
        )
        .await;
    let (sx, sy) = centre(&browser.eval(&format!("return FBKSD.viewer.comparison.screenOf({px}, {py});")).await);
    let want = at_plus_one(&reference(0), (px, py));
    assert_eq!(seen(&browser.screenshot().await, sx, sy), want, "flipped to the reference");
    browser.press("f").await;
    browser
        .wait_for(
            "the flip back to A",
            &format!("document.querySelector('canvas.main').dataset.shown.startsWith('{ada_pixels} flip ')"),
            Duration::from_secs(5),
        )
        .await;

    // False colour: the pixel's luminance, log2 from -8 to +4 stops, on the ramp.
    browser.click("#fbksd-viewer input[name=false_colour]").await;
    browser
        .wait_for(
            "false colour",
            "document.querySelector('canvas.main').dataset.shown.includes('|true')",
            Duration::from_secs(5),
        )
        .await;
    let y = 2.0 * (0.2126 * value(0) as f64 + 0.7152 * value(1) as f64 + 0.0722 * value(2) as f64);
    let t = (((y.log2() + 8.0) / 12.0) * 255.0).round().clamp(0.0, 255.0) / 255.0;
    assert_eq!(seen(&browser.screenshot().await, sx, sy), false_colour(t), "false colour of luminance {y}");
    browser.click("#fbksd-viewer input[name=false_colour]").await;

    // The feature buffers made with the reference are images A can show.
    browser.select("#fbksd-viewer select[name=a]", "reference:albedo").await;
    let albedo_pixels = sin_bands["buffers"]["albedo"].as_str().expect("the albedo buffer in the document").to_string();
    browser
        .wait_for(
            "the albedo buffer",
            &format!("document.querySelector('canvas.main').dataset.shown.startsWith('{albedo_pixels} ')"),
            Duration::from_secs(5),
        )
        .await;
    let want = at_plus_one(&common::albedo((W, H), 0), (px, py));
    assert_eq!(seen(&browser.screenshot().await, sx, sy), want, "the albedo buffer at ({px}, {py})");
    browser.select("#fbksd-viewer select[name=a]", adas).await;

    // One chart line per technique; its SVG export opens as an image.
    let lines =
        browser.eval("return [...document.querySelectorAll('svg.chart g.series')].map(g => g.dataset.name);").await;
    assert_eq!(lines.as_array().unwrap().len(), 3, "{lines}");
    let exported = browser
        .eval_async("const url = URL.createObjectURL(new Blob([FBKSD.svgText(FBKSD.viewer.chart)], { type: 'image/svg+xml' })); const img = new Image(); img.src = url; await img.decode(); return { width: img.naturalWidth, text: FBKSD.svgText(FBKSD.viewer.chart).slice(0, 60) };")
        .await;
    assert_eq!(exported["width"], 560, "{exported}");
    let png = browser
        .eval_async("const blob = await FBKSD.svgToPng(FBKSD.viewer.chart); const img = await createImageBitmap(blob); return { type: blob.type, width: img.width };")
        .await;
    assert_eq!(png, serde_json::json!({ "type": "image/png", "width": 1120 }), "the PNG export at twice the size");
    let csv = browser.eval("return FBKSD.viewer.chartCsv();").await;
    assert_eq!(csv.as_str().unwrap().lines().count(), 1 + 3 * SPPS.len(), "{csv}");
    // A technique named like a formula stays text in a spreadsheet (its author chose the name).
    let csv = browser
        .eval(r#"return FBKSD.chartCsv([{ name: '=HYPERLINK("http://x.example","y")', points: [{ spp: 4, x: 1, y: 2 }] }, { name: "@SUM(A1)", points: [{ spp: 4, x: 1, y: 2 }] }], "ms", "MSE");"#)
        .await;
    let rows: Vec<&str> = csv.as_str().unwrap().lines().skip(1).collect();
    assert_eq!(rows, [r#""'=HYPERLINK(""http://x.example"",""y"")",4,1,2"#, r#""'@SUM(A1)",4,1,2"#]);

    // A technique equal time leaves out (another runner class, or a runner
    // whose calibration had drifted) is off the time axis, and says why.
    let series = browser
        .eval(
            r#"const doc = { runner_class: "C", rankings: { equal_time: [{ scene: "s", metric: "MSE", at: { ms: 5 }, places: ["a", "b", "c"].map((k) => ({ technique: k, mean: 1 })) }] },
              techniques: [{ key: "a", name: "a", full_name: "a", runner_class: "C", runs: [] },
                { key: "b", name: "b", full_name: "b", runner_class: "C", untimed: "its runner's calibration +14 % from its class's", runs: [] },
                { key: "c", name: "c", full_name: "c", runner_class: "D", untimed: "another runner class", runs: [] }] };
            return FBKSD.chartSeries(doc, "s", "MSE", "equal_time").map((s) => [s.name, s.points.length]);"#,
        )
        .await;
    let series: Vec<(String, usize)> = serde_json::from_value(series).unwrap();
    assert_eq!(series[0].1, 1, "{series:?}");
    assert!(
        series[1].0.ends_with("(its runner's calibration +14 % from its class's: not on the time axis)")
            && series[1].1 == 0,
        "{series:?}"
    );
    assert!(series[2].0.ends_with("(another runner class: not on the time axis)") && series[2].1 == 0, "{series:?}");

    // A pixel file is decompressed no further than its header says: a runner
    // could upload kilobytes that inflate to gigabytes in every viewer's tab.
    let refused = browser
        .eval_async(
            r#"const header = (w, h, c) => { const b = new Uint8Array(20), v = new DataView(b.buffer); b.set([70, 66, 80, 88]); v.setUint32(4, 1, true); v.setUint32(8, w, true); v.setUint32(12, h, true); v.setUint32(16, c, true); return b; };
            const gzip = (parts) => new Response(new Blob(parts).stream().pipeThrough(new CompressionStream("gzip"))).arrayBuffer();
            const why = async (parts) => { try { await FBKSD.decodePixels(await gzip(parts), "x.fbpx"); return "decoded"; } catch (e) { return e.message; } };
            return [await why([header(2, 2, 1), new Uint8Array(64 << 20)]), await why([header(100000, 100000, 3)])];"#,
        )
        .await;
    assert_eq!(
        refused,
        serde_json::json!([
            "x.fbpx: longer than its header says",
            "x.fbpx: its header says 30000000000 values, more than the viewer opens (201326592)"
        ])
    );

    // The ranking follows the tag filter; Ada's row stands out.
    let all_scenes = browser.text("table.ranking tbody tr:first-child td:nth-child(2)").await;
    assert_eq!(all_scenes, "Box filter (Python) (bob-filter)", "first on all scenes");
    for (tag, scene, place) in [("bands", "sin-bands", 1), ("dof", "defocus", 3)] {
        browser.select("#fbksd-viewer select[name=tag]", tag).await;
        let shown = format!("[...document.querySelectorAll('table.ranking thead th.scene')].map(th => th.textContent).join() === '{scene}'");
        browser.wait_for(&format!("the ranking on {tag:?}"), &shown, Duration::from_secs(5)).await;
        let highlighted = browser.eval("return document.querySelector('table.ranking tr.highlight').rowIndex;").await;
        assert_eq!(highlighted, place, "Ada's place on {scene} (first on all scenes: {all_scenes})");
    }
    // The grid colours each scene's cell by its rank: the first green, the last red.
    browser.select("#fbksd-viewer select[name=tag]", "").await;
    browser
        .wait_for(
            "the ranking on all scenes",
            "document.querySelectorAll('table.ranking thead th.scene').length === 2",
            Duration::from_secs(5),
        )
        .await;
    let hues = browser
        .eval("return [...document.querySelectorAll('table.ranking tbody tr')].map(tr => getComputedStyle(tr.cells[tr.cells.length - 2]).backgroundColor);")
        .await;
    let hues: Vec<String> = serde_json::from_value(hues).unwrap();
    assert_eq!(hues.len(), 3, "{hues:?}");
    let distinct: std::collections::BTreeSet<&String> = hues.iter().collect();
    assert_eq!(distinct.len(), 3, "three ranks, three colours on sin-bands: {hues:?}");

    // Each run's costs are on the page.
    let costs = browser.text("table.costs").await;
    assert!(costs.contains("12.0 MiB") && costs.contains("ok") && costs.contains("log"), "{costs}");
    let titles = browser
        .eval("return ['Start-up', 'Technique time'].map(h => [...document.querySelectorAll('table.costs th')].find(th => th.textContent === h).title);")
        .await;
    assert!(titles[0].as_str().unwrap().contains("not charged"), "{titles}");
    assert!(titles[1].as_str().unwrap().contains("start-up included"), "{titles}");

    screenshot(&browser, "viewer-charts.png", "section.viewer-charts").await;
    browser.close().await;
}

/// The viewer's false-colour ramp at `t` in [0, 1], as 8-bit RGB: its
/// stops, linearly interpolated, rounded.
fn false_colour(t: f64) -> [u8; 3] {
    const STOPS: [(f64, [f64; 3]); 5] = [
        (0.0, [13.0, 8.0, 135.0]),
        (0.25, [84.0, 2.0, 163.0]),
        (0.5, [33.0, 145.0, 140.0]),
        (0.75, [144.0, 215.0, 67.0]),
        (1.0, [253.0, 231.0, 37.0]),
    ];
    let i = STOPS.iter().position(|(at, _)| t <= *at).unwrap_or(4).max(1);
    let ((a, ca), (b, cb)) = (STOPS[i - 1], STOPS[i]);
    let u = (t - a) / (b - a);
    [0, 1, 2].map(|c| (ca[c] + u * (cb[c] - ca[c]) + 0.5).floor() as u8)
}

/// With `FBKSD_SCREENSHOTS=<dir>`, saves what the window shows, scrolled to
/// `css`, for the docs (frontend/screenshots/viewer-*.png were made so).
async fn screenshot(browser: &Browser, name: &str, css: &str) {
    if let Ok(dir) = std::env::var("FBKSD_SCREENSHOTS") {
        browser.eval(&format!("document.querySelector('{css}').scrollIntoView({{ block: 'start' }});")).await;
        browser.screenshot().await.save(std::path::Path::new(&dir).join(name)).unwrap();
    }
}
