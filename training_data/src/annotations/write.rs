//! Writers: MOT Challenge 9-column `gt.txt` and TAO-style COCO with videos. Both are
//! written through a temporary file and a rename, and read back equal to what was
//! written (see each function for what the format cannot hold).
use super::mot::{MOT_CLASSES, labels_path, seqinfo_path};
use super::{AnnotatedVideo, VideoAnnotations};
use crate::dataset::{write_atomic, write_json_atomic};
use crate::{BBox, DataError};
use serde::Serialize;
use std::collections::HashSet;
use std::fmt::Write as _;
use std::path::Path;

/// `v` as the f64 a reader parses from its shortest decimal (`0.1f32` → `0.1`), which
/// converts back to `v` exactly.
fn short(v: f32) -> f64 {
    let t: f64 = v.to_string().parse().unwrap_or(f64::from(v));
    if t as f32 == v { t } else { f64::from(v) }
}

/// A size `w` such that a reader's `(x + w) as f32` (in f64) is exactly `edge`,
/// written as briefly as possible (`121`, not `120.99999237060547`).
fn extent(x: f64, edge: f32) -> f64 {
    let brief = short(edge - x as f32);
    if (x + brief) as f32 == edge {
        return brief;
    }
    let mut w = f64::from(edge) - x;
    // f64 has 29 more bits than f32: a few steps always land inside edge's rounding.
    for _ in 0..64 {
        match ((x + w) as f32).partial_cmp(&edge) {
            Some(std::cmp::Ordering::Less) => w = w.next_up(),
            Some(std::cmp::Ordering::Greater) => w = w.next_down(),
            _ => break,
        }
    }
    w
}

/// `[x, y, w, h]` of a box that reads back exactly, or why it cannot be written.
fn xywh(bbox: BBox) -> Result<[f64; 4], String> {
    let BBox { x1, y1, x2, y2 } = bbox;
    if ![x1, y1, x2, y2].iter().all(|v| v.is_finite()) {
        return Err(format!("box {bbox:?} is not finite"));
    }
    if x2 < x1 || y2 < y1 {
        return Err(format!("box {bbox:?} has a negative width or height"));
    }
    let (x, y) = (short(x1), short(y1));
    Ok([x, y, extent(x, x2), extent(y, y2)])
}

/// `<dir>` and `<ext>` when every frame's file is `<dir>/<frame:06><ext>` (MOT's
/// `imDir` / `imExt`, frame 1-based).
fn image_pattern(video: &AnnotatedVideo) -> Option<(String, String)> {
    let mut pattern: Option<(String, String)> = None;
    for (&k, frame) in &video.frames {
        let file = frame.file.as_deref()?;
        let (dir, base) = file.rsplit_once('/').unwrap_or(("", file));
        let ext = base.strip_prefix(&format!("{:06}", u64::from(k) + 1))?;
        if !ext.starts_with('.') {
            return None;
        }
        match &pattern {
            None => pattern = Some((dir.to_owned(), ext.to_owned())),
            Some((d, e)) if d == dir && e == ext => {}
            Some(_) => return None,
        }
    }
    pattern
}

/// A value that must fit on one line of a text file.
fn one_line(path: &Path, record: &str, s: &str) -> Result<(), DataError> {
    if s.contains(['\n', '\r']) || s.trim() != s || s.is_empty() {
        return Err(DataError::invalid(
            path,
            record,
            format!("{s:?} cannot be written (empty, line break or surrounding spaces)"),
        ));
    }
    Ok(())
}

