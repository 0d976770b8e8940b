//! Pre- and post-processing around the two networks, in plain Rust on `f32` slices so
//! that an ONNX executor can reuse it unchanged:
//!
//! 1. [`normalize`]: RGB8 frame → `[3, H, W]` floats (CHW).
//! 2. network `backbone + rpn_head(image) -> (features, objectness [1, A, h, w],
//!    deltas [1, 4A, h, w])` (channel `4a + k` holds coordinate `k` of anchor `a`).
//! 3. [`proposals`]: decode, clip, drop tiny boxes, top-k, NMS, top-k.
//! 4. network `roi_head(features, rois) -> (class_logits [R, K+1], box_deltas [R, 4K])`
//!    (column 0 of the logits is background; deltas of class `c` are columns `4c..4c+4`).
//! 5. [`detections`]: softmax, class-specific decoding, clipping, threshold, per-class
//!    NMS, the best `max_detections` by score.
use crate::boxes::{self, ROI_WEIGHTS, RPN_WEIGHTS};
use crate::config::ModelConfig;
use frugal_runtime::{BBox, ClassId, Detection, FrameRef};

/// Frame → normalised CHW floats: `(px / 255 − mean) / std` per channel.
pub fn normalize(frame: FrameRef<'_>, mean: [f32; 3], std: [f32; 3]) -> Vec<f32> {
    let plane = frame.width as usize * frame.height as usize;
    let mut out = vec![0.0f32; 3 * plane];
    for (i, px) in frame.rgb.chunks_exact(3).enumerate().take(plane) {
        for ch in 0..3 {
            out[ch * plane + i] = (f32::from(px[ch]) / 255.0 - mean[ch]) / std[ch];
        }
    }
    out
}

/// Feature-map size for an image: each stride-2 conv (3×3, padding 1) maps `n` to
/// `(n − 1) / 2 + 1`.
pub fn feature_size(cfg: &ModelConfig, height: usize, width: usize) -> (usize, usize) {
    cfg.backbone.iter().fold((height, width), |(h, w), b| {
        let s = b.stride as usize;
        ((h - 1) / s + 1, (w - 1) / s + 1)
    })
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
/// `[A, fh, fw]` (logits), `deltas` `[4A, fh, fw]`, `anchors` as from
/// [`boxes::anchors`].
pub fn proposals(
    objectness: &[f32],
    deltas: &[f32],
    (fh, fw): (usize, usize),
    anchors: &[BBox],
    (img_w, img_h): (f32, f32),
    p: ProposalParams,
) -> Vec<BBox> {
    let a_per = anchors.len() / (fh * fw).max(1);
    let plane = fh * fw;
    // score in anchor order (y, x, a)
    let scores: Vec<f32> = (0..anchors.len())
        .map(|i| {
            let (cell, a) = (i / a_per, i % a_per);
            objectness[a * plane + cell]
        })
        .collect();
    let mut cand = Vec::new();
    let mut cand_scores = Vec::new();
    for i in boxes::top_k(&scores, p.pre_nms) {
        let (cell, a) = (i / a_per, i % a_per);
        let d = [0, 1, 2, 3].map(|k| deltas[(4 * a + k) * plane + cell]);
        let b = boxes::decode(&anchors[i], d, RPN_WEIGHTS).clip(img_w, img_h);
        if b.width() >= p.min_size && b.height() >= p.min_size {
            cand.push(b);
            cand_scores.push(scores[i]);
        }
    }
    let mut keep = boxes::nms(&cand, &cand_scores, p.nms_iou);
    keep.truncate(p.post_nms);
    keep.into_iter().map(|i| cand[i]).collect()
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

impl DetectionParams {
    /// The parameters stored in a model config.
    pub fn from_config(cfg: &ModelConfig) -> Self {
        Self {
            num_classes: cfg.num_classes,
            score_threshold: cfg.score_threshold,
            nms_iou: cfg.nms_iou,
            max_detections: cfg.max_detections,
        }
    }
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
    let mut per_class: Vec<(Vec<BBox>, Vec<f32>)> = vec![(Vec::new(), Vec::new()); k];
    for (r, roi) in rois.iter().enumerate() {
        let probs = softmax(&logits[r * (k + 1)..(r + 1) * (k + 1)]);
        for c in 0..k {
            let s = probs[c + 1];
            if s < p.score_threshold {
                continue;
            }
            let o = r * 4 * k + 4 * c;
            let d = [deltas[o], deltas[o + 1], deltas[o + 2], deltas[o + 3]];
            let b = boxes::decode(roi, d, ROI_WEIGHTS).clip(img_w, img_h);
            if b.is_valid() {
                per_class[c].0.push(b);
                per_class[c].1.push(s);
            }
        }
    }
    let mut out = Vec::new();
    for (c, (bxs, scs)) in per_class.iter().enumerate() {
        for i in boxes::nms(bxs, scs, p.nms_iou) {
            out.push(Detection {
                bbox: bxs[i],
                score: scs[i],
                class: c as ClassId,
            });
        }
    }
    out.sort_by(|a, b| b.score.total_cmp(&a.score));
    out.truncate(p.max_detections);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalize_is_chw() {
        let px = [255u8, 0, 0, 0, 255, 0];
        let f = FrameRef::new(2, 1, &px).unwrap();
        assert_eq!(
            normalize(f, [0.0; 3], [1.0; 3]),
            vec![1.0, 0.0, 0.0, 1.0, 0.0, 0.0]
        );
        let cfg = ModelConfig::default();
        assert_eq!(feature_size(&cfg, 270, 480), (34, 60));
    }

    #[test]
    fn proposals_decode_the_best_anchor() {
        let anchors = boxes::anchors(2, 2, 16.0, &[16.0], &[1.0]);
        let mut obj = vec![-5.0f32; 4];
        obj[3] = 5.0; // cell (1, 1)
        let mut deltas = vec![0.0f32; 16];
        deltas[3] = 0.5; // dx of cell 3 (plane index 3 in channel 0)
        let p = ProposalParams {
            pre_nms: 10,
            post_nms: 2,
            nms_iou: 0.7,
            min_size: 1.0,
        };
        let out = proposals(&obj, &deltas, (2, 2), &anchors, (32.0, 32.0), p);
        assert_eq!(out.len(), 2);
        assert_eq!(out[0], BBox::new(24.0, 16.0, 32.0, 32.0)); // shifted by 8, clipped at 32
    }

    #[test]
    fn detections_pick_class_and_score() {
        let rois = [
            BBox::new(10.0, 10.0, 30.0, 30.0),
            BBox::new(11.0, 10.0, 31.0, 30.0),
        ];
        // K = 2: row 0 says class 1 (0-based) strongly, row 1 the same but weaker
        let logits = [0.0f32, 0.0, 4.0, 0.0, 0.0, 3.0];
        let deltas = [0.0f32; 16];
        let p = DetectionParams {
            num_classes: 2,
            score_threshold: 0.1,
            nms_iou: 0.5,
            max_detections: 10,
        };
        let d = detections(&logits, &deltas, &rois, (100.0, 100.0), p);
        assert_eq!(d.len(), 1);
        assert_eq!(d[0].class, 1);
        let want = 4f32.exp() / (2.0 + 4f32.exp());
        assert!((d[0].score - want).abs() < 1e-6);
        assert_eq!(d[0].bbox, rois[0]);
    }
}
