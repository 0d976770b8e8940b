//! Training targets and losses: anchor matching and sampling for the RPN, proposal
//! matching and sampling for the RoI head (the usual Faster R-CNN fg/bg rules).
use crate::FasterRcnn;
use crate::boxes::{self, ROI_WEIGHTS, RPN_WEIGHTS};
use crate::config::TrainConfig;
use crate::metrics::Truth;
use crate::model::boxes_tensor;
use frugal_runtime::BBox;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use tch::{Kind, Reduction, Tensor};

/// IoU at or above which an anchor is foreground.
const RPN_FG_IOU: f32 = 0.7;
/// IoU below which an anchor is background.
const RPN_BG_IOU: f32 = 0.3;
/// IoU at or above which a proposal is foreground for the RoI head.
const ROI_FG_IOU: f32 = 0.5;

/// The four loss terms of one image (scalars).
pub struct Losses {
    /// RPN objectness (binary cross-entropy over sampled anchors).
    pub rpn_objectness: Tensor,
    /// RPN box regression (smooth L1 over foreground anchors / sampled anchors).
    pub rpn_box: Tensor,
    /// RoI classification (cross-entropy over sampled RoIs, K + 1 classes).
    pub roi_class: Tensor,
    /// RoI box regression (smooth L1 over foreground RoIs / sampled RoIs).
    pub roi_box: Tensor,
}

impl Losses {
    /// Sum of the four terms.
    pub fn total(&self) -> Tensor {
        &self.rpn_objectness + &self.rpn_box + &self.roi_class + &self.roi_box
    }
}

/// For each box in `a`: best IoU with any of `b` and its index (−1 / 0 when `b` is empty).
fn best_match(a: &[BBox], b: &[BBox]) -> Vec<(f32, usize)> {
    a.iter()
        .map(|x| {
            b.iter()
                .enumerate()
                .fold((0.0f32, usize::MAX), |best, (j, y)| {
                    let iou = x.iou(y);
                    if iou > best.0 || best.1 == usize::MAX {
                        (iou, j)
                    } else {
                        best
                    }
                })
        })
        .collect()
}

/// Sample at most `n·frac` of `fg` and fill up to `n` with `bg`, shuffled by `rng`.
fn sample(
    mut fg: Vec<usize>,
    mut bg: Vec<usize>,
    n: usize,
    frac: f64,
    rng: &mut ChaCha8Rng,
) -> (Vec<usize>, Vec<usize>) {
    fg.shuffle(rng);
    bg.shuffle(rng);
    fg.truncate(((n as f64 * frac).round() as usize).min(fg.len()));
    bg.truncate(n - fg.len());
    (fg, bg)
}

/// RoI sampling with hard negatives: `fg` as [`sample`] does; of the background budget,
/// the share `roi_hard_negatives` goes to the first background candidates (proposals come
/// best objectness first, so these are what the RPN finds most sign-like), the rest is
/// drawn at random from the others.
fn sample_hard(
    fg: Vec<usize>,
    mut bg: Vec<usize>,
    tc: &TrainConfig,
    rng: &mut ChaCha8Rng,
) -> (Vec<usize>, Vec<usize>) {
    let (fg, _) = sample(fg, Vec::new(), tc.roi_batch, tc.roi_fg_fraction, rng);
    let budget = tc.roi_batch - fg.len();
    let hard = ((budget as f64 * tc.roi_hard_negatives).round() as usize).min(bg.len());
    let rest = bg.split_off(hard);
    let (_, rest) = sample(Vec::new(), rest, budget - hard, 0.0, rng);
    bg.extend(rest);
    (fg, bg)
}

/// RPN anchor labels: `(foreground anchors with their target box, background anchors)`.
/// Foreground: IoU ≥ 0.7 with some object, or the best anchor(s) of an object;
/// background: best IoU < 0.3.
pub fn rpn_assign(
    anchors: &[BBox],
    truth: &[BBox],
    tc: &TrainConfig,
    rng: &mut ChaCha8Rng,
) -> (Vec<(usize, BBox)>, Vec<usize>) {
    let best = best_match(anchors, truth);
    let mut fg_flag = vec![false; anchors.len()];
    for (i, (iou, _)) in best.iter().enumerate() {
        fg_flag[i] = !truth.is_empty() && *iou >= RPN_FG_IOU;
    }
    for t in truth {
        let top = anchors.iter().map(|a| a.iou(t)).fold(0.0f32, f32::max);
        if top > 0.0 {
            for (i, a) in anchors.iter().enumerate() {
                if a.iou(t) >= top - 1e-6 {
                    fg_flag[i] = true;
                }
            }
        }
    }
    let fg: Vec<usize> = (0..anchors.len()).filter(|&i| fg_flag[i]).collect();
    let bg: Vec<usize> = (0..anchors.len())
        .filter(|&i| !fg_flag[i] && (truth.is_empty() || best[i].0 < RPN_BG_IOU))
        .collect();
    let (fg, bg) = sample(fg, bg, tc.rpn_batch, tc.rpn_fg_fraction, rng);
    // the target of a low-quality (best-anchor) match is the object it overlaps most
    let fg = fg
        .into_iter()
        .map(|i| {
            let j = (0..truth.len())
                .max_by(|&x, &y| {
                    anchors[i]
                        .iou(&truth[x])
                        .total_cmp(&anchors[i].iou(&truth[y]))
                })
                .unwrap_or(0);
            (i, truth[j])
        })
        .collect();
    (fg, bg)
}

