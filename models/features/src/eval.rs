//! Accuracy and speed of a variant on labelled frames, and proposal recall.

use crate::edgeboxes::{EdgeBoxesConfig, proposals, recall_at};
use crate::error::Result;
use crate::model::FeatureModel;
use crate::params::HogParams;
use crate::train::LabeledFrame;
use frugal_runtime::{BBox, ClassId, Detection};
use std::time::Instant;

/// Counts of one class.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct ClassCounts {
    /// Detections matching a sign of this class.
    pub tp: usize,
    /// Detections of this class matching nothing.
    pub fp: usize,
    /// Signs of this class no detection matched.
    pub missed: usize,
}

impl ClassCounts {
    /// `tp / (tp + fp)`, or `None` without detections.
    pub fn precision(&self) -> Option<f64> {
        let n = self.tp + self.fp;
        (n > 0).then(|| self.tp as f64 / n as f64)
    }

    /// `tp / (tp + missed)`, or `None` without signs.
    pub fn recall(&self) -> Option<f64> {
        let n = self.tp + self.missed;
        (n > 0).then(|| self.tp as f64 / n as f64)
    }

    /// `2 tp / (2 tp + fp + missed)`, or `None` without detections and signs.
    pub fn f1(&self) -> Option<f64> {
        let n = 2 * self.tp + self.fp + self.missed;
        (n > 0).then(|| 2.0 * self.tp as f64 / n as f64)
    }
}

/// Accuracy and time of one variant.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct EvalReport {
    /// The variant.
    pub params: String,
    /// Detections at or above this score count.
    pub score_threshold: f32,
    /// IoU a detection needs with a sign of its class.
    pub iou: f32,
    /// Frames evaluated.
    pub frames: usize,
    /// Counts per class, indexed by class id.
    pub per_class: Vec<ClassCounts>,
    /// Mean wall time of one frame's detection, milliseconds.
    pub mean_ms: f64,
}

impl EvalReport {
    /// Counts summed over classes.
    pub fn total(&self) -> ClassCounts {
        self.per_class
            .iter()
            .fold(ClassCounts::default(), |a, c| ClassCounts {
                tp: a.tp + c.tp,
                fp: a.fp + c.fp,
                missed: a.missed + c.missed,
            })
    }
}

/// Match one frame's detections (best first) to its signs, greedily by score: a
/// detection at or above `threshold` is a true positive when it overlaps an unmatched
/// sign of its class at IoU ≥ `iou`, a false positive otherwise.
pub fn match_frame(
    dets: &[Detection],
    truth: &[(ClassId, BBox)],
    threshold: f32,
    iou: f32,
    counts: &mut [ClassCounts],
) {
    let mut used = vec![false; truth.len()];
    for d in dets.iter().filter(|d| d.score >= threshold) {
        let hit = truth
            .iter()
            .enumerate()
            .filter(|(i, (c, b))| !used[*i] && *c == d.class && b.iou(&d.bbox) >= iou)
            .max_by(|a, b| a.1.1.iou(&d.bbox).total_cmp(&b.1.1.iou(&d.bbox)));
        let Some(slot) = counts.get_mut(d.class as usize) else {
            continue;
        };
        match hit {
            Some((i, _)) => {
                used[i] = true;
                slot.tp += 1;
            }
            None => slot.fp += 1,
        }
    }
    for (i, (c, _)) in truth.iter().enumerate() {
        if !used[i]
            && let Some(slot) = counts.get_mut(*c as usize)
        {
            slot.missed += 1;
        }
    }
}

/// Run one variant over `frames`, timing each frame's detection (proposals included).
pub fn evaluate(
    model: &FeatureModel,
    params: HogParams,
    frames: &[LabeledFrame],
    threshold: f32,
    iou: f32,
) -> Result<EvalReport> {
    let mut per_class = [vec![ClassCounts::default(); model.classes.len()]];
    let mut secs = [0.0];
    let det = [model.detector(params)?];
    let mut acc = Tally {
        per_class: &mut per_class,
        secs: &mut secs,
    };
    run_variants(model, &det, frames, threshold, iou, &mut acc, &|_, _| {})?;
    let ([per_class], [secs]) = (per_class, secs);
    Ok(report(
        params,
        threshold,
        iou,
        frames.len(),
        per_class,
        secs,
    ))
}

/// Run many variants of one model over `frames`, sharing each frame's proposals: they
/// are computed once per frame at the largest proposal count among `variants` (the
/// first `n` of that list are the list for `n`), and that time is charged to every
/// variant, plus the time the variant takes to classify its first `n` proposals (HoG,
/// SVMs, NMS). `progress(done, total)` is called after each frame.
///
/// Every variant's HoG configuration must be trained in `model`.
pub fn evaluate_many(
    model: &FeatureModel,
    variants: &[HogParams],
    frames: &[LabeledFrame],
    threshold: f32,
    iou: f32,
    progress: &dyn Fn(usize, usize),
) -> Result<Vec<EvalReport>> {
    let dets = variants
        .iter()
        .map(|&p| model.detector(p))
        .collect::<Result<Vec<_>>>()?;
    let mut per_class = vec![vec![ClassCounts::default(); model.classes.len()]; variants.len()];
    let mut secs = vec![0.0f64; variants.len()];
    let mut acc = Tally {
        per_class: &mut per_class,
        secs: &mut secs,
    };
    run_variants(model, &dets, frames, threshold, iou, &mut acc, progress)?;
    Ok(variants
        .iter()
        .zip(per_class)
        .zip(secs)
        .map(|((p, per_class), s)| report(*p, threshold, iou, frames.len(), per_class, s))
        .collect())
}

