//! Accuracy (mAP@0.5, F1, IoU) and latency of detector variants, and their Pareto front.
#![deny(missing_docs)]
