//! The budget policy: which variant to run and how many frames to track before the
//! next detection, under an explicit per-frame latency budget, from what the frame
//! shows (`frugal policy budget`).
//!
//! # State, action, objective
//!
//! - **State**: the paper's (confidence bucket of the last detection, current variant)
//!   plus the content the runtime has for free ([`Content`]: the size bucket of the
//!   largest box shown, the motion bucket of its centre, the object-count bucket);
//!   numbered as the runtime's [`state_index`].
//! - **Action**: (variant, detect-every-`N`), `N` from [`BudgetConfig::periods`] (as
//!   ApproxDet's "sampling interval"): detect with the variant, carry every reported
//!   box with the KLT tracker for up to `N − 1` frames (a lost track ends the segment
//!   early), then decide again.
//! - **Objective** (a constrained semi-MDP, solved by Lagrangian relaxation): maximise
//!   the discounted sum of per-frame F1 (`2tp / (2tp + fp + fn)` of what each frame
//!   shows, 1 on a frame with nothing to find and nothing shown) subject to an
//!   expected device compute per frame ≤ the budget. A segment of `L` frames costing
//!   `C` device-ms earns `Σ F1 − λ (C / budget − L) − κ [variant changed]`; `λ ≥ 0`
//!   is the smallest (bisection) whose policy, rolled out on the training videos,
//!   spends at most the budget per frame; `κ` ([`BudgetConfig::switch_cost`]) pays
//!   for switching variants. Unlike the paper's `w / r(s')^α`, where `α` trades
//!   accuracy for cost at a rate nobody can read off a latency requirement, the
//!   budget is the requirement itself, in milliseconds on the device.
//!
//! # Estimation
//!
//! Every training frame `t`, every variant `v` and every period: the segment that
//! starts with `v` detecting frame `t` is replayed once (the logged detections, the
//! real KLT tracker on the real frames). Samples `(s, a, reward, s', L)` come from
//! pairing each segment ending at `t` (any variant, any period: the state it leaves)
//! with each segment starting at `t`. Rewards and transitions of a state with few
//! samples are shrunk towards those of its content alone, and those towards the
//! action's mean ([`BudgetConfig::smoothing`] samples of weight), so that a state the
//! training videos seldom reach still gets a sensible action.

use crate::error::{PolicyError, Result};
use crate::replay::{Frames, ReplayLog, VideoLog};
use crate::scoring::{TRACK_POINTS, TrackerCost};
pub(crate) use crate::scoring::{reported, truth};
use frugal_data::Split;
use frugal_models::metrics::{ImageResult, Truth, image_counts};
use frugal_runtime::bundle::BUCKET_COUNT;
use frugal_runtime::bundle::write::{BudgetSpec, ScheduleSpec};
use frugal_runtime::schedule::{
    BudgetInfo, CONTENT_STATES, Content, ContentEdges, ScheduleAction, largest_box, state_index,
};
use frugal_runtime::track::{Pyramid, Tracker, TrackerParams, rgb_to_gray};
use frugal_runtime::{BBox, Detection, TrackStatus};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// How the budget policies are learnt and evaluated.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BudgetConfig {
    /// Per-frame latency budgets, ms on the device (one policy table each).
    pub budgets_ms: Vec<f64>,
    /// The device profile's name.
    pub device: String,
    /// Device time over measured time (the profile's slowdown; tx2-like: 6).
    pub slowdown: f64,
    /// Detect-every-`N` choices, ascending, 1..=255 (at most 4).
    pub periods: Vec<u32>,
    /// `κ`: reward lost by switching variants (in frames of F1).
    pub switch_cost: f64,
    /// Per-frame discount `γ`, in `[0, 1)`.
    pub gamma: f64,
    /// Weight, in samples, of the coarser estimate a state's estimate is shrunk to.
    pub smoothing: f64,
    /// Most objects tracked at once.
    pub max_tracks: usize,
    /// Frame rate of the videos, frames per second.
    pub fps: f64,
    /// What happens to frames that arrive while perception is busy.
    pub rule: crate::stream::FrameRule,
    /// The ApproxDet-style scheduler's headroom: it keeps the expected latency under
    /// `budget / headroom`.
    pub approxdet_headroom: f64,
    /// The ApproxDet-style scheduler re-schedules every this many frames.
    pub approxdet_every: u32,
    /// Size edges (px) of the content state.
    pub size_px: [f32; 2],
    /// Motion edges (px per frame) of the content state.
    pub motion_px: [f32; 2],
    /// Seed of the random strategy and of the clock's jitter.
    pub seed: u64,
    /// Each video is streamed this many times, each frame's compute time drawn anew
    /// within ±`jitter` of its measured value, and the pairs of every run pooled: on a
    /// 30 fps clock a change of a fraction of a millisecond can shift which frames are
    /// skipped for the rest of a video, so one run is one sample of the figure.
    pub clock_runs: u32,
    /// Relative jitter of the compute times between clock runs (0 = none).
    pub jitter: f64,
}