/// Per-variant counts and detection seconds, filled by [`run_variants`].
struct Tally<'a> {
    per_class: &'a mut [Vec<ClassCounts>],
    secs: &'a mut [f64],
}

/// The frame loop of [`evaluate`] and [`evaluate_many`].
fn run_variants(
    model: &FeatureModel,
    dets: &[crate::model::HogDetector<'_>],
    frames: &[LabeledFrame],
    threshold: f32,
    iou: f32,
    acc: &mut Tally<'_>,
    progress: &dyn Fn(usize, usize),
) -> Result<()> {
    let max = dets
        .iter()
        .map(|d| d.params().proposals as usize)
        .max()
        .unwrap_or(0);
    for (i, f) in frames.iter().enumerate() {
        let img = f.view()?;
        let t = Instant::now();
        let props = model.proposals(&img, max)?;
        let shared = t.elapsed().as_secs_f64();
        for ((det, counts), s) in dets
            .iter()
            .zip(acc.per_class.iter_mut())
            .zip(acc.secs.iter_mut())
        {
            let t = Instant::now();
            let found = det.detect_proposals(&img, &props);
            *s += shared + t.elapsed().as_secs_f64();
            match_frame(&found, &f.objects, threshold, iou, counts);
        }
        progress(i + 1, frames.len());
    }
    Ok(())
}

fn report(
    params: HogParams,
    threshold: f32,
    iou: f32,
    frames: usize,
    per_class: Vec<ClassCounts>,
    secs: f64,
) -> EvalReport {
    EvalReport {
        params: params.to_string(),
        score_threshold: threshold,
        iou,
        frames,
        per_class,
        mean_ms: if frames == 0 {
            0.0
        } else {
            1e3 * secs / frames as f64
        },
    }
}

/// Proposal recall at IoU `iou` for each proposal count: `(count, recall)`, plus the
/// mean time to compute a frame's proposals (ms).
pub fn proposal_recall(
    cfg: &EdgeBoxesConfig,
    frames: &[LabeledFrame],
    counts: &[usize],
    iou: f32,
) -> Result<(Vec<(usize, f64)>, f64)> {
    let max = counts.iter().copied().max().unwrap_or(0);
    let mut hits = vec![(0usize, 0usize); counts.len()];
    let mut secs = 0.0;
    for f in frames {
        let img = f.view()?;
        let t = Instant::now();
        let props = proposals(&img, cfg, max)?;
        secs += t.elapsed().as_secs_f64();
        let boxes: Vec<BBox> = props.iter().map(|p| p.bbox).collect();
        let truth: Vec<BBox> = f.objects.iter().map(|o| o.1).collect();
        for (h, r) in hits.iter_mut().zip(recall_at(&boxes, &truth, counts, iou)) {
            h.0 += r.0;
            h.1 += r.1;
        }
    }
    let recall = counts
        .iter()
        .zip(hits)
        .map(|(&n, (hit, total))| {
            (
                n,
                if total == 0 {
                    0.0
                } else {
                    hit as f64 / total as f64
                },
            )
        })
        .collect();
    let ms = if frames.is_empty() {
        0.0
    } else {
        1e3 * secs / frames.len() as f64
    };
    Ok((recall, ms))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matching_counts_hits_false_alarms_and_misses() {
        let truth = [
            (1, BBox::new(0.0, 0.0, 10.0, 10.0)),
            (2, BBox::new(50.0, 50.0, 60.0, 60.0)),
        ];
        let d = |x: f32, class, score| Detection {
            bbox: BBox::new(x, 0.0, x + 10.0, 10.0),
            score,
            class,
        };
        let dets = [
            d(0.0, 1, 2.0),
            d(1.0, 1, 1.0),
            d(100.0, 0, 0.5),
            d(0.0, 2, -0.2),
        ];
        let mut counts = vec![ClassCounts::default(); 3];
        match_frame(&dets, &truth, 0.0, 0.5, &mut counts);
        assert_eq!(
            counts[1],
            ClassCounts {
                tp: 1,
                fp: 1,
                missed: 0
            }
        );
        assert_eq!(
            counts[0],
            ClassCounts {
                tp: 0,
                fp: 1,
                missed: 0
            }
        );
        // The class-2 detection is below the threshold and wrongly placed: a miss.
        assert_eq!(
            counts[2],
            ClassCounts {
                tp: 0,
                fp: 0,
                missed: 1
            }
        );
        assert_eq!(counts[1].precision(), Some(0.5));
        assert_eq!(counts[2].recall(), Some(0.0));
        assert_eq!(ClassCounts::default().precision(), None);
        assert_eq!(counts[1].f1(), Some(2.0 / 3.0));
        assert_eq!(counts[2].f1(), Some(0.0));
        assert_eq!(ClassCounts::default().f1(), None);
    }
}
