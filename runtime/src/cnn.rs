//! Pre- and post-processing of the two-stage CNN detector, in plain Rust on `f32`
//! slices (feature `std`). The tch model (`frugal-models`) and the ONNX Runtime
//! executor ([`crate::onnx`]) both call this code, so they agree by construction.
//!
//! 1. [`normalize`]: RGB8 frame → `[3, H, W]` floats (CHW).
//! 2. network `backbone + rpn_head(image) -> (features, objectness [A, h, w],
//!    deltas [4A, h, w])` (channel `4a + k` holds coordinate `k` of anchor `a`).
//! 3. [`proposals`]: decode, clip, drop tiny boxes, top-k, NMS, top-k.
//! 4. network `roi_head(features, rois) -> (class_logits [R, K+1], box_deltas [R, 4K])`
//!    (column 0 of the logits is background; deltas of class `c` are columns
//!    `4c..4c+4`).
//! 5. [`detections`]: softmax, class-specific decoding, clipping, threshold, per-class
//!    NMS, the best `max_detections` by score.
//!
//! Every access is checked: short or malformed network outputs give fewer boxes,
//! never a panic.

use crate::geom::{BBox, ClassId, Detection, FrameRef};
use std::vec::Vec;

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

/// Apply deltas to `reference` (inverse of [`encode`]); scales are clamped so a wild
/// delta cannot overflow.
pub fn decode(reference: &BBox, d: [f32; 4], w: CoderWeights) -> BBox {
    let (rw, rh) = (reference.width(), reference.height());
    let (rcx, rcy) = reference.center();
    let cx = rcx + d[0] / w[0] * rw;
    let cy = rcy + d[1] / w[1] * rh;
    let bw = rw * (d[2] / w[2]).min(MAX_LOG_SCALE).exp();
    let bh = rh * (d[3] / w[3]).min(MAX_LOG_SCALE).exp();
    BBox::new(cx - 0.5 * bw, cy - 0.5 * bh, cx + 0.5 * bw, cy + 0.5 * bh)
}

