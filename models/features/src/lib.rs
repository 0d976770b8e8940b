//! The feature-based detector family of the paper: EdgeBoxes proposals, HoG features
//! and a linear SVM per class, whose variants are parameter tuples
//! ⟨proposals, block size, cell size, histogram bins⟩.
//!
//! * [`edgeboxes`] — class-agnostic proposals (on gradient edges, see [`edges`]);
//! * [`hog`] — HoG with configurable cell, block and bins, equal to scikit-image's;
//! * [`svm`] — a deterministic dual coordinate descent linear SVM;
//! * [`train()`] — one-vs-rest SVMs per HoG configuration with hard-negative mining;
//! * [`FeatureModel`] / [`HogDetector`] — the trained family and one variant of it,
//!   which implements [`frugal_runtime::Detector`]; the score is the SVM margin,
//!   bucketed by [`ScoreThresholds::PAPER`] (`c_opt = 0.9, c_ge = 0, c_ua = −0.5`);
//! * [`eval`] — per-class precision / recall, time per frame (one variant, or many
//!   sharing each frame's proposals: [`eval::evaluate_many`]), proposal recall.
//!
//! ```
//! use frugal_features::{HogParams, hog::{HogConfig, hog}};
//! let p: HogParams = "1000,2,8,9".parse()?;
//! assert_eq!(p, HogParams::BASELINE);
//! assert_eq!(p.to_string(), "<1000,2,8,9>");
//! // HoG of a flat 48×48 RGB window: 5×5 blocks of 2×2 cells × 9 bins.
//! let f = hog(&vec![0.5; 48 * 48 * 3], 48, 48, 3, &p.hog(false));
//! assert_eq!(f.len(), 5 * 5 * 2 * 2 * 9);
//! # Ok::<(), frugal_features::Error>(())
//! ```
#![deny(missing_docs)]

pub mod data;
pub mod edgeboxes;
pub mod edges;
pub mod error;
pub mod eval;
pub mod frame;
pub mod hog;
pub mod model;
pub mod params;
pub mod svm;
pub mod train;

pub use error::{Error, Result};
pub use frame::Rgb;
pub use model::{Confidence, FeatureModel, HogDetector, HogSvms, ScoreThresholds};
pub use params::{HogParams, MAX_CELL_PX};
pub use train::{LabeledFrame, Progress, TrainConfig, train};
