//! Replay evaluation of the paper's strategies on held-out videos
//! (`frugal policy eval`).
//!
//! Every strategy runs the runtime's [`frugal_runtime::Controller`] over a bundle built with the
//! runtime's writer, so what is evaluated is what flies:
//!
//! 1. [`Strategy::Static`]: the most accurate variant (by F1 on the training videos)
//!    on every frame — a constant policy table, `N = M = 1`;
//! 2. [`Strategy::RandomTracker`]: a random variant at every policy query, tracker in
//!    between (paper thresholds);
//! 3. [`Strategy::Mdp`]: the trained policy, a detection every frame (`N = M = 1`);
//! 4. [`Strategy::StaticTracker`]: the static variant with the tracker;
//! 5. [`Strategy::MdpTracker`]: the trained policy with the tracker;
//! 6. [`Strategy::Oracle`]: per frame, the cheapest variant whose reported detections
//!    are all correct (every sign found at IoU ≥ 0.5, no false alarm); when none is,
//!    the static variant. It is never slower than static and never less accurate.
//!
//! Detections come from the replay log; the KLT tracker runs for real on the real
//! frames between detections, one tracker per reported detection (up to
//! [`EvalConfig::max_tracks`]), and the controller is given the worst IoU and quality
//! among them. A detection is *reported* (scored and tracked) when its score reaches
//! its family's `T_c`. Compute time per frame is the variant's measured latency plus,
//! for the tracker, the medians measured in the same run (pyramid build per frame,
//! track and init per object), so the replay's decisions are deterministic.

mod reference;
mod run;
mod score;

pub use crate::scoring::{Scenario, TRACK_POINTS, TrackerCost, correct, frame_f1, most_accurate};
pub use reference::ReferenceTracker;
pub use score::{ClassScore, Score, class_counts, class_scores, scores};

use crate::error::Result;
use crate::replay::{Frames, ReplayLog, VideoLog};
use crate::scoring::median;
use crate::train::TrainedPolicy;
use frugal_models::metrics::ImageResult;
use frugal_runtime::bundle::{BUCKET_COUNT, Thresholds};
use frugal_runtime::pilot::Carry;
use run::{Timings, run_oracle, run_timed};
use serde::{Deserialize, Serialize};

/// A strategy of the paper's Fig. PerfMDP, plus the oracle.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Strategy {
    /// 1. The most accurate variant on every frame.
    Static,
    /// 2. A random variant at each policy query, with the tracker.
    RandomTracker,
    /// 3. The MDP policy, detecting every frame.
    Mdp,
    /// 4. The static variant with the tracker.
    StaticTracker,
    /// 5. The MDP policy with the tracker.
    MdpTracker,
    /// 6. The per-frame oracle.
    Oracle,
}

impl Strategy {
    /// All, in the paper's order, the oracle last.
    pub const ALL: [Strategy; 6] = [
        Strategy::Static,
        Strategy::RandomTracker,
        Strategy::Mdp,
        Strategy::StaticTracker,
        Strategy::MdpTracker,
        Strategy::Oracle,
    ];

    /// Short name.
    pub fn name(self) -> &'static str {
        match self {
            Strategy::Static => "static",
            Strategy::RandomTracker => "random+tracker",
            Strategy::Mdp => "mdp",
            Strategy::StaticTracker => "static+tracker",
            Strategy::MdpTracker => "mdp+tracker",
            Strategy::Oracle => "oracle",
        }
    }

    /// Whether the KLT tracker runs between detections.
    pub fn uses_tracker(self) -> bool {
        matches!(
            self,
            Strategy::RandomTracker | Strategy::StaticTracker | Strategy::MdpTracker
        )
    }
}

