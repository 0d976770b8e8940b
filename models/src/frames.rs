//! Dataset frames as training, evaluation and compression use them: the ground truth
//! of a frame, its scenario, an even spread of a split, a frame as the model's input
//! tensor at its input size (boxes scaled alike), and a model's detections on a list of
//! frames paired with their ground truth.
use crate::metrics::{ImageResult, Truth};
use crate::{FasterRcnn, ModelError};
use frugal_data::{Dataset, FrameRecord};
use frugal_runtime::{BBox, FrameRef};
use tch::{Kind, Tensor};

/// The scenario of a frame, `"<clutter>-clutter/<light>-light"` (`"unknown"` when its
/// video is not in the manifest).
pub fn scenario(ds: &Dataset, f: &FrameRecord) -> String {
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

/// Up to `n` items (frames, or their indices) spread evenly over `items` (all when
/// `n == 0`).
pub fn spread<T: Copy>(items: Vec<T>, n: usize) -> Vec<T> {
    if n == 0 || items.len() <= n {
        return items;
    }
    (0..n).map(|i| items[i * items.len() / n]).collect()
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
            ignore: f.ignore.clone(),
        });
    }
    Ok(out)
}

/// `[1, 3, H, W]` image in `[0, 1]` from an RGB8 buffer.
pub fn image_tensor(rgb: &image::RgbImage) -> Tensor {
    let (w, h) = (rgb.width() as i64, rgb.height() as i64);
    Tensor::from_slice(rgb.as_raw())
        .reshape([h, w, 3])
        .permute([2, 0, 1])
        .unsqueeze(0)
        .to_kind(Kind::Float)
        / 255.0
}

/// Resize a `[1, 3, H, W]` image to `height × width` (bilinear, half-pixel centres).
pub fn resize(x: &Tensor, height: usize, width: usize) -> Tensor {
    let s = x.size();
    if s[2] == height as i64 && s[3] == width as i64 {
        return x.shallow_clone();
    }
    x.upsample_bilinear2d([height as i64, width as i64], false, None, None)
}

/// The ground truth of frame `f` in the pixels of its copy resized to `input =
/// (height, width)`.
pub fn scaled_truth(f: &FrameRecord, input: (usize, usize)) -> Vec<Truth> {
    let (sx, sy) = (
        input.1 as f32 / f.width as f32,
        input.0 as f32 / f.height as f32,
    );
    frame_truth(f)
        .into_iter()
        .map(|t| Truth {
            class: t.class,
            bbox: BBox::new(
                t.bbox.x1 * sx,
                t.bbox.y1 * sy,
                t.bbox.x2 * sx,
                t.bbox.y2 * sy,
            ),
        })
        .collect()
}

/// Frame `f` as a `[1, 3, H, W]` image in `[0, 1]` at `input = (height, width)`, with
/// its ground truth scaled the same way.
pub fn input_frame(
    ds: &Dataset,
    f: &FrameRecord,
    input: (usize, usize),
) -> Result<(Tensor, Vec<Truth>), ModelError> {
    let rgb = ds
        .load_rgb(f)
        .map_err(|e| ModelError::Data(e.to_string()))?;
    Ok((
        resize(&image_tensor(&rgb), input.0, input.1),
        scaled_truth(f, input),
    ))
}
