//! The replay evaluation's scores: per scenario and strategy, and per sign class (the
//! paper's KUL table).

use super::{EvalConfig, Runs, Strategy, VideoRun};
use crate::replay::{ReplayLog, VideoLog};
use crate::scoring::scenario_groups;
use frugal_models::metrics::{ImageResult, Interpolation, evaluate, image_counts};
use frugal_runtime::ClassId;
use serde::{Deserialize, Serialize};

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
        ignore: im
            .ignore
            .iter()
            .filter(|r| r.class.is_none_or(|c| c == class))
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
