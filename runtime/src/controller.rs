//! The per-frame decision: detect with variant `k`, or track.
//!
//! This is the paper's loop, as pure, allocation-free, O(1) code, so the workbench's
//! replay, the maze simulation and the drone all run exactly this:
//!
//! - the policy is asked at the start, every `N` frames (the MDP re-run), when the last
//!   detection scored below its family's `T_c` (or found nothing), when the tracker lost
//!   the object, and when the tracker's IoU with the last detection fell below `θ_th`;
//!   the state is (confidence bucket of the last score on the current variant's
//!   family scale, current variant) and the action is the variant to run next;
//! - otherwise a detection with the current variant re-initialises the tracker every
//!   `M` frames;
//! - otherwise the frame is tracked;
//! - after any detection that scored below `T_c` (or found nothing), the policy is
//!   asked again at once and its choice runs on the same image ([`Controller::detected`]),
//!   up to the bundle's accesses per image (paper: 5) and never twice with one variant
//!   on one image (the detectors are deterministic, so a repeat would only cost time).
//!
//! The calling loop, per frame `t`:
//!
//! 1. if the tracker holds a box, track it into frame `t` and compute its IoU with the
//!    last detection's box ([`TrackStatus`]);
//! 2. `controller.step(&Observation { frame: t, score, track })`, where `score` is the
//!    best score of the detection that the previous [`Decision::Detect`] asked for
//!    (`None` when it found nothing; ignored after [`Decision::Track`]);
//! 3. on [`Decision::Detect`], run that variant on frame `t` and hand its best score to
//!    [`Controller::detected`]; while it answers [`Access::Again`], run that variant on
//!    the same frame and hand its score over in turn. Then (re)initialise the tracker on
//!    the last detection's best box; on [`Decision::Track`], report the tracker's box.
//!
//! A caller that never calls [`Controller::detected`] passes the score in the next
//! [`Observation`] instead and gets one detection per image.

use crate::bundle::{Bucket, Bundle, MAX_ACCESSES, Thresholds};
use crate::geom::{BBox, VariantId};

/// `a < b`, with NaN on either side counting as below (a NaN IoU or quality is not trusted).
#[allow(clippy::neg_cmp_op_on_partial_ord)]
const fn below(a: f32, b: f32) -> bool {
    !(a >= b)
}

/// What the tracker says about the current frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackStatus {
    /// The tracked box in this frame.
    pub bbox: BBox,
    /// IoU of `bbox` with the last detection's box (`θ(B_d, B_t)`).
    pub iou: f32,
    /// Fraction of the tracker's initial points still tracked, in `[0, 1]`.
    pub quality: f32,
}

/// What the controller is told at each frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observation {
    /// Frame index (consecutive; wrapping is fine).
    pub frame: u32,
    /// The best classifier score of the detection that the previous decision asked for;
    /// `None` when that detection found nothing. Ignored unless the previous decision
    /// was [`Decision::Detect`].
    pub score: Option<f32>,
    /// The tracker's result on this frame; `None` when it holds no box (lost, failed,
    /// or never initialised).
    pub track: Option<TrackStatus>,
}

/// Why a detection was asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Trigger {
    /// The first frame: run the bundle's initial variant.
    Start,
    /// `N` frames since the policy was last asked.
    Periodic,
    /// The last detection scored below `T_c` or found nothing.
    LowScore,
    /// The tracker holds no box or too few of its points survive (`T_m`).
    TrackerLost,
    /// The tracker's IoU with the last detection fell below `θ_th`.
    Drift,
    /// `M` frames since the last detection: re-initialise the tracker (no policy query).
    Reinit,
}

impl Trigger {
    /// Every trigger, in declaration order (`ALL[t as usize] == t`).
    pub const ALL: [Trigger; 6] = [
        Trigger::Start,
        Trigger::Periodic,
        Trigger::LowScore,
        Trigger::TrackerLost,
        Trigger::Drift,
        Trigger::Reinit,
    ];

    /// True when this trigger consulted the policy (all but [`Trigger::Start`], which
    /// runs the bundle's initial variant, and [`Trigger::Reinit`]).
    pub const fn queried_policy(self) -> bool {
        !matches!(self, Trigger::Start | Trigger::Reinit)
    }
}

/// The controller's answer for one frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decision {
    /// Run detector `variant` on this frame and re-initialise the tracker on its box.
    Detect {
        /// The variant to run.
        variant: VariantId,
        /// Why.
        reason: Trigger,
    },
    /// Keep the tracker's box for this frame.
    Track,
}

/// The answer to [`Controller::detected`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    /// The image is done: report (and track) the last detection.
    Done,
    /// The last detection scored below `T_c`: run this variant on the same image.
    Again(VariantId),
}

/// Counters since construction (for replay reports).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stats {
    /// Frames decided.
    pub frames: u32,
    /// Detections asked for.
    pub detections: u32,
    /// Policy queries.
    pub queries: u32,
}

/// The per-frame controller over a parsed [`Bundle`]. `Copy`, a few dozen bytes.
#[derive(Clone, Copy, Debug)]
pub struct Controller<'a> {
    bundle: Bundle<'a>,
    thresholds: Thresholds,
    variant: VariantId,
    score: Option<f32>,
    awaiting_detection: bool,
    started: bool,
    last_query: u32,
    last_detection: u32,
    /// Variants run on the current image, in order; `accesses` of them are valid.
    tried: [VariantId; MAX_ACCESSES as usize],
    accesses: usize,
    stats: Stats,
}

