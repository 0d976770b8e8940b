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

/// The losses of one normalised image `[1, 3, H, W]` with its ground truth
/// ([`batch_losses`] of a batch of one).
pub fn image_losses(
    model: &FasterRcnn,
    image: &Tensor,
    truth: &[Truth],
    tc: &TrainConfig,
    rng: &mut ChaCha8Rng,
) -> Losses {
    batch_losses(model, image, &[truth], tc, rng)
}

/// The losses of a batch of normalised images `[B, 3, H, W]` (one size) with each
/// image's ground truth: one forward pass of the network over the whole batch, while the
/// anchors and RoIs are matched and sampled image by image (image 0's RPN anchors, its
/// RoIs, then image 1's, … — the draws from `rng` that [`image_losses`] makes image by
/// image). Each term is the mean over the images of that image's term (the RPN and RoI
/// losses are normalised by each image's own sample counts), so the result equals the
/// mean of the images' [`image_losses`] up to float rounding. An image without any RoI
/// (no proposals and no truth) adds 0 to the RoI terms. The backbone and RPN run in
/// `tc.precision`.
pub fn batch_losses<T: AsRef<[Truth]>>(
    model: &FasterRcnn,
    images: &Tensor,
    truths: &[T],
    tc: &TrainConfig,
    rng: &mut ChaCha8Rng,
) -> Losses {
    let dev = model.device();
    let size = images.size();
    let (batch, h, w) = (size[0], size[2] as usize, size[3] as usize);
    assert_eq!(
        batch as usize,
        truths.len(),
        "one ground truth per image of the batch"
    );
    let per_image = 1.0 / batch.max(1) as f64;
    let out = model.backbone_rpn_as(images, tc.precision.kind(dev));
    let a = model.config().anchors_per_cell() as i64;
    let (anchors, _) = model.anchors(h, w);
    // image b's anchor i is row b·N + i of `obj` and `del`
    let obj = out.objectness.permute([0, 2, 3, 1]).reshape([-1]);
    let (_, _, fh, fw) = out.deltas.size4().unwrap_or((1, 4, 1, 1));
    let del = out
        .deltas
        .reshape([batch, a, 4, fh, fw])
        .permute([0, 3, 4, 1, 2])
        .reshape([-1, 4]);

    // targets of the whole batch, each row weighted by 1 / (its image's sample count · B)
    let mut rpn = Targets::default();
    let mut rpn_fg = Targets::default();
    let mut roi = Targets::default();
    let mut roi_fg = Targets::default();
    let mut roi_boxes: Vec<BBox> = Vec::new();
    let mut roi_images: Vec<i64> = Vec::new();
    for (b, truth) in truths.iter().enumerate() {
        let truth = truth.as_ref();
        let base = (b * anchors.len()) as i64;
        let tboxes: Vec<BBox> = truth.iter().map(|t| t.bbox).collect();
        let (fg, bg) = rpn_assign(&anchors, &tboxes, tc, rng);
        let n_sampled = fg.len() + bg.len();
        let wt = per_image / n_sampled.max(1) as f64;
        for (i, t) in &fg {
            rpn.push(base + *i as i64, 1, wt);
            rpn_fg.push(base + *i as i64, 0, wt);
            rpn_fg
                .boxes
                .extend(boxes::encode(&anchors[*i], t, RPN_WEIGHTS));
        }
        for &i in &bg {
            rpn.push(base + i as i64, 0, wt);
        }

        let props = model.proposals_of(&out, b as i64, (h, w), true);
        let rois = roi_assign(&props, truth, tc, rng);
        let wt = per_image / rois.len().max(1) as f64;
        for (bx, label, target) in &rois {
            let row = roi_boxes.len() as i64;
            roi.push(row, *label, wt);
            if *label > 0 {
                roi_fg.push(row, *label - 1, wt);
                roi_fg
                    .boxes
                    .extend(boxes::encode(bx, &target.unwrap_or(*bx), ROI_WEIGHTS));
            }
            roi_boxes.push(*bx);
            roi_images.push(b as i64);
        }
    }

    // RPN
    let rpn_objectness = if rpn.rows.is_empty() {
        obj.sum(Kind::Float) * 0.0
    } else {
        let labels: Vec<f32> = rpn.labels.iter().map(|&l| l as f32).collect();
        obj.index_select(0, &rpn.rows_tensor(dev))
            .binary_cross_entropy_with_logits(
                &Tensor::from_slice(&labels).to_device(dev),
                Some(rpn.weights_tensor(dev)),
                None::<Tensor>,
                Reduction::Sum,
            )
    };
    let rpn_box = if rpn_fg.rows.is_empty() {
        del.sum(Kind::Float) * 0.0
    } else {
        let pred = del.index_select(0, &rpn_fg.rows_tensor(dev));
        weighted_smooth_l1(&pred, &rpn_fg, 1.0 / 9.0, dev)
    };

    // RoI head, over the RoIs of every image at once
    let (logits, deltas) = model.roi_head(
        &out.features,
        &boxes_tensor(&roi_boxes).to_device(dev),
        &roi_images,
    );
    let roi_class = if roi.rows.is_empty() {
        logits.sum(Kind::Float) * 0.0
    } else {
        let labels = Tensor::from_slice(&roi.labels).to_device(dev);
        (logits.cross_entropy_loss::<Tensor>(&labels, None, Reduction::None, -100, 0.0)
            * roi.weights_tensor(dev))
        .sum(Kind::Float)
    };
    let roi_box = if roi_fg.rows.is_empty() {
        deltas.sum(Kind::Float) * 0.0
    } else {
        let k = model.config().num_classes as i64;
        let pred = deltas.reshape([-1, k, 4]).index(&[
            Some(roi_fg.rows_tensor(dev)),
            Some(Tensor::from_slice(&roi_fg.labels).to_device(dev)),
        ]);
        weighted_smooth_l1(&pred, &roi_fg, 1.0, dev)
    };
    Losses {
        rpn_objectness,
        rpn_box,
        roi_class,
        roi_box,
    }
}

