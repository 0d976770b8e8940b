//! The speed/accuracy curve of policies: the MDP re-solved for a grid of `α` on the
//! same estimated transitions, for both rewards (and, for the paper's confidence
//! reward, a grid of `w_ge` scales), each policy replayed without the tracker (a
//! detection every frame) on held-out videos.

use crate::error::Result;
use crate::eval::{EvalConfig, Strategy, run_with_bundle};
use crate::replay::{ReplayLog, VideoLog};
use crate::train::{PolicyConfig, Reward, Transitions, solve};
use frugal_data::Split;
use frugal_models::metrics::{ImageResult, Interpolation, evaluate};
use serde::{Deserialize, Serialize};

/// One policy of the sweep.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SweepPoint {
    /// The reward.
    pub reward: Reward,
    /// `α`.
    pub alpha: f64,
    /// `w_ge` multiplier (1 for the outcome reward, which has no weights).
    pub ge_scale: f64,
    /// Mean detector time per frame, ms.
    pub ms_per_frame: f64,
    /// F1 at the evaluation IoU.
    pub f1: f64,
    /// The policy table (bundle layout).
    pub actions: Vec<u16>,
}

/// The videos a sweep is scored on: validation if any, else test, else training.
pub fn sweep_videos(log: &ReplayLog) -> Vec<&VideoLog> {
    for split in [Split::Val, Split::Test, Split::Train] {
        let v: Vec<&VideoLog> = log.split(split).collect();
        if !v.is_empty() {
            return v;
        }
    }
    Vec::new()
}

/// Solve and score every (`α`, `w_ge` scale) of `cfg`'s sweep grid.
pub fn sweep(log: &ReplayLog, cfg: &PolicyConfig, eval: &EvalConfig) -> Result<Vec<SweepPoint>> {
    sweep_with(log, &Transitions::training(log, cfg), cfg, eval)
}

/// [`sweep`] on transitions already counted by [`Transitions::training`].
pub fn sweep_with(
    log: &ReplayLog,
    transitions: &Transitions,
    cfg: &PolicyConfig,
    eval: &EvalConfig,
) -> Result<Vec<SweepPoint>> {
    let videos = sweep_videos(log);
    let training: Vec<u32> = log.split(Split::Train).map(|v| v.id).collect();
    let scales = if cfg.sweep_ge_scale.is_empty() {
        vec![1.0]
    } else {
        cfg.sweep_ge_scale.clone()
    };
    let grid = scales
        .iter()
        .map(|&sc| (Reward::Confidence, sc))
        .chain([(Reward::Outcome, 1.0)]);
    let mut out = Vec::new();
    for (reward, ge_scale) in grid {
        for &alpha in &cfg.sweep_alpha {
            let mut c = cfg.clone();
            c.reward = reward;
            c.alpha = alpha;
            c.weights.ge *= ge_scale;
            let policy = solve(log, transitions, &c, training.clone())?;
            let bundle = crate::bundle::policy_bundle(&policy, eval.every_frame())?;
            let runs = run_with_bundle(log, &videos, Strategy::Mdp, &bundle, None, eval)?;
            let images: Vec<ImageResult> =
                runs.iter().flat_map(|r| r.images.iter().cloned()).collect();
            let frames: usize = runs.iter().map(|r| r.frames.len()).sum();
            let total: f64 = runs.iter().flat_map(|r| &r.frames).map(|t| t.time_ms).sum();
            let s = evaluate(
                &images,
                log.classes.max(1),
                eval.eval_iou,
                f32::NEG_INFINITY,
                Interpolation::AllPoint,
            );
            out.push(SweepPoint {
                reward,
                alpha,
                ge_scale,
                ms_per_frame: if frames > 0 {
                    total / frames as f64
                } else {
                    0.0
                },
                f1: s.f1,
                actions: policy.actions,
            });
        }
    }
    Ok(out)
}