impl Default for BudgetConfig {
    fn default() -> Self {
        let e = ContentEdges::DEFAULT;
        Self {
            budgets_ms: vec![33.0, 16.0, 8.0],
            device: "tx2-like".into(),
            slowdown: 6.0,
            periods: vec![1, 2, 4, 8],
            switch_cost: 0.02,
            gamma: 0.8,
            smoothing: 5.0,
            max_tracks: 4,
            fps: 30.0,
            rule: crate::stream::FrameRule::Latest,
            approxdet_headroom: 1.3,
            approxdet_every: 8,
            size_px: e.size_px,
            motion_px: e.motion_px,
            seed: 7,
            clock_runs: 8,
            jitter: 0.05,
        }
    }
}

impl BudgetConfig {
    /// The content edges.
    pub fn edges(&self) -> ContentEdges {
        ContentEdges {
            size_px: self.size_px,
            motion_px: self.motion_px,
        }
    }

    /// Checks every value; `path` names the file in the error.
    pub fn check(&self, path: &std::path::Path) -> Result<()> {
        let bad = |field: &str, m: &str| Err(PolicyError::invalid(path, field, m.to_string()));
        if self.budgets_ms.is_empty()
            || self.budgets_ms.len() > frugal_runtime::schedule::MAX_BUDGETS
            || self.budgets_ms.iter().any(|b| !(b.is_finite() && *b > 0.0))
        {
            return bad("budgets_ms", "1 to 8 budgets, each finite and > 0");
        }
        if !(self.slowdown.is_finite() && self.slowdown > 0.0) {
            return bad("slowdown", "must be finite and > 0");
        }
        if self.periods.is_empty()
            || self.periods.len() > frugal_runtime::schedule::MAX_PERIODS
            || self.periods.windows(2).any(|w| w[0] >= w[1])
            || self.periods.iter().any(|&p| p == 0 || p > 255)
        {
            return bad(
                "periods",
                "1 to 4 periods, strictly ascending, each in 1..=255",
            );
        }
        if !(0.0..1.0).contains(&self.gamma) {
            return bad("gamma", "must be in [0, 1)");
        }
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return bad("fps", "must be finite and > 0");
        }
        if !(self.approxdet_headroom.is_finite() && self.approxdet_headroom >= 1.0) {
            return bad("approxdet_headroom", "must be >= 1");
        }
        if self.clock_runs == 0 || !(0.0..1.0).contains(&self.jitter) {
            return bad("clock_runs", "clock_runs must be >= 1 and jitter in [0, 1)");
        }
        if self.approxdet_every == 0 || self.max_tracks == 0 {
            return bad(
                "approxdet_every",
                "approxdet_every and max_tracks must be >= 1",
            );
        }
        if !(self.switch_cost.is_finite() && self.switch_cost >= 0.0 && self.smoothing >= 0.0) {
            return bad(
                "switch_cost",
                "switch_cost and smoothing must be finite and >= 0",
            );
        }
        Ok(())
    }

    /// The action index of (variant, period index).
    pub fn action(&self, variant: usize, period: usize) -> usize {
        variant * self.periods.len() + period
    }
}

/// The F1 of what a frame shows, 1 when there is nothing to find and nothing shown.
pub fn shown_f1(shown: &[Detection], truth: &[Truth], iou: f32) -> f64 {
    let (tp, fp, fneg) = image_counts(
        &ImageResult {
            detections: shown.to_vec(),
            truth: truth.to_vec(),
        },
        iou,
        f32::NEG_INFINITY,
    );
    if tp + fp + fneg == 0 {
        1.0
    } else {
        (2 * tp) as f64 / (2 * tp + fp + fneg) as f64
    }
}

/// The largest box of a frame's output, as the runtime's scheduler takes it.
pub fn largest(shown: &[Detection]) -> Option<BBox> {
    largest_box(shown.iter().map(|d| d.bbox))
}

/// How the trackers fared on a frame (the runtime's [`frugal_runtime::schedule::TrackState`]).
pub use frugal_runtime::schedule::TrackState;

/// An error of the tracker on frame `f` of `video`.
fn at<E: std::fmt::Display>(video: &VideoLog, f: usize) -> impl Fn(E) -> PolicyError + '_ {
    move |e| PolicyError::Tracker {
        video: video.id,
        frame: video.frames[f].index,
        message: e.to_string(),
    }
}

struct Held {
    tracker: Tracker<TRACK_POINTS>,
    det: Detection,
}

