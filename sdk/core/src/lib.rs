//! The core of the FBKSD SDK: everything the three processes of a benchmark
//! run (technique, manager, renderer) must agree on, and nothing else.
//!
//! - [`layout`]: the sample layout a technique asks for (random parameters and
//!   features, INPUT or OUTPUT), its validation and its compiled form.
//! - [`scene_info`]: typed scene information (`width`, `max_spp`, …).
//! - [`protocol`]: the control messages and their framing on the wire
//!   (see `sdk/PROTOCOL.md`).
//! - [`shm`]: shared-memory regions (the tile ring and the result image),
//!   mapped from files in the run's rendezvous directory.
//! - [`tile`]: what a tile is and how its samples are laid out.
//!
//! ```
//! use fbksd_core::layout::{SampleLayout, ElementIo};
//! let layout = SampleLayout::new()
//!     .with_io("IMAGE_X", ElementIo::Input)
//!     .with("COLOR_R").with("COLOR_G").with("COLOR_B")
//!     .with_number("NORMAL_X", 1);
//! let compiled = layout.compile().unwrap();
//! assert_eq!(compiled.sample_size(), 5);
//! ```
#![deny(missing_docs)]

pub mod layout;
pub mod protocol;
pub mod rendezvous;
pub mod scene_info;
pub mod shm;
pub mod tile;

pub use layout::{CompiledLayout, ElementIo, Feature, LayoutError, RandomParameter, SampleLayout};
pub use scene_info::{SceneInfo, SceneInfoError, SceneValue};
pub use tile::{Tile, TileRect};
