//! Model and training configuration: serde structs with built-in defaults, read from
//! TOML or JSON (unknown fields are rejected), saved as JSON next to every checkpoint.
use crate::ModelError;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// One backbone block: `convs` 3×3 convolutions + ReLU, the first with `stride`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlockConfig {
    /// Output channels of every conv in the block.
    pub out_channels: i64,
    /// Stride of the first conv (1 or 2).
    pub stride: i64,
    /// Number of 3×3 convs (at least 1).
    pub convs: usize,
}

/// The detector's structure and its fixed pre/post-processing parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ModelConfig {
    /// Number of object classes (background excluded). Training sets it to the
    /// dataset's class count: the classes are the data's, not the model's.
    pub num_classes: usize,
    /// The input size `[width, height]` the detector runs at: every frame is resized to
    /// it (bilinear; the aspect ratio follows the size given) and boxes map back to the
    /// frame's own pixels, so evaluation reports in source pixels. Unset: the training
    /// frames' size, scaled down to at most [`DEFAULT_MAX_SIDE`] pixels on the longer
    /// side (training records the value it used).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_size: Option<[usize; 2]>,
    /// Backbone blocks, input to output; the feature stride is the product of strides.
    pub backbone: Vec<BlockConfig>,
    /// Channels of the RPN's shared 3×3 conv.
    pub rpn_channels: i64,
    /// Anchor sizes in pixels (square root of the area).
    pub anchor_sizes: Vec<f32>,
    /// Anchor aspect ratios `h / w`.
    pub anchor_ratios: Vec<f32>,
    /// RoIAlign output side (`roi_size × roi_size`).
    pub roi_size: i64,
    /// RoIAlign sampling points per bin side (fixed, as in ONNX `sampling_ratio`).
    pub roi_sampling_ratio: i64,
    /// Width of the RoI head's two hidden FC layers.
    pub roi_hidden: i64,
    /// Per-channel mean subtracted from pixels in `[0, 1]` (RGB).
    pub pixel_mean: [f32; 3],
    /// Per-channel standard deviation pixels are divided by (RGB).
    pub pixel_std: [f32; 3],
    /// Proposals kept before the RPN's NMS at inference.
    pub pre_nms_test: usize,
    /// Proposals kept after the RPN's NMS at inference.
    pub post_nms_test: usize,
    /// Proposals kept before the RPN's NMS in training.
    pub pre_nms_train: usize,
    /// Proposals kept after the RPN's NMS in training.
    pub post_nms_train: usize,
    /// IoU threshold of the RPN's NMS.
    pub rpn_nms_iou: f32,
    /// Proposals narrower or shorter than this (pixels) are dropped.
    pub min_box_size: f32,
    /// Detections scoring below this are dropped.
    pub score_threshold: f32,
    /// IoU threshold of the final per-class NMS.
    pub nms_iou: f32,
    /// At most this many detections per image.
    pub max_detections: usize,
}

impl Default for ModelConfig {
    fn default() -> Self {
        let block = |out_channels, stride| BlockConfig {
            out_channels,
            stride,
            convs: 1,
        };
        Self {
            num_classes: 10,
            input_size: None,
            // stride 8: signs are 12-100 px, and a 30 px sign must span a few cells
            // for the RoI head to tell arrows and digits apart
            backbone: vec![block(32, 2), block(64, 2), block(128, 2), block(256, 1)],
            rpn_channels: 64,
            anchor_sizes: vec![16.0, 32.0, 64.0],
            anchor_ratios: vec![0.5, 1.0, 2.0],
            roi_size: 7,
            roi_sampling_ratio: 2,
            roi_hidden: 256,
            pixel_mean: [0.485, 0.456, 0.406],
            pixel_std: [0.229, 0.224, 0.225],
            pre_nms_test: 600,
            post_nms_test: 50,
            pre_nms_train: 1000,
            post_nms_train: 200,
            rpn_nms_iou: 0.7,
            min_box_size: 2.0,
            score_threshold: 0.05,
            nms_iou: 0.5,
            max_detections: 20,
        }
    }
}

/// The longer side of the default input size: frames larger than this are scaled down.
pub const DEFAULT_MAX_SIDE: usize = 640;