/// The perception loop of the budget strategies over a replay log: the logged
/// detections, every reported box carried by a real KLT tracker on the real frames
/// (as the runtime's `Pilot::scheduled`), compute charged from the measured
/// latencies and the tracker's measured medians.
pub struct Perceiver<'a> {
    log: &'a ReplayLog,
    video: &'a VideoLog,
    frames: &'a dyn Frames,
    cost: TrackerCost,
    max_tracks: usize,
    params: TrackerParams,
    prev: Vec<u8>,
    cur: Vec<u8>,
    gray: Vec<u8>,
    have_prev: bool,
    loaded: Option<usize>,
    held: Vec<Held>,
    status: Option<TrackStatus>,
}

impl<'a> Perceiver<'a> {
    /// A perceiver over one video.
    pub fn new(
        log: &'a ReplayLog,
        video: &'a VideoLog,
        frames: &'a dyn Frames,
        cost: TrackerCost,
        max_tracks: usize,
    ) -> Self {
        let params = TrackerParams::DEFAULT;
        let (w, h) = (video.width as usize, video.height as usize);
        let need = Pyramid::required_len(w, h, params.lk.levels).unwrap_or(0);
        Self {
            log,
            video,
            frames,
            cost,
            max_tracks,
            params,
            prev: vec![0; need],
            cur: vec![0; need],
            gray: vec![0; w * h],
            have_prev: false,
            loaded: None,
            held: Vec::new(),
            status: None,
        }
    }

    /// Loads frame `f` into the current pyramid (the previous one is kept for tracking).
    fn load(&mut self, f: usize) -> Result<()> {
        let (w, h) = (self.video.width as usize, self.video.height as usize);
        let img = self
            .frames
            .load(self.video.id, self.video.frames[f].index)?;
        if img.width as usize != w || img.height as usize != h {
            return Err(at(self.video, f)(format!(
                "frame is {}x{}, the log says {w}x{h}",
                img.width, img.height
            )));
        }
        std::mem::swap(&mut self.prev, &mut self.cur);
        self.have_prev = self.loaded.is_some();
        let video = self.video;
        let gray = rgb_to_gray(&img.view(), &mut self.gray).map_err(at(video, f))?;
        Pyramid::new(&mut self.cur, w, h, self.params.lk.levels)
            .and_then(|mut p| p.build(&gray))
            .map_err(at(video, f))?;
        self.loaded = Some(f);
        Ok(())
    }

    /// Frame `f`, step 1: load it and carry the held boxes into it. Returns how the
    /// trackers fared and the compute charged (ms, measuring machine).
    pub fn track(&mut self, f: usize) -> Result<(TrackState, f64)> {
        self.load(f)?;
        self.status = None;
        if self.held.is_empty() {
            return Ok((TrackState::Idle, 0.0));
        }
        let (w, h, levels) = (
            self.video.width as usize,
            self.video.height as usize,
            self.params.lk.levels,
        );
        let mut ms = self.cost.pyramid_ms;
        if self.have_prev {
            let prev = Pyramid::new(&mut self.prev, w, h, levels).map_err(at(self.video, f))?;
            let cur = Pyramid::new(&mut self.cur, w, h, levels).map_err(at(self.video, f))?;
            // as the runtime's `Pilot` reports it: the box that drifted most from its
            // detection, the worst tracking quality (0 for a track lost on this frame)
            let (mut iou, mut quality, mut bbox) = (f32::INFINITY, f32::INFINITY, None);
            for t in &mut self.held {
                ms += self.cost.track_ms;
                match t.tracker.track(&prev, &cur) {
                    Ok(o) => {
                        let i = o.bbox.iou(&t.det.bbox);
                        if i < iou {
                            iou = i;
                            bbox = Some(o.bbox);
                        }
                        quality = quality.min(o.quality);
                    }
                    Err(_) => quality = 0.0,
                }
            }
            self.status = bbox.map(|bbox| TrackStatus { bbox, iou, quality });
        }
        self.held.retain(|t| t.tracker.is_active());
        Ok((
            if self.held.is_empty() {
                TrackState::Lost
            } else {
                TrackState::Held
            },
            ms,
        ))
    }

    /// How the held boxes fared on the last [`Perceiver::track`], as the runtime's
    /// controller is told (`None`: nothing tracked into that frame).
    pub fn status(&self) -> Option<TrackStatus> {
        self.status
    }

