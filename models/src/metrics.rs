//! Detection metrics in plain Rust on [`Detection`] / [`BBox`] (no `tch`): average
//! precision at an IoU threshold (all-point interpolation as in PASCAL VOC 2010+, or
//! COCO's 101-point interpolation), precision / recall / F1 at a score threshold, the
//! mean IoU of matched detections and a confusion matrix.
//!
//! Matching follows COCO: per class, detections are taken by descending score (stable
//! over the image order) and each takes the unmatched ground-truth box of its class in
//! its image with the highest IoU, if that IoU is at least the threshold. A detection
//! that takes no box but lies in an ignore region of its class (a COCO crowd) is
//! excused as pycocotools excuses it: covered by the region for at least the threshold
//! of its own area (intersection over the detection's area), it counts neither as a
//! true nor as a false positive; ignore regions are never missed.
pub use frugal_data::IgnoreRegion;
use frugal_runtime::{BBox, ClassId, Detection};
use serde::Serialize;

/// One ground-truth object.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Truth {
    /// Its class.
    pub class: ClassId,
    /// Its box.
    pub bbox: BBox,
}

/// Detections and ground truth of one image.
#[derive(Clone, Debug, Default)]
pub struct ImageResult {
    /// What the detector found.
    pub detections: Vec<Detection>,
    /// What is there.
    pub truth: Vec<Truth>,
    /// Where detections are not scored.
    pub ignore: Vec<IgnoreRegion>,
}

/// How precision is interpolated over recall.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    /// Area under the monotone precision envelope (VOC 2010+).
    AllPoint,
    /// Mean envelope precision at recall 0, 0.01, …, 1 (COCO).
    Coco101,
}

/// What [`match_image`] found.
struct Matching {
    /// `(det, truth, iou)`.
    pairs: Vec<(usize, usize, f32)>,
    /// Detections that took no box but lie in an ignore region.
    excused: Vec<usize>,
}

impl Matching {
    fn scored(&self, d: usize) -> bool {
        !self.excused.contains(&d)
    }
}

/// Greedy COCO matching of `dets` (indices into `image.detections`, sorted by score)
/// against the truth of class `class` (or any class when `None`), then the unmatched
/// ones against the ignore regions of that class.
fn match_image(
    image: &ImageResult,
    dets: &[usize],
    class: Option<ClassId>,
    iou_thr: f32,
) -> Matching {
    let mut used = vec![false; image.truth.len()];
    let mut out = Matching {
        pairs: Vec::new(),
        excused: Vec::new(),
    };
    for &d in dets {
        let db = image.detections[d].bbox;
        let mut best: Option<(usize, f32)> = None;
        for (g, t) in image.truth.iter().enumerate() {
            if used[g] || class.is_some_and(|c| c != t.class) {
                continue;
            }
            let iou = db.iou(&t.bbox);
            if iou >= iou_thr && best.is_none_or(|(_, b)| iou > b) {
                best = Some((g, iou));
            }
        }
        if let Some((g, iou)) = best {
            used[g] = true;
            out.pairs.push((d, g, iou));
        } else if image.ignore.iter().any(|r| {
            let applies = match (class, r.class) {
                (Some(c), Some(rc)) => c == rc,
                _ => true,
            };
            applies && covered(&db, &r.bbox) >= iou_thr
        }) {
            out.excused.push(d);
        }
    }
    out
}

/// The share of `det`'s area inside `region` (pycocotools' IoU against a crowd).
fn covered(det: &BBox, region: &BBox) -> f32 {
    let area = det.area();
    if area > 0.0 {
        det.intersection(region).area() / area
    } else {
        0.0
    }
}

