//! COCO JSON with videos, in its two common styles.
//!
//! - **TAO style** (also mmtracking's CocoVID, BDD100K MOT, …): `videos` `{id, name,
//!   width, height, (length), (fps)}`; `images` `{id, video_id, frame_id |
//!   frame_index, file_name, width, height}` with a **0-based** frame index;
//!   `annotations` `{id, image_id, (video_id), category_id, bbox: [x, y, w, h],
//!   (track_id | instance_id), (iscrowd), (ignore), (segmentation)}`.
//! - **YouTube-VIS style**: `videos` `{id, width, height, length, file_names: [...]}`
//!   (frame `k` is `file_names[k]`) and `annotations` `{id, video_id, category_id,
//!   iscrowd, bboxes: [[x, y, w, h] | null, …]}` with one entry per frame (`null`:
//!   not in that frame); the annotation `id` is the track.
//!
//! An annotation with `image_id` is TAO style, one with `bboxes` (or only
//! `segmentations`) YouTube-VIS style; both may be in one file. Boxes are
//! `[x, y, w, h]` in pixels, `x2 = x + w` (exclusive). As in pycocotools:
//! - category id 0 is an ordinary id; the class list is the categories in id order
//!   (class index = position in that order, not the id);
//! - `iscrowd: 1` (or a true `ignore`) makes the box an ignore region;
//! - without `bbox`, a polygon `segmentation` gives the polygon's bounding box
//!   (min / max of its points); an RLE segmentation without `bbox` is an error.
//!
//! Extras written by [`write_coco_video`](super::write_coco_video) are read back:
//! `occluded` (bool) and `visibility` (number) on annotations. Frames are the images
//! (and `file_names`), so frames without boxes are kept; `file` is the `file_name`.
//!
//! Errors name the id: duplicate video, image, annotation or category ids, an image of
//! an unknown video or without frame index, two images at one frame, an annotation of
//! an unknown image, video or category, a `bbox` that is not 4 numbers or has a
//! negative size, `bboxes` of the wrong length, a frame past the video's `length` or
//! [`ReadOptions::length`]. A JSON file without `videos` is plain COCO, not this.
use super::{
    AnnotatedBox, AnnotatedFrame, AnnotatedVideo, AnnotationFormat, Limit, ReadOptions,
    VideoAnnotations, read_text,
};
use crate::{BBox, DataError};
use serde::Deserialize;
use serde_json::Value;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

#[derive(Deserialize)]
struct RawFile {
    videos: Option<Vec<RawVideo>>,
    #[serde(default)]
    images: Vec<RawImage>,
    #[serde(default)]
    annotations: Vec<RawAnnotation>,
    #[serde(default)]
    categories: Vec<RawCategory>,
}

#[derive(Deserialize)]
struct RawVideo {
    id: u64,
    name: Option<String>,
    width: Option<u32>,
    height: Option<u32>,
    length: Option<u32>,
    fps: Option<f64>,
    file_names: Option<Vec<String>>,
}

#[derive(Deserialize)]
struct RawImage {
    id: u64,
    video_id: Option<u64>,
    frame_id: Option<u32>,
    frame_index: Option<u32>,
    file_name: Option<String>,
    width: Option<u32>,
    height: Option<u32>,
}

#[derive(Deserialize)]
struct RawAnnotation {
    id: Option<u64>,
    image_id: Option<u64>,
    video_id: Option<u64>,
    category_id: u64,
    bbox: Option<Value>,
    bboxes: Option<Vec<Value>>,
    segmentation: Option<Value>,
    segmentations: Option<Vec<Value>>,
    track_id: Option<u64>,
    instance_id: Option<u64>,
    iscrowd: Option<Value>,
    ignore: Option<Value>,
    occluded: Option<Value>,
    visibility: Option<f64>,
}

#[derive(Deserialize)]
struct RawCategory {
    id: u64,
    name: String,
}

/// `1`, `true` (and any non-zero number) are true.
fn truthy(v: Option<&Value>) -> bool {
    match v {
        Some(Value::Bool(b)) => *b,
        Some(Value::Number(n)) => n.as_f64().is_some_and(|x| x != 0.0),
        _ => false,
    }
}

