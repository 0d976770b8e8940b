//! Box arithmetic in plain Rust: anchors, the box coder, NMS. No tensors here, so an
//! ONNX executor can reuse all of it.
use frugal_runtime::BBox;

/// Largest log-scale a decoded delta may apply (as in Detectron2: `ln(1000/16)`).
const MAX_LOG_SCALE: f32 = 4.135_166_6;

/// Weights of the box coder: deltas are `(wx·dx, wy·dy, ww·dw, wh·dh)`.
pub type CoderWeights = [f32; 4];

/// Box-coder weights of the RPN.
pub const RPN_WEIGHTS: CoderWeights = [1.0, 1.0, 1.0, 1.0];
/// Box-coder weights of the RoI head.
pub const ROI_WEIGHTS: CoderWeights = [10.0, 10.0, 5.0, 5.0];

/// The deltas `(dx, dy, dw, dh)` that move `reference` onto `target` (Faster R-CNN
/// parametrisation, scaled by `w`).
pub fn encode(reference: &BBox, target: &BBox, w: CoderWeights) -> [f32; 4] {
    let (rw, rh) = (reference.width().max(1e-3), reference.height().max(1e-3));
    let (rcx, rcy) = reference.center();
    let (tw, th) = (target.width().max(1e-3), target.height().max(1e-3));
    let (tcx, tcy) = target.center();
    [
        w[0] * (tcx - rcx) / rw,
        w[1] * (tcy - rcy) / rh,
        w[2] * (tw / rw).ln(),
        w[3] * (th / rh).ln(),
    ]
}

/// Apply deltas to `reference` (inverse of [`encode`]); scales are clamped so a
/// wild delta cannot overflow.
pub fn decode(reference: &BBox, d: [f32; 4], w: CoderWeights) -> BBox {
    let (rw, rh) = (reference.width(), reference.height());
    let (rcx, rcy) = reference.center();
    let cx = rcx + d[0] / w[0] * rw;
    let cy = rcy + d[1] / w[1] * rh;
    let bw = rw * (d[2] / w[2]).min(MAX_LOG_SCALE).exp();
    let bh = rh * (d[3] / w[3]).min(MAX_LOG_SCALE).exp();
    BBox::new(cx - 0.5 * bw, cy - 0.5 * bh, cx + 0.5 * bw, cy + 0.5 * bh)
}

/// Anchors for a `fh × fw` feature map of the given stride, in the order
/// `(y, x, a)`: index `(y·fw + x)·A + a`, with `a = size_index·R + ratio_index`.
/// Anchors are centred on the cell centre `((x + 0.5)·stride, (y + 0.5)·stride)`.
pub fn anchors(fh: usize, fw: usize, stride: f32, sizes: &[f32], ratios: &[f32]) -> Vec<BBox> {
    let mut out = Vec::with_capacity(fh * fw * sizes.len() * ratios.len());
    for y in 0..fh {
        for x in 0..fw {
            let (cx, cy) = ((x as f32 + 0.5) * stride, (y as f32 + 0.5) * stride);
            for &s in sizes {
                for &r in ratios {
                    let w = s / r.sqrt();
                    let h = s * r.sqrt();
                    out.push(BBox::new(
                        cx - 0.5 * w,
                        cy - 0.5 * h,
                        cx + 0.5 * w,
                        cy + 0.5 * h,
                    ));
                }
            }
        }
    }
    out
}

/// Greedy non-maximum suppression: indices of the kept boxes, best score first. A box
/// is dropped when its IoU with an already kept box is above `iou`.
pub fn nms(boxes: &[BBox], scores: &[f32], iou: f32) -> Vec<usize> {
    let mut order: Vec<usize> = (0..boxes.len().min(scores.len())).collect();
    order.sort_by(|&a, &b| scores[b].total_cmp(&scores[a]).then(a.cmp(&b)));
    let mut keep: Vec<usize> = Vec::new();
    for i in order {
        if keep.iter().all(|&k| boxes[k].iou(&boxes[i]) <= iou) {
            keep.push(i);
        }
    }
    keep
}

