//! Per-variant confidence calibration.
//!
//! The MDP's states are confidence buckets, and its reward trusts them: a variant whose
//! scores land in "good enough" is worth running. That holds when a score means the same
//! thing whichever variant produced it. For the paper's SVM margins it roughly does; for
//! the CNN family it does not: a pruned or int8 variant of a weak base model can be
//! *confidently wrong*, scoring its mistakes as high as the base model scores its hits.
//!
//! Calibration gives every variant its own bucket edges, chosen so that a bucket means
//! the same *precision* for every variant: on the training videos of the replay log,
//! the reference variant (the one with the most correct best detections) defines the
//! precision each of its family's edges stands for — the fraction of its frames scoring
//! at least `c_opt`, `c_ge` or `c_ua` whose best detection is right (class and IoU ≥
//! 0.5) — and each variant's edge is then the lowest score above which that variant is
//! at least as precise. A variant that never reaches a precision gets an edge no score
//! reaches ([`UNREACHABLE`]), so it can never be "good enough". Each variant then gets
//! a family of its own in the log (`<family>/<variant>`), which the policy, the replay
//! evaluation and the bundle carry unchanged; `T_c` (the reporting threshold) stays the
//! family's. Test videos are never looked at.
use crate::replay::ReplayLog;
use crate::variants::{Buckets, FamilyInfo};
use frugal_data::Split;
use serde::{Deserialize, Serialize};

/// The edge of a bucket a variant never reaches precisely enough (finite, as the
/// bundle requires).
pub const UNREACHABLE: f32 = f32::MAX;

/// What calibration decided for one variant.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VariantCalibration {
    /// The variant.
    pub variant: String,
    /// Training frames on which it detected something.
    pub samples: usize,
    /// Fraction of those whose best detection is right.
    pub precision: f64,
    /// Its family's edges before calibration.
    pub before: Buckets,
    /// Its own edges.
    pub after: Buckets,
}

/// The precision targets and every variant's edges.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// The reference variant.
    pub reference: String,
    /// Precision the reference reaches at `c_opt`, `c_ge`, `c_ua` of its family.
    pub targets: [f64; 3],
    /// Per variant, in the log's order.
    pub variants: Vec<VariantCalibration>,
}

/// `(best score, right?)` of every training frame on which variant `v` detected something.
fn scored_frames(log: &ReplayLog, v: usize, iou: f32) -> Vec<(f32, bool)> {
    let mut out = Vec::new();
    for video in log.split(Split::Train) {
        for f in &video.frames {
            let Some(best) = f.detections.get(v).and_then(|d| {
                d.iter()
                    .filter(|d| d.score.is_finite())
                    .max_by(|a, b| a.score.total_cmp(&b.score))
            }) else {
                continue;
            };
            let right = f
                .truth
                .iter()
                .any(|t| t.class == best.class && t.bbox().iou(&best.bbox()) >= iou);
            out.push((best.score, right));
        }
    }
    // best first; ties keep the right ones first so an edge never splits them badly
    out.sort_by(|a, b| b.0.total_cmp(&a.0).then(b.1.cmp(&a.1)));
    out
}

/// Precision of the frames scoring at least `edge`.
fn precision_above(frames: &[(f32, bool)], edge: f32) -> Option<f64> {
    let above: Vec<bool> = frames
        .iter()
        .take_while(|(s, _)| *s >= edge)
        .map(|f| f.1)
        .collect();
    (!above.is_empty()).then(|| above.iter().filter(|r| **r).count() as f64 / above.len() as f64)
}

/// The lowest score above which (inclusive) at least `min_samples` frames are at least
/// `target` precise; [`UNREACHABLE`] when there is none.
fn edge_for(frames: &[(f32, bool)], target: f64, min_samples: usize) -> f32 {
    let mut right = 0usize;
    let mut edge = UNREACHABLE;
    for (i, &(score, ok)) in frames.iter().enumerate() {
        right += usize::from(ok);
        let n = i + 1;
        // only where the next frame scores lower, so the edge keeps ties together
        let boundary = frames.get(i + 1).is_none_or(|f| f.0 < score);
        if boundary && n >= min_samples && right as f64 >= target * n as f64 - 1e-9 {
            edge = score;
        }
    }
    edge
}