/// A box from `bbox` (`[x, y, w, h]`), else from a polygon segmentation.
fn to_box(
    path: &Path,
    record: &str,
    bbox: Option<&Value>,
    seg: Option<&Value>,
) -> Result<Option<BBox>, DataError> {
    let bad = |problem: String| DataError::invalid(path, record, problem);
    match bbox {
        Some(Value::Null) | None => {}
        Some(v) => {
            let xs: Option<Vec<f64>> = v
                .as_array()
                .filter(|a| a.len() == 4)
                .map(|a| a.iter().filter_map(Value::as_f64).collect());
            let Some([x, y, w, h]) = xs.and_then(|xs| <[f64; 4]>::try_from(xs).ok()) else {
                return Err(bad(format!("bbox {v} is not [x, y, w, h]")));
            };
            if w < 0.0 || h < 0.0 {
                return Err(bad(format!("bbox {v} has a negative width or height")));
            }
            return Ok(Some(BBox::new(
                x as f32,
                y as f32,
                (x + w) as f32,
                (y + h) as f32,
            )));
        }
    }
    match seg {
        None | Some(Value::Null) => Ok(None),
        Some(Value::Object(_)) => Err(bad(
            "RLE segmentation without bbox: its box is not read (add a bbox)".into(),
        )),
        Some(Value::Array(polys)) => {
            let (mut x1, mut y1, mut x2, mut y2) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
            for poly in polys {
                let pts: Vec<f64> = poly
                    .as_array()
                    .map(|a| a.iter().filter_map(Value::as_f64).collect())
                    .unwrap_or_default();
                let n = poly.as_array().map_or(0, Vec::len);
                if pts.len() != n || n < 2 || n % 2 != 0 {
                    return Err(bad(format!(
                        "segmentation polygon {poly} is not a list of x, y pairs"
                    )));
                }
                for p in pts.chunks_exact(2) {
                    (x1, y1, x2, y2) = (x1.min(p[0]), y1.min(p[1]), x2.max(p[0]), y2.max(p[1]));
                }
            }
            if polys.is_empty() {
                return Err(bad("empty segmentation and no bbox".into()));
            }
            Ok(Some(BBox::new(x1 as f32, y1 as f32, x2 as f32, y2 as f32)))
        }
        Some(v) => Err(bad(format!("segmentation {v} is neither polygons nor RLE"))),
    }
}