impl ModelConfig {
    /// The input size `(height, width)` for frames of `width × height`: the configured
    /// one, else the frame's scaled down to at most [`DEFAULT_MAX_SIDE`] on its longer
    /// side.
    pub fn input_for(&self, width: usize, height: usize) -> (usize, usize) {
        if let Some([w, h]) = self.input_size {
            return (h, w);
        }
        let long = width.max(height);
        if long <= DEFAULT_MAX_SIDE || long == 0 {
            return (height, width);
        }
        let scale = DEFAULT_MAX_SIDE as f64 / long as f64;
        let side = |v: usize| ((v as f64 * scale).round() as usize).max(1);
        (side(height), side(width))
    }

    /// The backbone's total stride (feature-map cell size in pixels).
    pub fn stride(&self) -> i64 {
        self.backbone.iter().map(|b| b.stride).product()
    }

    /// Anchors per feature-map cell.
    pub fn anchors_per_cell(&self) -> usize {
        self.anchor_sizes.len() * self.anchor_ratios.len()
    }

    /// Channels of the feature map the RoI head reads.
    pub fn feature_channels(&self) -> i64 {
        self.backbone.last().map_or(3, |b| b.out_channels)
    }

    /// Check the structure makes sense; `what` names the file or source for errors.
    pub fn validate(&self, what: &str) -> Result<(), ModelError> {
        let bad = |msg: String| {
            Err(ModelError::Config {
                file: what.to_string(),
                msg,
            })
        };
        if self.num_classes == 0 {
            return bad("num_classes must be at least 1".into());
        }
        if let Some([w, h]) = self.input_size
            && (w < 16 || h < 16 || w > 8192 || h > 8192)
        {
            return bad(format!(
                "input_size [{w}, {h}]: each side must be 16..=8192"
            ));
        }
        if self.backbone.is_empty() {
            return bad("backbone needs at least one block".into());
        }
        for (i, b) in self.backbone.iter().enumerate() {
            if b.out_channels < 1 || !(1..=2).contains(&b.stride) || b.convs == 0 {
                return bad(format!(
                    "backbone block {i}: out_channels >= 1, stride 1 or 2 and convs >= 1 required"
                ));
            }
        }
        if self.anchor_sizes.is_empty() || self.anchor_ratios.is_empty() {
            return bad("anchor_sizes and anchor_ratios must not be empty".into());
        }
        if self
            .anchor_sizes
            .iter()
            .chain(&self.anchor_ratios)
            .any(|v| v.is_nan() || *v <= 0.0)
        {
            return bad("anchor sizes and ratios must be positive".into());
        }
        if self.roi_size < 1 || self.roi_sampling_ratio < 1 || self.roi_hidden < 1 {
            return bad("roi_size, roi_sampling_ratio and roi_hidden must be >= 1".into());
        }
        if self.rpn_channels < 1 || self.pixel_std.iter().any(|s| s.is_nan() || *s <= 0.0) {
            return bad("rpn_channels and pixel_std must be positive".into());
        }
        if self.post_nms_test == 0 || self.post_nms_train == 0 || self.max_detections == 0 {
            return bad("proposal and detection counts must be >= 1".into());
        }
        Ok(())
    }
}

/// The optimizer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OptimizerKind {
    /// SGD with momentum 0.9 and L2 weight decay.
    Sgd,
    /// AdamW (β = 0.9, 0.999) with decoupled weight decay.
    AdamW,
}

/// The number format of the backbone and RPN convolutions in training passes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// `bf16` on a CPU with native bfloat16 arithmetic (AVX-512 BF16 or AMX), `f32`
    /// elsewhere (without it `bf16` convolutions are emulated and slow) and on CUDA.
    Auto,
    /// Plain `f32`.
    F32,
    /// Mixed precision: the convolutions in bfloat16 (about twice as fast on a CPU with
    /// native support), the weights, gradients, optimizer, RoI head and losses in `f32`.
    Bf16,
}

impl Precision {
    /// The tensor kind the convolutions run in on `device`.
    pub fn kind(self, device: tch::Device) -> tch::Kind {
        let bf16 = match self {
            Self::F32 => false,
            Self::Bf16 => true,
            Self::Auto => device == tch::Device::Cpu && native_bf16(),
        };
        if bf16 {
            tch::Kind::BFloat16
        } else {
            tch::Kind::Float
        }
    }
}