/// Anchors for a `fh × fw` feature map of the given stride, in the order `(y, x, a)`:
/// index `(y·fw + x)·A + a`, with `a = size_index·R + ratio_index`. Anchors are centred
/// on the cell centre `((x + 0.5)·stride, (y + 0.5)·stride)`.
pub fn anchors(fh: usize, fw: usize, stride: f32, sizes: &[f32], ratios: &[f32]) -> Vec<BBox> {
    let mut out = Vec::with_capacity(fh * fw * sizes.len() * ratios.len());
    for y in 0..fh {
        for x in 0..fw {
            let (cx, cy) = ((x as f32 + 0.5) * stride, (y as f32 + 0.5) * stride);
            for &s in sizes {
                for &r in ratios {
                    let (w, h) = (s / r.sqrt(), s * r.sqrt());
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

/// `scores[a]` vs `scores[b]`, best first, ties by index (missing scores last).
fn by_score(scores: &[f32], a: usize, b: usize) -> core::cmp::Ordering {
    let s = |i: usize| scores.get(i).copied().unwrap_or(f32::NEG_INFINITY);
    s(b).total_cmp(&s(a)).then(a.cmp(&b))
}

/// Greedy non-maximum suppression: indices of the kept boxes, best score first. A box
/// is dropped when its IoU with an already kept box is above `iou`.
pub fn nms(boxes: &[BBox], scores: &[f32], iou: f32) -> Vec<usize> {
    nms_first(boxes, scores, iou, usize::MAX)
}

/// The first `limit` boxes [`nms`] keeps (the same boxes as truncating its result):
/// the search stops once `limit` are kept, instead of comparing every remaining box
/// with every kept one.
pub fn nms_first(boxes: &[BBox], scores: &[f32], iou: f32, limit: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..boxes.len().min(scores.len())).collect();
    order.sort_by(|&a, &b| by_score(scores, a, b));
    let mut keep: Vec<usize> = Vec::new();
    for i in order {
        if keep.len() >= limit {
            break;
        }
        let Some(bi) = boxes.get(i) else { continue };
        if keep
            .iter()
            .filter_map(|&k| boxes.get(k))
            .all(|bk| bk.iou(bi) <= iou)
        {
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
        idx.select_nth_unstable_by(k, |&a, &b| by_score(scores, a, b));
        idx.truncate(k);
    }
    idx.sort_by(|&a, &b| by_score(scores, a, b));
    idx
}

/// Frame → normalised CHW floats: `(px / 255 − mean) / std` per channel.
pub fn normalize(frame: FrameRef<'_>, mean: [f32; 3], std: [f32; 3]) -> Vec<f32> {
    let plane = frame.width as usize * frame.height as usize;
    let mut out = Vec::with_capacity(3 * plane);
    // one table per channel: the same f32 arithmetic per value as per pixel, done 256
    // times instead of once per pixel (bit-identical results); the planes are written
    // once each, never zeroed first
    for (c, (m, s)) in mean.into_iter().zip(std).enumerate() {
        let table: [f32; 256] = core::array::from_fn(|v| (v as f32 / 255.0 - m) / s);
        out.extend(frame.rgb.chunks_exact(3).take(plane).map(|px| {
            px.get(c)
                .and_then(|&v| table.get(usize::from(v)))
                .copied()
                .unwrap_or(0.0)
        }));
    }
    out.resize(3 * plane, 0.0);
    out
}

/// The two source indices and the weight of the second for output index `d` of an
/// axis resized by `scale` (source length over output length) from `n > 0` samples,
/// pixel centres aligned (`align_corners = false`).
fn bilinear_taps(d: usize, scale: f32, n: usize) -> (usize, usize, f32) {
    let s = ((d as f32 + 0.5) * scale - 0.5).max(0.0);
    let i0 = (s as usize).min(n.saturating_sub(1));
    let i1 = (i0 + 1).min(n.saturating_sub(1));
    (i0, i1, s - i0 as f32)
}

/// The source and output sizes of a resize of `frame` to `w × h` and the source length
/// per output pixel, `(sw, sh, dw, dh, fx, fy)`; `None` when either is empty.
fn resize_axes(
    frame: FrameRef<'_>,
    w: u32,
    h: u32,
) -> Option<(usize, usize, usize, usize, f32, f32)> {
    let (sw, sh) = (frame.width as usize, frame.height as usize);
    let (dw, dh) = (w as usize, h as usize);
    if sw == 0 || sh == 0 || dw == 0 || dh == 0 {
        return None;
    }
    Some((sw, sh, dw, dh, sw as f32 / dw as f32, sh as f32 / dh as f32))
}

/// Resize an RGB8 frame to `w × h` with bilinear interpolation (pixel centres aligned,
/// as `align_corners = false`). An empty frame or target gives black pixels; pixels a
/// short buffer lacks read as black (it is padded with them first).
///
/// Per output value: `top = p00 + (p10 − p00)·tx`, `bot = p01 + (p11 − p01)·tx`,
/// `top + (bot − top)·ty`, rounded half away from zero. The column taps are computed
/// once per image and the two source rows are sliced once per output row, so the inner
/// loop indexes plain slices; the rounding adds ½ and truncates (the value is never
/// negative beyond float error, and the cast saturates), which equals `round` then
/// clamping to 0..=255 without a library call per value.
pub fn resize_bilinear(frame: FrameRef<'_>, w: u32, h: u32) -> Vec<u8> {
    let mut out = std::vec![0u8; w as usize * h as usize * 3];
    let Some((sw, sh, dw, _, fx, fy)) = resize_axes(frame, w, h) else {
        return out;
    };
    // byte offsets of the two taps within a row, and the weight
    let xs: Vec<(usize, usize, f32)> = (0..dw)
        .map(|x| {
            let (x0, x1, tx) = bilinear_taps(x, fx, sw);
            (x0 * 3, x1 * 3, tx)
        })
        .collect();
    let row_bytes = sw * 3;
    // a buffer shorter than its size says: what it lacks reads as black
    let padded: Vec<u8>;
    let rgb = if frame.rgb.len() >= row_bytes * sh {
        frame.rgb
    } else {
        padded = frame
            .rgb
            .iter()
            .copied()
            .chain(core::iter::repeat(0))
            .take(row_bytes * sh)
            .collect();
        &padded
    };
    let row = |y: usize| rgb.get(y * row_bytes..(y + 1) * row_bytes);
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let to_u8 = |v: f32| (v + 0.5) as u8;
    for (y, dst_row) in out.chunks_exact_mut(dw * 3).enumerate() {
        let (y0, y1, ty) = bilinear_taps(y, fy, sh);
        // always there: y0, y1 < sh, x0, x1 < sw and the buffer is whole
        let (Some(r0), Some(r1)) = (row(y0), row(y1)) else {
            continue;
        };
        for (&(a, b, tx), dst) in xs.iter().zip(dst_row.chunks_exact_mut(3)) {
            let taps = (r0.get(a..a + 3), r0.get(b..b + 3));
            let (Some(p00), Some(p10)) = taps else {
                continue;
            };
            let taps = (r1.get(a..a + 3), r1.get(b..b + 3));
            let (Some(p01), Some(p11)) = taps else {
                continue;
            };
            let px = p00.iter().zip(p10).zip(p01.iter().zip(p11));
            for (v, ((&q00, &q10), (&q01, &q11))) in dst.iter_mut().zip(px) {
                let top = lerp(f32::from(q00), f32::from(q10), tx);
                let bot = lerp(f32::from(q01), f32::from(q11), tx);
                *v = to_u8(lerp(top, bot, ty));
            }
        }
    }
    out
}

/// Detections found on a `from = (width, height)` resized copy of a frame, mapped back
/// to the frame's own `to = (width, height)` pixels (clamped to the frame).
pub fn rescale_detections(dets: &mut [Detection], from: (u32, u32), to: (u32, u32)) {
    let (sx, sy) = (
        to.0 as f32 / from.0.max(1) as f32,
        to.1 as f32 / from.1.max(1) as f32,
    );
    let (fw, fh) = (to.0 as f32, to.1 as f32);
    for d in dets {
        let b = d.bbox;
        d.bbox = BBox::new(
            (b.x1 * sx).clamp(0.0, fw),
            (b.y1 * sy).clamp(0.0, fh),
            (b.x2 * sx).clamp(0.0, fw),
            (b.y2 * sy).clamp(0.0, fh),
        );
    }
}

/// Parameters of [`proposals`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProposalParams {
    /// Best anchors kept before NMS.
    pub pre_nms: usize,
    /// Proposals kept after NMS.
    pub post_nms: usize,
    /// NMS IoU threshold.
    pub nms_iou: f32,
    /// Smallest side kept (pixels).
    pub min_size: f32,
}

/// RPN outputs → proposals (image pixels), best objectness first. `objectness` is
/// `[A, fh, fw]` (logits), `deltas` `[4A, fh, fw]`, `anchors` as from [`anchors`].
pub fn proposals(
    objectness: &[f32],
    deltas: &[f32],
    (fh, fw): (usize, usize),
    anchors: &[BBox],
    (img_w, img_h): (f32, f32),
    p: ProposalParams,
) -> Vec<BBox> {
    let plane = fh * fw;
    let a_per = anchors.len() / plane.max(1);
    if a_per == 0 {
        return Vec::new();
    }
    // score in anchor order (y, x, a)
    let scores: Vec<f32> = (0..anchors.len())
        .map(|i| {
            let (cell, a) = (i / a_per, i % a_per);
            objectness
                .get(a * plane + cell)
                .copied()
                .unwrap_or(f32::NEG_INFINITY)
        })
        .collect();
    let mut cand = Vec::new();
    let mut cand_scores = Vec::new();
    for i in top_k(&scores, p.pre_nms) {
        let (cell, a) = (i / a_per, i % a_per);
        let d = [0, 1, 2, 3].map(|k| {
            deltas
                .get((4 * a + k) * plane + cell)
                .copied()
                .unwrap_or(0.0)
        });
        let (Some(anchor), Some(&score)) = (anchors.get(i), scores.get(i)) else {
            continue;
        };
        if !score.is_finite() {
            continue; // no objectness for this anchor (short or malformed output)
        }
        let b = decode(anchor, d, RPN_WEIGHTS).clip(img_w, img_h);
        if b.width() >= p.min_size && b.height() >= p.min_size {
            cand.push(b);
            cand_scores.push(score);
        }
    }
    nms_first(&cand, &cand_scores, p.nms_iou, p.post_nms)
        .into_iter()
        .filter_map(|i| cand.get(i).copied())
        .collect()
}

/// Parameters of [`detections`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetectionParams {
    /// Number of object classes `K`.
    pub num_classes: usize,
    /// Detections below this softmax probability are dropped.
    pub score_threshold: f32,
    /// Per-class NMS IoU threshold.
    pub nms_iou: f32,
    /// At most this many detections.
    pub max_detections: usize,
}

/// Softmax of one row of logits.
pub fn softmax(logits: &[f32]) -> Vec<f32> {
    let m = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let e: Vec<f32> = logits.iter().map(|l| (l - m).exp()).collect();
    let s: f32 = e.iter().sum();
    e.into_iter().map(|v| v / s).collect()
}

/// RoI head outputs → detections sorted by score (highest first). `logits` is
/// `[R, K+1]` row-major, `deltas` `[R, 4K]`. The score is the softmax probability of
/// the detection's class (in `[0, 1]`); the class id is 0-based (logit column − 1).
pub fn detections(
    logits: &[f32],
    deltas: &[f32],
    rois: &[BBox],
    (img_w, img_h): (f32, f32),
    p: DetectionParams,
) -> Vec<Detection> {
    let k = p.num_classes;
    let mut per_class: Vec<(Vec<BBox>, Vec<f32>)> = std::vec![(Vec::new(), Vec::new()); k];
    let rows = logits
        .chunks_exact(k + 1)
        .zip(deltas.chunks_exact(4 * k.max(1)));
    for ((row, row_deltas), roi) in rows.zip(rois) {
        let probs = softmax(row);
        let class_probs = probs.iter().skip(1);
        let class_deltas = row_deltas.chunks_exact(4);
        for ((&s, d), (boxes, scores)) in class_probs.zip(class_deltas).zip(per_class.iter_mut()) {
            if s < p.score_threshold {
                continue;
            }
            let d = [0, 1, 2, 3].map(|i| d.get(i).copied().unwrap_or(0.0));
            let b = decode(roi, d, ROI_WEIGHTS).clip(img_w, img_h);
            if b.is_valid() {
                boxes.push(b);
                scores.push(s);
            }
        }
    }
    let mut out = Vec::new();
    for (c, (bxs, scs)) in per_class.iter().enumerate() {
        for i in nms(bxs, scs, p.nms_iou) {
            if let (Some(&bbox), Some(&score)) = (bxs.get(i), scs.get(i)) {
                out.push(Detection {
                    bbox,
                    score,
                    class: c as ClassId,
                });
            }
        }
    }
    out.sort_by(|a, b| b.score.total_cmp(&a.score));
    out.truncate(p.max_detections);
    out
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// The resize as first written (its taps as the faster one takes them), one checked
    /// pixel read and a library `round` per value: what the faster one must equal byte
    /// for byte.
    #[allow(clippy::indexing_slicing)]
    fn resize_reference(frame: FrameRef<'_>, w: u32, h: u32) -> Vec<u8> {
        let mut out = std::vec![0u8; w as usize * h as usize * 3];
        let Some((sw, sh, dw, dh, fx, fy)) = resize_axes(frame, w, h) else {
            return out;
        };
        let px = |x: usize, y: usize, c: usize| {
            f32::from(frame.rgb.get((y * sw + x) * 3 + c).copied().unwrap_or(0))
        };
        for y in 0..dh {
            let (y0, y1, ty) = bilinear_taps(y, fy, sh);
            for x in 0..dw {
                let (x0, x1, tx) = bilinear_taps(x, fx, sw);
                for c in 0..3 {
                    let top = px(x0, y0, c) + (px(x1, y0, c) - px(x0, y0, c)) * tx;
                    let bot = px(x0, y1, c) + (px(x1, y1, c) - px(x0, y1, c)) * tx;
                    out[(y * dw + x) * 3 + c] =
                        (top + (bot - top) * ty).round().clamp(0.0, 255.0) as u8;
                }
            }
        }
        out
    }

    #[test]
    #[allow(clippy::indexing_slicing)]
    fn the_resize_equals_the_per_pixel_reference_byte_for_byte() {
        let mut seed = 0x9e37_79b9_u32;
        let mut noise = |n: usize| -> Vec<u8> {
            (0..n)
                .map(|_| {
                    seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    (seed >> 24) as u8
                })
                .collect()
        };
        // down (the variants' 0.75 and 0.5 inputs, footage to the detector's size), up,
        // odd sizes, one pixel, and flat extremes
        let cases: [((u32, u32), (u32, u32)); 8] = [
            ((480, 270), (360, 203)),
            ((480, 270), (240, 135)),
            ((640, 480), (480, 270)),
            ((37, 23), (64, 41)),
            ((1, 1), (5, 3)),
            ((3, 2), (1, 1)),
            ((7, 5), (7, 5)),
            ((101, 3), (13, 17)),
        ];
        let mut compared = 0usize;
        for ((sw, sh), (dw, dh)) in cases {
            let n = (sw * sh * 3) as usize;
            for px in [noise(n), std::vec![0u8; n], std::vec![255u8; n]] {
                let frame = FrameRef::new(sw, sh, &px).unwrap();
                let fast = resize_bilinear(frame, dw, dh);
                assert_eq!(
                    fast,
                    resize_reference(frame, dw, dh),
                    "{sw}×{sh} → {dw}×{dh}"
                );
                compared += fast.len();
            }
            // a buffer shorter than its size: no panic, the missing pixels black
            let short = noise(n / 2);
            let frame = FrameRef {
                width: sw,
                height: sh,
                rgb: &short,
            };
            assert_eq!(
                resize_bilinear(frame, dw, dh),
                resize_reference(frame, dw, dh)
            );
        }
        assert!(compared > 400_000, "{compared}");
        // the extremes: flat frames stay flat
        let white = std::vec![255u8; 480 * 270 * 3];
        let up = resize_bilinear(FrameRef::new(480, 270, &white).unwrap(), 360, 203);
        assert!(up.iter().all(|&v| v == 255));
        // nothing to read or nothing to write
        assert_eq!(
            resize_bilinear(
                FrameRef {
                    width: 0,
                    height: 4,
                    rgb: &[]
                },
                2,
                2
            ),
            [0; 12]
        );
        assert!(resize_bilinear(FrameRef::new(2, 2, &[9; 12]).unwrap(), 0, 3).is_empty());
    }

    #[test]
    fn malformed_outputs_give_fewer_boxes_not_panics() {
        let anchors = anchors(2, 2, 16.0, &[16.0], &[1.0]);
        let p = ProposalParams {
            pre_nms: 10,
            post_nms: 5,
            nms_iou: 0.7,
            min_size: 1.0,
        };
        // objectness and deltas far too short
        let out = proposals(&[1.0], &[], (2, 2), &anchors, (32.0, 32.0), p);
        assert!(out.len() <= 1);
        assert!(proposals(&[], &[], (0, 0), &[], (32.0, 32.0), p).is_empty());
        let dp = DetectionParams {
            num_classes: 2,
            score_threshold: 0.1,
            nms_iou: 0.5,
            max_detections: 5,
        };
        let rois = [BBox::new(0.0, 0.0, 10.0, 10.0); 3];
        assert!(detections(&[0.0; 4], &[0.0; 3], &rois, (20.0, 20.0), dp).is_empty());
        assert!(nms(&rois, &[1.0], 0.5).len() == 1);
    }

    #[test]
    fn nms_first_keeps_the_same_boxes_as_truncating_nms() {
        // a deterministic cloud of overlapping boxes with tied and distinct scores
        let mut state = 0x2545_f491_u32;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state % 1000) as f32 / 10.0
        };
        let boxes: std::vec::Vec<BBox> = (0..300)
            .map(|_| {
                let (x, y, w, h) = (next(), next(), 5.0 + next() / 4.0, 5.0 + next() / 4.0);
                BBox::new(x, y, x + w, y + h)
            })
            .collect();
        let scores: std::vec::Vec<f32> = (0..300).map(|_| (next() / 10.0).floor()).collect();
        for iou in [0.3, 0.5, 0.7] {
            let all = nms(&boxes, &scores, iou);
            assert!(
                all.len() > 20,
                "the cloud must leave more than the limits below"
            );
            for limit in [0, 1, 5, 20, all.len(), all.len() + 10] {
                let first = nms_first(&boxes, &scores, iou, limit);
                assert_eq!(
                    Some(first.as_slice()),
                    all.get(..limit.min(all.len())),
                    "iou {iou} limit {limit}"
                );
            }
        }
    }

    #[test]
    fn normalize_by_table_is_the_per_pixel_formula_bit_for_bit() {
        let rgb: std::vec::Vec<u8> = (0..=255u8).flat_map(|v| [v, 255 - v, v / 3]).collect();
        let f = FrameRef::new(256, 1, &rgb).unwrap();
        let (mean, std) = ([0.485, 0.456, 0.406], [0.229, 0.224, 0.225]);
        let out = normalize(f, mean, std);
        for (i, px) in rgb.chunks_exact(3).enumerate() {
            for (c, ((&v, m), s)) in px.iter().zip(mean).zip(std).enumerate() {
                let want = (f32::from(v) / 255.0 - m) / s;
                assert_eq!(
                    out.get(c * 256 + i).map(|x| x.to_bits()),
                    Some(want.to_bits())
                );
            }
        }
    }

    #[test]
    fn normalize_is_chw() {
        let px = [255u8, 0, 0, 0, 255, 0];
        let f = FrameRef::new(2, 1, &px).unwrap();
        assert_eq!(
            normalize(f, [0.0; 3], [1.0; 3]),
            std::vec![1.0, 0.0, 0.0, 1.0, 0.0, 0.0]
        );
    }
}