    /// Frame `f`, step 2 on a detection: variant `v`'s reported detections, every one
    /// carried (up to the most tracks). Returns them, their best score and the compute.
    pub fn detect(&mut self, f: usize, v: usize) -> Result<(Vec<Detection>, Option<f32>, f64)> {
        // best first, as the runtime's `Pilot` is handed them
        let mut dets = reported(self.log, self.video, f, v);
        dets.sort_by(|a, b| b.score.total_cmp(&a.score));
        let score = self.video.frames[f].best_score(v);
        let (w, h, levels) = (
            self.video.width as usize,
            self.video.height as usize,
            self.params.lk.levels,
        );
        let mut ms = self.log.variants[v].latency_ms;
        let tracked_before = !self.held.is_empty();
        self.held.clear();
        let cur = Pyramid::new(&mut self.cur, w, h, levels).map_err(at(self.video, f))?;
        for d in dets.iter().take(self.max_tracks) {
            let mut tracker = Tracker::new(self.params);
            ms += self.cost.init_ms;
            if tracker.init(&cur, d.bbox).is_ok() {
                self.held.push(Held { tracker, det: *d });
            }
        }
        if !dets.is_empty() && !tracked_before {
            // the pyramid was built for the trackers' start, not charged by `track`
            ms += self.cost.pyramid_ms;
        }
        Ok((dets, score, ms))
    }

    /// Frame `f`, step 2 on a tracked frame: the carried boxes with their detection's
    /// class and score.
    pub fn tracked(&self) -> Vec<Detection> {
        self.held
            .iter()
            .map(|t| Detection {
                bbox: t.tracker.bbox(),
                ..t.det
            })
            .collect()
    }
}

/// One replayed segment: `v` detects frame `t`, the tracker carries its boxes.
#[derive(Clone, Debug, Default)]
pub struct Segment {
    /// The detection's best score.
    pub score: Option<f32>,
    /// Per frame of the segment (the detection frame first): F1, boxes shown, largest
    /// box, compute (ms, measuring machine). Ends at the longest period, the video's
    /// end, or the frame before the one on which every track was lost.
    pub frames: Vec<(f64, usize, Option<BBox>, f64)>,
}

/// Every segment of a video: `segments[t][v]`.
pub fn video_segments(
    log: &ReplayLog,
    video: &VideoLog,
    frames: &dyn Frames,
    cost: TrackerCost,
    cfg: &BudgetConfig,
    iou: f32,
) -> Result<Vec<Vec<Segment>>> {
    let longest = *cfg.periods.last().unwrap_or(&1) as usize;
    let n = video.frames.len();
    let mut out = Vec::with_capacity(n);
    for t in 0..n {
        let mut row = Vec::with_capacity(log.variants.len());
        for v in 0..log.variants.len() {
            let mut p = Perceiver::new(log, video, frames, cost, cfg.max_tracks);
            p.load(t)?;
            let (shown, score, ms) = p.detect(t, v)?;
            let tr = truth(video, t);
            let mut seg = Segment {
                score,
                frames: vec![(shown_f1(&shown, &tr, iou), shown.len(), largest(&shown), ms)],
            };
            for k in 1..longest {
                if t + k >= n {
                    break;
                }
                let (state, ms) = p.track(t + k)?;
                if state == TrackState::Lost {
                    break;
                }
                let shown = p.tracked();
                let tr = truth(video, t + k);
                seg.frames
                    .push((shown_f1(&shown, &tr, iou), shown.len(), largest(&shown), ms));
            }
            row.push(seg);
        }
        out.push(row);
    }
    Ok(out)
}

/// Content after showing `boxes` (count, largest) frame after frame, starting from the
/// last box shown before them (`prev`: its frame offset, negative, and box).
fn content_after(
    edges: &ContentEdges,
    prev: Option<(i64, BBox)>,
    boxes: &[(usize, Option<BBox>)],
) -> (Content, Option<(i64, BBox)>) {
    let mut last = prev;
    let mut motion = None;
    let mut shown = (0usize, None::<BBox>);
    for (i, &(count, b)) in boxes.iter().enumerate() {
        let i = i as i64;
        shown = (count, b);
        if let Some(b) = b {
            motion = last.map(|(j, p): (i64, BBox)| {
                let (cx, cy) = b.center();
                let (px, py) = p.center();
                ((cx - px).hypot(cy - py)) / (i - j).max(1) as f32
            });
            last = Some((i, b));
        } else {
            motion = None;
        }
    }
    let content = edges.content(shown.1.map(|b| b.height()), motion, shown.0);
    let n = boxes.len() as i64;
    (content, last.map(|(j, b)| (j - n, b)))
}

/// The last box shown before a segment: its frame offset (negative) and box.
type LastBox = Option<(i64, BBox)>;

/// A sample of the semi-MDP.
#[derive(Clone, Copy, Debug)]
struct Sample {
    s: usize,
    a: usize,
    reward: f64,
    cost_ms: f64,
    len: usize,
    next: usize,
}

