//! The part of frugal that flies: small shared types, the policy bundle reader, the
//! per-frame controller and the KLT tracker.
//!
//! The crate is `#![no_std]` and uses no allocator; every buffer is caller-provided or
//! sized by a const generic. The workbench (training, Pareto, replay, simulation) uses
//! these same types and this same decision code, so what is evaluated is what flies.
//!
//! - [`bundle`]: the policy bundle format (the module docs are the byte-level spec),
//!   its zero-copy reader [`Bundle::parse`] and, with `std`, its writer
//!   `bundle::write::BundleWriter`;
//! - [`controller`]: [`Controller::step`] turns an [`Observation`] into a [`Decision`]
//!   (detect with variant `k`, or track);
//! - [`schedule`]: the budget policy with a content state: [`Scheduler::step`] picks a
//!   variant and a detection period from the bundle's table for the current latency
//!   budget, switchable in flight ([`Scheduler::set_budget`]);
//! - [`pilot`]: the whole per-frame loop, controller (or scheduler) plus one tracker
//!   per detected sign ([`pilot::Pilot`]);
//! - [`forecast`]: boxes moved at their velocity to the frame they are used on
//!   ([`Forecaster`]), for outputs that arrive frames late;
//! - [`track`]: the KLT [`Tracker`] (Shi-Tomasi + pyramidal Lucas-Kanade + median flow);
//! - [`geom`]: boxes, detections, frames, the [`Detector`] trait.
//!
//! Features: `std` (the bundle writer, the synthetic test clips in `synth`, the CNN
//! detector's pre/post-processing in `cnn`, `std::error` conveniences), `onnx` (the
//! ONNX Runtime executor `onnx::OrtDetector`, which runs a bundle's exported CNN
//! variants on a companion computer; implies `std`).
//!
//! ```
//! use frugal_runtime::bundle::write::{BundleWriter, FamilySpec, VariantSpec};
//! use frugal_runtime::bundle::{ScoreBuckets, Thresholds};
//! use frugal_runtime::{Bundle, Controller, Decision, Observation};
//!
//! // Two HoG variants; the policy moves to the costly one on a low score.
//! let bytes = BundleWriter::new(Thresholds::PAPER)
//!     .family(FamilySpec { name: "hog".into(), buckets: ScoreBuckets::PAPER_SVM })
//!     .variant(VariantSpec::new("fast", 0, 1.0, 10.0))
//!     .variant(VariantSpec::new("full", 0, 4.0, 40.0))
//!     .policy(0, vec![0, 0, 0, 0, 1, 1, 1, 1])
//!     .finish()?;
//! let bundle = Bundle::parse(&bytes)?;
//! let mut ctl = Controller::new(bundle);
//! let first = ctl.step(&Observation { frame: 0, score: None, track: None });
//! assert!(matches!(first, Decision::Detect { variant: 0, .. }));
//! // The detection found nothing: the policy switches to the full variant.
//! let second = ctl.step(&Observation { frame: 1, score: None, track: None });
//! assert!(matches!(second, Decision::Detect { variant: 1, .. }));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![no_std]
#![deny(missing_docs)]
#![deny(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

#[cfg(feature = "std")]
extern crate std;

pub mod bundle;
#[cfg(feature = "std")]
pub mod cnn;
pub mod content;
pub mod controller;
pub mod crc;
pub mod forecast;
pub mod geom;
#[cfg(feature = "onnx")]
pub mod onnx;
pub mod pilot;
pub mod schedule;
#[cfg(feature = "std")]
pub mod synth;
pub mod track;

pub use bundle::{Bundle, BundleError, Schedules, Thresholds};
pub use controller::{Access, Controller, Decision, Observation, TrackStatus, Trigger};
pub use forecast::{ForecastParams, Forecaster};
pub use geom::{BBox, ClassId, Detection, Detector, FrameRef, VariantId};
pub use schedule::{
    BudgetInfo, BudgetKeeper, Content, ContentEdges, FrameClock, ScheduleAction, ScheduleError,
    Scheduler, TrackState,
};
pub use track::{Tracker, TrackerParams};
