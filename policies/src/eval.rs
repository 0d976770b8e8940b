//! Replay evaluation of the paper's strategies on held-out videos
//! (`frugal policy eval`).
//!
//! Every strategy runs the runtime's [`Controller`] over a bundle built with the
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

use crate::error::{PolicyError, Result};
use crate::replay::{Frames, ReplayLog, VideoLog};
use crate::train::TrainedPolicy;
use frugal_data::{Clutter, Light, Split};
use frugal_models::metrics::{ImageResult, Interpolation, Truth, evaluate, image_counts};
use frugal_runtime::bundle::{BUCKET_COUNT, Thresholds};
use frugal_runtime::pilot::Carry;
use frugal_runtime::track::{Pyramid, Tracker, TrackerParams, rgb_to_gray};
use frugal_runtime::{
    BBox, Bundle, ClassId, Controller, Decision, Detection, Observation, TrackStatus,
};
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Points per KLT tracker.
pub const TRACK_POINTS: usize = 48;

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

/// A test scenario (the paper's low clutter, high clutter, low light; plus medium).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Scenario {
    /// Low clutter, normal light.
    LowClutter,
    /// Medium clutter, normal light.
    MediumClutter,
    /// High clutter, normal light.
    HighClutter,
    /// Low light, any clutter.
    LowLight,
}

impl Scenario {
    /// All scenarios.
    pub const ALL: [Scenario; 4] = [
        Scenario::LowClutter,
        Scenario::MediumClutter,
        Scenario::HighClutter,
        Scenario::LowLight,
    ];

    /// The scenario of a video.
    pub fn of(video: &VideoLog) -> Scenario {
        match (video.light, video.clutter) {
            (Light::Low, _) => Scenario::LowLight,
            (Light::Normal, Clutter::Low) => Scenario::LowClutter,
            (Light::Normal, Clutter::Medium) => Scenario::MediumClutter,
            (Light::Normal, Clutter::High) => Scenario::HighClutter,
        }
    }

    /// Short name.
    pub fn name(self) -> &'static str {
        match self {
            Scenario::LowClutter => "low-clutter",
            Scenario::MediumClutter => "medium-clutter",
            Scenario::HighClutter => "high-clutter",
            Scenario::LowLight => "low-light",
        }
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
    pub carry: CarryFrom,
}

/// The bucket from which the tracker strategies carry a detection (the runtime's
/// [`Carry`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CarryFrom {
    /// From the variant's optimal bucket up.
    #[default]
    Optimal,
    /// From the variant's good-enough bucket up.
    GoodEnough,
    /// Every reported detection (from the family's `T_c` up): the paper's rule.
    Reported,
}

impl From<CarryFrom> for Carry {
    fn from(c: CarryFrom) -> Self {
        match c {
            CarryFrom::Optimal => Carry::Optimal,
            CarryFrom::GoodEnough => Carry::GoodEnough,
            CarryFrom::Reported => Carry::Reported,
        }
    }
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
            carry: CarryFrom::Optimal,
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

/// Tracker cost medians measured in the run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrackerCost {
    /// Gray conversion + pyramid build, per frame, ms.
    pub pyramid_ms: f64,
    /// Tracking one object one frame, ms.
    pub track_ms: f64,
    /// Starting one tracker, ms.
    pub init_ms: f64,
    /// Samples behind each median (pyramid, track, init).
    pub samples: (usize, usize, usize),
}

