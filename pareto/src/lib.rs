//! Accuracy (mAP@0.5, F1, IoU) and latency of detector variants, and their Pareto front.
#![deny(missing_docs)]

pub mod front;
pub mod latency;
pub mod plot;
pub mod stats;

pub use front::{Point, dominators, front};
pub use latency::measure;
pub use plot::{FrontPlot, PlotError, plot_front};
pub use stats::Latency;