/// RoI sampling: proposals plus the ground truth, foreground (IoU ≥ 0.5, label = class
/// + 1, with target box) and background (label 0).
pub fn roi_assign(
    proposals: &[BBox],
    truth: &[Truth],
    tc: &TrainConfig,
    rng: &mut ChaCha8Rng,
) -> Vec<(BBox, i64, Option<BBox>)> {
    let mut cand: Vec<BBox> = proposals.to_vec();
    cand.extend(truth.iter().map(|t| t.bbox));
    let tb: Vec<BBox> = truth.iter().map(|t| t.bbox).collect();
    let best = best_match(&cand, &tb);
    let fg: Vec<usize> = (0..cand.len())
        .filter(|&i| !tb.is_empty() && best[i].0 >= ROI_FG_IOU)
        .collect();
    let bg: Vec<usize> = (0..cand.len())
        .filter(|&i| tb.is_empty() || best[i].0 < ROI_FG_IOU)
        .collect();
    let (fg, bg) = sample_hard(fg, bg, tc, rng);
    let mut out: Vec<(BBox, i64, Option<BBox>)> = fg
        .into_iter()
        .map(|i| {
            let t = truth[best[i].1];
            (cand[i], i64::from(t.class) + 1, Some(t.bbox))
        })
        .collect();
    out.extend(bg.into_iter().map(|i| (cand[i], 0, None)));
    out
}

