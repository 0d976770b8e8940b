//! Estimating the MDP from a replay log and solving it (`frugal policy train`).
//!
//! - States `s = (bucket, variant)`, numbered `bucket · V + variant` (the bundle's
//!   policy layout), buckets as [`Bucket`] (optimal, good enough, inadequate, miss).
//! - Actions: the variant to run on the next detection.
//! - Transitions: for every pair of consecutive frames `(t, t+1)` of every training
//!   video, every current variant `v` (state `(b_t(v), v)`) and every action `a`, one
//!   count for the next state `(b_{t+1}(a), a)`, where `b_t(v)` is the bucket of `v`'s
//!   best score on frame `t`. Rows get additive smoothing `λ` over the four buckets of
//!   the action's variant (the next variant is always the action).
//! - Reward `R(s', w) = w / r(a)^α` with `r` the cost relative to the cheapest
//!   variant; `R(s, a)` is its expectation over the training transitions. The weight
//!   `w` is chosen by [`Reward`]: the paper's weight of the confidence bucket reached,
//!   `w(b')` ([`Reward::Confidence`]), or what the replay knows and the drone does not,
//!   the next frame's F1 `w = 2tp / (2tp + fp + fn)` of the action's reported
//!   detections against the ground truth ([`Reward::Outcome`], the default). The states
//!   stay confidence buckets either way: the policy only looks at what the runtime can
//!   see.
//! - Solved by value iteration to the configured tolerance, cross-checked with policy
//!   iteration.

use crate::error::{PolicyError, Result};
use crate::mdp::{Mdp, Solution};
use crate::replay::ReplayLog;
use crate::variants::{FamilyInfo, VariantInfo};
use frugal_data::Split;
use frugal_runtime::bundle::{BUCKET_COUNT, Bucket};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Reward weights per confidence bucket of the state reached.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Weights {
    /// `w_opt`.
    pub opt: f64,
    /// `w_ge` (`≫ w_opt`, as in the paper, so that "good enough" wins).
    pub ge: f64,
    /// `w_ua`.
    pub ua: f64,
    /// `w_miss` (the detector found nothing usable).
    pub miss: f64,
}

impl Default for Weights {
    fn default() -> Self {
        Self {
            opt: 2.0,
            ge: 10.0,
            ua: 0.2,
            miss: 0.0,
        }
    }
}

impl Weights {
    /// The weight of a bucket.
    pub fn of(&self, b: Bucket) -> f64 {
        match b {
            Bucket::Optimal => self.opt,
            Bucket::GoodEnough => self.ge,
            Bucket::Inadequate => self.ua,
            Bucket::Miss => self.miss,
        }
    }
}

/// What the weight `w` of the reward `w / r^α` is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Reward {
    /// The paper's: the weight of the confidence bucket reached ([`Weights`]). It
    /// rewards a variant for being *confident*, right or wrong.
    Confidence,
    /// The F1 of the next frame's reported detections against the replay's ground
    /// truth: it rewards a variant for being *right*. The CNN variants are confidently
    /// wrong often enough that only this one keeps the accuracy (README, section 5).
    Outcome,
}

impl Reward {
    /// Both rewards.
    pub const ALL: [Reward; 2] = [Reward::Confidence, Reward::Outcome];

    /// The reward called `name` ([`Reward::name`]).
    pub fn from_name(name: &str) -> Option<Reward> {
        Reward::ALL.into_iter().find(|r| r.name() == name)
    }

    /// `confidence` or `outcome`.
    pub fn name(self) -> &'static str {
        match self {
            Reward::Confidence => "confidence",
            Reward::Outcome => "outcome",
        }
    }
}

/// Prior F1 of an outcome row with few samples: the smoothing pulls its mean reward
/// towards this, with the weight of `λ` samples.
pub const OUTCOME_PRIOR: f64 = 0.5;

/// How the policy is estimated and solved. Every field has a built-in default; a
/// TOML/JSON file may override any subset (unknown keys are rejected).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PolicyConfig {
    /// What the reward's weight is.
    pub reward: Reward,
    /// IoU at which a detection counts as right for [`Reward::Outcome`].
    pub outcome_iou: f32,
    /// Signs whose box is shorter than this (pixels) are don't-care for
    /// [`Reward::Outcome`]: missing one costs nothing, finding one is no false alarm.
    /// 0 (the default) counts every sign. A drone that acts on signs only within some
    /// distance sets the height of a sign at that distance, so that the policy does not
    /// pay for reading signs it has no use for yet.
    pub outcome_min_px: f32,
    /// `α`: how strongly cost discounts the reward.
    pub alpha: f64,
    /// `γ`: the discount factor, in `[0, 1)`.
    pub gamma: f64,
    /// Value iteration stops when its values are within this of the optimum (sup norm).
    pub tolerance: f64,
    /// Additive smoothing `λ` per next bucket.
    pub smoothing: f64,
    /// Reward weights of [`Reward::Confidence`].
    pub weights: Weights,
    /// The `α` values of the speed/accuracy sweep (both rewards).
    pub sweep_alpha: Vec<f64>,
    /// Multipliers of `w_ge` swept together with `α` for [`Reward::Confidence`]
    /// (1 = the configured weights).
    pub sweep_ge_scale: Vec<f64>,
}