/// Loss targets gathered over a batch: rows of a prediction tensor, a label per row
/// (class, or 0/1), the row's weight in the batch loss and, for box regression, four
/// encoded target values per row.
#[derive(Default)]
struct Targets {
    rows: Vec<i64>,
    labels: Vec<i64>,
    weights: Vec<f32>,
    boxes: Vec<f32>,
}

impl Targets {
    fn push(&mut self, row: i64, label: i64, weight: f64) {
        self.rows.push(row);
        self.labels.push(label);
        self.weights.push(weight as f32);
    }

    fn rows_tensor(&self, dev: tch::Device) -> Tensor {
        Tensor::from_slice(&self.rows).to_device(dev)
    }

    fn weights_tensor(&self, dev: tch::Device) -> Tensor {
        Tensor::from_slice(&self.weights).to_device(dev)
    }
}

/// Σ over rows of weight · smooth L1 (summed over the four coordinates) between `pred`
/// (`[n, 4]`, in the order of `t.rows`) and `t.boxes`.
fn weighted_smooth_l1(pred: &Tensor, t: &Targets, beta: f64, dev: tch::Device) -> Tensor {
    let target = Tensor::from_slice(&t.boxes).reshape([-1, 4]).to_device(dev);
    (pred.smooth_l1_loss(&target, Reduction::None, beta) * t.weights_tensor(dev).unsqueeze(1))
        .sum(Kind::Float)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Precision;
    use rand::SeedableRng;

    /// The loss terms (as numbers) and every weight's gradient after `backward`.
    fn terms_and_grads(model: &FasterRcnn, losses: &[Losses]) -> (Vec<f64>, Vec<Tensor>) {
        let mut vars = model.var_store().trainable_variables();
        for v in &mut vars {
            v.zero_grad();
        }
        let n = losses.len() as f64;
        let mut terms = vec![0.0; 4];
        let mut total = Tensor::zeros([], (Kind::Float, tch::Device::Cpu));
        for l in losses {
            for (s, t) in
                terms
                    .iter_mut()
                    .zip([&l.rpn_objectness, &l.rpn_box, &l.roi_class, &l.roi_box])
            {
                *s += t.double_value(&[]) / n;
            }
            total += l.total() / n;
        }
        total.backward();
        (terms, vars.iter().map(|v| v.grad().copy()).collect())
    }

    #[test]
    fn a_batch_gives_the_mean_of_its_images_losses_and_gradients() {
        let model = crate::testing::tiny_model(5, &[(8, 2, 1), (16, 2, 1), (16, 2, 1)]);
        tch::manual_seed(6);
        let images = Tensor::randn([3, 3, 64, 96], (Kind::Float, tch::Device::Cpu));
        let t = |class, x: f32, y: f32, s: f32| Truth {
            class,
            bbox: BBox::new(x, y, x + s, y + s),
        };
        // two objects, none (background only), one
        let truths = vec![
            vec![t(0, 8.0, 6.0, 24.0), t(2, 50.0, 20.0, 30.0)],
            vec![],
            vec![t(1, 30.0, 10.0, 40.0)],
        ];
        let tc = TrainConfig {
            rpn_batch: 64,
            roi_batch: 16,
            precision: Precision::F32,
            ..Default::default()
        };
        // image by image, drawing the samples from one generator in image order ...
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let single: Vec<Losses> = truths
            .iter()
            .enumerate()
            .map(|(i, truth)| {
                image_losses(&model, &images.narrow(0, i as i64, 1), truth, &tc, &mut rng)
            })
            .collect();
        let (want, want_grads) = terms_and_grads(&model, &single);
        // ... and the three stacked, from the same generator state
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let batched = batch_losses(&model, &images, &truths, &tc, &mut rng);
        let (got, got_grads) = terms_and_grads(&model, &[batched]);
        assert!(
            want.iter().all(|&v| v > 0.0),
            "every term takes part: {want:?}"
        );
        for (g, w) in got.iter().zip(&want) {
            assert!(
                (g - w).abs() <= 1e-5 * w.abs().max(1e-3),
                "{got:?} vs {want:?}"
            );
        }
        assert_eq!(got_grads.len(), want_grads.len());
        for (g, w) in got_grads.iter().zip(&want_grads) {
            let scale = w.abs().max().double_value(&[]).max(1e-8);
            let diff = (g - w).abs().max().double_value(&[]);
            assert!(
                diff <= 1e-4 * scale,
                "gradient differs by {diff} (largest {scale})"
            );
        }
    }

    #[test]
    fn bf16_convolutions_give_nearly_the_f32_losses_and_gradients() {
        let model = crate::testing::tiny_model(5, &[(8, 2, 1), (16, 2, 1), (16, 2, 1)]);
        tch::manual_seed(7);
        let images = Tensor::randn([2, 3, 64, 96], (Kind::Float, tch::Device::Cpu));
        let truths = vec![
            vec![Truth {
                class: 1,
                bbox: BBox::new(10.0, 8.0, 40.0, 38.0),
            }],
            vec![Truth {
                class: 2,
                bbox: BBox::new(40.0, 20.0, 80.0, 60.0),
            }],
        ];
        let run = |precision| {
            let tc = TrainConfig {
                rpn_batch: 64,
                roi_batch: 16,
                precision,
                ..Default::default()
            };
            let mut rng = ChaCha8Rng::seed_from_u64(4);
            let l = batch_losses(&model, &images, &truths, &tc, &mut rng);
            terms_and_grads(&model, &[l])
        };
        let (t32, g32) = run(Precision::F32);
        let (t16, g16) = run(Precision::Bf16);
        // bfloat16 keeps 8 significant bits: the losses agree to about 1 %
        for (a, b) in t16.iter().zip(&t32) {
            assert!((a - b).abs() <= 0.03 * b.abs() + 1e-4, "{t16:?} vs {t32:?}");
        }
        // and the gradient points the same way: over all weights together (0.999 on this
        // machine), and for each weight tensor alone less closely (0.86-1.0: a small
        // gradient, e.g. a bias's, is near the rounding of the activations behind it)
        let cosine = |a: &Tensor, b: &Tensor| {
            let dot = (a * b).sum(Kind::Double).double_value(&[]);
            dot / (a.norm().double_value(&[]) * b.norm().double_value(&[])).max(1e-30)
        };
        let flat =
            |g: &[Tensor]| Tensor::cat(&g.iter().map(|t| t.flatten(0, -1)).collect::<Vec<_>>(), 0);
        let each: Vec<f64> = g16.iter().zip(&g32).map(|(a, b)| cosine(a, b)).collect();
        let all = cosine(&flat(&g16), &flat(&g32));
        assert!(all > 0.99, "cosine of the whole gradient {all}");
        assert!(each.iter().all(|&c| c > 0.8), "cosines per tensor {each:?}");
    }

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