/// Evaluation settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvalConfig {
    /// Thresholds of the tracker strategies (paper: θ_th 0.5, N 100, M 10).
    pub iou_threshold: f32,
    /// `T_m`.
    pub min_track_quality: f32,
    /// `N`.
    pub mdp_period: u32,
    /// `M`.
    pub reinit_period: u32,
    /// Most MDP accesses (detections) per image (paper 5; 1 turns them off).
    pub accesses_per_image: u32,
    /// IoU for a correct detection (paper 0.5).
    pub eval_iou: f32,
    /// Most objects tracked at once.
    pub max_tracks: usize,
    /// Seed of the random strategy.
    pub seed: u64,
    /// Which detections the tracker strategies carry: `"optimal"` (from the variant's
    /// `c_opt` up, the default), `"good-enough"` (from `c_ge` up) or `"reported"` (from
    /// `T_c` up, the paper's rule), as the runtime's
    /// `Pilot::with_carry`.
    pub carry: Carry,
}

impl Default for EvalConfig {
    fn default() -> Self {
        let t = Thresholds::PAPER;
        Self {
            iou_threshold: t.iou_threshold,
            min_track_quality: t.min_track_quality,
            mdp_period: t.mdp_period,
            reinit_period: t.reinit_period,
            accesses_per_image: t.accesses_per_image,
            eval_iou: 0.5,
            max_tracks: 4,
            seed: 7,
            carry: Carry::Optimal,
        }
    }
}

impl EvalConfig {
    /// The tracker strategies' thresholds.
    pub fn thresholds(&self) -> Thresholds {
        Thresholds {
            iou_threshold: self.iou_threshold,
            min_track_quality: self.min_track_quality,
            mdp_period: self.mdp_period,
            reinit_period: self.reinit_period,
            accesses_per_image: self.accesses_per_image,
        }
    }

    /// The no-tracker strategies' thresholds: the policy is asked and a detection runs
    /// on every frame.
    pub fn every_frame(&self) -> Thresholds {
        Thresholds {
            mdp_period: 1,
            reinit_period: 1,
            ..self.thresholds()
        }
    }
}

/// What happened on one frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameTrace {
    /// Frame index.
    pub frame: u32,
    /// The variant whose detections the frame reports, `None` when it was tracked.
    pub detect: Option<u16>,
    /// Variants run on this frame before `detect`, whose detections scored below
    /// `T_c` (the paper's MDP accesses per image).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tried: Vec<u16>,
    /// Why the detection ran (the controller's trigger), if it did.
    pub reason: Option<String>,
    /// The controller's state after the decision: `bucket · V + variant`.
    pub state: usize,
    /// Objects tracked into this frame.
    pub tracked: usize,
    /// Trackers started on this frame.
    pub inits: usize,
    /// Whether a pyramid was needed (tracking or init).
    pub pyramid: bool,
    /// True positives, false positives, false negatives of what was reported.
    pub counts: (usize, usize, usize),
    /// Compute time charged to the frame, ms.
    pub time_ms: f64,
}

/// One strategy on one video.
#[derive(Clone, Debug)]
pub struct VideoRun {
    /// The video id.
    pub video: u32,
    /// Per-frame trace.
    pub frames: Vec<FrameTrace>,
    /// Reported detections and truth per frame (for the metrics).
    pub images: Vec<ImageResult>,
}

/// Everything `policy eval` measures.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EvalReport {
    /// The settings.
    pub config: EvalConfig,
    /// The static strategy's variant.
    pub static_variant: String,
    /// Tracker cost medians.
    pub tracker_cost: TrackerCost,
    /// Per scenario and strategy.
    pub scores: Vec<Score>,
    /// Test videos used.
    pub videos: Vec<u32>,
}

/// All strategies' runs over `videos`, keyed by strategy (same order as
/// [`Strategy::ALL`]), with frame times filled in.
pub struct Runs {
    /// `(strategy, runs per video)`.
    pub runs: Vec<(Strategy, Vec<VideoRun>)>,
    /// Tracker cost medians.
    pub cost: TrackerCost,
    /// The static variant.
    pub static_variant: usize,
}