impl Default for PolicyConfig {
    fn default() -> Self {
        Self {
            reward: Reward::Outcome,
            outcome_iou: 0.5,
            outcome_min_px: 0.0,
            // outcome rewards live in [0, 1]: a variant 4× the cost must be right about
            // 7 % more often to be chosen (4^0.05 ≈ 1.07)
            alpha: 0.05,
            gamma: 0.9,
            tolerance: 1e-9,
            smoothing: 1.0,
            weights: Weights::default(),
            sweep_alpha: vec![0.0, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0, 2.0, 4.0],
            sweep_ge_scale: vec![0.25, 1.0, 4.0],
        }
    }
}

impl PolicyConfig {
    /// Read a `.toml` or JSON config.
    pub fn read(path: &Path) -> Result<Self> {
        let cfg: PolicyConfig = crate::error::read_toml_or_json(path)?;
        cfg.check(path)?;
        Ok(cfg)
    }

    /// Check ranges; `path` names the file in errors.
    pub fn check(&self, path: &Path) -> Result<()> {
        let bad = |field: &str, msg: String| Err(PolicyError::invalid(path, field, msg));
        if !(0.0..1.0).contains(&self.gamma) {
            return bad("gamma", format!("{} is outside [0, 1)", self.gamma));
        }
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return bad("alpha", format!("{} must be finite and >= 0", self.alpha));
        }
        if !(self.outcome_iou > 0.0 && self.outcome_iou <= 1.0) {
            return bad(
                "outcome_iou",
                format!("{} is outside (0, 1]", self.outcome_iou),
            );
        }
        if !(self.outcome_min_px >= 0.0 && self.outcome_min_px.is_finite()) {
            return bad(
                "outcome_min_px",
                format!("{} must be finite and >= 0", self.outcome_min_px),
            );
        }
        if !(self.tolerance > 0.0 && self.tolerance.is_finite()) {
            return bad("tolerance", format!("{} must be > 0", self.tolerance));
        }
        if !(self.smoothing >= 0.0 && self.smoothing.is_finite()) {
            return bad("smoothing", format!("{} must be >= 0", self.smoothing));
        }
        let w = self.weights;
        if [w.opt, w.ge, w.ua, w.miss].iter().any(|v| !v.is_finite()) {
            return bad("weights", "must be finite".into());
        }
        if self
            .sweep_alpha
            .iter()
            .chain(&self.sweep_ge_scale)
            .any(|v| !(v.is_finite() && *v >= 0.0))
        {
            return bad(
                "sweep_alpha / sweep_ge_scale",
                "must be finite and >= 0".into(),
            );
        }
        Ok(())
    }
}

/// State index of (bucket, variant) with `v` variants.
pub fn state(bucket: Bucket, variant: usize, v: usize) -> usize {
    bucket.index() * v + variant
}

/// Transition counts `counts[(a · S + s) · 4 + b']` for next state `(b', a)`, and the
/// summed next-frame F1 of every row.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Transitions {
    /// Number of variants `V` (states `4 V`, actions `V`).
    pub variants: usize,
    /// Raw counts.
    pub counts: Vec<u64>,
    /// `f1[a · S + s]`: the sum over the row's transitions of the F1 of `a`'s reported
    /// detections on the next frame ([`crate::scoring::frame_f1`]).
    pub f1: Vec<f64>,
}

impl Transitions {
    /// Count the transitions of the videos of `log` for which `keep` holds; a
    /// detection is right at IoU ≥ `iou`.
    pub fn count(
        log: &ReplayLog,
        iou: f32,
        keep: impl Fn(&crate::replay::VideoLog) -> bool,
    ) -> Self {
        Self::count_from(log, iou, 0.0, keep)
    }