/// Does this CPU compute in bfloat16 natively (AVX-512 BF16, which every CPU with AMX
/// has too)?
fn native_bf16() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx512bf16")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Training hyper-parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// Seed of weight init (`tch::manual_seed`) and data order (ChaCha).
    pub seed: u64,
    /// Passes over the training split.
    pub epochs: usize,
    /// Images per optimizer step.
    pub batch_size: usize,
    /// The optimizer.
    pub optimizer: OptimizerKind,
    /// Peak learning rate.
    pub lr: f64,
    /// Weight decay.
    pub weight_decay: f64,
    /// Linear warm-up steps from `lr / 10` to `lr`.
    pub warmup_steps: usize,
    /// Cosine decay to `lr * final_lr_fraction` at the last step.
    pub final_lr_fraction: f64,
    /// Anchors sampled per image for the RPN loss.
    pub rpn_batch: usize,
    /// Largest share of foreground among sampled anchors.
    pub rpn_fg_fraction: f64,
    /// RoIs sampled per image for the RoI head loss.
    pub roi_batch: usize,
    /// Largest share of foreground among sampled RoIs.
    pub roi_fg_fraction: f64,
    /// Share of the background RoI budget filled with the background proposals the RPN
    /// ranks highest (hard negatives: sign-like distractors), the rest drawn at random.
    /// 0 = all random.
    pub roi_hard_negatives: f64,
    /// Brightness factor drawn in `[1 - b, 1 + b]`.
    pub brightness: f32,
    /// Largest Gaussian noise σ (pixels in `[0, 1]`).
    pub noise: f32,
    /// Zoom factor drawn in `[1/(1+z), 1+z]` (crop or pad back to size; boxes follow).
    pub scale_jitter: f32,
    /// Per-channel colour gain drawn in `[1 − g, 1 + g]`.
    pub channel_gain: f32,
    /// Probability of a 3×3 Gaussian blur.
    pub blur_prob: f64,
    /// Validation frames scored per epoch (0 = the whole split).
    pub val_frames: usize,
    /// Validate after every this many epochs, and always after the last one; the best
    /// model is the best of the validated epochs.
    pub val_every: usize,
    /// Training frames used per epoch (0 = the whole split).
    pub train_frames: usize,
    /// Sampling weight per scenario `"<clutter>-clutter/<light>-light"` (others: 1).
    /// An epoch keeps its number of steps; a frame of weight 2 is drawn about twice as
    /// often as one of weight 1.
    pub scenario_weights: BTreeMap<String, f64>,
    /// Intra-op threads for libtorch (0 = libtorch's default). The default is 1:
    /// on a shared 2-core machine, 2 OpenMP threads ran 4-5× slower than 1.
    pub threads: usize,
    /// The number format of the convolutions in training passes (validation and
    /// inference always run in `f32`). The default is `f32`: the one default training
    /// with `bf16` convolutions scored test mAP@0.5 0.969, the `f32` one 0.975
    /// (docs/experiments/2026-11-26-batched-training.md).
    pub precision: Precision,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            seed: 7,
            epochs: 8,
            batch_size: 4,
            optimizer: OptimizerKind::AdamW,
            lr: 1e-3,
            weight_decay: 0.05,
            warmup_steps: 100,
            final_lr_fraction: 0.02,
            rpn_batch: 256,
            rpn_fg_fraction: 0.5,
            roi_batch: 64,
            roi_fg_fraction: 0.25,
            roi_hard_negatives: 0.5,
            brightness: 0.3,
            noise: 0.03,
            blur_prob: 0.2,
            scale_jitter: 0.3,
            channel_gain: 0.1,
            val_frames: 300,
            val_every: 1,
            train_frames: 0,
            scenario_weights: BTreeMap::from([("high-clutter/low-light".to_string(), 2.0)]),
            threads: 1,
            precision: Precision::F32,
        }
    }
}

/// The whole configuration: model structure and training hyper-parameters.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// The detector.
    pub model: ModelConfig,
    /// Its training.
    pub train: TrainConfig,
}

