//! The built-in physically based renderer: a unidirectional path tracer on
//! Intel Embree 3 that reads a subset of the pbrt-v4 scene format and
//! serves samples over the FBKSD protocol.
//!
//! - [`pbrt`]: the scene parser (errors carry file and line; unused
//!   parameters are errors).
//! - [`scene`]: camera, shapes, textures, materials, lights, and the BVH.
//! - [`bsdf`]: the scattering models, in the local shading frame.
//! - [`integrator`]: path tracing with NEE, MIS and Russian roulette, and
//!   every feature of the sample layout; paths are traced in batches,
//!   wavefront style, their rays going to Embree in packets and their
//!   common cases shaded in SIMD lanes ([`lanes`]).
//! - [`render`]: the protocol's tiles, and in-process rendering.
//! - [`embree`]: the thin layer over Embree.
//!
//! ```no_run
//! let scene = fbksd_embree::pbrt::load(std::path::Path::new("scenes/production/cornell-box/scene.pbrt")).unwrap();
//! let image = fbksd_embree::render::render_image(&scene, 16, 0);
//! assert_eq!(image.rgb.len(), (scene.width() * scene.height() * 3) as usize);
//! ```
#![deny(missing_docs)]
// `!(x > 0.0)` is how this crate rejects NaN along with the out-of-range values.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod bench;
pub mod bsdf;
pub mod embree;
pub mod integrator;
pub mod lanes;
pub mod math;
pub mod pbrt;
pub mod reference;
pub mod render;
pub mod scene;

use fbksd_renderer::RenderingServer;
use scene::Scene;
use std::sync::Arc;

/// Serves `scene` to the manager named by the environment until it finishes.
pub fn serve(scene: Scene) -> Result<(), fbksd_renderer::RendererError> {
    let scene = Arc::new(scene);
    let info = scene.info();
    RenderingServer::new()
        .on_get_tile_size(|| 16)
        .on_get_scene_info(move || info.clone())
        .on_evaluate_samples(move |eval| render::evaluate(&scene, eval).map_err(Into::into))
        .run()
}