/// A policy per budget, with what training measured of it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BudgetPolicy {
    /// The budget, device ms per frame.
    pub budget_ms: f64,
    /// The Lagrange multiplier found.
    pub lambda: f64,
    /// Device ms per frame of its rollouts on the training videos.
    pub expected_ms: f64,
    /// 95th percentile over training videos of the device ms per frame.
    pub p95_ms: f64,
    /// Mean per-frame F1 of its rollouts on the training videos.
    pub train_f1: f64,
    /// Action per state ([`state_index`] order): `variant · P + period index`.
    pub actions: Vec<u16>,
}

/// Budget policies for every configured budget, and the ApproxDet-style tables.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BudgetPolicies {
    /// Settings.
    pub config: BudgetConfig,
    /// Variant names (the log's order).
    pub variants: Vec<String>,
    /// Device ms of each variant's detection (measured × slowdown).
    pub variant_device_ms: Vec<f64>,
    /// The first action (before any state): the cheapest variant, shortest period.
    pub initial: u16,
    /// One per budget.
    pub policies: Vec<BudgetPolicy>,
    /// ApproxDet-style accuracy table: mean per-frame F1 of each action by content
    /// (`content · A + action`) on the training videos.
    pub approx_f1: Vec<f64>,
    /// Device ms per frame of each action on the training videos.
    pub action_ms: Vec<f64>,
    /// Mean per-frame F1 of each variant detecting every frame on the training videos.
    pub variant_f1: Vec<f64>,
}

impl BudgetPolicies {
    /// The runtime action of an action index.
    pub fn schedule_action(&self, a: usize) -> ScheduleAction {
        let p = self.config.periods.len();
        ScheduleAction {
            variant: (a / p) as u16,
            period: self.config.periods[a % p],
        }
    }

    /// The runtime's form: one table per budget, for the bundle.
    pub fn schedule_spec(&self) -> ScheduleSpec {
        ScheduleSpec {
            edges: self.config.edges(),
            periods: self.config.periods.clone(),
            initial: self.schedule_action(usize::from(self.initial)),
            budgets: self
                .policies
                .iter()
                .map(|p| BudgetSpec {
                    info: BudgetInfo {
                        budget_ms: p.budget_ms as f32,
                        slowdown: self.config.slowdown as f32,
                        expected_ms: p.expected_ms as f32,
                        p95_ms: p.p95_ms as f32,
                    },
                    actions: p
                        .actions
                        .iter()
                        .map(|&a| self.schedule_action(usize::from(a)))
                        .collect(),
                })
                .collect(),
        }
    }

    /// The actions a policy under `budget_ms` may take: those whose device ms per frame
    /// (on the training videos) fit the budget; the cheapest alone when none does. So
    /// the policy never runs a variant that breaks the budget while a cheaper choice
    /// keeps it, and the expected-latency constraint decides among the rest.
    pub fn allowed(&self, budget_ms: f64) -> Vec<usize> {
        let a_n = self.action_ms.len();
        let fits: Vec<usize> = (0..a_n)
            .filter(|&a| self.action_ms[a] <= budget_ms)
            .collect();
        if fits.is_empty() {
            (0..a_n)
                .min_by(|&a, &b| self.action_ms[a].total_cmp(&self.action_ms[b]))
                .into_iter()
                .collect()
        } else {
            fits
        }
    }

    /// The ApproxDet-style choice under `budget_ms` for `content`: the most accurate
    /// action (on the training videos, in this content) whose device ms per frame is at
    /// most `budget_ms / headroom`; the cheapest action when none is.
    pub fn approxdet(&self, budget_ms: f64, content: Content) -> usize {
        let a_n = self.action_ms.len();
        let f1 = |a: usize| self.approx_f1[content.index() * a_n + a];
        self.allowed(budget_ms / self.config.approxdet_headroom)
            .into_iter()
            .max_by(|&a, &b| {
                f1(a)
                    .total_cmp(&f1(b))
                    .then(self.action_ms[b].total_cmp(&self.action_ms[a]))
            })
            .unwrap_or(0)
    }

    /// The best static variant under `budget_ms`: the most accurate (detecting every
    /// frame, on the training videos) whose detection fits the budget; the cheapest
    /// when none does.
    pub fn static_under(&self, budget_ms: f64) -> usize {
        let v_n = self.variants.len();
        let fits: Vec<usize> = (0..v_n)
            .filter(|&v| self.variant_device_ms[v] <= budget_ms)
            .collect();
        if fits.is_empty() {
            return (0..v_n)
                .min_by(|&a, &b| self.variant_device_ms[a].total_cmp(&self.variant_device_ms[b]))
                .unwrap_or(0);
        }
        fits.into_iter()
            .max_by(|&a, &b| {
                self.variant_f1[a]
                    .total_cmp(&self.variant_f1[b])
                    .then(self.variant_device_ms[b].total_cmp(&self.variant_device_ms[a]))
            })
            .unwrap_or(0)
    }

