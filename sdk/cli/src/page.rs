//! `fbksd results page`: the results viewer as a static folder, from a
//! results directory. The folder opens from `file://` or any static
//! server: the document is a script (`data.js`), each pixel file a script
//! that hands its base64 to the viewer (`px/<n>.js`; browsers refuse
//! `fetch` on `file://`), and the viewer's code is the service's own
//! ([`fbksd_exchange::viewer::ASSETS`]).
//!
//! ```text
//! <out>/index.html   <out>/data.js   <out>/viewer/*.js, viewer.css
//! <out>/px/<n>.js    pixels of every result and reference
//! <out>/files/…      error maps and technique logs, copied
//! ```

use anyhow::Context;
use base64::Engine;
use fbksd_exchange::results::{IndexEntry, ResultsDir, RunFiles};
use fbksd_exchange::scenes::{SceneMeta, FEATURE_BUFFERS};
use fbksd_exchange::viewer::{Delivery, Rankings, ViewerData, ViewerRun, ViewerScene, ViewerTechnique, ASSETS};
use fbksd_exchange::MetricInfo;
use fbksd_iqa::image::Image;
use fbksd_iqa::Metric;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// What `write` produced.
pub struct Written {
    /// Pixel files written (results and references).
    pub pixel_files: usize,
    /// Their total size in bytes.
    pub pixel_bytes: u64,
    /// Runs without an image to show, and why.
    pub notes: Vec<String>,
}

/// Writes the viewer of `results` (with references from `scenes`) into `out`.
pub fn write(results: &ResultsDir, scenes: &BTreeMap<String, SceneMeta>, out: &Path) -> anyhow::Result<Written> {
    let index = results.read_index()?;
    if index.runs.is_empty() {
        anyhow::bail!("{} holds no runs: run a benchmark first (fbksd run)", results.root().display());
    }
    std::fs::create_dir_all(out.join("viewer")).with_context(|| format!("creating {}", out.display()))?;
    std::fs::create_dir_all(out.join("px"))?;
    for (name, text) in ASSETS {
        std::fs::write(out.join("viewer").join(name), text)?;
    }
    let mut page = Page { out, written: Written { pixel_files: 0, pixel_bytes: 0, notes: Vec::new() } };

    let title = format!("Results in {}", results.root().display());
    let mut doc = ViewerData::new(title, Delivery::Script);
    let acronyms: BTreeSet<&String> = index.runs.iter().flat_map(|r| r.metrics.keys()).collect();
    doc.metrics = acronyms.into_iter().map(|a| metric_info(a)).collect();
    let scene_names: BTreeSet<&str> = index.runs.iter().map(|r| r.scene.as_str()).collect();
    for name in scene_names {
        let meta = scenes.get(name);
        let reference = match meta.map(SceneMeta::reference_file).filter(|p| p.is_file()) {
            Some(path) => Some(page.pixels(&Image::read(&path)?.pixels_file())?),
            None => {
                page.written.notes.push(format!("{name}: no reference found (give its scene directory with --scenes)"));
                None
            }
        };
        let mut buffers = BTreeMap::new();
        for buffer in FEATURE_BUFFERS {
            if let Some(path) = meta.map(|m| m.feature_buffer_file(buffer)).filter(|p| p.is_file()) {
                buffers.insert(buffer.to_string(), page.pixels(&Image::read(&path)?.pixels_file())?);
            }
        }
        doc.scenes.push(ViewerScene {
            name: name.to_string(),
            tags: meta.map(|m| m.tags.clone()).unwrap_or_default(),
            reference,
            buffers,
        });
    }
    let mut by_technique: BTreeMap<&str, Vec<&IndexEntry>> = BTreeMap::new();
    for run in &index.runs {
        by_technique.entry(&run.technique).or_default().push(run);
    }
    for (technique, runs) in by_technique {
        let runs =
            runs.into_iter().map(|r| page.run(results.root(), r, &doc.metrics)).collect::<anyhow::Result<_>>()?;
        doc.techniques.push(ViewerTechnique {
            key: technique.to_string(),
            name: technique.to_string(),
            full_name: technique.to_string(),
            citation: String::new(),
            runner_class: None,
            untimed: None,
            runs,
        });
    }
    let lower_is_better =
        |acronym: &str| doc.metrics.iter().find(|m| m.acronym == acronym).is_none_or(|m| m.lower_is_better);
    // One machine measured every run of a results directory.
    doc.rankings = Rankings::of(&index.runs, |_| true, lower_is_better);
    doc.set_costs(&index.runs);
    let json = serde_json::to_string(&doc)?;
    std::fs::write(out.join("data.js"), format!("window.FBKSD_DOCUMENT = {json};\n"))?;
    std::fs::write(out.join("index.html"), index_html(&doc.title))?;
    Ok(page.written)
}

