//! The part of frugal that flies: small shared types, the policy bundle reader, the
//! per-frame controller and the KLT tracker.
//!
//! The crate is `#![no_std]` and uses no allocator; every buffer is caller-provided or
//! sized by a const generic. The workbench (training, Pareto, replay, simulation) uses
//! these same types and this same decision code, so what is evaluated is what flies.
#![no_std]
#![deny(missing_docs)]
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing, clippy::panic)]

#[cfg(feature = "std")]
extern crate std;

pub mod geom;

pub use geom::{BBox, ClassId, Detection, Detector, FrameRef, VariantId};
