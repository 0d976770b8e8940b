//! Box arithmetic: anchors, the box coder, NMS. The code lives in
//! [`frugal_runtime::cnn`] (plain Rust, shared with the ONNX Runtime executor that
//! flies); this module re-exports it for the training code and keeps its tests.
pub use frugal_runtime::cnn::{
    CoderWeights, ROI_WEIGHTS, RPN_WEIGHTS, anchors, decode, encode, nms, top_k,
};

#[cfg(test)]
mod tests {
    use super::*;
    use frugal_runtime::BBox;

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
