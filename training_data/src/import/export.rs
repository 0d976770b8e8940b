//! Export a dataset in the video annotation formats people's tools read: MOT Challenge
//! (one sequence folder per video) and COCO with videos (TAO / YouTube-VIS style), with
//! the frames copied (hard-linked when possible) beside the annotations, so the export
//! imports back as it was.
//!
//! What the formats cannot hold is lost: per-frame times (both keep only the frame
//! rate), the scenario levels and the splits (export one split at a time to keep them
//! apart). An ignore region of any class is written once per class, as a COCO crowd
//! excuses detections of its own category only.
use crate::annotations::{
    self, AnnotatedBox, AnnotatedFrame, AnnotatedVideo, AnnotationFormat, VideoAnnotations,
};
use crate::dataset::PartialDir;
use crate::{DataError, Dataset, FrameRecord, Split};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Export `ds` (all splits, or one) as `format` into the new folder `out`; returns the
/// annotation file (COCO-video) or the folder of sequences (MOT).
///
/// - MOT: `out/<sequence>/gt/gt.txt` with `labels.txt` and `seqinfo.ini` beside, and
///   the frames as `out/<sequence>/img1/<frame:06>.<ext>` (1-based). A sequence is
///   named after its video (`/` and `#` replaced by `_`), else `video<id:04>`.
/// - COCO-video: `out/annotations.json`, the frames under their dataset paths.
///
/// Only [`AnnotationFormat::Mot`] and [`AnnotationFormat::CocoVideo`] are written.
pub fn export_video(
    ds: &Dataset,
    split: Option<Split>,
    format: AnnotationFormat,
    out: &Path,
) -> Result<PathBuf, DataError> {
    if !matches!(format, AnnotationFormat::Mot | AnnotationFormat::CocoVideo) {
        return Err(DataError::invalid(
            out,
            "format",
            format!(
                "{} cannot be written (export writes mot, coco-video or coco)",
                format.name()
            ),
        ));
    }
    let mut by_video: BTreeMap<u32, Vec<&FrameRecord>> = BTreeMap::new();
    for f in ds
        .frames
        .iter()
        .filter(|f| split.is_none_or(|s| f.split == s))
    {
        by_video.entry(f.video).or_default().push(f);
    }
    if by_video.is_empty() {
        return Err(DataError::Empty {
            path: ds.root.clone(),
            reason: match split {
                Some(s) => format!("no frames in split {}", s.name()),
                None => "no frames".into(),
            },
        });
    }
    let classes: Vec<String> = ds.classes.iter().map(|c| c.name.clone()).collect();
    let partial = PartialDir::new(out)?;
    let mut names = std::collections::BTreeSet::new();
    let mut videos = Vec::with_capacity(by_video.len());
    for (id, mut frames) in by_video {
        frames.sort_by_key(|f| f.index);
        let meta = ds.video(id);
        let mut name = meta
            .and_then(|m| m.name.clone())
            .map(|n| n.replace(['/', '\\', '#'], "_"))
            .unwrap_or_else(|| format!("video{id:04}"));
        if !names.insert(name.clone()) {
            name = format!("{name}_{id:04}");
            names.insert(name.clone());
        }
        let mut video = AnnotatedVideo::new(&name);
        video.fps = meta.map(|m| m.fps());
        video.length = frames.last().map(|f| f.index + 1);
        (video.width, video.height) = (frames[0].width, frames[0].height);
        for f in &frames {
            let file = match format {
                AnnotationFormat::Mot => {
                    let ext = f.file.extension().and_then(|e| e.to_str()).unwrap_or("png");
                    format!("img1/{:06}.{ext}", f.index + 1)
                }
                _ => f.file.to_string_lossy().replace('\\', "/"),
            };
            let dst = match format {
                AnnotationFormat::Mot => partial.path().join(&name).join(&file),
                _ => partial.path().join(&file),
            };
            link_or_copy(&ds.frame_path(f), &dst)?;
            video.frames.insert(
                f.index,
                AnnotatedFrame {
                    file: Some(file),
                    boxes: frame_boxes(f, ds.classes.len()),
                },
            );
        }
        videos.push(video);
    }
    let ann = VideoAnnotations {
        format,
        classes,
        videos,
    };
    let result = match format {
        AnnotationFormat::Mot => {
            for v in &ann.videos {
                let gt = partial.path().join(&v.name).join("gt");
                std::fs::create_dir_all(&gt).map_err(|e| DataError::io(&gt, e))?;
                annotations::write_mot(v, &ann.classes, &gt.join("gt.txt"))?;
            }
            out.to_owned()
        }
        _ => {
            annotations::write_coco_video(&ann, &partial.path().join("annotations.json"))?;
            out.join("annotations.json")
        }
    };
    partial.commit()?;
    Ok(result)
}

/// A frame's objects, then its ignore regions (one per class for a region of any).
fn frame_boxes(f: &FrameRecord, classes: usize) -> Vec<AnnotatedBox> {
    let mut boxes: Vec<AnnotatedBox> = f
        .objects
        .iter()
        .map(|o| AnnotatedBox::new(usize::from(o.class), o.bbox))
        .collect();
    for r in &f.ignore {
        let of: Vec<usize> = match r.class {
            Some(c) => vec![usize::from(c)],
            None => (0..classes).collect(),
        };
        for class in of {
            boxes.push(AnnotatedBox {
                ignore: true,
                ..AnnotatedBox::new(class, r.bbox)
            });
        }
    }
    boxes
}

fn link_or_copy(src: &Path, dst: &Path) -> Result<(), DataError> {
    if let Some(parent) = dst.parent() {
        std::fs::create_dir_all(parent).map_err(|e| DataError::io(parent, e))?;
    }
    if std::fs::hard_link(src, dst).is_err() {
        std::fs::copy(src, dst).map_err(|e| DataError::io(src, e))?;
    }
    Ok(())
}
