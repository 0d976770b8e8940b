//! Short fine-tuning of a compressed model: a fixed number of optimizer steps on a
//! spread subset of the training split, at the variant's input resolution, with
//! magnitude-pruning masks re-applied after every step.
use super::prune::{Masks, apply_masks};
use crate::config::TrainConfig;
use crate::frames::{image_tensor, resize, scaled_truth, spread};
use crate::loss::batch_losses;
use crate::optim::{Optimizer, learning_rate};
use crate::train::augment;
use crate::{FasterRcnn, ModelError};
use frugal_data::{Dataset, FrameRecord, Split};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use tch::Tensor;

/// The fine-tuning budget.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FinetuneConfig {
    /// Optimizer steps per fine-tuned variant.
    pub steps: usize,
    /// Images per step.
    pub batch_size: usize,
    /// Peak learning rate (short warm-up, cosine decay).
    pub lr: f64,
    /// Training frames drawn from (spread evenly over the split; 0 = all).
    pub frames: usize,
    /// Seed of the data order and augmentation.
    pub seed: u64,
}

impl Default for FinetuneConfig {
    fn default() -> Self {
        Self {
            steps: 80,
            batch_size: 2,
            lr: 3e-4,
            frames: 400,
            seed: 11,
        }
    }
}

/// Normalise a `[1, 3, H, W]` image in `[0, 1]` with the model's mean / std.
pub fn normalise(model: &FasterRcnn, x: &Tensor) -> Tensor {
    let c = model.config();
    let mean = Tensor::from_slice(&c.pixel_mean).reshape([1, 3, 1, 1]);
    let std = Tensor::from_slice(&c.pixel_std).reshape([1, 3, 1, 1]);
    (x - mean) / std
}

/// Frame `f` as the model's normalised input at `height × width`.
pub fn model_input(
    model: &FasterRcnn,
    ds: &Dataset,
    f: &FrameRecord,
    input: (usize, usize),
) -> Result<Tensor, ModelError> {
    let rgb = ds
        .load_rgb(f)
        .map_err(|e| ModelError::Data(e.to_string()))?;
    Ok(normalise(
        model,
        &resize(&image_tensor(&rgb), input.0, input.1),
    ))
}

/// Fine-tune `model` in place for `cfg.steps` steps at input size `input = (height,
/// width)`; `masks` (magnitude pruning) are re-applied after every step. `base` gives
/// the sampling and augmentation settings of the original training. Returns the mean
/// loss of the last 10 steps.
pub fn finetune(
    model: &FasterRcnn,
    ds: &Dataset,
    base: &TrainConfig,
    cfg: &FinetuneConfig,
    input: (usize, usize),
    masks: Option<&Masks>,
    mut on_step: impl FnMut(usize, f64),
) -> Result<f64, ModelError> {
    let frames: Vec<&FrameRecord> = spread(ds.split(Split::Train).collect(), cfg.frames);
    if frames.is_empty() {
        return Err(ModelError::Data(format!(
            "{}: the train split is empty",
            ds.root.display()
        )));
    }
    let tc = TrainConfig {
        lr: cfg.lr,
        batch_size: cfg.batch_size.max(1),
        warmup_steps: (cfg.steps / 10).max(1),
        ..base.clone()
    };
    let mut opt = Optimizer::new(model.var_store(), &tc);
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let mut order: Vec<usize> = Vec::new();
    let mut recent = Vec::new();
    for step in 0..cfg.steps {
        tch::manual_seed((cfg.seed ^ step as u64) as i64);
        opt.zero_grad();
        let mut images = Vec::with_capacity(tc.batch_size);
        let mut truths = Vec::with_capacity(tc.batch_size);
        for _ in 0..tc.batch_size {
            if order.is_empty() {
                order = (0..frames.len()).collect();
                order.shuffle(&mut rng);
            }
            let f = frames[order.pop().unwrap_or(0)];
            let rgb = ds
                .load_rgb(f)
                .map_err(|e| ModelError::Data(e.to_string()))?;
            let img = augment(&image_tensor(&rgb), &tc, &mut rng);
            images.push(normalise(model, &resize(&img, input.0, input.1)));
            truths.push(scaled_truth(f, input));
        }
        // one forward and backward pass over the batch (all frames at `input`)
        let total = batch_losses(model, &Tensor::cat(&images, 0), &truths, &tc, &mut rng).total();
        total.backward();
        opt.step(learning_rate(&tc, step, cfg.steps));
        if let Some(m) = masks {
            apply_masks(model, m);
        }
        let loss = total.double_value(&[]);
        recent.push(loss);
        on_step(step + 1, loss);
    }
    let tail = &recent[recent.len().saturating_sub(10)..];
    Ok(tail.iter().sum::<f64>() / tail.len().max(1) as f64)
}