/// Indices of the `k` highest scores, best first (ties by index).
pub fn top_k(scores: &[f32], k: usize) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..scores.len()).collect();
    let k = k.min(idx.len());
    if k < idx.len() {
        idx.select_nth_unstable_by(k, |&a, &b| scores[b].total_cmp(&scores[a]).then(a.cmp(&b)));
        idx.truncate(k);
    }
    idx.sort_by(|&a, &b| scores[b].total_cmp(&scores[a]).then(a.cmp(&b)));
    idx
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(state: &mut u64) -> f32 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*state >> 33) as f32) / (1u64 << 31) as f32
    }

    #[test]
    fn encode_decode_round_trips() {
        let mut s = 1u64;
        for _ in 0..500 {
            let r = BBox::from_xywh(
                lcg(&mut s) * 400.0,
                lcg(&mut s) * 200.0,
                4.0 + lcg(&mut s) * 90.0,
                4.0 + lcg(&mut s) * 90.0,
            );
            let t = BBox::from_xywh(
                lcg(&mut s) * 400.0,
                lcg(&mut s) * 200.0,
                4.0 + lcg(&mut s) * 90.0,
                4.0 + lcg(&mut s) * 90.0,
            );
            for w in [RPN_WEIGHTS, ROI_WEIGHTS] {
                let back = decode(&r, encode(&r, &t, w), w);
                for (a, b) in [
                    (back.x1, t.x1),
                    (back.y1, t.y1),
                    (back.x2, t.x2),
                    (back.y2, t.y2),
                ] {
                    assert!((a - b).abs() < 1e-2, "{back:?} vs {t:?}");
                }
            }
        }
        let r = BBox::new(0.0, 0.0, 10.0, 10.0);
        assert_eq!(encode(&r, &r, ROI_WEIGHTS), [0.0; 4]);
        assert!(decode(&r, [0.0, 0.0, 1e9, 1e9], RPN_WEIGHTS).is_valid());
    }

    #[test]
    fn anchors_have_the_asked_sizes_ratios_and_order() {
        let a = anchors(2, 3, 16.0, &[16.0, 32.0], &[0.5, 1.0, 2.0]);
        assert_eq!(a.len(), 2 * 3 * 6);
        // cell (y=1, x=2), size 32, ratio 2 (h/w): index (1*3+2)*6 + 1*3 + 2
        let b = a[(3 + 2) * 6 + 5];
        assert_eq!(b.center(), (40.0, 24.0));
        assert!((b.width() * b.height() - 32.0 * 32.0).abs() < 1e-2);
        assert!((b.height() / b.width() - 2.0).abs() < 1e-4);
    }

    /// Brute-force reference: a box is kept iff no higher-ranked *kept* box overlaps it;
    /// computed by a fixed-point sweep rather than the greedy loop.
    fn nms_reference(boxes: &[BBox], scores: &[f32], iou: f32) -> Vec<usize> {
        let n = boxes.len();
        let rank = |i: usize, j: usize| scores[i] > scores[j] || (scores[i] == scores[j] && i < j);
        let mut kept = vec![None::<bool>; n];
        while kept.iter().any(Option::is_none) {
            for i in 0..n {
                if kept[i].is_some() {
                    continue;
                }
                let higher: Vec<usize> = (0..n).filter(|&j| j != i && rank(j, i)).collect();
                if higher.iter().all(|&j| kept[j].is_some()) {
                    let suppressed = higher
                        .iter()
                        .any(|&j| kept[j] == Some(true) && boxes[i].iou(&boxes[j]) > iou);
                    kept[i] = Some(!suppressed);
                }
            }
        }
        let mut out: Vec<usize> = (0..n).filter(|&i| kept[i] == Some(true)).collect();
        out.sort_by(|&a, &b| {
            if rank(a, b) {
                std::cmp::Ordering::Less
            } else {
                std::cmp::Ordering::Greater
            }
        });
        out
    }

    #[test]
    fn nms_matches_brute_force_reference() {
        let mut s = 42u64;
        for trial in 0..200 {
            let n = 1 + trial % 30;
            let boxes: Vec<BBox> = (0..n)
                .map(|_| {
                    BBox::from_xywh(
                        lcg(&mut s) * 60.0,
                        lcg(&mut s) * 60.0,
                        5.0 + lcg(&mut s) * 30.0,
                        5.0 + lcg(&mut s) * 30.0,
                    )
                })
                .collect();
            let scores: Vec<f32> = (0..n)
                .map(|_| (lcg(&mut s) * 10.0).floor() / 10.0)
                .collect();
            for iou in [0.3, 0.5, 0.7] {
                assert_eq!(
                    nms(&boxes, &scores, iou),
                    nms_reference(&boxes, &scores, iou)
                );
            }
        }
    }

    #[test]
    fn top_k_picks_the_best() {
        assert_eq!(top_k(&[0.1, 0.9, 0.5, 0.9, 0.2], 3), vec![1, 3, 2]);
        assert_eq!(top_k(&[0.1], 5), vec![0]);
    }
}