/// Write one video as a MOT Challenge 9-column `gt.txt`
/// (`frame,id,x,y,w,h,flag,class,visibility`, see [`mot`](super::mot)).
///
/// - Frames are written 1-based; `id` is the track, `-1` without one; `flag` is 0 for
///   ignore regions, else 1; `visibility` is `-1` when unknown. Numbers are the
///   shortest decimals that read back to the same f32 box.
/// - Class column: when every name in `classes` is a MOT name, the MOT class id
///   (`car` = 3), so the MOT devkit reads the file. Otherwise the 1-based index into
///   `classes`. Either way `labels.txt` beside the file lists the names by id (the
///   12 MOT names, or `classes`), as CVAT and Datumaro write MOT.
/// - When the file is in a folder called `gt`, `../seqinfo.ini` is written too
///   (name, size, `seqLength`, `frameRate`, and `imDir` / `imExt` when every frame's
///   file is `<dir>/<frame:06><ext>`).
///
/// Read back (in the `<seq>/gt/` layout) the video is equal, except what MOT cannot
/// hold: frames without boxes, `occluded`, file names off the pattern, a distractor
/// box ([`MOT_DISTRACTORS`](super::MOT_DISTRACTORS)) not marked ignore (it reads back
/// ignored), and, when all names are MOT names but `classes` is not the MOT list,
/// the class indices (the names stay, indexed into the MOT list).
pub fn write_mot(video: &AnnotatedVideo, classes: &[String], path: &Path) -> Result<(), DataError> {
    let all_mot = classes.iter().all(|c| MOT_CLASSES.contains(&c.as_str()));
    let ids: Vec<usize> = classes
        .iter()
        .enumerate()
        .map(|(i, c)| match MOT_CLASSES.iter().position(|m| m == c) {
            Some(m) if all_mot => m + 1,
            _ => i + 1,
        })
        .collect();
    let mut out = String::new();
    let mut seen = HashSet::new();
    for (&k, frame) in &video.frames {
        if k == u32::MAX {
            return Err(DataError::invalid(
                path,
                format!("frame index {k}"),
                "too large for MOT's 1-based u32 frames",
            ));
        }
        for (i, b) in frame.boxes.iter().enumerate() {
            let record = format!("frame index {k} box {i}");
            let class = ids.get(b.class).ok_or_else(|| {
                DataError::invalid(
                    path,
                    &record,
                    format!(
                        "class {} is not one of the {} classes",
                        b.class,
                        classes.len()
                    ),
                )
            })?;
            let [x, y, w, h] = xywh(b.bbox).map_err(|p| DataError::invalid(path, &record, p))?;
            let track = match b.track {
                Some(t) if t > i64::MAX as u64 => {
                    return Err(DataError::invalid(
                        path,
                        &record,
                        format!("track {t} is too large"),
                    ));
                }
                Some(t) if !seen.insert((k, t)) => {
                    return Err(DataError::invalid(
                        path,
                        &record,
                        format!("track {t} has two boxes in this frame"),
                    ));
                }
                Some(t) => t.to_string(),
                None => "-1".to_owned(),
            };
            let visibility = match b.visibility {
                Some(v) if v.is_finite() && v >= 0.0 => short(v).to_string(),
                Some(v) => {
                    return Err(DataError::invalid(
                        path,
                        &record,
                        format!("visibility {v} is not a fraction"),
                    ));
                }
                None => "-1".to_owned(),
            };
            let flag = u8::from(!b.ignore);
            let _ = writeln!(
                out,
                "{},{track},{x},{y},{w},{h},{flag},{class},{visibility}",
                u64::from(k) + 1
            );
        }
    }
    let names: Vec<&str> = if all_mot {
        MOT_CLASSES.to_vec()
    } else {
        classes.iter().map(String::as_str).collect()
    };
    let labels = labels_path(path);
    let mut text = String::new();
    for (i, n) in names.iter().enumerate() {
        one_line(&labels, &format!("class {i}"), n)?;
        text.push_str(n);
        text.push('\n');
    }
    if let Some(ini) = seqinfo_path(path) {
        let mut s = String::from("[Sequence]\n");
        if !video.name.is_empty() {
            one_line(&ini, "name", &video.name)?;
            let _ = writeln!(s, "name={}", video.name);
        }
        let pattern = image_pattern(video);
        if let Some((dir, _)) = &pattern {
            let _ = writeln!(s, "imDir={dir}");
        }
        if let Some(fps) = video.fps {
            if !fps.is_finite() || fps <= 0.0 {
                return Err(DataError::invalid(
                    &ini,
                    "frameRate",
                    format!("{fps} is not a frame rate"),
                ));
            }
            let _ = writeln!(s, "frameRate={fps}");
        }
        if let Some(n) = video.length {
            let _ = writeln!(s, "seqLength={n}");
        }
        if video.width > 0 || video.height > 0 {
            let _ = writeln!(s, "imWidth={}\nimHeight={}", video.width, video.height);
        }
        if let Some((_, ext)) = &pattern {
            let _ = writeln!(s, "imExt={ext}");
        }
        write_atomic(&ini, s.as_bytes())?;
    }
    write_atomic(&labels, text.as_bytes())?;
    write_atomic(path, out.as_bytes())
}