/// One class's detections in `images` matched at IoU `iou_thr`: the number of truth
/// boxes of the class, and `(score, is_tp)` of every scored detection (those excused by
/// an ignore region left out), image by image, best first within an image. Records of
/// several image sets, concatenated in image order, are the records of their union:
/// [`ap_of_records`] of them equals [`average_precision`] of the union.
pub fn class_records(
    images: &[ImageResult],
    class: ClassId,
    iou_thr: f32,
) -> (usize, Vec<(f32, bool)>) {
    let n_truth: usize = images
        .iter()
        .map(|im| im.truth.iter().filter(|t| t.class == class).count())
        .sum();
    let mut scored: Vec<(f32, bool)> = Vec::new();
    for im in images {
        let mut dets: Vec<usize> = (0..im.detections.len())
            .filter(|&i| im.detections[i].class == class)
            .collect();
        if dets.is_empty() {
            continue;
        }
        dets.sort_by(|&a, &b| im.detections[b].score.total_cmp(&im.detections[a].score));
        let matched = match_image(im, &dets, Some(class), iou_thr);
        for &d in dets.iter().filter(|&&d| matched.scored(d)) {
            scored.push((
                im.detections[d].score,
                matched.pairs.iter().any(|m| m.0 == d),
            ));
        }
    }
    (n_truth, scored)
}

/// Average precision from [`class_records`] (`n_truth` truth boxes, `(score, is_tp)`
/// records in image order); `None` when `n_truth` is 0.
pub fn ap_of_records(
    n_truth: usize,
    mut scored: Vec<(f32, bool)>,
    interp: Interpolation,
) -> Option<f64> {
    if n_truth == 0 {
        return None;
    }
    scored.sort_by(|a, b| b.0.total_cmp(&a.0)); // stable: ties keep image order
    let (mut tp, mut fp) = (0usize, 0usize);
    let mut rec = Vec::with_capacity(scored.len());
    let mut prec = Vec::with_capacity(scored.len());
    for (_, hit) in &scored {
        if *hit {
            tp += 1
        } else {
            fp += 1
        }
        rec.push(tp as f64 / n_truth as f64);
        prec.push(tp as f64 / (tp + fp) as f64);
    }
    // monotone envelope from the right
    for i in (0..prec.len().saturating_sub(1)).rev() {
        prec[i] = prec[i].max(prec[i + 1]);
    }
    Some(match interp {
        Interpolation::AllPoint => {
            let mut ap = 0.0;
            let mut last_r = 0.0;
            for (r, p) in rec.iter().zip(&prec) {
                ap += (r - last_r) * p;
                last_r = *r;
            }
            ap
        }
        Interpolation::Coco101 => {
            let mut sum = 0.0;
            for k in 0..=100 {
                // numpy's `linspace(0, 1, 101)`, as pycocotools takes it: `k * 0.01`
                // (0.07 is 0.07000000000000001 there), and exactly 1 at the end
                let t = if k == 100 { 1.0 } else { k as f64 * 0.01 };
                // first index with rec >= t (numpy searchsorted, side left; rec never
                // falls)
                if let Some(p) = prec.get(rec.partition_point(|&r| r < t)) {
                    sum += p;
                }
            }
            sum / 101.0
        }
    })
}

/// Average precision of one class at IoU `iou_thr`; `None` when the class has no
/// ground truth in `images`.
pub fn average_precision(
    images: &[ImageResult],
    class: ClassId,
    iou_thr: f32,
    interp: Interpolation,
) -> Option<f64> {
    let (n_truth, scored) = class_records(images, class, iou_thr);
    ap_of_records(n_truth, scored, interp)
}

