//! The flight's readings against the renderer's ground truth: reported (events,
//! confirmation reads, in-loop detection counts), never used to navigate.
use crate::render::{FrameTruth, SignTruth};
use frugal_runtime::{BBox, Detection};

/// The sign board that `bbox` overlaps most, if it overlaps one: what a reading of
/// that box should have said.
pub(super) fn true_sign<'t>(truth: &'t FrameTruth, bbox: &BBox) -> Option<&'t SignTruth> {
    truth
        .signs
        .iter()
        .map(|s| (s.bbox.iou(bbox), s))
        .filter(|&(iou, _)| iou > 0.0)
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, s)| s)
}

/// In-loop detection quality against the renderer's ground truth.
pub(super) fn score(
    truth: &FrameTruth,
    dets: &[Detection],
    frames: &mut u64,
    hits: &mut u64,
    false_dets: &mut u64,
) {
    let visible: Vec<_> = truth
        .signs
        .iter()
        .filter(|s| s.bbox.height() >= 8.0 && s.visible_fraction >= 0.5)
        .collect();
    if !visible.is_empty() {
        *frames += 1;
        let found = visible.iter().any(|s| {
            dets.iter()
                .any(|d| d.class == s.class && d.bbox.iou(&s.bbox) >= 0.5)
        });
        if found {
            *hits += 1;
        }
    }
    *false_dets += dets
        .iter()
        .filter(|d| {
            !truth
                .signs
                .iter()
                .any(|s| s.class == d.class && d.bbox.iou(&s.bbox) >= 0.3)
        })
        .count() as u64;
}
