//! Parity between the tch model and its ONNX Runtime export on real frames.

use crate::FasterRcnn;
use frugal_runtime::FrameRef;
use frugal_runtime::onnx::{OrtDetector, OrtError};
use serde::Serialize;
use tch::Kind;

/// How closely the exported detector follows the tch model.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ParityReport {
    /// Frames compared.
    pub frames: usize,
    /// Largest absolute difference over every raw network output (features,
    /// objectness, RPN deltas, class logits, box deltas).
    pub max_raw_diff: f32,
    /// Detections made by tch (after NMS), summed over frames.
    pub tch_detections: usize,
    /// Detections made by ONNX Runtime, summed over frames.
    pub ort_detections: usize,
    /// tch detections with an ONNX Runtime detection of the same class, rank and
    /// IoU ≥ 0.99.
    pub matched: usize,
    /// Smallest IoU between rank-matched detections.
    pub min_iou: f32,
}

impl ParityReport {
    /// Raw outputs within `tolerance` and every detection matched.
    pub fn agrees(&self, tolerance: f32) -> bool {
        self.max_raw_diff <= tolerance
            && self.tch_detections == self.ort_detections
            && self.matched == self.tch_detections
    }
}

fn max_diff(a: &tch::Tensor, b: &[f32]) -> f32 {
    let a = Vec::<f32>::try_from(a.to_kind(Kind::Float).flatten(0, -1)).unwrap_or_default();
    if a.len() != b.len() {
        return f32::INFINITY;
    }
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// Compare `model` and `ort` on `frames` (RGB8, `(width, height, pixels)`): raw outputs
/// of both graphs on the same proposals, then the final detections.
pub fn parity(
    model: &FasterRcnn,
    ort: &mut OrtDetector,
    frames: &[(u32, u32, Vec<u8>)],
) -> Result<ParityReport, OrtError> {
    let mut r = ParityReport {
        min_iou: 1.0,
        ..ParityReport::default()
    };
    for (w, h, px) in frames {
        let Some(frame) = FrameRef::new(*w, *h, px) else {
            continue;
        };
        r.frames += 1;
        let image = model.frame_tensor(frame);
        let out = tch::no_grad(|| model.backbone_rpn(&image));
        let flat = Vec::<f32>::try_from(image.flatten(0, -1)).unwrap_or_default();
        let (feat, obj, del) = ort.run_backbone(flat)?;
        r.max_raw_diff = r
            .max_raw_diff
            .max(max_diff(&out.features, &feat))
            .max(max_diff(&out.objectness, &obj))
            .max(max_diff(&out.deltas, &del));
        let props = model.proposals_of(&out, 0, (*h as usize, *w as usize), false);
        if !props.is_empty() {
            let rois = crate::boxes_tensor(&props);
            let (l, d) =
                tch::no_grad(|| model.roi_head(&out.features, &rois, &vec![0; props.len()]));
            let (l2, d2) = ort.run_head(feat, &props)?;
            r.max_raw_diff = r.max_raw_diff.max(max_diff(&l, &l2)).max(max_diff(&d, &d2));
        }
        let a = model.detect(frame);
        let b = ort.detect(frame)?;
        r.tch_detections += a.len();
        r.ort_detections += b.len();
        for (x, y) in a.iter().zip(&b) {
            let iou = x.bbox.iou(&y.bbox);
            r.min_iou = r.min_iou.min(iou);
            if x.class == y.class && iou >= 0.99 {
                r.matched += 1;
            }
        }
    }
    Ok(r)
}
