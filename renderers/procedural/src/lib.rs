//! The procedural renderer: scenes are programs in a subset of the ExprTk
//! expression language that map a sample's random parameters (IMAGE_X,
//! IMAGE_Y in pixels, LENS_U, LENS_V, TIME, LIGHT_X, LIGHT_Y) to its
//! features (COLOR_R, …) — thesis appendix C. Listing C.1 renders unchanged.
//!
//! - [`syntax`]: lexer and parser, errors with line, column and the source line.
//! - [`program`]: compilation to slots, and the 64-lane masked interpreter.
//! - [`scene`]: scene files (header, `#`, program) and their scene info.
//! - [`render`]: sampling and filling the protocol's tiles; in-process
//!   rendering for references and benchmarks.
//!
//! ```
//! let scene = fbksd_procedural::Scene::parse("demo", "width := 4; height := 2;\n#\nCOLOR_R := IMAGE_X / width;").unwrap();
//! let image = fbksd_procedural::render::render_image(&scene, 16, 0).unwrap();
//! assert!((image[3] - 0.375).abs() < 0.01); // pixel 1: mean of x/4 over [1, 2)
//! ```
#![deny(missing_docs)]

pub mod program;
pub mod reference;
pub mod render;
pub mod scene;
pub mod syntax;

pub use scene::Scene;

use fbksd_core::Feature;
use fbksd_renderer::RenderingServer;
use std::sync::{Arc, Mutex};

/// Serves `scene` to the manager named by the environment until it finishes.
pub fn serve(scene: Scene) -> Result<(), fbksd_renderer::RendererError> {
    let scene = Arc::new(scene);
    // The program cut down to the current session's layout.
    let session: Arc<Mutex<Option<Arc<program::Program>>>> = Arc::default();
    let info = scene.info();
    let (for_layout, for_eval) = (session.clone(), session);
    let eval_scene = scene.clone();
    RenderingServer::new()
        .on_get_tile_size(|| 16)
        .on_get_scene_info(move || info.clone())
        .on_set_parameters(move |layout| {
            let wanted: Vec<(Feature, u8)> = layout
                .elements()
                .iter()
                .filter_map(|(e, _)| match e {
                    fbksd_core::layout::Element::Feature(f, n) => Some((*f, *n)),
                    _ => None,
                })
                .collect();
            *for_layout.lock().unwrap() = Some(Arc::new(scene.program.specialise(&wanted)));
            Ok(())
        })
        .on_evaluate_samples(move |eval| {
            let program = for_eval.lock().unwrap().clone().ok_or("evaluate before set_parameters")?;
            render::evaluate(&eval_scene, &program, eval).map_err(Into::into)
        })
        .run()
}
