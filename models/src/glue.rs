//! Pre- and post-processing around the two networks. The slice-level code lives in
//! [`frugal_runtime::cnn`], shared with the ONNX Runtime executor
//! ([`frugal_runtime::onnx`]), so the tch model and the deployed variants agree by
//! construction:
//!
//! 1. [`normalize`]: RGB8 frame → `[3, H, W]` floats (CHW).
//! 2. network `backbone + rpn_head(image) -> (features, objectness [1, A, h, w],
//!    deltas [1, 4A, h, w])` (channel `4a + k` holds coordinate `k` of anchor `a`).
//! 3. [`proposals`]: decode, clip, drop tiny boxes, top-k, NMS, top-k.
//! 4. network `roi_head(features, rois) -> (class_logits [R, K+1], box_deltas [R, 4K])`
//!    (column 0 of the logits is background; deltas of class `c` are columns `4c..4c+4`).
//! 5. [`detections`]: softmax, class-specific decoding, clipping, threshold, per-class
//!    NMS, the best `max_detections` by score.
//!
//! This module adds what depends on the model's config.
use crate::config::ModelConfig;
pub use frugal_runtime::cnn::{
    DetectionParams, ProposalParams, detections, normalize, proposals, resize_bilinear, softmax,
};

/// Feature-map size for an image: each stride-2 conv (3×3, padding 1) maps `n` to
/// `(n − 1) / 2 + 1`.
pub fn feature_size(cfg: &ModelConfig, height: usize, width: usize) -> (usize, usize) {
    cfg.backbone.iter().fold((height, width), |(h, w), b| {
        let s = b.stride as usize;
        ((h - 1) / s + 1, (w - 1) / s + 1)
    })
}

/// The detection parameters stored in a model config.
pub fn detection_params(cfg: &ModelConfig) -> DetectionParams {
    DetectionParams {
        num_classes: cfg.num_classes,
        score_threshold: cfg.score_threshold,
        nms_iou: cfg.nms_iou,
        max_detections: cfg.max_detections,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::boxes;
    use frugal_runtime::{BBox, FrameRef};

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
