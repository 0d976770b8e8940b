//! Synthetic drone videos of signs in warehouse-like scenes, with exact boxes, and
//! import / export of real datasets (COCO JSON, Pascal VOC XML, GTSDB-style CSV).
//!
//! Real drone footage is not available, so [`generate`](fn@generate) renders stand-in videos: a
//! camera drifting and shaking through a warehouse aisle, approaching and passing
//! 1-3 signs at a time, at three clutter levels and two illumination levels. Every
//! video is seeded from (global seed, video id) with ChaCha, so the same config gives
//! the same bytes on any machine and thread count.
//!
//! - Classes ([`Sign`], [`classes`](fn@classes)): turn_left / turn_right (D1a-style arrows), stop
//!   (B5), wait (pedestrian crossing), danger (A14), no_parking (E1), no_entry (C1),
//!   speed_limit_30 (C43), no_right_turn (C31R), weight_limit_5t (C21); the first four
//!   carry a [`NavAction`]. [`render_sign`] draws any of them as an RGBA sprite. No
//!   augmentation flips images, so left and right never swap.
//! - Layout on disk and COCO conventions: see [`dataset`] (`category_id = class id + 1`).
//! - How boxes are made and which partly visible signs are dropped: see [`video`].
//! - Import / export conventions (VOC 1-based corners, GTSDB inclusive corners, class
//!   maps, splits of imported sets): see [`import`](mod@import).
//! - Output is written to `<out>.partial-XXXX` and renamed into place only when
//!   complete; single files go through a temporary file and a rename.
//!
//! ```no_run
//! use frugal_data::{Dataset, GenConfig, Split};
//! # fn main() -> Result<(), frugal_data::DataError> {
//! let ds = frugal_data::generate(&GenConfig::tiny(), "runs/tiny/data".as_ref(), false)?;
//! let again = Dataset::load(&ds.root)?;
//! for frame in again.split(Split::Val) {
//!     let rgb = again.load_rgb(frame)?;
//!     assert_eq!(rgb.width(), frame.width);
//! }
//! # Ok(())
//! # }
//! ```
#![deny(missing_docs)]

pub mod annotations;
pub mod classes;
pub mod coco;
pub mod config;
pub mod dataset;
pub mod error;
pub mod font;
pub mod generate;
pub mod import;
pub mod media;
pub mod raster;
pub mod scene;
pub mod show;
pub mod sign;
pub mod summary;
pub mod video;

pub use classes::{ClassInfo, NavAction, Sign, classes};
pub use config::{GENERATOR_VERSION, GenConfig, VideoPlan};
pub use dataset::{
    Clutter, Counts, DEFAULT_FPS, Dataset, FrameRecord, IgnoreRegion, Light, Manifest, Object,
    Source, Split, VideoMeta,
};
pub use error::DataError;
pub use frugal_runtime::{BBox, ClassId};
pub use generate::{generate, generate_or_reuse};
pub use import::{
    ClassList, ClassMap, Format, ImportCounts, ImportOptions, ImportSettings, export_coco,
    export_video, import, parse_action,
};
pub use sign::{SignStyle, render_sign};
pub use summary::{Summary, summary};

#[cfg(test)]
mod tests;