/// Everything [`evaluate`] measures.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    /// Mean of the per-class APs over classes that have ground truth.
    pub map: f64,
    /// AP per class (`None` = no ground truth of that class).
    pub ap_per_class: Vec<Option<f64>>,
    /// Score threshold of the counts below.
    pub score_threshold: f32,
    /// Matched detections (right class, IoU ≥ threshold) at the score threshold.
    pub true_positives: usize,
    /// Unmatched detections at the score threshold.
    pub false_positives: usize,
    /// Unmatched ground truth at the score threshold.
    pub false_negatives: usize,
    /// `tp / (tp + fp)` (1 when there are no detections).
    pub precision: f64,
    /// `tp / (tp + fn)` (1 when there is no ground truth).
    pub recall: f64,
    /// Harmonic mean of precision and recall.
    pub f1: f64,
    /// Mean IoU of the true positives (0 when none).
    pub mean_iou: f64,
    /// `(K+1) × (K+1)` counts: row = true class, column = predicted class, index `K`
    /// = background (a missed object is in column `K`, a spurious detection in row
    /// `K`). Class-agnostic matching at the IoU threshold, detections above the score
    /// threshold.
    pub confusion: Vec<Vec<usize>>,
    /// Number of images.
    pub images: usize,
}

/// Per-image true positives, false positives, false negatives at a score threshold.
pub fn image_counts(image: &ImageResult, iou_thr: f32, score_thr: f32) -> (usize, usize, usize) {
    let mut tp = 0;
    let mut n_det = 0;
    let classes: std::collections::BTreeSet<ClassId> =
        image.detections.iter().map(|d| d.class).collect();
    for c in classes {
        let mut dets: Vec<usize> = (0..image.detections.len())
            .filter(|&i| image.detections[i].class == c && image.detections[i].score >= score_thr)
            .collect();
        dets.sort_by(|&a, &b| {
            image.detections[b]
                .score
                .total_cmp(&image.detections[a].score)
        });
        let m = match_image(image, &dets, Some(c), iou_thr);
        n_det += dets.len() - m.excused.len();
        tp += m.pairs.len();
    }
    (tp, n_det - tp, image.truth.len() - tp)
}