    /// [`Transitions::count`] with signs shorter than `min_px` don't-care in the F1
    /// ([`PolicyConfig::outcome_min_px`]).
    pub fn count_from(
        log: &ReplayLog,
        iou: f32,
        min_px: f32,
        keep: impl Fn(&crate::replay::VideoLog) -> bool,
    ) -> Self {
        let v_n = log.variants.len();
        let s_n = BUCKET_COUNT * v_n;
        let mut counts = vec![0u64; v_n * s_n * BUCKET_COUNT];
        let mut f1 = vec![0.0; v_n * s_n];
        let buckets: Vec<_> = (0..v_n).map(|v| log.buckets(v).to_runtime()).collect();
        for video in log.videos.iter().filter(|v| keep(v)) {
            for t in 1..video.frames.len() {
                let (now, next) = (&video.frames[t - 1], &video.frames[t]);
                let next_f1: Vec<f64> = (0..v_n)
                    .map(|a| crate::scoring::frame_f1(log, video, t, a, iou, min_px))
                    .collect();
                for v in 0..v_n {
                    let s = state(buckets[v].bucket(now.best_score(v)), v, v_n);
                    for a in 0..v_n {
                        let b2 = buckets[a].bucket(next.best_score(a));
                        counts[(a * s_n + s) * BUCKET_COUNT + b2.index()] += 1;
                        f1[a * s_n + s] += next_f1[a];
                    }
                }
            }
        }
        Self {
            variants: v_n,
            counts,
            f1,
        }
    }

    /// The smoothed mean next-frame F1 of row `(s, a)`: `(Σ F1 + λ · prior) / (n + λ)`
    /// with the prior [`OUTCOME_PRIOR`].
    pub fn mean_f1(&self, s: usize, a: usize, smoothing: f64) -> f64 {
        let s_n = BUCKET_COUNT * self.variants;
        let n = self.samples(s, a) as f64;
        if n + smoothing > 0.0 {
            (self.f1[a * s_n + s] + smoothing * OUTCOME_PRIOR) / (n + smoothing)
        } else {
            OUTCOME_PRIOR
        }
    }

    /// The transitions of `log`'s training videos, outcomes judged at `cfg`'s IoU.
    pub fn training(log: &ReplayLog, cfg: &PolicyConfig) -> Self {
        Self::count_from(log, cfg.outcome_iou, cfg.outcome_min_px, |v| {
            v.split == Split::Train
        })
    }

    /// Samples behind row `(s, a)`.
    pub fn samples(&self, s: usize, a: usize) -> u64 {
        let s_n = BUCKET_COUNT * self.variants;
        let i = (a * s_n + s) * BUCKET_COUNT;
        self.counts[i..i + BUCKET_COUNT].iter().sum()
    }

    /// The smoothed probability of next bucket `b2` from `s` under `a`. A row with no
    /// samples and no smoothing is uniform over the action's buckets.
    pub fn prob(&self, s: usize, a: usize, b2: usize, smoothing: f64) -> f64 {
        let s_n = BUCKET_COUNT * self.variants;
        let i = (a * s_n + s) * BUCKET_COUNT;
        let row = &self.counts[i..i + BUCKET_COUNT];
        let total = row.iter().sum::<u64>() as f64 + smoothing * BUCKET_COUNT as f64;
        if total > 0.0 {
            (row[b2] as f64 + smoothing) / total
        } else {
            1.0 / BUCKET_COUNT as f64
        }
    }

    /// The MDP for these counts, costs and config.
    pub fn mdp(&self, costs: &[f64], cfg: &PolicyConfig) -> Result<Mdp> {
        let v_n = self.variants;
        let s_n = BUCKET_COUNT * v_n;
        let mut p = vec![0.0; v_n * s_n * s_n];
        let mut r = vec![0.0; s_n * v_n];
        for a in 0..v_n {
            let discount = costs[a].powf(cfg.alpha);
            for s in 0..s_n {
                let row = Bucket::ALL.map(|b| (b, self.prob(s, a, b.index(), cfg.smoothing)));
                for (b, pr) in row {
                    p[(a * s_n + s) * s_n + state(b, a, v_n)] = pr;
                }
                let w = match cfg.reward {
                    Reward::Confidence => row.iter().map(|&(b, pr)| pr * cfg.weights.of(b)).sum(),
                    Reward::Outcome => self.mean_f1(s, a, cfg.smoothing),
                };
                r[s * v_n + a] = w / discount;
            }
        }
        Ok(Mdp::new(s_n, v_n, p, r)?)
    }
}

