//! Accuracy (mAP@0.5, F1, IoU) and latency of detector variants, and their Pareto front.
//!
//! # Fronts within noise
//!
//! The report's fronts (and `variants.json`, which the policy stage reads) only count
//! differences larger than the measurement noise ([`front_within_noise`]). A variant
//! is on the front only if it is faster than each more accurate front variant by more
//! than the latency noise, and more accurate than each faster one by more than the
//! sampling error; every variant left out has a front variant that is neither
//! clearly slower nor clearly less accurate than it (`dominated_by` in the report),
//! and variants within noise of each other in both coordinates are one point
//! (`merged_into`), normally the cheaper. Of the sets with these properties the
//! front is the cheapest: variants are taken fastest first, each kept if the rest
//! can still be completed into such a set.
//!
//! - **Latency** of a variant ([`Latency::cost_ms`]): the fastest of its timed runs
//!   (one per validation frame, variants interleaved frame by frame). Other work on
//!   a shared machine only adds time, so the fastest run is the least disturbed; it
//!   is the cost on the front, in the variants file and, scaled, on the device.
//! - **Latency noise** of a variant ([`Latency::noise_ms`]): the spread of its timed
//!   runs, half the inter-decile range `(p90 − p10) / 2`, but at least 5 % of its
//!   cost ([`stats::LATENCY_NOISE_FLOOR`]) and at most 15 %
//!   ([`stats::LATENCY_NOISE_CEILING`]: a wider spread measures other work on the
//!   machine, not how far the fastest run moves). Two costs are within noise when they
//!   differ by no more than the larger of the two noises. The floor is there because the
//!   spread within one pass says little about the drift between passes: two runs on
//!   one host (the README's variant table and its flight grid) timed p20, p20-int8
//!   and ch50-int8 13-16 % slower in the second, yet the ratios between them moved
//!   by under 2 %; 5 % is about three times that, and far above the 0.3-0.6 % that
//!   separates the magnitude-pruned copies of the base model, which run the same
//!   dense kernels.
//! - **Sampling error** of an accuracy (`map_se`, `f1_se`, `mean_iou_se`): the
//!   standard deviation of the metric over 200 bootstrap resamples of the validation
//!   *videos* (drawn with replacement, every frame of a drawn video scored, fixed
//!   seed; frames of one video are correlated, so frames are not resampled one by
//!   one). Two accuracies differ when the gap exceeds `√(se_a² + se_b²)`. This treats
//!   the two errors as independent; the variants are scored on the same videos, so
//!   the error of their difference is usually smaller, and the rule errs towards
//!   merging.
//!
//! [`front()`] is still the plain non-dominated set (`plain_fronts` in the report).
#![deny(missing_docs)]

mod files;
pub mod front;
pub mod latency;
pub mod measure;
pub mod plot;
pub mod stats;
pub mod variants;

pub use front::{
    NoisyPoint, Point, covered_by, dominators, front, front_within_noise, merged_into,
};
pub use latency::measure;
pub use plot::{FrontPlot, PlotError, plot_front};
pub use stats::Latency;

use std::path::{Path, PathBuf};

/// What can go wrong measuring variants.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ParetoError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A variant, the dataset or a model is unusable.
    #[error("{0}")]
    Input(String),
    /// A plot could not be drawn.
    #[error(transparent)]
    Plot(#[from] PlotError),
}

impl ParetoError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }
}