impl Config {
    /// Read a TOML (`.toml`) or JSON (anything else) config file; missing fields take
    /// their defaults, unknown fields are an error naming the file.
    pub fn load(path: &Path) -> Result<Self, ModelError> {
        let text = std::fs::read_to_string(path).map_err(|e| ModelError::io(path, e))?;
        let file = path.display().to_string();
        let cfg: Config = if path.extension().is_some_and(|e| e == "toml") {
            toml::from_str(&text).map_err(|e| ModelError::Config {
                file: file.clone(),
                msg: e.to_string(),
            })?
        } else {
            serde_json::from_str(&text).map_err(|e| ModelError::Config {
                file: file.clone(),
                msg: e.to_string(),
            })?
        };
        cfg.validate(&file)?;
        Ok(cfg)
    }

    /// Check both parts; `what` names the source for errors.
    pub fn validate(&self, what: &str) -> Result<(), ModelError> {
        self.model.validate(what)?;
        let t = &self.train;
        if t.epochs == 0
            || t.batch_size == 0
            || t.rpn_batch == 0
            || t.roi_batch == 0
            || t.val_every == 0
        {
            return Err(ModelError::Config {
                file: what.to_string(),
                msg: "epochs, batch_size, rpn_batch, roi_batch and val_every must be >= 1".into(),
            });
        }
        if t.lr.is_nan() || t.lr <= 0.0 {
            return Err(ModelError::Config {
                file: what.to_string(),
                msg: "lr must be positive".into(),
            });
        }
        if !(0.0..=1.0).contains(&t.roi_hard_negatives) {
            return Err(ModelError::Config {
                file: what.to_string(),
                msg: format!(
                    "roi_hard_negatives must be in [0, 1], not {}",
                    t.roi_hard_negatives
                ),
            });
        }
        let scenarios = scenario_names();
        for (name, w) in &t.scenario_weights {
            if !scenarios.contains(name) {
                return Err(ModelError::Config {
                    file: what.to_string(),
                    msg: format!(
                        "scenario_weights: unknown scenario {name:?}; the scenarios are {}",
                        scenarios.join(", ")
                    ),
                });
            }
            if !(0.0..=10.0).contains(w) {
                return Err(ModelError::Config {
                    file: what.to_string(),
                    msg: format!("scenario_weights.{name:?} must be in [0, 10], not {w}"),
                });
            }
        }
        Ok(())
    }
}

/// Every scenario name `"<clutter>-clutter/<light>-light"`, as the evaluation reports them.
pub fn scenario_names() -> Vec<String> {
    use frugal_data::{Clutter, Light};
    Clutter::ALL
        .into_iter()
        .flat_map(|c| Light::ALL.map(|l| scenario_name(c, l)))
        .collect()
}

/// The name of one scenario, `"<clutter>-clutter/<light>-light"`.
pub fn scenario_name(c: frugal_data::Clutter, l: frugal_data::Light) -> String {
    format!("{}-clutter/{}-light", c.name(), l.name())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_round_trip_and_unknown_fields_are_rejected() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.json");
        std::fs::write(&p, serde_json::to_string(&Config::default()).unwrap()).unwrap();
        assert_eq!(Config::load(&p).unwrap(), Config::default());
        let t = dir.path().join("c.toml");
        std::fs::write(&t, "[train]\nepochs = 3\n[model]\nroi_size = 5\n").unwrap();
        let c = Config::load(&t).unwrap();
        assert_eq!((c.train.epochs, c.model.roi_size), (3, 5));
        std::fs::write(&t, "[train]\nepoch = 3\n").unwrap();
        let err = Config::load(&t).unwrap_err().to_string();
        assert!(err.contains("c.toml") && err.contains("epoch"), "{err}");
        assert_eq!(ModelConfig::default().stride(), 8);
        std::fs::write(&t, "[train.scenario_weights]\n\"dark/high\" = 2.0\n").unwrap();
        let err = Config::load(&t).unwrap_err().to_string();
        assert!(
            err.contains("dark/high") && err.contains("high-clutter/low-light"),
            "{err}"
        );
        std::fs::write(&t, "[train]\nroi_hard_negatives = 1.5\n").unwrap();
        let err = Config::load(&t).unwrap_err().to_string();
        assert!(err.contains("roi_hard_negatives"), "{err}");
    }
}
