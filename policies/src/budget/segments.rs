//! Replayed segments: a variant detects a frame, the tracker carries its boxes for up to
//! the longest period; and the content state a run of shown frames leaves.

use crate::error::Result;
use crate::replay::{Frames, ReplayLog, VideoLog};
use crate::scoring::TrackerCost;
use crate::scoring::ground_truth;
use frugal_runtime::BBox;
use frugal_runtime::schedule::{Content, ContentEdges};

use super::{
    BudgetConfig, BudgetReward, Perceiver, TrackState, VideoCache, largest, shown_f1, shown_on,
};

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
    let cache = VideoCache::default();
    let longest = *cfg.periods.last().unwrap_or(&1) as usize;
    let n = video.frames.len();
    let mut out = Vec::with_capacity(n);
    // the truth an output of frame `f` costing `ms` (measuring machine) is scored on
    let arrivals = video.arrivals_ms(cfg.fps);
    let truth = |f: usize, ms: f64| match cfg.reward {
        BudgetReward::Shown => ground_truth(video, f),
        BudgetReward::Streaming => ground_truth(video, shown_on(&arrivals, f, ms * cfg.slowdown)),
    };
    for t in 0..n {
        let mut row = Vec::with_capacity(log.variants.len());
        for v in 0..log.variants.len() {
            let mut p = Perceiver::new(log, video, frames, &cache, cost, cfg.max_tracks);
            let (shown, score, ms) = p.detect(t, v)?;
            let tr = truth(t, ms);
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
                let tr = truth(t + k, ms);
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
pub(super) fn content_after(
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
pub(super) type LastBox = Option<(i64, BBox)>;