    /// The shortest period whose action with variant `v` fits `budget_ms` (the longest
    /// when none does): static + tracker.
    pub fn period_under(&self, v: usize, budget_ms: f64) -> usize {
        let p = self.config.periods.len();
        (0..p)
            .find(|&i| self.action_ms[self.config.action(v, i)] <= budget_ms)
            .unwrap_or(p - 1)
    }
}

/// Learn the budget policies from the log's training videos.
pub fn train_budget(
    log: &ReplayLog,
    frames: &dyn Frames,
    cost: TrackerCost,
    cfg: &BudgetConfig,
    iou: f32,
) -> Result<BudgetPolicies> {
    cfg.check(std::path::Path::new("<budget config>"))?;
    let train: Vec<&VideoLog> = if log.split(Split::Train).next().is_some() {
        log.split(Split::Train).collect()
    } else {
        log.videos.iter().collect()
    };
    let v_n = log.variants.len();
    let p_n = cfg.periods.len();
    let a_n = v_n * p_n;
    let s_n = BUCKET_COUNT * v_n * CONTENT_STATES;
    let edges = cfg.edges();
    // every frame is read by up to `periods.last()` segments of every variant: decode
    // each video once; videos in parallel
    let segs: Vec<Vec<Vec<Segment>>> = {
        use rayon::prelude::*;
        train
            .par_iter()
            .map(|v| {
                let cached = crate::replay::MemoryFrames::of_video(frames, v)?;
                video_segments(log, v, &cached, cost, cfg, iou)
            })
            .collect::<Result<_>>()?
    };
    let seg_len = |seg: &Segment, period: usize| seg.frames.len().min(cfg.periods[period] as usize);
    let seg_cost = |seg: &Segment, len: usize| -> f64 {
        seg.frames[..len].iter().map(|f| f.3).sum::<f64>() * cfg.slowdown
    };
    // the state a segment leaves: bucket of its score on its variant, the variant, content
    let leave = |v: usize, seg: &Segment, len: usize, prev: Option<(i64, BBox)>| {
        let boxes: Vec<(usize, Option<BBox>)> =
            seg.frames[..len].iter().map(|f| (f.1, f.2)).collect();
        let (content, last) = content_after(&edges, prev, &boxes);
        let bucket = log.buckets(v).to_runtime().bucket(seg.score);
        (state_index(bucket, v as u16, content, v_n), last)
    };
    let mut samples: Vec<Sample> = Vec::new();
    let mut action_cost = vec![(0.0f64, 0usize); a_n];
    let mut variant_f1 = vec![(0.0f64, 0usize); v_n];
    let mut approx = vec![(0.0f64, 0usize); CONTENT_STATES * a_n];
    for video in &segs {
        let n = video.len();
        for t in 0..n {
            for (acc, seg) in variant_f1.iter_mut().zip(&video[t]) {
                acc.0 += seg.frames[0].0;
                acc.1 += 1;
            }
            // states that segments ending at t leave: (state, variant, its last box)
            let mut entering: Vec<(usize, usize, LastBox)> = Vec::new();
            for (p0, &period) in cfg.periods.iter().enumerate() {
                let Some(start) = t.checked_sub(period as usize) else {
                    continue;
                };
                for (v0, seg) in video[start].iter().enumerate() {
                    if seg_len(seg, p0) != cfg.periods[p0] as usize {
                        continue; // that segment ended earlier (lost track) or is shorter
                    }
                    let (s, last) = leave(v0, seg, cfg.periods[p0] as usize, None);
                    entering.push((s, v0, last));
                }
            }
            for (v, seg) in video[t].iter().enumerate() {
                for p in 0..p_n {
                    let len = seg_len(seg, p);
                    let a = cfg.action(v, p);
                    let c = seg_cost(seg, len);
                    action_cost[a].0 += c / len as f64;
                    action_cost[a].1 += 1;
                    let reward: f64 = seg.frames[..len].iter().map(|f| f.0).sum();
                    for &(s, v0, last) in &entering {
                        let (next, _) = leave(v, seg, len, last);
                        let content = s % CONTENT_STATES;
                        approx[content * a_n + a].0 += reward / len as f64;
                        approx[content * a_n + a].1 += 1;
                        samples.push(Sample {
                            s,
                            a,
                            reward: reward - if v != v0 { cfg.switch_cost } else { 0.0 },
                            cost_ms: c,
                            len,
                            next,
                        });
                    }
                }
            }
        }
    }
    let mean = |(s, n): (f64, usize)| if n > 0 { s / n as f64 } else { 0.0 };
    let action_ms: Vec<f64> = action_cost.iter().copied().map(mean).collect();
    let model = Model::estimate(&samples, s_n, a_n, cfg);
    let variant_device_ms: Vec<f64> = log
        .variants
        .iter()
        .map(|v| v.latency_ms * cfg.slowdown)
        .collect();
    let cheapest = (0..v_n)
        .min_by(|&a, &b| variant_device_ms[a].total_cmp(&variant_device_ms[b]))
        .unwrap_or(0);
    let mut out = BudgetPolicies {
        config: cfg.clone(),
        variants: log.variants.iter().map(|v| v.name.clone()).collect(),
        variant_device_ms,
        initial: cfg.action(cheapest, 0) as u16,
        policies: Vec::new(),
        approx_f1: approx.iter().copied().map(mean).collect(),
        action_ms,
        variant_f1: variant_f1.iter().copied().map(mean).collect(),
    };
    let initial = out.initial as usize;
    for &budget in &cfg.budgets_ms {
        let allowed = out.allowed(budget);
        let solve = |lambda: f64| {
            let actions = model.solve(budget, lambda, cfg, &allowed);
            let (ms, p95, f1) = rollout(&segs, &actions, initial, cfg, &leave, &seg_len, &seg_cost);
            (actions, ms, p95, f1)
        };
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        let mut best = solve(0.0);
        if best.1 > budget {
            // grow λ until the budget holds (or give up at a very large price)
            let mut found = None;
            while hi < 1e4 {
                let r = solve(hi);
                if r.1 <= budget {
                    found = Some(r);
                    break;
                }
                lo = hi;
                hi *= 4.0;
            }
            match found {
                None => best = solve(hi),
                Some(r) => {
                    best = r;
                    for _ in 0..20 {
                        let mid = 0.5 * (lo + hi);
                        let r = solve(mid);
                        if r.1 <= budget {
                            hi = mid;
                            best = r;
                        } else {
                            lo = mid;
                        }
                    }
                }
            }
        } else {
            hi = 0.0;
        }
        out.policies.push(BudgetPolicy {
            budget_ms: budget,
            lambda: hi,
            expected_ms: best.1,
            p95_ms: best.2,
            train_f1: best.3,
            actions: best.0.iter().map(|&a| a as u16).collect(),
        });
    }
    Ok(out)
}

