//! The renderer side of FBKSD: turn any renderer into a sample server.
//!
//! A renderer builds a [`RenderingServer`] with callbacks (the same concepts
//! as the original C++ `RenderingServer`: tile size, scene info, parameters
//! i.e. the sample layout, evaluate samples, finish) and calls
//! [`RenderingServer::run`]. For each request the evaluate callback gets an
//! [`Evaluation`]: the request (`spp`, `remaining` count, `pipe_size`), the
//! layout, a tile plan, and [`Evaluation::pipe`], which hands out a
//! [`SamplesPipe`] — one slot of the shared ring — per tile. A pipe gives a
//! [`SampleBuffer`] per sample; `set_param` writes OUTPUT random parameters
//! and returns the technique's value for INPUT ones.
//!
//! [`sampler`] draws reproducible, stratified sample positions for
//! renderers that have no sampler of their own.
//!
//! The evaluate callback runs on its own thread and may use any number of
//! threads; pipes may be created and filled concurrently. The contract: a
//! request is complete when pipes covering exactly `spp` samples of every
//! pixel plus `remaining` pixel-free samples have been filled, and every
//! OUTPUT element of every sample has been written.
//!
//! ```no_run
//! use fbksd_renderer::{RenderingServer, Evaluation};
//! use fbksd_core::{SceneInfo, Feature, RandomParameter};
//! let mut info = SceneInfo::new();
//! info.set("width", 64).set("height", 64);
//! RenderingServer::new()
//!     .on_get_scene_info(move || info.clone())
//!     .on_evaluate_samples(|eval: &Evaluation| {
//!         for tile in eval.plan() {
//!             let mut pipe = eval.pipe(tile)?;
//!             for i in 0..pipe.len() {
//!                 let mut s = pipe.sample(i);
//!                 let x = s.set_param(RandomParameter::ImageX, 0.5);
//!                 s.set(Feature::ColorR, x / 64.0);
//!             }
//!             pipe.finish()?;
//!         }
//!         Ok(())
//!     })
//!     .run()
//!     .unwrap();
//! ```
#![deny(missing_docs)]

mod plan;
pub mod sampler;
mod server;

pub use plan::plan_tiles;
pub use server::{sample_stream, Evaluation, MappingGuard, RendererError, RenderingServer, SampleBuffer, SamplesPipe};

/// For a renderer's command-line subcommands, not its protocol server: when
/// the reader of standard output goes away (`… bench | head`), end quietly
/// as command-line tools do, instead of panicking in `println!`. Call it
/// before any thread starts.
pub fn end_quietly_when_stdout_closes() {
    // SAFETY: restores the default action of one signal; no handler runs Rust code.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