/// The losses of one normalised image `[1, 3, H, W]` with its ground truth.
pub fn image_losses(
    model: &FasterRcnn,
    image: &Tensor,
    truth: &[Truth],
    tc: &TrainConfig,
    rng: &mut ChaCha8Rng,
) -> Losses {
    let dev = model.device();
    let (h, w) = (image.size()[2] as usize, image.size()[3] as usize);
    let out = model.backbone_rpn(image);
    let a = model.config().anchors_per_cell() as i64;
    let (anchors, _) = model.anchors(h, w);
    let tboxes: Vec<BBox> = truth.iter().map(|t| t.bbox).collect();

    // RPN
    let obj = out.objectness.permute([0, 2, 3, 1]).reshape([-1]);
    let (_, _, fh, fw) = out.deltas.size4().unwrap_or((1, 4, 1, 1));
    let del = out
        .deltas
        .reshape([1, a, 4, fh, fw])
        .permute([0, 3, 4, 1, 2])
        .reshape([-1, 4]);
    let (fg, bg) = rpn_assign(&anchors, &tboxes, tc, rng);
    let n_sampled = (fg.len() + bg.len()).max(1) as f64;
    let idx: Vec<i64> = fg
        .iter()
        .map(|f| f.0 as i64)
        .chain(bg.iter().map(|&b| b as i64))
        .collect();
    let labels: Vec<f32> = fg
        .iter()
        .map(|_| 1.0)
        .chain(bg.iter().map(|_| 0.0))
        .collect();
    let rpn_objectness = if idx.is_empty() {
        obj.sum(Kind::Float) * 0.0
    } else {
        obj.index_select(0, &Tensor::from_slice(&idx).to_device(dev))
            .binary_cross_entropy_with_logits::<Tensor>(
                &Tensor::from_slice(&labels).to_device(dev),
                None,
                None,
                Reduction::Mean,
            )
    };
    let rpn_box = if fg.is_empty() {
        del.sum(Kind::Float) * 0.0
    } else {
        let fidx: Vec<i64> = fg.iter().map(|f| f.0 as i64).collect();
        let tgt: Vec<f32> = fg
            .iter()
            .flat_map(|(i, t)| boxes::encode(&anchors[*i], t, RPN_WEIGHTS))
            .collect();
        let pred = del.index_select(0, &Tensor::from_slice(&fidx).to_device(dev));
        pred.smooth_l1_loss(
            &Tensor::from_slice(&tgt).reshape([-1, 4]).to_device(dev),
            Reduction::Sum,
            1.0 / 9.0,
        ) / n_sampled
    };

    // RoI head
    let props = model.proposals_of(&out, 0, (h, w), true);
    let rois = roi_assign(&props, truth, tc, rng);
    let rb: Vec<BBox> = rois.iter().map(|r| r.0).collect();
    let (logits, deltas) = model.roi_head(
        &out.features,
        &boxes_tensor(&rb).to_device(dev),
        &vec![0; rb.len()],
    );
    let labels: Vec<i64> = rois.iter().map(|r| r.1).collect();
    let roi_class = logits.cross_entropy_for_logits(&Tensor::from_slice(&labels).to_device(dev));
    let fg_rows: Vec<i64> = (0..rois.len())
        .filter(|&i| rois[i].1 > 0)
        .map(|i| i as i64)
        .collect();
    let roi_box = if fg_rows.is_empty() {
        deltas.sum(Kind::Float) * 0.0
    } else {
        let k = model.config().num_classes as i64;
        let cls: Vec<i64> = fg_rows.iter().map(|&i| rois[i as usize].1 - 1).collect();
        let tgt: Vec<f32> = fg_rows
            .iter()
            .flat_map(|&i| {
                let r = &rois[i as usize];
                boxes::encode(&r.0, &r.2.unwrap_or(r.0), ROI_WEIGHTS)
            })
            .collect();
        let pred = deltas.reshape([-1, k, 4]).index(&[
            Some(Tensor::from_slice(&fg_rows).to_device(dev)),
            Some(Tensor::from_slice(&cls).to_device(dev)),
        ]);
        pred.smooth_l1_loss(
            &Tensor::from_slice(&tgt).reshape([-1, 4]).to_device(dev),
            Reduction::Sum,
            1.0,
        ) / rois.len().max(1) as f64
    };
    Losses {
        rpn_objectness,
        rpn_box,
        roi_class,
        roi_box,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn rpn_assignment_respects_thresholds_and_budget() {
        let anchors = boxes::anchors(8, 8, 16.0, &[16.0, 32.0], &[1.0]);
        let truth = [BBox::new(20.0, 20.0, 52.0, 52.0)];
        let tc = TrainConfig {
            rpn_batch: 32,
            ..Default::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let (fg, bg) = rpn_assign(&anchors, &truth, &tc, &mut rng);
        assert!(!fg.is_empty() && fg.len() <= 16);
        assert_eq!(fg.len() + bg.len(), 32);
        let top = anchors.iter().map(|a| a.iou(&truth[0])).fold(0.0, f32::max);
        assert!(
            fg.iter()
                .all(|(i, _)| anchors[*i].iou(&truth[0]) >= RPN_FG_IOU.min(top) - 1e-6)
        );
        assert!(bg.iter().all(|&i| anchors[i].iou(&truth[0]) < RPN_BG_IOU));
        let (fg, bg) = rpn_assign(&anchors, &[], &tc, &mut rng);
        assert!(fg.is_empty() && bg.len() == 32);
    }

    #[test]
    fn roi_assignment_labels_classes_from_one() {
        let truth = [Truth {
            class: 3,
            bbox: BBox::new(10.0, 10.0, 40.0, 40.0),
        }];
        let props = [
            BBox::new(12.0, 10.0, 40.0, 40.0),
            BBox::new(60.0, 60.0, 90.0, 90.0),
        ];
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let tc = TrainConfig {
            roi_batch: 8,
            roi_fg_fraction: 0.5,
            ..Default::default()
        };
        let r = roi_assign(&props, &truth, &tc, &mut rng);
        assert_eq!(r.iter().filter(|x| x.1 == 4).count(), 2); // the close proposal and the truth itself
        assert_eq!(r.iter().filter(|x| x.1 == 0).count(), 1);
    }

    #[test]
    fn hard_negatives_are_the_best_ranked_background_proposals() {
        // 40 background proposals, best objectness first; no truth at all
        let props: Vec<BBox> = (0..40)
            .map(|i| BBox::new(i as f32 * 10.0, 0.0, i as f32 * 10.0 + 8.0, 8.0))
            .collect();
        let tc = TrainConfig {
            roi_batch: 10,
            roi_hard_negatives: 0.5,
            ..Default::default()
        };
        for seed in 0..20 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let r = roi_assign(&props, &[], &tc, &mut rng);
            assert_eq!(r.len(), 10);
            let mut x: Vec<f32> = r.iter().map(|x| x.0.x1).collect();
            x.sort_by(f32::total_cmp);
            // the five best-ranked always, five more drawn from the rest
            assert_eq!(&x[..5], &[0.0, 10.0, 20.0, 30.0, 40.0]);
            assert!(x[5..].iter().all(|&v| v >= 50.0));
        }
        // none hard: the first five are not always there
        let random = TrainConfig {
            roi_hard_negatives: 0.0,
            ..tc
        };
        let always = (0..20).all(|seed| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let r = roi_assign(&props, &[], &random, &mut rng);
            (0..5).all(|i| r.iter().any(|x| x.0.x1 == i as f32 * 10.0))
        });
        assert!(!always);
    }
}
