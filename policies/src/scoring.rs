//! What one frame holds and what a variant got right on it, and the tracker's cost
//! model: the pieces every evaluation (the paper's strategies, the budget strategies)
//! and the policies' training build on.

use crate::replay::{ReplayLog, VideoLog};
use frugal_data::{Clutter, Light, Split};
use frugal_models::metrics::{ImageResult, Interpolation, Truth, evaluate, image_counts};
use frugal_runtime::Detection;
use serde::{Deserialize, Serialize};

/// Points per KLT tracker.
pub const TRACK_POINTS: usize = 48;

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
    /// The reference tracker's median ([`crate::eval::ReferenceTracker`]), timed
    /// between the calls behind the medians above: the tracker's anchor. `None` for
    /// costs kept before it was timed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_ms: Option<f64>,
}

impl TrackerCost {
    /// Every cost times `k` (the reference's too).
    pub fn scaled(self, k: f64) -> Self {
        Self {
            pyramid_ms: self.pyramid_ms * k,
            track_ms: self.track_ms * k,
            init_ms: self.init_ms * k,
            reference_ms: self.reference_ms.map(|r| r * k),
            ..self
        }
    }
}

pub(crate) fn median(v: &mut [f64]) -> f64 {
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

/// What frame `f` of `video` holds (its objects and ignore regions), no detections.
pub(crate) fn ground_truth(video: &VideoLog, f: usize) -> ImageResult {
    let frame = &video.frames[f];
    ImageResult {
        detections: Vec::new(),
        truth: frame
            .truth
            .iter()
            .map(|d| Truth {
                class: d.class,
                bbox: d.bbox(),
            })
            .collect(),
        ignore: frame.ignore.iter().map(|r| r.region()).collect(),
    }
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
    let gt = ground_truth(video, f);
    let (counted, ignored): (Vec<Truth>, Vec<Truth>) = gt
        .truth
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
        ignore: gt.ignore,
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
    f1_of_counts(tp, fp, fneg)
}

/// `2 tp / (2 tp + fp + fn)`, and 1 when there is nothing to find and nothing found.
pub fn f1_of_counts(tp: usize, fp: usize, fneg: usize) -> f64 {
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
                    ..ground_truth(video, f)
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
