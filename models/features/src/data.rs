//! Frames of a `frugal-data` dataset as [`LabeledFrame`]s.

use crate::error::Result;
use crate::train::LabeledFrame;
use frugal_data::{Dataset, Split};
use rayon::prelude::*;

/// Decode the frames of `split`, taking every `stride`-th frame (consecutive video
/// frames are near duplicates) up to `limit` frames, in frame-id order.
pub fn load_frames(
    ds: &Dataset,
    split: Split,
    stride: usize,
    limit: usize,
) -> Result<Vec<LabeledFrame>> {
    let picked: Vec<_> = ds.split(split).step_by(stride.max(1)).take(limit).collect();
    picked
        .par_iter()
        .map(|f| {
            let rgb = ds.load_rgb(f)?;
            Ok(LabeledFrame {
                width: rgb.width() as usize,
                height: rgb.height() as usize,
                rgb: rgb.into_raw(),
                objects: f.objects.iter().map(|o| (o.class, o.bbox)).collect(),
            })
        })
        .collect()
}

/// The dataset's class names, in id order.
pub fn class_names(ds: &Dataset) -> Vec<String> {
    ds.classes.iter().map(|c| c.name.clone()).collect()
}