impl<'a> Controller<'a> {
    /// A controller starting from the bundle's initial variant.
    pub const fn new(bundle: Bundle<'a>) -> Self {
        let thresholds = bundle.thresholds();
        let variant = bundle.policy().initial();
        Self {
            bundle,
            thresholds,
            variant,
            score: None,
            awaiting_detection: false,
            started: false,
            last_query: 0,
            last_detection: 0,
            tried: [0; MAX_ACCESSES as usize],
            accesses: 0,
            stats: Stats {
                frames: 0,
                detections: 0,
                queries: 0,
            },
        }
    }

    /// Back to the state of [`Controller::new`].
    pub fn reset(&mut self) {
        *self = Self::new(self.bundle);
    }

    /// The variant the controller currently runs.
    pub const fn current_variant(&self) -> VariantId {
        self.variant
    }

    /// The last detection's score as the controller saw it.
    pub const fn last_score(&self) -> Option<f32> {
        self.score
    }

    /// Counters.
    pub const fn stats(&self) -> Stats {
        self.stats
    }

    /// The bundle this controller reads.
    pub const fn bundle(&self) -> &Bundle<'a> {
        &self.bundle
    }

    /// The current variant's `T_c` (its family's), `None` for a variant outside the bundle.
    pub fn t_c(&self) -> Option<f32> {
        self.bundle.variant_buckets(self.variant).map(|b| b.t_c)
    }

    /// The policy's state for the current variant and last score: the confidence bucket.
    pub fn bucket(&self) -> Bucket {
        self.bundle
            .variant_buckets(self.variant)
            .map_or(Bucket::Miss, |b| b.bucket(self.score))
    }

    /// The policy lookup: bucket of `score` on `current`'s family scale, then the action.
    /// Falls back to `current` for a variant outside the bundle.
    pub fn lookup(&self, score: Option<f32>, current: VariantId) -> VariantId {
        let bucket = self
            .bundle
            .variant_buckets(current)
            .map_or(Bucket::Miss, |b| b.bucket(score));
        self.bundle
            .policy()
            .action(bucket, current)
            .unwrap_or(current)
    }

    /// Decides what to do with frame `obs.frame`. O(1), allocation-free, never panics.
    pub fn step(&mut self, obs: &Observation) -> Decision {
        if self.awaiting_detection {
            self.awaiting_detection = false;
            self.score = obs.score;
        }
        self.stats.frames = self.stats.frames.wrapping_add(1);
        let th = &self.thresholds;
        let t_c = self.t_c().unwrap_or(f32::INFINITY);
        let since_query = obs.frame.wrapping_sub(self.last_query);
        let since_detection = obs.frame.wrapping_sub(self.last_detection);
        let reason = if !self.started {
            Some(Trigger::Start)
        } else if since_query >= th.mdp_period {
            Some(Trigger::Periodic)
        } else if !self.score.is_some_and(|s| s >= t_c) {
            Some(Trigger::LowScore)
        } else if obs
            .track
            .is_none_or(|t| below(t.quality, th.min_track_quality) || !t.bbox.is_valid())
        {
            Some(Trigger::TrackerLost)
        } else if obs.track.is_some_and(|t| below(t.iou, th.iou_threshold)) {
            Some(Trigger::Drift)
        } else if since_detection >= th.reinit_period {
            Some(Trigger::Reinit)
        } else {
            None
        };
        match reason {
            None => Decision::Track,
            Some(reason) => {
                if reason.queried_policy() {
                    self.variant = self.lookup(self.score, self.variant);
                    self.stats.queries = self.stats.queries.wrapping_add(1);
                }
                if reason != Trigger::Reinit {
                    self.last_query = obs.frame;
                }
                self.started = true;
                self.awaiting_detection = true;
                self.last_detection = obs.frame;
                self.stats.detections = self.stats.detections.wrapping_add(1);
                self.tried[0] = self.variant;
                self.accesses = 1;
                Decision::Detect {
                    variant: self.variant,
                    reason,
                }
            }
        }
    }

    /// The best score of the detection just run on the current image (`None`: it found
    /// nothing). When it is below the variant's `T_c`, the policy is asked again from
    /// (bucket of this score, this variant) and [`Access::Again`] names the variant to
    /// run on the same image, unless the image already had its accesses per image or
    /// the policy names a variant already run on it. Called without a pending
    /// detection, it only records the score and answers [`Access::Done`].
    pub fn detected(&mut self, score: Option<f32>) -> Access {
        self.awaiting_detection = false;
        self.score = score;
        let limit = (self.thresholds.accesses_per_image as usize).min(self.tried.len());
        let t_c = self.t_c().unwrap_or(f32::NEG_INFINITY);
        if self.accesses == 0 || self.accesses >= limit || score.is_some_and(|s| s >= t_c) {
            self.accesses = 0;
            return Access::Done;
        }
        let next = self.lookup(score, self.variant);
        self.stats.queries = self.stats.queries.wrapping_add(1);
        let tried = self.tried.get(..self.accesses).unwrap_or(&[]);
        if tried.contains(&next) {
            self.accesses = 0;
            return Access::Done;
        }
        if let Some(slot) = self.tried.get_mut(self.accesses) {
            *slot = next;
        }
        self.accesses += 1;
        self.variant = next;
        self.stats.detections = self.stats.detections.wrapping_add(1);
        Access::Again(next)
    }
}