/// Roll a policy out on the training segments: (device ms per frame overall, its 95th
/// percentile over videos, mean per-frame F1).
#[allow(clippy::type_complexity)]
fn rollout(
    segs: &[Vec<Vec<Segment>>],
    actions: &[usize],
    initial: usize,
    cfg: &BudgetConfig,
    leave: &dyn Fn(usize, &Segment, usize, Option<(i64, BBox)>) -> (usize, Option<(i64, BBox)>),
    seg_len: &dyn Fn(&Segment, usize) -> usize,
    seg_cost: &dyn Fn(&Segment, usize) -> f64,
) -> (f64, f64, f64) {
    let p_n = cfg.periods.len();
    let (mut ms, mut frames, mut f1) = (0.0, 0usize, 0.0);
    let mut per_video = Vec::new();
    for video in segs {
        let (mut t, mut a, mut last) = (0usize, initial, None);
        let (mut vms, mut vframes) = (0.0, 0usize);
        while t < video.len() {
            let (v, p) = (a / p_n, a % p_n);
            let seg = &video[t][v];
            let len = seg_len(seg, p);
            vms += seg_cost(seg, len);
            f1 += seg.frames[..len].iter().map(|f| f.0).sum::<f64>();
            vframes += len;
            let (s, l) = leave(v, seg, len, last);
            last = l;
            a = actions[s];
            t += len;
        }
        ms += vms;
        frames += vframes;
        per_video.push(vms / vframes.max(1) as f64);
    }
    per_video.sort_by(f64::total_cmp);
    let p95 = per_video
        .get(((0.95 * per_video.len() as f64).ceil() as usize).clamp(1, per_video.len().max(1)) - 1)
        .copied()
        .unwrap_or(0.0);
    (ms / frames.max(1) as f64, p95, f1 / frames.max(1) as f64)
}

/// The estimated semi-MDP: per (state, action), smoothed reward, cost, frames, and
/// next states with their expected discount `E[γ^L]`.
struct Model {
    s_n: usize,
    a_n: usize,
    reward: Vec<f64>,
    cost: Vec<f64>,
    len: Vec<f64>,
    next: Vec<Vec<(usize, f64)>>,
}