/// All metrics over `images` with `num_classes` classes.
pub fn evaluate(
    images: &[ImageResult],
    num_classes: usize,
    iou_thr: f32,
    score_thr: f32,
    interp: Interpolation,
) -> Summary {
    let ap_per_class: Vec<Option<f64>> = (0..num_classes)
        .map(|c| average_precision(images, c as ClassId, iou_thr, interp))
        .collect();
    let present: Vec<f64> = ap_per_class.iter().flatten().copied().collect();
    let map = if present.is_empty() {
        0.0
    } else {
        present.iter().sum::<f64>() / present.len() as f64
    };
    let (mut tp, mut fp, mut fneg) = (0, 0, 0);
    let mut iou_sum = 0.0;
    let k = num_classes;
    let mut confusion = vec![vec![0usize; k + 1]; k + 1];
    for im in images {
        let (t, f, n) = image_counts(im, iou_thr, score_thr);
        tp += t;
        fp += f;
        fneg += n;
        // mean IoU over class-aware matches
        for c in 0..k as ClassId {
            let mut dets: Vec<usize> = (0..im.detections.len())
                .filter(|&i| im.detections[i].class == c && im.detections[i].score >= score_thr)
                .collect();
            dets.sort_by(|&a, &b| im.detections[b].score.total_cmp(&im.detections[a].score));
            iou_sum += match_image(im, &dets, Some(c), iou_thr)
                .pairs
                .iter()
                .map(|m| f64::from(m.2))
                .sum::<f64>();
        }
        // class-agnostic confusion
        let mut dets: Vec<usize> = (0..im.detections.len())
            .filter(|&i| im.detections[i].score >= score_thr)
            .collect();
        dets.sort_by(|&a, &b| im.detections[b].score.total_cmp(&im.detections[a].score));
        let matching = match_image(im, &dets, None, iou_thr);
        let m = &matching.pairs;
        for &(d, g, _) in m {
            let (tc, pc) = (im.truth[g].class as usize, im.detections[d].class as usize);
            if tc < k && pc < k {
                confusion[tc][pc] += 1;
            }
        }
        for (g, t) in im.truth.iter().enumerate() {
            if !m.iter().any(|x| x.1 == g) && (t.class as usize) < k {
                confusion[t.class as usize][k] += 1;
            }
        }
        for &d in dets.iter().filter(|&&d| matching.scored(d)) {
            if !m.iter().any(|x| x.0 == d) && (im.detections[d].class as usize) < k {
                confusion[k][im.detections[d].class as usize] += 1;
            }
        }
    }
    let precision = if tp + fp == 0 {
        1.0
    } else {
        tp as f64 / (tp + fp) as f64
    };
    let recall = if tp + fneg == 0 {
        1.0
    } else {
        tp as f64 / (tp + fneg) as f64
    };
    let f1 = if precision + recall > 0.0 {
        2.0 * precision * recall / (precision + recall)
    } else {
        0.0
    };
    Summary {
        map,
        ap_per_class,
        score_threshold: score_thr,
        true_positives: tp,
        false_positives: fp,
        false_negatives: fneg,
        precision,
        recall,
        f1,
        mean_iou: if tp == 0 { 0.0 } else { iou_sum / tp as f64 },
        confusion,
        images: images.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(x: f32, score: f32, class: ClassId) -> Detection {
        Detection {
            bbox: BBox::from_xywh(x, 0.0, 10.0, 10.0),
            score,
            class,
        }
    }
    fn truth(x: f32, class: ClassId) -> Truth {
        Truth {
            class,
            bbox: BBox::from_xywh(x, 0.0, 10.0, 10.0),
        }
    }

    #[test]
    fn hand_computed_all_point_ap() {
        // class 0: 3 objects. Ranked: TP (0.9), FP (0.8), TP (0.7), FP (0.6); one missed.
        // rec/prec: (1/3, 1), (1/3, 1/2), (2/3, 2/3), (2/3, 1/2)
        // envelope: 1, 2/3, 2/3, 1/2 → AP = 1/3·1 + 1/3·2/3 = 5/9
        let images = vec![
            ImageResult {
                detections: vec![det(0.0, 0.9, 0), det(50.0, 0.8, 0)],
                truth: vec![truth(0.0, 0), truth(100.0, 0)],
                ignore: Vec::new(),
            },
            ImageResult {
                detections: vec![det(1.0, 0.7, 0), det(30.0, 0.6, 0)],
                truth: vec![truth(0.0, 0)],
                ignore: Vec::new(),
            },
        ];
        let ap = average_precision(&images, 0, 0.5, Interpolation::AllPoint).unwrap();
        assert!((ap - 5.0 / 9.0).abs() < 1e-12, "{ap}");
        assert_eq!(
            average_precision(&images, 1, 0.5, Interpolation::AllPoint),
            None
        );
        let s = evaluate(&images, 2, 0.5, 0.65, Interpolation::AllPoint);
        assert_eq!(
            (s.true_positives, s.false_positives, s.false_negatives),
            (2, 1, 1)
        );
        assert!((s.precision - 2.0 / 3.0).abs() < 1e-12 && (s.recall - 2.0 / 3.0).abs() < 1e-12);
        assert!((s.map - 5.0 / 9.0).abs() < 1e-12);
        let iou1 = BBox::from_xywh(1.0, 0.0, 10.0, 10.0).iou(&BBox::from_xywh(0.0, 0.0, 10.0, 10.0))
            as f64;
        assert!((s.mean_iou - (1.0 + iou1) / 2.0).abs() < 1e-6);
        // confusion: two class-0 hits, one missed (col K), one spurious (row K)
        assert_eq!(s.confusion[0][0], 2);
        assert_eq!(s.confusion[0][2], 1);
        assert_eq!(s.confusion[2][0], 1);
    }

    /// Records of image sets concatenated in image order score as their union, with
    /// ties between sets kept in image order, at every interpolation.
    #[test]
    fn records_of_parts_give_the_ap_of_the_whole() {
        let images: Vec<ImageResult> = (0..7)
            .map(|i| ImageResult {
                detections: vec![
                    det(0.0, 0.5 + 0.05 * (i % 3) as f32, 0),
                    det(40.0 + i as f32, 0.6, 0),
                    det(80.0, 0.7, 1),
                ],
                truth: (0..(i % 3)).map(|k| truth(40.0 * k as f32, 0)).collect(),
                ignore: Vec::new(),
            })
            .collect();
        for interp in [Interpolation::AllPoint, Interpolation::Coco101] {
            for iou in [0.5, 0.75] {
                let whole = average_precision(&images, 0, iou, interp);
                let (mut n, mut recs) = (0, Vec::new());
                for part in [&images[..2], &images[2..3], &images[3..]] {
                    let (pn, pr) = class_records(part, 0, iou);
                    n += pn;
                    recs.extend(pr);
                }
                assert_eq!(ap_of_records(n, recs, interp), whole);
                assert!(whole.is_some_and(|ap| ap > 0.0 && ap < 1.0), "{whole:?}");
            }
        }
        // no truth of the class: no AP
        assert_eq!(
            ap_of_records(0, vec![(0.9, false)], Interpolation::Coco101),
            None
        );
    }

    #[test]
    fn wrong_class_is_confused_not_matched() {
        let images = vec![ImageResult {
            detections: vec![det(0.0, 0.9, 1)],
            truth: vec![truth(0.0, 0)],
            ignore: Vec::new(),
        }];
        let s = evaluate(&images, 2, 0.5, 0.5, Interpolation::AllPoint);
        assert_eq!(s.map, 0.0);
        assert_eq!(s.confusion[0][1], 1);
        assert_eq!(
            (s.true_positives, s.false_positives, s.false_negatives),
            (0, 1, 1)
        );
    }

    #[test]
    fn perfect_detections_give_one_in_both_modes() {
        let images = vec![ImageResult {
            detections: vec![det(0.0, 0.9, 0), det(40.0, 0.8, 1)],
            truth: vec![truth(0.0, 0), truth(40.0, 1)],
            ignore: Vec::new(),
        }];
        for i in [Interpolation::AllPoint, Interpolation::Coco101] {
            assert!((evaluate(&images, 2, 0.5, 0.5, i).map - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn detections_in_an_ignore_region_are_excused_only_for_its_classes() {
        // class 0 object at x 0; a crowd of class 0 over x 100..140; a region of any
        // class over x 200..240
        let im = |detections| ImageResult {
            detections,
            truth: vec![truth(0.0, 0)],
            ignore: vec![
                IgnoreRegion {
                    class: Some(0),
                    bbox: BBox::new(100.0, 0.0, 140.0, 10.0),
                },
                IgnoreRegion {
                    class: None,
                    bbox: BBox::new(200.0, 0.0, 240.0, 10.0),
                },
            ],
        };
        // a class-0 box wholly in the crowd, one 60 % in, one 40 % in; class 1 in
        // the crowd; class 1 in the any-class region
        let images = vec![im(vec![
            det(0.0, 0.9, 0),
            det(110.0, 0.8, 0),
            det(134.0, 0.7, 0),
            det(136.0, 0.6, 0),
            det(120.0, 0.5, 1),
            det(220.0, 0.4, 1),
        ])];
        // excused: 0.8 and 0.7 (class 0 in its crowd, ≥ 50 % covered) and 0.4 (any
        // class); false alarms: 0.6 (40 % covered) and 0.5 (another class)
        assert_eq!(image_counts(&images[0], 0.5, 0.0), (1, 2, 0));
        let s = evaluate(&images, 2, 0.5, 0.0, Interpolation::AllPoint);
        assert_eq!(
            (s.true_positives, s.false_positives, s.false_negatives),
            (1, 2, 0)
        );
        // AP of class 0: TP at 0.9, then the one false alarm → 1
        assert_eq!(
            average_precision(&images, 0, 0.5, Interpolation::AllPoint),
            Some(1.0)
        );
        // regions are never missed, and an image with only a region has no truth
        let empty = ImageResult {
            truth: Vec::new(),
            ..im(Vec::new())
        };
        assert_eq!(image_counts(&empty, 0.5, 0.0), (0, 0, 0));
    }
}