/// Read a COCO-with-videos JSON file (see the module documentation).
pub(crate) fn read(path: &Path, opts: &ReadOptions) -> Result<VideoAnnotations, DataError> {
    let text = read_text(path)?;
    let raw: RawFile = serde_json::from_str(&text).map_err(|e| DataError::json(path, e))?;
    let Some(raw_videos) = raw.videos else {
        return Err(DataError::invalid(
            path,
            "top level",
            "no \"videos\" list: this is plain COCO (images only), not COCO with videos",
        ));
    };

    let mut categories: Vec<&RawCategory> = raw.categories.iter().collect();
    categories.sort_by_key(|c| c.id);
    for w in categories.windows(2) {
        if w[0].id == w[1].id {
            return Err(DataError::invalid(
                path,
                format!("category id {}", w[1].id),
                "appears twice",
            ));
        }
    }
    let class_of: HashMap<u64, usize> = categories
        .iter()
        .enumerate()
        .map(|(i, c)| (c.id, i))
        .collect();
    let classes: Vec<String> = categories.iter().map(|c| c.name.clone()).collect();

    let mut videos = Vec::with_capacity(raw_videos.len());
    let mut video_of: HashMap<u64, usize> = HashMap::new();
    let mut limits = Vec::with_capacity(raw_videos.len());
    for v in &raw_videos {
        let record = format!("video id {}", v.id);
        if video_of.insert(v.id, videos.len()).is_some() {
            return Err(DataError::invalid(path, record, "appears twice"));
        }
        let name = v.name.clone().unwrap_or_else(|| {
            v.file_names
                .as_ref()
                .and_then(|f| f.first())
                .and_then(|f| f.rsplit_once('/'))
                .map_or_else(|| format!("video_{}", v.id), |(dir, _)| dir.to_owned())
        });
        let mut video = AnnotatedVideo {
            name,
            width: v.width.unwrap_or(0),
            height: v.height.unwrap_or(0),
            length: v.length,
            fps: v.fps,
            frames: BTreeMap::new(),
        };
        let limit = Limit::new(opts, v.length, "the video's length");
        for (k, f) in v.file_names.iter().flatten().enumerate() {
            let k = u32::try_from(k).unwrap_or(u32::MAX);
            Limit::check(limit, path, &record, k, u64::from(k))?;
            video.frames.insert(
                k,
                AnnotatedFrame {
                    file: Some(f.clone()),
                    boxes: Vec::new(),
                },
            );
        }
        videos.push(video);
        limits.push(limit);
    }

    // Images: (video index, frame index) by image id.
    let mut image_at: HashMap<u64, (usize, u32)> = HashMap::new();
    let mut image_of_frame: HashMap<(usize, u32), u64> = HashMap::new();
    for img in &raw.images {
        let record = format!("image id {}", img.id);
        let vid = img.video_id.ok_or_else(|| {
            DataError::invalid(
                path,
                &record,
                "has no video_id (a COCO-video image belongs to a video)",
            )
        })?;
        let &v = video_of.get(&vid).ok_or_else(|| {
            DataError::invalid(path, &record, format!("video id {vid} does not exist"))
        })?;
        let frame = match (img.frame_id, img.frame_index) {
            (Some(a), Some(b)) if a != b => {
                return Err(DataError::invalid(
                    path,
                    &record,
                    format!("frame_id {a} and frame_index {b} disagree"),
                ));
            }
            (Some(a), _) | (None, Some(a)) => a,
            (None, None) => {
                return Err(DataError::invalid(
                    path,
                    &record,
                    "has neither frame_id nor frame_index",
                ));
            }
        };
        Limit::check(limits[v], path, &record, frame, u64::from(frame))?;
        if image_at.insert(img.id, (v, frame)).is_some() {
            return Err(DataError::invalid(path, &record, "appears twice"));
        }
        if let Some(other) = image_of_frame.insert((v, frame), img.id) {
            return Err(DataError::invalid(
                path,
                &record,
                format!("frame {frame} of video id {vid} is also image id {other}"),
            ));
        }
        let video = &mut videos[v];
        if video.width == 0 && video.height == 0 {
            video.width = img.width.unwrap_or(0);
            video.height = img.height.unwrap_or(0);
        }
        let slot = video.frames.entry(frame).or_default();
        match (&slot.file, &img.file_name) {
            (Some(a), Some(b)) if a != b => {
                return Err(DataError::invalid(
                    path,
                    &record,
                    format!(
                        "file_name {b:?} but the video's file_names has {a:?} at frame {frame}"
                    ),
                ));
            }
            (_, Some(b)) => slot.file = Some(b.clone()),
            _ => {}
        }
    }

    let mut ann_ids: HashMap<u64, usize> = HashMap::new();
    for (n, a) in raw.annotations.iter().enumerate() {
        let id = a.id.ok_or_else(|| {
            DataError::invalid(path, format!("annotation #{}", n + 1), "has no id")
        })?;
        let record = format!("annotation id {id}");
        if ann_ids.insert(id, n).is_some() {
            return Err(DataError::invalid(
                path,
                &record,
                "appears twice (annotation ids must be unique)",
            ));
        }
        let &class = class_of.get(&a.category_id).ok_or_else(|| {
            DataError::invalid(
                path,
                &record,
                format!("category id {} does not exist", a.category_id),
            )
        })?;
        let make = |bbox: BBox| AnnotatedBox {
            class,
            track: a.track_id.or(a.instance_id),
            bbox,
            ignore: truthy(a.iscrowd.as_ref()) || truthy(a.ignore.as_ref()),
            visibility: a.visibility.map(|v| v as f32),
            occluded: truthy(a.occluded.as_ref()),
        };
        if let Some(image) = a.image_id {
            let &(v, frame) = image_at.get(&image).ok_or_else(|| {
                DataError::invalid(path, &record, format!("image id {image} does not exist"))
            })?;
            if let Some(vid) = a.video_id
                && video_of.get(&vid) != Some(&v)
            {
                return Err(DataError::invalid(
                    path,
                    &record,
                    format!("video id {vid} is not the video of image id {image}"),
                ));
            }
            let bbox = to_box(path, &record, a.bbox.as_ref(), a.segmentation.as_ref())?
                .ok_or_else(|| {
                    DataError::invalid(path, &record, "has neither bbox nor segmentation")
                })?;
            let b = make(bbox);
            videos[v].frames.entry(frame).or_default().boxes.push(b);
            continue;
        }
        // YouTube-VIS style: one entry per frame of the video.
        let vid = a.video_id.ok_or_else(|| {
            DataError::invalid(path, &record, "has neither image_id nor video_id")
        })?;
        let &v = video_of.get(&vid).ok_or_else(|| {
            DataError::invalid(path, &record, format!("video id {vid} does not exist"))
        })?;
        let per_frame: Vec<(Option<&Value>, Option<&Value>)> = match (&a.bboxes, &a.segmentations) {
            (Some(b), s) => b
                .iter()
                .enumerate()
                .map(|(k, b)| (Some(b), s.as_ref().and_then(|s| s.get(k))))
                .collect(),
            (None, Some(s)) => s.iter().map(|s| (None, Some(s))).collect(),
            (None, None) => {
                return Err(DataError::invalid(
                    path,
                    &record,
                    "has no image_id, bboxes or segmentations",
                ));
            }
        };
        let frames = raw_videos[v]
            .file_names
            .as_ref()
            .map(Vec::len)
            .or(raw_videos[v].length.map(|l| l as usize));
        if let Some(n) = frames
            && n != per_frame.len()
        {
            return Err(DataError::invalid(
                path,
                &record,
                format!(
                    "has {} per-frame boxes but video id {vid} has {n} frames",
                    per_frame.len()
                ),
            ));
        }
        let track = a.track_id.or(a.instance_id).unwrap_or(id);
        for (k, (bbox, seg)) in per_frame.into_iter().enumerate() {
            let k = u32::try_from(k).unwrap_or(u32::MAX);
            let frame_record = format!("{record} frame {k}");
            if let Some(bbox) = to_box(path, &frame_record, bbox, seg)? {
                Limit::check(limits[v], path, &frame_record, k, u64::from(k))?;
                let mut b = make(bbox);
                b.track = Some(track);
                videos[v].frames.entry(k).or_default().boxes.push(b);
            }
        }
    }
    Ok(VideoAnnotations {
        format: AnnotationFormat::CocoVideo,
        classes,
        videos,
    })
}
