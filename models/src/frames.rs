//! Dataset frames as training, evaluation and compression use them: the ground truth
//! of a frame, its scenario, an even spread of a split, and a model's detections on a
//! list of frames paired with their ground truth.
use crate::metrics::{ImageResult, Truth};
use crate::{FasterRcnn, ModelError};
use frugal_data::{Dataset, FrameRecord};
use frugal_runtime::FrameRef;

/// The scenario of a frame, `"<clutter>-clutter/<light>-light"` (`"unknown"` when its
/// video is not in the manifest).
pub(crate) fn scenario(ds: &Dataset, f: &FrameRecord) -> String {
    match ds.video(f.video) {
        Some(v) => crate::config::scenario_name(v.clutter, v.light),
        None => "unknown".into(),
    }
}

/// Ground truth of a frame.
pub fn frame_truth(f: &FrameRecord) -> Vec<Truth> {
    f.objects
        .iter()
        .map(|o| Truth {
            class: o.class,
            bbox: o.bbox,
        })
        .collect()
}

/// Up to `n` frames spread evenly over `frames` (all when `n == 0`).
pub fn spread(frames: Vec<&FrameRecord>, n: usize) -> Vec<&FrameRecord> {
    if n == 0 || frames.len() <= n {
        return frames;
    }
    (0..n).map(|i| frames[i * frames.len() / n]).collect()
}

/// Run `model` on frames and pair the detections with the ground truth.
pub fn detect_frames(
    model: &FasterRcnn,
    ds: &Dataset,
    frames: &[&FrameRecord],
) -> Result<Vec<ImageResult>, ModelError> {
    let mut out = Vec::with_capacity(frames.len());
    for f in frames {
        let rgb = ds
            .load_rgb(f)
            .map_err(|e| ModelError::Data(e.to_string()))?;
        let frame = FrameRef::new(rgb.width(), rgb.height(), rgb.as_raw()).ok_or_else(|| {
            ModelError::Data(format!("{}: pixel buffer size mismatch", f.file.display()))
        })?;
        out.push(ImageResult {
            detections: model.detect(frame),
            truth: frame_truth(f),
        });
    }
    Ok(out)
}