#[derive(Serialize)]
struct OutFile<'a> {
    videos: Vec<OutVideo<'a>>,
    images: Vec<OutImage<'a>>,
    annotations: Vec<OutAnnotation>,
    categories: Vec<OutCategory<'a>>,
}

#[derive(Serialize)]
struct OutVideo<'a> {
    id: u64,
    name: &'a str,
    width: u32,
    height: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    length: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    fps: Option<f64>,
}

#[derive(Serialize)]
struct OutImage<'a> {
    id: u64,
    video_id: u64,
    frame_id: u32,
    frame_index: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    file_name: Option<&'a str>,
    width: u32,
    height: u32,
}

#[derive(Serialize)]
struct OutAnnotation {
    id: u64,
    image_id: u64,
    video_id: u64,
    category_id: u64,
    bbox: [f64; 4],
    area: f64,
    iscrowd: u8,
    #[serde(skip_serializing_if = "Option::is_none")]
    track_id: Option<u64>,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    occluded: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    visibility: Option<f64>,
}

#[derive(Serialize)]
struct OutCategory<'a> {
    id: u64,
    name: &'a str,
}

/// Write `ann` as TAO-style COCO with videos (see [`coco_video`](super::coco_video)).
///
/// Videos, images and annotations are numbered from 1 in order; `category_id` is the
/// class index + 1; every frame is an image with `frame_id` (and TAO's `frame_index`,
/// the same 0-based number) and its `file_name` when it has one; ignore regions are
/// `iscrowd: 1`; `track_id`, `occluded` (when true) and `visibility` (when known) are
/// written on annotations. Reading the file back gives `ann` again (with
/// `format: CocoVideo`).
pub fn write_coco_video(ann: &VideoAnnotations, path: &Path) -> Result<(), DataError> {
    let mut out = OutFile {
        videos: Vec::new(),
        images: Vec::new(),
        annotations: Vec::new(),
        categories: ann
            .classes
            .iter()
            .enumerate()
            .map(|(i, name)| OutCategory {
                id: i as u64 + 1,
                name,
            })
            .collect(),
    };
    for (vi, video) in ann.videos.iter().enumerate() {
        let video_id = vi as u64 + 1;
        if video.fps.is_some_and(|f| !f.is_finite()) {
            return Err(DataError::invalid(
                path,
                format!("video {:?}", video.name),
                "fps is not finite",
            ));
        }
        out.videos.push(OutVideo {
            id: video_id,
            name: &video.name,
            width: video.width,
            height: video.height,
            length: video.length,
            fps: video.fps,
        });
        for (&k, frame) in &video.frames {
            let image_id = out.images.len() as u64 + 1;
            out.images.push(OutImage {
                id: image_id,
                video_id,
                frame_id: k,
                frame_index: k,
                file_name: frame.file.as_deref(),
                width: video.width,
                height: video.height,
            });
            for (i, b) in frame.boxes.iter().enumerate() {
                let record = format!("video {:?} frame index {k} box {i}", video.name);
                if b.class >= ann.classes.len() {
                    return Err(DataError::invalid(
                        path,
                        &record,
                        format!(
                            "class {} is not one of the {} classes",
                            b.class,
                            ann.classes.len()
                        ),
                    ));
                }
                let bbox = xywh(b.bbox).map_err(|p| DataError::invalid(path, &record, p))?;
                let visibility = match b.visibility {
                    Some(v) if !v.is_finite() => {
                        return Err(DataError::invalid(
                            path,
                            &record,
                            "visibility is not finite",
                        ));
                    }
                    v => v.map(short),
                };
                out.annotations.push(OutAnnotation {
                    id: out.annotations.len() as u64 + 1,
                    image_id,
                    video_id,
                    category_id: b.class as u64 + 1,
                    bbox,
                    area: bbox[2] * bbox[3],
                    iscrowd: u8::from(b.ignore),
                    track_id: b.track,
                    occluded: b.occluded,
                    visibility,
                });
            }
        }
    }
    write_json_atomic(path, &out)
}
