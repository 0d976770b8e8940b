//! Accuracy (mAP@0.5, F1, IoU) and latency of detector variants, and their Pareto front.
#![deny(missing_docs)]

pub mod front;
pub mod latency;
pub mod measure;
pub mod plot;
pub mod stats;
pub mod variants;

pub use front::{Point, dominators, front};
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