/// A bundle whose policy always answers `variant`.
pub fn constant_bundle(log: &ReplayLog, variant: u16, thresholds: Thresholds) -> Result<Vec<u8>> {
    let actions = vec![variant; BUCKET_COUNT * log.variants.len()];
    crate::bundle::bundle_bytes(
        &log.families,
        &log.variants,
        &[],
        thresholds,
        variant,
        Some(variant),
        &actions,
        None,
        &[("strategy".into(), format!("constant {variant}"))],
    )
}

/// The bundle of each controlled strategy (the oracle has none).
pub fn strategy_bundle(
    log: &ReplayLog,
    policy: &TrainedPolicy,
    strategy: Strategy,
    static_variant: usize,
    cfg: &EvalConfig,
) -> Result<Option<Vec<u8>>> {
    let th = if strategy.uses_tracker() {
        cfg.thresholds()
    } else {
        cfg.every_frame()
    };
    Ok(match strategy {
        Strategy::Static | Strategy::StaticTracker => {
            Some(constant_bundle(log, static_variant as u16, th)?)
        }
        Strategy::RandomTracker => Some(constant_bundle(log, 0, th)?),
        Strategy::Mdp | Strategy::MdpTracker => Some(crate::bundle::policy_bundle(policy, th)?),
        Strategy::Oracle => None,
    })
}

/// Run `strategy` over `videos` with a given bundle (as built by [`strategy_bundle`],
/// or read back from disk). Frame times are left at the detection latency; tracker
/// costs are added by [`run_all`].
pub fn run_with_bundle(
    log: &ReplayLog,
    videos: &[&VideoLog],
    strategy: Strategy,
    bundle: &[u8],
    frames: Option<&dyn Frames>,
    cfg: &EvalConfig,
) -> Result<Vec<VideoRun>> {
    let mut timings = Timings::default();
    run_timed(log, videos, strategy, bundle, frames, cfg, &mut timings)
}

/// The static strategy's variant: the policy's reference, the most accurate on the
/// videos it was trained on; for a policy saved without one, the most accurate on the
/// log's training videos ([`most_accurate`]). Never chosen on the videos being
/// evaluated when the log holds only test videos (a held-out log).
pub fn static_variant(log: &ReplayLog, policy: &TrainedPolicy, iou: f32) -> usize {
    policy
        .reference
        .map(usize::from)
        .filter(|&v| v < log.variants.len())
        .unwrap_or_else(|| most_accurate(log, iou))
}

/// Run every strategy over `videos`, measure the tracker's medians and charge them.
pub fn run_all(
    log: &ReplayLog,
    policy: &TrainedPolicy,
    videos: &[&VideoLog],
    frames: Option<&dyn Frames>,
    cfg: &EvalConfig,
    strategies: &[Strategy],
) -> Result<Runs> {
    let static_variant = static_variant(log, policy, cfg.eval_iou);
    let mut timings = Timings::default();
    let mut runs = Vec::new();
    for &s in strategies {
        let r = match strategy_bundle(log, policy, s, static_variant, cfg)? {
            Some(bundle) => run_timed(log, videos, s, &bundle, frames, cfg, &mut timings)?,
            None => videos
                .iter()
                .map(|v| run_oracle(log, v, static_variant, cfg))
                .collect(),
        };
        runs.push((s, r));
    }
    let cost = TrackerCost {
        samples: (
            timings.pyramid.len(),
            timings.track.len(),
            timings.init.len(),
        ),
        pyramid_ms: median(&mut timings.pyramid),
        track_ms: median(&mut timings.track),
        init_ms: median(&mut timings.init),
        reference_ms: (!timings.reference.is_empty()).then(|| median(&mut timings.reference)),
    };
    for (_, rs) in &mut runs {
        for r in rs {
            for t in &mut r.frames {
                t.time_ms += if t.pyramid { cost.pyramid_ms } else { 0.0 }
                    + t.tracked as f64 * cost.track_ms
                    + t.inits as f64 * cost.init_ms;
            }
        }
    }
    Ok(Runs {
        runs,
        cost,
        static_variant,
    })
}