#[derive(Default)]
struct Timings {
    pyramid: Vec<f64>,
    track: Vec<f64>,
    init: Vec<f64>,
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// Reported detections of variant `v` on frame `f` of `video`: score ≥ its `T_c`.
pub(crate) fn reported(log: &ReplayLog, video: &VideoLog, f: usize, v: usize) -> Vec<Detection> {
    let t_c = log.buckets(v).t_c;
    video.frames[f].detections[v]
        .iter()
        .filter(|d| d.score >= t_c)
        .map(|d| d.detection())
        .collect()
}

pub(crate) fn truth(video: &VideoLog, f: usize) -> Vec<Truth> {
    video.frames[f]
        .truth
        .iter()
        .map(|d| Truth {
            class: d.class,
            bbox: d.bbox(),
        })
        .collect()
}

/// True positives, false positives and false negatives of variant `v`'s reported
/// detections on frame `f`, matched at `iou`. Signs whose box is shorter than `min_px`
/// are don't-care (0 counts every sign): missing one is no miss, and a detection that
/// covers one (IoU ≥ `iou`, any class) and no sign that counts is no false alarm. A
/// detection of nothing stays a false alarm, whatever its size.
fn frame_counts(
    log: &ReplayLog,
    video: &VideoLog,
    f: usize,
    v: usize,
    iou: f32,
    min_px: f32,
) -> (usize, usize, usize) {
    let (counted, ignored): (Vec<Truth>, Vec<Truth>) = truth(video, f)
        .into_iter()
        .partition(|t| t.bbox.height() >= min_px || t.bbox.height().is_nan());
    let mut detections = reported(log, video, f, v);
    if !ignored.is_empty() {
        let covers = |d: &Detection, ts: &[Truth]| ts.iter().any(|t| d.bbox.iou(&t.bbox) >= iou);
        detections.retain(|d| covers(d, &counted) || !covers(d, &ignored));
    }
    let im = ImageResult {
        detections,
        truth: counted,
    };
    image_counts(&im, iou, f32::NEG_INFINITY)
}

/// Per-frame correctness of a variant: every sign found, no false alarm.
pub fn correct(log: &ReplayLog, video: &VideoLog, f: usize, v: usize, iou: f32) -> bool {
    let (_, fp, fneg) = frame_counts(log, video, f, v, iou, 0.0);
    fp == 0 && fneg == 0
}

/// The F1 of variant `v` on frame `f` alone, `2 tp / (2 tp + fp + fn)`: 1 when it
/// reports exactly the signs there are (nothing, on a frame without signs), 0 when it
/// finds none of them or only false alarms. Signs shorter than `min_px` are don't-care
/// (see [`PolicyConfig::outcome_min_px`](crate::PolicyConfig); 0 counts every sign).
pub fn frame_f1(
    log: &ReplayLog,
    video: &VideoLog,
    f: usize,
    v: usize,
    iou: f32,
    min_px: f32,
) -> f64 {
    let (tp, fp, fneg) = frame_counts(log, video, f, v, iou, min_px);
    if tp + fp + fneg == 0 {
        1.0
    } else {
        (2 * tp) as f64 / (2 * tp + fp + fneg) as f64
    }
}

/// The most accurate variant (F1 detecting every frame) on the log's training videos
/// (all videos if there are none); ties go to the cheaper.
pub fn most_accurate(log: &ReplayLog, iou: f32) -> usize {
    let train: Vec<&VideoLog> = if log.split(Split::Train).next().is_some() {
        log.split(Split::Train).collect()
    } else {
        log.videos.iter().collect()
    };
    let mut best = (0, f64::NEG_INFINITY);
    for v in 0..log.variants.len() {
        let images: Vec<ImageResult> = train
            .iter()
            .flat_map(|video| {
                (0..video.frames.len()).map(move |f| ImageResult {
                    detections: reported(log, video, f, v),
                    truth: truth(video, f),
                })
            })
            .collect();
        let f1 = evaluate(
            &images,
            log.classes.max(1),
            iou,
            f32::NEG_INFINITY,
            Interpolation::AllPoint,
        )
        .f1;
        if f1 > best.1 + 1e-12 {
            best = (v, f1);
        }
    }
    best.0
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

struct Track {
    tracker: Tracker<TRACK_POINTS>,
    init: BBox,
    det: Detection,
}

fn tracker_err(
    video: u32,
    frame: u32,
) -> impl Fn(frugal_runtime::track::TrackError) -> PolicyError {
    move |e| PolicyError::Tracker {
        video,
        frame,
        message: e.to_string(),
    }
}

/// Run one strategy over one video with the controller over `bundle`. `frames` is
/// needed when `tracker` is set; `random` overrides the variant at every policy query.
#[allow(clippy::too_many_arguments)]
fn run_controlled(
    log: &ReplayLog,
    video: &VideoLog,
    bundle: &[u8],
    tracker: Option<&dyn Frames>,
    random: Option<u64>,
    cfg: &EvalConfig,
    timings: &mut Timings,
) -> Result<VideoRun> {
    let bundle = Bundle::parse(bundle).map_err(|e| PolicyError::Bundle {
        path: "<memory>".into(),
        message: e.to_string(),
    })?;
    let v_n = log.variants.len();
    let mut ctl = Controller::new(bundle);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(random.unwrap_or(0) ^ u64::from(video.id));
    let mut random_variant: u16 = 0;
    let (w, h) = (video.width as usize, video.height as usize);
    let params = TrackerParams::DEFAULT;
    let levels = params.lk.levels;
    let need = Pyramid::required_len(w, h, levels).unwrap_or(0);
    let (mut prev_buf, mut cur_buf, mut gray_buf) = if tracker.is_some() {
        (vec![0u8; need], vec![0u8; need], vec![0u8; w * h])
    } else {
        (Vec::new(), Vec::new(), Vec::new())
    };
    let mut have_prev = false;
    let mut tracks: Vec<Track> = Vec::new();
    // a reported detection of the last detection frame has no tracker (as in the
    // runtime's `Pilot`: the controller is told the track is lost, and detects again)
    let mut untracked = false;
    let mut score: Option<f32> = None;
    let mut out = VideoRun {
        video: video.id,
        frames: Vec::with_capacity(video.frames.len()),
        images: Vec::with_capacity(video.frames.len()),
    };
    for (fi, f) in video.frames.iter().enumerate() {
        let err = tracker_err(video.id, f.index);
        let mut trace = FrameTrace {
            frame: f.index,
            detect: None,
            tried: Vec::new(),
            reason: None,
            state: 0,
            tracked: 0,
            inits: 0,
            pyramid: false,
            counts: (0, 0, 0),
            time_ms: 0.0,
        };
        let mut status: Option<TrackStatus> = None;
        if let Some(frames) = tracker {
            let img = frames.load(video.id, f.index)?;
            if img.width as usize != w || img.height as usize != h {
                return Err(PolicyError::Tracker {
                    video: video.id,
                    frame: f.index,
                    message: format!(
                        "frame is {}x{}, the log says {w}x{h}",
                        img.width, img.height
                    ),
                });
            }
            let t0 = Instant::now();
            let gray = rgb_to_gray(&img.view(), &mut gray_buf).map_err(&err)?;
            Pyramid::new(&mut cur_buf, w, h, levels)
                .and_then(|mut p| p.build(&gray))
                .map_err(&err)?;
            timings.pyramid.push(t0.elapsed().as_secs_f64() * 1e3);
            if have_prev && !tracks.is_empty() {
                let prev = Pyramid::new(&mut prev_buf, w, h, levels).map_err(&err)?;
                let cur = Pyramid::new(&mut cur_buf, w, h, levels).map_err(&err)?;
                let (mut iou, mut quality, mut bbox) = (f32::INFINITY, f32::INFINITY, None);
                for t in &mut tracks {
                    let t0 = Instant::now();
                    let r = t.tracker.track(&prev, &cur);
                    timings.track.push(t0.elapsed().as_secs_f64() * 1e3);
                    trace.tracked += 1;
                    match r {
                        Ok(o) => {
                            let i = o.bbox.iou(&t.init);
                            if i < iou {
                                iou = i;
                                bbox = Some(o.bbox);
                            }
                            quality = quality.min(o.quality);
                        }
                        Err(_) => quality = 0.0,
                    }
                }
                trace.pyramid = true;
                tracks.retain(|t| t.tracker.is_active());
                if untracked {
                    quality = 0.0;
                }
                status = bbox.map(|bbox| TrackStatus { bbox, iou, quality });
            }
        }
        let decision = ctl.step(&Observation {
            frame: f.index,
            score,
            track: status,
        });
        let shown: Vec<Detection> = match decision {
            Decision::Detect { variant, reason } => {
                let mut variant = match random {
                    Some(_) => {
                        if reason != frugal_runtime::Trigger::Reinit {
                            random_variant = rng.random_range(0..v_n) as u16;
                        }
                        random_variant
                    }
                    None => variant,
                };
                trace.reason = Some(format!("{reason:?}"));
                // the paper's MDP accesses per image: while the detection scores below
                // T_c, the policy's next choice runs on the same frame (the random
                // strategy has no policy to ask)
                loop {
                    score = video.frames[fi].best_score(usize::from(variant));
                    match ctl.detected(score) {
                        frugal_runtime::Access::Again(next) if random.is_none() => {
                            trace.tried.push(variant);
                            variant = next;
                        }
                        _ => break,
                    }
                }
                let v = usize::from(variant);
                trace.detect = Some(variant);
                let dets = reported(log, video, fi, v);
                if tracker.is_some() {
                    tracks.clear();
                    untracked = false;
                    // only a detection in the optimal bucket (by default) is carried
                    // for up to M frames; a good-enough one is reported on its frame
                    // alone. The edges are the bundle's, as the runtime's `Pilot` reads
                    // them (a policy's calibrated edges even on an uncalibrated log).
                    let carry = bundle
                        .variant_buckets(variant)
                        .map_or(f32::INFINITY, |b| Carry::from(cfg.carry).edge(&b));
                    let cur = Pyramid::new(&mut cur_buf, w, h, levels).map_err(&err)?;
                    for d in dets.iter().take(cfg.max_tracks) {
                        if d.score < carry {
                            untracked = true;
                            continue;
                        }
                        let mut t = Track {
                            tracker: Tracker::new(params),
                            init: d.bbox,
                            det: *d,
                        };
                        let t0 = Instant::now();
                        let ok = t.tracker.init(&cur, d.bbox).is_ok();
                        timings.init.push(t0.elapsed().as_secs_f64() * 1e3);
                        trace.inits += 1;
                        trace.pyramid = true;
                        if ok {
                            tracks.push(t);
                        } else {
                            untracked = true;
                        }
                    }
                }
                dets
            }
            Decision::Track => tracks
                .iter()
                .map(|t| Detection {
                    bbox: t.tracker.bbox(),
                    ..t.det
                })
                .collect(),
        };
        let shown_variant = trace.detect.map_or(ctl.current_variant(), |v| v);
        let bucket = log
            .buckets(usize::from(shown_variant))
            .to_runtime()
            .bucket(score);
        trace.state = bucket.index() * v_n + usize::from(shown_variant);
        let im = ImageResult {
            detections: shown,
            truth: truth(video, fi),
        };
        trace.counts = image_counts(&im, cfg.eval_iou, f32::NEG_INFINITY);
        out.images.push(im);
        out.frames.push(trace);
        if tracker.is_some() {
            std::mem::swap(&mut prev_buf, &mut cur_buf);
            have_prev = true;
        }
    }
    Ok(out)
}

fn run_oracle(log: &ReplayLog, video: &VideoLog, fallback: usize, cfg: &EvalConfig) -> VideoRun {
    let v_n = log.variants.len();
    let mut out = VideoRun {
        video: video.id,
        frames: Vec::new(),
        images: Vec::new(),
    };
    for (fi, f) in video.frames.iter().enumerate() {
        let v = (0..v_n)
            .find(|&v| correct(log, video, fi, v, cfg.eval_iou))
            .unwrap_or(fallback);
        let im = ImageResult {
            detections: reported(log, video, fi, v),
            truth: truth(video, fi),
        };
        let bucket = log.buckets(v).to_runtime().bucket(f.best_score(v));
        out.frames.push(FrameTrace {
            frame: f.index,
            detect: Some(v as u16),
            tried: Vec::new(),
            reason: Some("Oracle".into()),
            state: bucket.index() * v_n + v,
            tracked: 0,
            inits: 0,
            pyramid: false,
            counts: image_counts(&im, cfg.eval_iou, f32::NEG_INFINITY),
            time_ms: log.variants[v].latency_ms,
        });
        out.images.push(im);
    }
    out
}

/// Scores of one strategy on one scenario.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Score {
    /// Scenario name (`all` for every test video).
    pub scenario: String,
    /// Strategy name.
    pub strategy: String,
    /// Videos.
    pub videos: usize,
    /// Frames.
    pub frames: usize,
    /// F1 at the evaluation IoU.
    pub f1: f64,
    /// Precision.
    pub precision: f64,
    /// Recall.
    pub recall: f64,
    /// Mean IoU of matched detections.
    pub mean_iou: f64,
    /// Total compute time, ms.
    pub total_ms: f64,
    /// Per frame, ms.
    pub ms_per_frame: f64,
    /// Frames per second that compute time allows.
    pub fps: f64,
    /// Static's total time over this one's.
    pub speedup_vs_static: f64,
    /// Static's F1 minus this one's (absolute).
    pub f1_loss_vs_static: f64,
    /// Detections run.
    pub detections: usize,
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

fn run_timed(
    log: &ReplayLog,
    videos: &[&VideoLog],
    strategy: Strategy,
    bundle: &[u8],
    frames: Option<&dyn Frames>,
    cfg: &EvalConfig,
    timings: &mut Timings,
) -> Result<Vec<VideoRun>> {
    let tracker = if strategy.uses_tracker() {
        Some(frames.ok_or_else(|| {
            PolicyError::invalid(
                &log.dataset,
                "frames",
                format!("strategy {} needs the video frames", strategy.name()),
            )
        })?)
    } else {
        None
    };
    let random = (strategy == Strategy::RandomTracker).then_some(cfg.seed);
    videos
        .iter()
        .map(|video| {
            let mut run = run_controlled(log, video, bundle, tracker, random, cfg, timings)?;
            for t in &mut run.frames {
                t.time_ms = t
                    .detect
                    .iter()
                    .chain(&t.tried)
                    .map(|&v| log.variants[usize::from(v)].latency_ms)
                    .sum();
            }
            Ok(run)
        })
        .collect()
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

/// Score a set of runs (videos already filtered to one scenario).
fn score(
    log: &ReplayLog,
    scenario: &str,
    strategy: Strategy,
    runs: &[&VideoRun],
    cfg: &EvalConfig,
) -> Score {
    let images: Vec<ImageResult> = runs.iter().flat_map(|r| r.images.iter().cloned()).collect();
    let s = evaluate(
        &images,
        log.classes.max(1),
        cfg.eval_iou,
        f32::NEG_INFINITY,
        Interpolation::AllPoint,
    );
    let frames: usize = runs.iter().map(|r| r.frames.len()).sum();
    let total: f64 = runs.iter().flat_map(|r| &r.frames).map(|t| t.time_ms).sum();
    let per = if frames > 0 {
        total / frames as f64
    } else {
        0.0
    };
    Score {
        scenario: scenario.into(),
        strategy: strategy.name().into(),
        videos: runs.len(),
        frames,
        f1: s.f1,
        precision: s.precision,
        recall: s.recall,
        mean_iou: s.mean_iou,
        total_ms: total,
        ms_per_frame: per,
        fps: if per > 0.0 { 1e3 / per } else { f64::INFINITY },
        speedup_vs_static: 1.0,
        f1_loss_vs_static: 0.0,
        detections: runs
            .iter()
            .flat_map(|r| &r.frames)
            .map(|t| usize::from(t.detect.is_some()) + t.tried.len())
            .sum(),
    }
}

/// The scenarios present among `videos` with their video ids, then `all`.
pub(crate) fn scenario_groups(videos: &[&VideoLog]) -> Vec<(String, Vec<u32>)> {
    let mut groups: Vec<(String, Vec<u32>)> = Scenario::ALL
        .iter()
        .map(|s| {
            (
                s.name().to_owned(),
                videos
                    .iter()
                    .filter(|v| Scenario::of(v) == *s)
                    .map(|v| v.id)
                    .collect::<Vec<_>>(),
            )
        })
        .filter(|(_, ids)| !ids.is_empty())
        .collect();
    groups.push(("all".into(), videos.iter().map(|v| v.id).collect()));
    groups
}

/// Scores per scenario (and `all`) and strategy, with speed-up and F1 loss against
/// the static strategy of the same scenario.
pub fn scores(log: &ReplayLog, videos: &[&VideoLog], runs: &Runs, cfg: &EvalConfig) -> Vec<Score> {
    let groups = scenario_groups(videos);
    let mut out = Vec::new();
    for (name, ids) in &groups {
        let mut group: Vec<Score> = runs
            .runs
            .iter()
            .map(|(s, rs)| {
                let sel: Vec<&VideoRun> = rs.iter().filter(|r| ids.contains(&r.video)).collect();
                score(log, name, *s, &sel, cfg)
            })
            .collect();
        if let Some(st) = group
            .iter()
            .find(|s| s.strategy == Strategy::Static.name())
            .cloned()
        {
            for s in &mut group {
                s.speedup_vs_static = if s.total_ms > 0.0 {
                    st.total_ms / s.total_ms
                } else {
                    f64::INFINITY
                };
                s.f1_loss_vs_static = st.f1 - s.f1;
            }
        }
        out.extend(group);
    }
    out
}

/// Precision, recall and compute time of one strategy on one sign class (or on every
/// class: `class == None`), the rows of the paper's KUL table.
///
/// Counts are the class's share of the overall matching (class-aware, IoU ≥
/// [`EvalConfig::eval_iou`]): true positives and false negatives go to the sign's
/// class, false positives to the detection's class, so the per-class counts sum to
/// the overall ones. Time is the compute time charged to the frames on which a sign
/// of the class is in the ground truth (the `all` row: every frame).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClassScore {
    /// Strategy name.
    pub strategy: String,
    /// Class id, `None` for the all-classes row.
    pub class: Option<ClassId>,
    /// Class name (`all` for the all-classes row).
    pub name: String,
    /// Frames the time is averaged over (frames showing the class; all: every frame).
    pub frames: usize,
    /// True positives.
    pub tp: usize,
    /// False positives.
    pub fp: usize,
    /// False negatives (signs missed).
    pub fn_: usize,
    /// `tp / (tp + fp)`, `None` without detections of the class.
    pub precision: Option<f64>,
    /// `tp / (tp + fn)`, `None` without signs of the class.
    pub recall: Option<f64>,
    /// Mean compute time of those frames, ms.
    pub ms_per_frame: f64,
    /// Standard deviation of the compute time over those frames, ms.
    pub ms_std: f64,
}

/// Counts `(tp, fp, fn)` of class `class` in one image (the class's share of
/// [`image_counts`]: matching is class-aware, so the shares sum to the whole).
pub fn class_counts(im: &ImageResult, class: ClassId, iou: f32) -> (usize, usize, usize) {
    let only = ImageResult {
        detections: im
            .detections
            .iter()
            .filter(|d| d.class == class)
            .copied()
            .collect(),
        truth: im
            .truth
            .iter()
            .filter(|t| t.class == class)
            .copied()
            .collect(),
    };
    image_counts(&only, iou, f32::NEG_INFINITY)
}

fn mean_std(v: &[f64]) -> (f64, f64) {
    if v.is_empty() {
        return (0.0, 0.0);
    }
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / n;
    (m, var.sqrt())
}

fn ratio(a: usize, b: usize) -> Option<f64> {
    (a + b > 0).then(|| a as f64 / (a + b) as f64)
}

/// Per-class scores of every strategy in `runs` (classes `0..log.classes`, then the
/// all-classes row), named by `names` (`class <id>` where a name is missing).
pub fn class_scores(
    log: &ReplayLog,
    runs: &Runs,
    cfg: &EvalConfig,
    names: &[String],
) -> Vec<ClassScore> {
    let classes = log.classes.max(1);
    let mut out = Vec::new();
    for (strategy, rs) in &runs.runs {
        let mut counts = vec![(0usize, 0usize, 0usize); classes];
        let mut times: Vec<Vec<f64>> = vec![Vec::new(); classes];
        let mut all_times = Vec::new();
        for r in rs {
            for (im, t) in r.images.iter().zip(&r.frames) {
                all_times.push(t.time_ms);
                for (c, (count, time)) in counts.iter_mut().zip(&mut times).enumerate() {
                    let (tp, fp, fneg) = class_counts(im, c as ClassId, cfg.eval_iou);
                    count.0 += tp;
                    count.1 += fp;
                    count.2 += fneg;
                    if im.truth.iter().any(|x| usize::from(x.class) == c) {
                        time.push(t.time_ms);
                    }
                }
            }
        }
        let row = |class: Option<ClassId>, name: String, c: (usize, usize, usize), t: &[f64]| {
            let (ms, sd) = mean_std(t);
            ClassScore {
                strategy: strategy.name().into(),
                class,
                name,
                frames: t.len(),
                tp: c.0,
                fp: c.1,
                fn_: c.2,
                precision: ratio(c.0, c.1),
                recall: ratio(c.0, c.2),
                ms_per_frame: ms,
                ms_std: sd,
            }
        };
        for (c, (count, time)) in counts.iter().zip(&times).enumerate() {
            let name = names
                .get(c)
                .cloned()
                .unwrap_or_else(|| format!("class {c}"));
            out.push(row(Some(c as ClassId), name, *count, time));
        }
        let total = counts
            .iter()
            .fold((0, 0, 0), |a, c| (a.0 + c.0, a.1 + c.1, a.2 + c.2));
        out.push(row(None, "all".into(), total, &all_times));
    }
    out
}