/// A trained policy: what `policy train` writes and `bundle write` reads.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainedPolicy {
    /// The config it was trained with.
    pub config: PolicyConfig,
    /// Families (with buckets).
    pub families: Vec<FamilyInfo>,
    /// Variants, cheapest first.
    pub variants: Vec<VariantInfo>,
    /// The training videos' ids.
    pub training_videos: Vec<u32>,
    /// Variant run before any detection: the policy's action in (miss, cheapest).
    pub initial: u16,
    /// The most accurate variant on the training videos (the replay's static one),
    /// which the bundle names as its reference ([`frugal_runtime::bundle::Policy::reference`]).
    /// Set by [`train`] / [`train_with`]; `None` from [`solve`] alone and in policies
    /// saved before it existed: the bundle then names the costliest.
    #[serde(default)]
    pub reference: Option<u16>,
    /// `actions[bucket · V + v]`: the next variant (the bundle's layout).
    pub actions: Vec<u16>,
    /// State values under the policy.
    pub values: Vec<f64>,
    /// Value-iteration sweeps.
    pub iterations: usize,
    /// Whether policy iteration found the same policy (values within 1e-6).
    pub policy_iteration_agrees: bool,
    /// `samples[s · V + a]`: transitions behind row `(s, a)`.
    pub samples: Vec<u64>,
    /// The estimated MDP.
    pub mdp: Mdp,
    /// Budget + content tables learnt on the same log (`frugal policy budget`), which
    /// the bundle carries beside the paper's table.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub budget: Option<crate::budget::BudgetPolicies>,
}

impl TrainedPolicy {
    /// Save as JSON (atomic).
    pub fn save(&self, path: &Path) -> Result<()> {
        frugal_data::dataset::write_json_atomic(path, self).map_err(PolicyError::from)
    }

    /// Load a saved policy and check its shape.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| PolicyError::io(path, e))?;
        let p: TrainedPolicy = serde_json::from_str(&text).map_err(|e| PolicyError::Parse {
            path: path.into(),
            message: e.to_string(),
        })?;
        let v = p.variants.len();
        if v == 0
            || p.actions.len() != BUCKET_COUNT * v
            || p.actions
                .iter()
                .chain([&p.initial])
                .any(|&a| a as usize >= v)
            || p.variants.iter().any(|x| x.family >= p.families.len())
        {
            return Err(PolicyError::invalid(
                path,
                "actions",
                format!("policy table does not fit {v} variants"),
            ));
        }
        Ok(p)
    }

    /// The action in state (bucket, variant).
    pub fn action(&self, bucket: Bucket, variant: usize) -> u16 {
        self.actions[state(bucket, variant, self.variants.len())]
    }
}

/// Estimate the MDP from `log`'s training videos and solve it.
pub fn train(log: &ReplayLog, cfg: &PolicyConfig) -> Result<TrainedPolicy> {
    train_with(log, &Transitions::training(log, cfg), cfg)
}

/// [`train`] on transitions already counted by [`Transitions::training`].
pub fn train_with(
    log: &ReplayLog,
    transitions: &Transitions,
    cfg: &PolicyConfig,
) -> Result<TrainedPolicy> {
    let training_videos: Vec<u32> = log.split(Split::Train).map(|v| v.id).collect();
    if training_videos.is_empty() {
        return Err(PolicyError::invalid(
            "<replay log>",
            "videos",
            "the log has no training videos",
        ));
    }
    let mut policy = solve(log, transitions, cfg, training_videos)?;
    // once per policy, not per solve (the α sweep solves many and needs none)
    policy.reference = u16::try_from(crate::scoring::most_accurate(log, cfg.outcome_iou)).ok();
    Ok(policy)
}

/// Solve the MDP of given transitions.
pub fn solve(
    log: &ReplayLog,
    transitions: &Transitions,
    cfg: &PolicyConfig,
    training_videos: Vec<u32>,
) -> Result<TrainedPolicy> {
    let costs: Vec<f64> = log.variants.iter().map(|v| v.relative_cost).collect();
    let mdp = transitions.mdp(&costs, cfg)?;
    let vi: Solution = mdp.value_iteration(cfg.gamma, cfg.tolerance)?;
    let pi = mdp.policy_iteration(cfg.gamma)?;
    let agrees = vi.policy == pi.policy
        && vi
            .values
            .iter()
            .zip(&pi.values)
            .all(|(a, b)| (a - b).abs() < 1e-6);
    let v_n = log.variants.len();
    let s_n = BUCKET_COUNT * v_n;
    let samples = (0..s_n)
        .flat_map(|s| (0..v_n).map(move |a| (s, a)))
        .map(|(s, a)| transitions.samples(s, a))
        .collect();
    let actions: Vec<u16> = vi.policy.iter().map(|&a| a as u16).collect();
    Ok(TrainedPolicy {
        config: cfg.clone(),
        families: log.families.clone(),
        variants: log.variants.clone(),
        training_videos,
        initial: actions[state(Bucket::Miss, 0, v_n)],
        reference: None,
        actions,
        values: vi.values,
        iterations: vi.iterations,
        policy_iteration_agrees: agrees,
        samples,
        mdp,
        budget: None,
    })
}