struct Page<'a> {
    out: &'a Path,
    written: Written,
}

impl Page<'_> {
    /// Writes a pixel file as a script; returns its address.
    fn pixels(&mut self, file: &[u8]) -> anyhow::Result<String> {
        let address = format!("px/{}.js", self.written.pixel_files);
        let base64 = base64::engine::general_purpose::STANDARD.encode(file);
        std::fs::write(self.out.join(&address), format!("fbksdPixels({address:?}, \"{base64}\");\n"))?;
        self.written.pixel_files += 1;
        self.written.pixel_bytes += file.len() as u64;
        Ok(address)
    }

    /// Copies a file of the results directory, if it exists; returns its address.
    fn copy(&mut self, root: &Path, rel: &Path) -> anyhow::Result<Option<String>> {
        let from = root.join(rel);
        if !from.is_file() {
            return Ok(None);
        }
        let address = PathBuf::from("files").join(rel);
        let to = self.out.join(&address);
        std::fs::create_dir_all(to.parent().unwrap_or(self.out))?;
        std::fs::copy(&from, &to).with_context(|| format!("copying {}", from.display()))?;
        Ok(Some(address.to_string_lossy().replace('\\', "/")))
    }

    fn run(&mut self, root: &Path, r: &IndexEntry, metrics: &[MetricInfo]) -> anyhow::Result<ViewerRun> {
        let files = RunFiles::first(r.spp);
        let dir = Path::new(&r.log).parent().map(Path::to_path_buf).unwrap_or_default();
        let pixels = match &r.image {
            Some(image) if r.status == fbksd_exchange::RunStatus::Ok => {
                let fbpx = root.join(&dir).join(files.pixels());
                let bytes = match std::fs::read(&fbpx) {
                    Ok(bytes) => bytes,
                    // Results computed before the viewer: encode the EXR now.
                    Err(_) => Image::read(&root.join(image))?.pixels_file(),
                };
                Some(self.pixels(&bytes)?)
            }
            _ => {
                self.written
                    .notes
                    .push(format!("{} / {} / {} spp: {} (no image)", r.technique, r.scene, r.spp, r.status));
                None
            }
        };
        let mut error_maps = BTreeMap::new();
        for m in metrics.iter().filter(|m| m.has_error_map) {
            if let Some(address) = self.copy(root, &dir.join(files.error_map(&m.acronym)))? {
                error_maps.insert(m.acronym.clone(), address);
            }
        }
        Ok(ViewerRun {
            pixels,
            log: self.copy(root, &dir.join(files.technique_log()))?,
            error_maps,
            ..ViewerRun::measured(r)
        })
    }
}

/// A built-in metric's description; an external metric's is inferred
/// (lower is better, an error map if one was drawn).
fn metric_info(acronym: &str) -> MetricInfo {
    Metric::from_acronym(acronym).map(|m| m.info()).unwrap_or_else(|| MetricInfo {
        acronym: acronym.to_string(),
        name: acronym.to_string(),
        reference: String::new(),
        lower_is_better: true,
        has_error_map: true,
    })
}

fn index_html(title: &str) -> String {
    let title = title.replace('&', "&amp;").replace('<', "&lt;");
    format!(
        "<!doctype html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{title} · FBKSD</title>\n\
         <style>:root {{ --muted: #667085; --hl: #fff6d6; }} body {{ font: 15px/1.45 system-ui, sans-serif; margin: 1rem 1.5rem; }} \
         table {{ border-collapse: collapse; }} th, td {{ border-bottom: 1px solid #d9dee7; padding: .25rem .6rem; text-align: left; }} \
         td.num {{ text-align: right; font-variant-numeric: tabular-nums; }} tr.highlight td {{ background: var(--hl); font-weight: 600; }} \
         .muted {{ color: var(--muted); }} .error {{ color: #b42318; }} .ok {{ color: #067647; }}</style>\n\
         {}<script src=\"data.js\"></script>\n</head>\n<body>\n<h1>{title}</h1>\n<div id=\"fbksd-viewer\"></div>\n</body>\n</html>\n",
        fbksd_exchange::viewer::asset_tags("viewer/")
    )
}
