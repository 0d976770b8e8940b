//! Sign detectors: a small Faster-R-CNN-style CNN trained with `tch`.
//!
//! The design follows Faster R-CNN (the paper's detector) at a size that trains on two
//! CPU cores in minutes:
//!
//! - **backbone**: a stack of 3×3 conv + ReLU blocks described in
//!   [`config::ModelConfig::backbone`] (`{out_channels, stride, convs}` each; the
//!   default reaches 256 channels at stride 8), every layer named
//!   `backbone/block{i}/conv{j}` in the [`tch::nn::VarStore`];
//! - **RPN**: anchors of several sizes and aspect ratios per feature cell,
//!   objectness and box deltas, decoding, clipping, NMS and top-k ([`glue::proposals`]);
//! - **RoI head**: RoIAlign ([`roi_align`], same semantics as ONNX `RoiAlign` with
//!   `half_pixel`, `avg`, fixed sampling ratio), two FC layers, class logits
//!   (+ background) and class-specific box deltas, per-class NMS ([`glue::detections`]).
//!
//! The network splits at two clean points — `backbone + rpn_head(image)` and
//! `roi_head(features, rois)` ([`FasterRcnn::backbone_rpn`], [`FasterRcnn::roi_head`]) —
//! and everything between and around them is plain Rust in [`glue`] and [`boxes`], so
//! an ONNX executor can reuse it.
//!
//! **Confidence scale.** Each [`Detection`](frugal_runtime::Detection) carries
//! `score` = the softmax probability of its class among the `K + 1` outputs
//! (background included), in `[0, 1]`. The MDP's confidence buckets
//! (`c_opt`, `c_ge`, `c_ua`) for this detector family are defined on that scale.
//!
//! [`metrics`] (mAP@0.5 all-point or COCO 101-point, precision/recall/F1, mean IoU,
//! confusion matrix) does not use `tch` at all. [`train`] and [`eval`] are the library
//! side of `frugal train` / `frugal eval`.
//!
//! The example is not a doctest: doctest binaries are built in a temporary folder where
//! the loader cannot find libtorch (even a `no_run` one is linked into a binary that
//! runs). The same code runs as the test `crate_docs_example` (`tests/tests.rs`).
//!
//! ```ignore
//! use frugal_models::{FasterRcnn, config::ModelConfig};
//! use frugal_runtime::FrameRef;
//! tch::manual_seed(0);
//! let model = FasterRcnn::new(ModelConfig::default(), tch::Device::Cpu).unwrap();
//! let pixels = vec![128u8; 96 * 64 * 3];
//! let dets = model.detect(FrameRef::new(96, 64, &pixels).unwrap());
//! assert!(dets.iter().all(|d| (0.0..=1.0).contains(&d.score)));
//! ```
#![deny(missing_docs)]

pub mod boxes;
pub mod compress;
pub mod config;
pub mod curves;
pub mod eval;
mod frames;
pub mod glue;
pub mod loss;
pub mod metrics;
mod model;
pub mod onnx;
pub mod optim;
pub mod roi_align;
#[cfg(test)]
mod testing;
pub mod train;

pub use model::{FasterRcnn, LayerInfo, RpnOutput, boxes_tensor};

use std::path::Path;

/// What can go wrong loading, training or evaluating a model.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ModelError {
    /// A file could not be read or written.
    #[error("{file}: {source}")]
    Io {
        /// The file.
        file: String,
        /// The cause.
        source: std::io::Error,
    },
    /// A config file is invalid.
    #[error("{file}: invalid config: {msg}")]
    Config {
        /// The file (or "model config").
        file: String,
        /// What is wrong.
        msg: String,
    },
    /// A checkpoint is corrupt or does not match the model.
    #[error("{file}: bad checkpoint: {msg}")]
    Checkpoint {
        /// The file.
        file: String,
        /// What is wrong.
        msg: String,
    },
    /// libtorch failed.
    #[error("{file}: libtorch: {msg}")]
    Torch {
        /// The file or step involved.
        file: String,
        /// libtorch's message.
        msg: String,
    },
    /// The dataset could not be used.
    #[error("dataset: {0}")]
    Data(String),
}

impl ModelError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            file: path.display().to_string(),
            source,
        }
    }
}