/// Give every variant of `log` its own family with calibrated edges (see the module
/// docs); `min_samples` frames must back an edge. Returns what was decided; the log is
/// left unchanged when it has no training frames with detections.
pub fn calibrate(log: &mut ReplayLog, min_samples: usize) -> Option<Calibration> {
    const IOU: f32 = 0.5;
    let frames: Vec<Vec<(f32, bool)>> = (0..log.variants.len())
        .map(|v| scored_frames(log, v, IOU))
        .collect();
    let reference = (0..frames.len()).max_by_key(|&v| {
        (
            frames[v].iter().filter(|f| f.1).count(),
            std::cmp::Reverse(v),
        )
    })?;
    let rb = log.buckets(reference);
    let targets = [rb.c_opt, rb.c_ge, rb.c_ua]
        .map(|edge| precision_above(&frames[reference], edge).unwrap_or(1.0));
    if frames[reference].is_empty() {
        return None;
    }
    let mut families = Vec::with_capacity(log.variants.len());
    let mut variants = Vec::with_capacity(log.variants.len());
    for (v, info) in log.variants.iter_mut().enumerate() {
        let family = &log.families[info.family];
        let before = family.buckets;
        let [c_opt, c_ge, c_ua] = targets.map(|t| edge_for(&frames[v], t, min_samples));
        // keep the order the bundle requires even where precision is not monotone
        let c_ge = c_ge.min(c_opt);
        let c_ua = c_ua.min(c_ge);
        let after = Buckets {
            c_opt,
            c_ge,
            c_ua,
            t_c: before.t_c,
        };
        let f = &frames[v];
        variants.push(VariantCalibration {
            variant: info.name.clone(),
            samples: f.len(),
            precision: if f.is_empty() {
                0.0
            } else {
                f.iter().filter(|x| x.1).count() as f64 / f.len() as f64
            },
            before,
            after,
        });
        families.push(FamilyInfo {
            name: format!("{}/{}", family.name, info.name),
            buckets: after,
        });
        info.family = v;
    }
    log.families = families;
    Some(Calibration {
        reference: log.variants[reference].name.clone(),
        targets,
        variants,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::replay::{Det, FrameLog, LOG_FORMAT, LOG_VERSION, VideoLog};
    use crate::variants::{CNN_BUCKETS, VariantInfo, VariantSource};
    use frugal_data::{Clutter, Light};

    fn det(class: u16, score: f32, x: f32) -> Det {
        Det {
            class,
            score,
            bbox: [x, 10.0, x + 20.0, 30.0],
        }
    }

    /// Variant 0 is cheap and confidently wrong half the time; variant 1 is right
    /// whenever it scores high.
    fn log(split: Split) -> ReplayLog {
        let frames = (0..40u32)
            .map(|i| {
                let truth = vec![det(1, 1.0, 10.0)];
                let cheap = if i % 2 == 0 {
                    det(1, 0.95, 10.0)
                } else {
                    det(2, 0.95, 10.0) // wrong class, just as confident
                };
                let good = det(1, 0.8 + 0.004 * i as f32, 10.0);
                FrameLog {
                    index: i,
                    truth,
                    detections: vec![vec![cheap], vec![good]],
                    ignore: Vec::new(),
                    time_s: None,
                }
            })
            .collect();
        let info = |name: &str, ms: f64| VariantInfo {
            name: name.into(),
            family: 0,
            latency_ms: ms,
            relative_cost: ms,
            precision: Default::default(),
            source: VariantSource::Onnx { dir: "x".into() },
        };
        ReplayLog {
            format: LOG_FORMAT.into(),
            version: LOG_VERSION,
            dataset: "".into(),
            classes: 3,
            families: vec![FamilyInfo {
                name: "cnn".into(),
                buckets: CNN_BUCKETS,
            }],
            variants: vec![info("cheap", 1.0), info("good", 4.0)],
            max_detections: 8,
            reference_ms: None,
            reference_int8_ms: None,
            videos: vec![VideoLog {
                id: 0,
                clutter: Clutter::Low,
                light: Light::Normal,
                split,
                width: 64,
                height: 48,
                frames,
            }],
        }
    }

    #[test]
    fn a_confidently_wrong_variant_loses_its_good_enough_bucket() {
        let mut l = log(Split::Train);
        let c = calibrate(&mut l, 5).unwrap();
        assert_eq!(c.reference, "good");
        assert_eq!(
            c.targets[1], 1.0,
            "the reference is always right above c_ge"
        );
        // the cheap variant is 50 % precise at every score: no edge reaches 100 %
        let cheap = l.buckets(0).to_runtime();
        assert_eq!(
            cheap.bucket(Some(0.95)),
            frugal_runtime::bundle::Bucket::Miss
        );
        assert_eq!(c.variants[0].precision, 0.5);
        // the reference keeps a reachable good-enough edge at or below its old one
        let good = l.buckets(1);
        assert!(good.c_ge <= CNN_BUCKETS.c_ge.max(0.8), "{good:?}");
        assert_eq!(
            good.to_runtime().bucket(Some(0.9)),
            frugal_runtime::bundle::Bucket::Optimal
        );
        assert_eq!(l.families.len(), 2);
        assert_eq!(l.families[0].name, "cnn/cheap");
        assert_eq!((l.variants[0].family, l.variants[1].family), (0, 1));
        assert!(l.families.iter().all(|f| f.buckets.to_runtime().is_valid()));
    }

    #[test]
    fn only_training_videos_are_used() {
        let mut l = log(Split::Test);
        assert!(calibrate(&mut l, 5).is_none());
        assert_eq!(l.families.len(), 1, "an uncalibrated log is left as it was");
    }

    #[test]
    fn edges_need_enough_samples_and_keep_ties_together() {
        let frames = [(0.9, true), (0.8, true), (0.8, false), (0.5, false)];
        assert_eq!(edge_for(&frames, 1.0, 1), 0.9);
        assert_eq!(edge_for(&frames, 1.0, 2), UNREACHABLE);
        assert_eq!(edge_for(&frames, 0.6, 2), 0.8);
        assert_eq!(edge_for(&frames, 0.5, 1), 0.5);
    }
}