impl Model {
    fn estimate(samples: &[Sample], s_n: usize, a_n: usize, cfg: &BudgetConfig) -> Model {
        #[derive(Default, Clone)]
        struct Acc {
            n: f64,
            reward: f64,
            cost: f64,
            len: f64,
            next: HashMap<usize, f64>,
        }
        impl Acc {
            fn add(&mut self, x: &Sample, gamma: f64) {
                self.n += 1.0;
                self.reward += x.reward;
                self.cost += x.cost_ms;
                self.len += x.len as f64;
                *self.next.entry(x.next).or_default() += gamma.powi(x.len as i32);
            }
        }
        let content = |s: usize| s % CONTENT_STATES;
        let mut fine = vec![Acc::default(); s_n * a_n];
        let mut coarse = vec![Acc::default(); CONTENT_STATES * a_n];
        let mut action = vec![Acc::default(); a_n];
        for x in samples {
            fine[x.s * a_n + x.a].add(x, cfg.gamma);
            coarse[content(x.s) * a_n + x.a].add(x, cfg.gamma);
            action[x.a].add(x, cfg.gamma);
        }
        let m = cfg.smoothing;
        // shrink `a` towards `prior` (given as means and a next-state distribution)
        let shrink = |a: &Acc, prior: &(f64, f64, f64, Vec<(usize, f64)>)| {
            let w = a.n + m;
            if w <= 0.0 {
                return prior.clone();
            }
            let r = (a.reward + m * prior.0) / w;
            let c = (a.cost + m * prior.1) / w;
            let l = (a.len + m * prior.2) / w;
            let mut next: HashMap<usize, f64> = HashMap::new();
            for (&s, &g) in &a.next {
                *next.entry(s).or_default() += g / w;
            }
            for &(s, g) in &prior.3 {
                *next.entry(s).or_default() += g * m / w;
            }
            let mut next: Vec<(usize, f64)> = next.into_iter().collect();
            next.sort_by_key(|x| x.0);
            (r, c, l, next)
        };
        let as_prior = |a: &Acc| {
            let n = a.n.max(1.0);
            let mut next: Vec<(usize, f64)> = a.next.iter().map(|(&s, &g)| (s, g / n)).collect();
            next.sort_by_key(|x| x.0);
            (a.reward / n, a.cost / n, a.len / n, next)
        };
        let action_prior: Vec<_> = action.iter().map(as_prior).collect();
        let coarse_prior: Vec<_> = (0..CONTENT_STATES * a_n)
            .map(|i| shrink(&coarse[i], &action_prior[i % a_n]))
            .collect();
        let mut model = Model {
            s_n,
            a_n,
            reward: vec![0.0; s_n * a_n],
            cost: vec![0.0; s_n * a_n],
            len: vec![1.0; s_n * a_n],
            next: vec![Vec::new(); s_n * a_n],
        };
        for s in 0..s_n {
            for a in 0..a_n {
                let (r, c, l, next) =
                    shrink(&fine[s * a_n + a], &coarse_prior[content(s) * a_n + a]);
                model.reward[s * a_n + a] = r;
                model.cost[s * a_n + a] = c;
                model.len[s * a_n + a] = l.max(1.0);
                model.next[s * a_n + a] = next;
            }
        }
        model
    }

    /// Value iteration of the Lagrangian reward; the greedy action per state.
    fn solve(&self, budget: f64, lambda: f64, cfg: &BudgetConfig, allowed: &[usize]) -> Vec<usize> {
        let s_n = self.s_n;
        let a_n = self.a_n;
        let q = |s: usize, a: usize, v: &[f64]| {
            let i = s * a_n + a;
            let r = self.reward[i] - lambda * (self.cost[i] / budget - self.len[i]);
            r + self.next[i].iter().map(|&(s2, g)| g * v[s2]).sum::<f64>()
        };
        let mut v = vec![0.0; s_n];
        let tol = 1e-6 * (1.0 - cfg.gamma);
        for _ in 0..10_000 {
            let mut delta = 0.0f64;
            let nv: Vec<f64> = (0..s_n)
                .map(|s| {
                    allowed
                        .iter()
                        .map(|&a| q(s, a, &v))
                        .fold(f64::NEG_INFINITY, f64::max)
                })
                .collect();
            for (a, b) in nv.iter().zip(&v) {
                delta = delta.max((a - b).abs());
            }
            v = nv;
            if delta < tol {
                break;
            }
        }
        (0..s_n)
            .map(|s| {
                let mut best = allowed.first().copied().unwrap_or(0);
                let mut bq = f64::NEG_INFINITY;
                for &a in allowed {
                    let x = q(s, a, &v);
                    if x > bq + 1e-12 {
                        bq = x;
                        best = a;
                    }
                }
                best
            })
            .collect()
    }
}
