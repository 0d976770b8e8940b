//! Policies: which detector variant to run on the next frame, learned as an MDP from
//! replayed videos, evaluated by replaying the paper's strategies through the
//! runtime's own controller, and shipped as a policy bundle.
//!
//! - [`calibrate`]: per-variant bucket edges of equal precision (for the CNN family);
//! - [`variants`]: the [`VariantSet`] (families, confidence buckets, latencies,
//!   relative costs, boxed detectors);
//! - [`replay`]: the [`ReplayLog`] — every variant run once on every frame;
//! - [`train`]: transition estimation, the reward, [`train::train`] and the α sweep;
//! - [`mdp`]: the MDP and its solvers;
//! - [`eval`]: the strategies, replayed with the runtime's controller and KLT tracker;
//! - [`bundle`]: writing, verifying and inspecting bundle folders;
//! - [`plot`]: the figures;
//! - [`report`]: what `frugal policy train|eval` write.
//!
//! The example is not a doctest: the crate links libtorch (through `frugal-models`'
//! metrics) and doctest binaries live outside `target/`, where the rpath to
//! `.deps/libtorch` does not reach. The same code runs as the test
//! `it::doc_example::crate_docs_example` (`tests/it/doc_example.rs`).
//!
//! ```ignore
//! use frugal_data::{Clutter, Light, Split};
//! use frugal_policies::replay::{Det, FrameLog, MemoryFrames, RgbFrame, VideoLog, record};
//! use frugal_policies::variants::*;
//! use frugal_policies::{PolicyConfig, VariantSet, train::train};
//! use frugal_runtime::bundle::Bucket;
//!
//! // One training video of 20 blank frames with one sign; two synthetic variants:
//! // a cheap one with good-enough scores and a costly one with optimal scores.
//! let mut frames = MemoryFrames::default();
//! let mut logs = Vec::new();
//! for i in 0..20 {
//!     frames.frames.insert((0, i), RgbFrame { width: 64, height: 48, rgb: vec![0; 64 * 48 * 3] });
//!     let truth = vec![Det { class: 0, score: 1.0, bbox: [10.0, 10.0, 30.0, 30.0] }];
//!     logs.push(FrameLog { index: i, truth, detections: vec![], ignore: vec![], time_s: None });
//! }
//! let video = VideoLog { id: 0, clutter: Clutter::Low, light: Light::Normal,
//!     split: Split::Train, width: 64, height: 48, frames: logs };
//! let spec = |seed, score| SyntheticSpec { seed, score, ..SyntheticSpec::default() };
//! let family = FamilyInfo { name: "cnn".into(), buckets: CNN_BUCKETS };
//! let info = |name: &str, ms, s: &SyntheticSpec| VariantInfo { name: name.into(), family: 0,
//!     latency_ms: ms, relative_cost: 1.0, precision: Default::default(),
//!     source: VariantSource::Synthetic(s.clone()) };
//! let (cheap, costly) = (spec(1, [0.6, 0.8]), spec(2, [0.95, 1.0]));
//! let mut set = VariantSet::new(
//!     vec![family],
//!     vec![info("cheap", 2.0, &cheap), info("costly", 10.0, &costly)],
//!     vec![Box::new(SyntheticDetector(cheap)), Box::new(SyntheticDetector(costly))],
//! );
//! let log = record(&mut set, &frames, vec![video], "".into(), 1, 8, false)?;
//! let policy = train(&log, &PolicyConfig::default())?;
//! // Good enough on the cheap variant: stay on it.
//! assert_eq!(policy.action(Bucket::GoodEnough, 0), 0);
//! # Ok::<(), frugal_policies::PolicyError>(())
//! ```
#![deny(missing_docs)]

pub mod budget;
pub mod budget_eval;
pub mod bundle;
pub mod calibrate;
pub mod error;
pub mod eval;
pub mod mdp;
pub mod plot;
pub mod replay;
pub mod report;
pub mod scoring;
pub mod stream;
pub mod sweep;
pub mod train;
pub mod variants;

pub use error::{PolicyError, Result};
pub use mdp::{Mdp, MdpError, Solution};
pub use replay::ReplayLog;
pub use train::{PolicyConfig, Reward, TrainedPolicy, Weights};
pub use variants::VariantSet;
