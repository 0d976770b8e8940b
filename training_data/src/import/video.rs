//! Import of video annotation formats (MOT Challenge, CVAT for video, COCO with videos,
//! ImageNet VID; see [`annotations`](mod@crate::annotations)) with their frames.
//!
//! Where the frames come from:
//! - `video` given: a video file (decoded by the `ffmpeg` program, see
//!   [`media`](mod@crate::media)) or a folder of images in name order; the annotations
//!   must then describe one video;
//! - else the images the annotations name (COCO with videos, ImageNet VID), relative to
//!   `images` (default: the annotation file's folder);
//! - else, for MOT, the sequence's `img1/` folder next to `gt/`.
//!
//! Frames are streamed: decoded, checked, encoded (JPEG, quality 95: the source is
//! lossy already, and a PNG of every 720p frame would take 20 times the space) and
//! written a few at a time, never all held. Each kept frame carries its presentation
//! time; boxes are in the source's pixels.
//!
//! Splits: `split` puts everything in one; otherwise a `time_split` (fractions for
//! train, val, test) cuts each source video into three consecutive parts, each a video
//! of the dataset named `<video>#<first>-<last>` by its source frame indices, with
//! times from the part's start; without either, sets of three or more videos are split
//! by video hash and smaller ones by time, 70 / 15 / 15.
use super::{ImportCounts, ImportOptions, collect_videos, hashed_split, place_box};
use crate::annotations::{self, AnnotatedVideo, AnnotationFormat, ReadOptions};
use crate::dataset::PartialDir;
use crate::media::{DecodedFrame, FrameSource};
use crate::{ClassId, DataError, Dataset, FrameRecord, IgnoreRegion, Object, Split, VideoMeta};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// The time split used when a set has fewer than three videos and no split is given.
pub const DEFAULT_TIME_SPLIT: [f64; 3] = [0.70, 0.15, 0.15];

/// Frames decoded before they are encoded and written in parallel.
const BATCH: usize = 16;

/// One frame written to the partial folder, before splits are assigned.
struct Written {
    index: u32,
    time_s: f64,
    file: PathBuf,
    width: u32,
    height: u32,
    objects: Vec<Object>,
    ignore: Vec<IgnoreRegion>,
}

/// Import `opts.input` in a video annotation `format` into `out`.
pub(crate) fn import_video(
    opts: &ImportOptions,
    format: AnnotationFormat,
    out: &Path,
) -> Result<Dataset, DataError> {
    let read = ReadOptions {
        default_class: opts.default_class.clone(),
        min_visibility: opts.min_visibility,
        ..ReadOptions::default()
    };
    let ann = annotations::read(format, &opts.input, &read)?;
    if ann.videos.is_empty() {
        return Err(DataError::Empty {
            path: opts.input.clone(),
            reason: "no video".into(),
        });
    }
    if opts.video.is_some() && ann.videos.len() != 1 {
        return Err(DataError::invalid(
            &opts.input,
            "videos",
            format!(
                "describes {} videos, but one video file or folder was given; give the image root instead",
                ann.videos.len()
            ),
        ));
    }
    let mut table = super::ClassTable::new(&opts.classes, &opts.class_map, opts.drop_unmapped);
    // the classes some kept box uses, in the order the source declares them (a format's
    // whole vocabulary, such as MOT's twelve classes, is not the data's class list)
    let mut used = vec![false; ann.classes.len()];
    for b in ann
        .videos
        .iter()
        .flat_map(|v| v.frames.values())
        .flat_map(|f| &f.boxes)
        .filter(|b| !b.ignore)
    {
        if let Some(u) = used.get_mut(b.class) {
            *u = true;
        }
    }
    let mut class_of: Vec<Option<ClassId>> = Vec::with_capacity(ann.classes.len());
    for (name, used) in ann.classes.iter().zip(used) {
        class_of.push(if used {
            table.resolve(&opts.input, &format!("class {name:?}"), name, None)?
        } else {
            None
        });
    }
    let classes = table.finish(&opts.actions, &opts.input)?;

    let partial = PartialDir::new(out)?;
    let dir = partial.path().to_owned();
    let mut counts = ImportCounts::default();
    let mut sources: Vec<(String, Option<f64>, Vec<Written>)> = Vec::new();
    for (vi, video) in ann.videos.iter().enumerate() {
        let staging = PathBuf::from(format!("staging/s{vi:04}"));
        std::fs::create_dir_all(dir.join(&staging)).map_err(|e| DataError::io(&dir, e))?;
        let (written, fps) =
            read_video(opts, format, video, &class_of, &dir, &staging, &mut counts)?;
        sources.push((video.name.clone(), fps, written));
    }
    if sources.iter().all(|(_, _, w)| w.is_empty()) {
        return Err(DataError::Empty {
            path: opts.input.clone(),
            reason: "no frame could be read".into(),
        });
    }

    // Splits and final places.
    let by_time = opts.split.is_none() && (opts.time_split.is_some() || sources.len() < 3);
    let fractions = opts.time_split.unwrap_or(DEFAULT_TIME_SPLIT);
    let mut frames = Vec::new();
    let mut metas: Vec<VideoMeta> = Vec::new();
    for (vi, (name, fps, written)) in sources.into_iter().enumerate() {
        let parts: Vec<(Split, Vec<Written>)> = if by_time {
            cut(written, fractions)
        } else {
            let split = opts.split.unwrap_or_else(|| hashed_split(vi as u32));
            vec![(split, written)]
        };
        let whole = parts.len() == 1;
        for (split, part) in parts {
            let (Some(first), Some(last)) = (part.first(), part.last()) else {
                continue;
            };
            let id = metas.len() as u32;
            let t0 = first.time_s;
            metas.push(VideoMeta {
                id,
                seed: 0,
                clutter: opts.clutter,
                light: opts.light,
                split,
                frames: 0,
                name: Some(if whole {
                    name.clone()
                } else {
                    format!("{name}#{}-{}", first.index, last.index)
                }),
                fps,
            });
            for (k, w) in part.into_iter().enumerate() {
                let file = PathBuf::from(format!("frames/v{id:04}/{k:06}.jpg"));
                let to = dir.join(&file);
                if let Some(parent) = to.parent() {
                    std::fs::create_dir_all(parent).map_err(|e| DataError::io(parent, e))?;
                }
                std::fs::rename(dir.join(&w.file), &to).map_err(|e| DataError::io(&to, e))?;
                frames.push(FrameRecord {
                    id: frames.len() as u64,
                    file,
                    width: w.width,
                    height: w.height,
                    video: id,
                    index: k as u32,
                    split,
                    objects: w.objects,
                    ignore: w.ignore,
                    // microseconds: the precision of video timestamps, and a value
                    // that survives the JSON round trip unchanged
                    time_s: Some(((w.time_s - t0) * 1e6).round() / 1e6),
                });
            }
        }
    }
    let _ = std::fs::remove_dir_all(dir.join("staging"));
    let videos = collect_videos(&frames, &opts.input, |f| metas[f.video as usize].clone())?;
    let source = super::imported(format.name(), &opts.input, counts);
    super::finish(partial, out, classes, videos, frames, source)
}

/// Consecutive parts of a video's frames: `fractions` of its frames for train, val and
/// test (rounded; empty parts are left out).
fn cut(frames: Vec<Written>, fractions: [f64; 3]) -> Vec<(Split, Vec<Written>)> {
    let n = frames.len();
    let total: f64 = fractions.iter().sum();
    let train = ((n as f64 * fractions[0] / total).round() as usize).min(n);
    let val = ((n as f64 * fractions[1] / total).round() as usize).min(n - train);
    let mut train_part = frames;
    let test_part = train_part.split_off(train + val);
    let val_part = train_part.split_off(train);
    let mut parts = vec![
        (Split::Train, train_part),
        (Split::Val, val_part),
        (Split::Test, test_part),
    ];
    parts.retain(|(_, p)| !p.is_empty());
    parts
}

/// Where one annotated video's frames come from.
enum Frames {
    /// A video file or an image folder.
    Stream(Box<FrameSource>),
    /// Image files the annotations name, with their frame indices.
    Files(Vec<(u32, PathBuf)>),
}

fn frames_of(
    opts: &ImportOptions,
    format: AnnotationFormat,
    video: &AnnotatedVideo,
) -> Result<Frames, DataError> {
    let fps = opts.fps.or(video.fps);
    if let Some(path) = &opts.video {
        return Ok(Frames::Stream(Box::new(FrameSource::open(
            path,
            fps,
            &opts.sampling,
        )?)));
    }
    let named: Vec<(u32, &String)> = video
        .frames
        .iter()
        .filter_map(|(&i, f)| f.file.as_ref().map(|file| (i, file)))
        .collect();
    if !named.is_empty() {
        // MOT names images relative to the sequence folder (`seqinfo.ini`'s `imDir`),
        // the other formats relative to the annotation file
        let mot_seq = (format == AnnotationFormat::Mot)
            .then(|| crate::annotations::mot::seqinfo_path(&opts.input))
            .flatten()
            .and_then(|ini| ini.parent().map(Path::to_owned));
        let root = match (&opts.images, mot_seq) {
            (Some(r), _) => r.clone(),
            (None, Some(seq)) => seq,
            (None, None) => opts.input.parent().map(Path::to_owned).unwrap_or_default(),
        };
        return Ok(Frames::Files(
            named.into_iter().map(|(i, f)| (i, root.join(f))).collect(),
        ));
    }
    if format == AnnotationFormat::Mot {
        // <seq>/gt/gt.txt → <seq>/img1
        let img1 = opts
            .input
            .parent()
            .and_then(Path::parent)
            .map(|seq| seq.join("img1"))
            .filter(|p| p.is_dir());
        if let Some(img1) = img1 {
            let fps = fps.or(Some(crate::DEFAULT_FPS));
            return Ok(Frames::Stream(Box::new(FrameSource::open(
                &img1,
                fps,
                &opts.sampling,
            )?)));
        }
    }
    Err(DataError::invalid(
        &opts.input,
        format!("video {:?}", video.name),
        "names no image files: give the video file or image folder (--video)",
    ))
}

/// Read, check and stage one annotated video's frames; returns them in source order
/// and the video's frame rate.
fn read_video(
    opts: &ImportOptions,
    format: AnnotationFormat,
    video: &AnnotatedVideo,
    class_of: &[Option<ClassId>],
    dir: &Path,
    staging: &Path,
    counts: &mut ImportCounts,
) -> Result<(Vec<Written>, Option<f64>), DataError> {
    let source = frames_of(opts, format, video)?;
    let (fps, total) = match &source {
        Frames::Stream(s) => (Some(s.info().fps), s.info().frames),
        Frames::Files(f) => (opts.fps.or(video.fps), Some(f.len() as u64)),
    };
    let bar = if opts.progress {
        ProgressBar::new(total.unwrap_or(0))
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("import {msg} [{bar:30}] {pos}/{len} frames ({per_sec})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message(video.name.clone());
    let mut written = Vec::new();
    let mut batch: Vec<DecodedFrame> = Vec::with_capacity(BATCH);
    let mut last_index = None;
    let flush = |batch: &mut Vec<DecodedFrame>,
                 written: &mut Vec<Written>,
                 counts: &mut ImportCounts|
     -> Result<(), DataError> {
        let done: Vec<Result<(Written, ImportCounts), DataError>> = batch
            .par_drain(..)
            .map(|f| stage(opts, video, class_of, dir, staging, f))
            .collect();
        for d in done {
            let (w, c) = d?;
            counts.clipped_boxes += c.clipped_boxes;
            counts.ignored_boxes += c.ignored_boxes;
            written.push(w);
        }
        bar.set_position(written.len() as u64);
        Ok(())
    };
    match source {
        Frames::Stream(stream) => {
            for frame in *stream {
                let frame = frame?;
                last_index = Some(frame.index);
                batch.push(frame);
                if batch.len() == BATCH {
                    flush(&mut batch, &mut written, counts)?;
                }
            }
        }
        Frames::Files(files) => {
            let fps = fps.unwrap_or(crate::DEFAULT_FPS);
            for (index, path) in files {
                if !path.is_file() {
                    if opts.strict {
                        return Err(DataError::MissingImage {
                            path: opts.input.clone(),
                            record: format!("video {:?} frame {index}", video.name),
                            image: path,
                        });
                    }
                    counts.missing_images += 1;
                    continue;
                }
                let image = image::open(&path)
                    .map_err(|e| DataError::image(&path, e))?
                    .to_rgb8();
                last_index = Some(u64::from(index));
                batch.push(DecodedFrame {
                    index: u64::from(index),
                    time_s: f64::from(index) / fps,
                    image,
                });
                if batch.len() == BATCH {
                    flush(&mut batch, &mut written, counts)?;
                }
            }
        }
    }
    flush(&mut batch, &mut written, counts)?;
    bar.finish_and_clear();
    // Boxes on frames past the video's end are an annotation error (a window or a
    // sampling that stops early is not).
    let annotated_last = video
        .frames
        .iter()
        .filter(|(_, f)| !f.boxes.is_empty())
        .map(|(&i, _)| i)
        .max();
    let length = total.or(last_index.map(|i| i + 1));
    if let (Some(a), Some(n)) = (annotated_last, length)
        && opts.sampling.end_s.is_none()
        && u64::from(a) >= n
        && !matches!(
            format,
            AnnotationFormat::CocoVideo | AnnotationFormat::ImagenetVid
        )
    {
        return Err(DataError::invalid(
            &opts.input,
            format!(
                "frame {} (0-based {a})",
                u64::from(a) + u64::from(format == AnnotationFormat::Mot)
            ),
            format!("has boxes, but video {:?} has only {n} frames", video.name),
        ));
    }
    Ok((written, fps))
}

/// Check one decoded frame's boxes against it, and encode and write it.
fn stage(
    opts: &ImportOptions,
    video: &AnnotatedVideo,
    class_of: &[Option<ClassId>],
    dir: &Path,
    staging: &Path,
    frame: DecodedFrame,
) -> Result<(Written, ImportCounts), DataError> {
    let (w, h) = frame.image.dimensions();
    let index = u32::try_from(frame.index).map_err(|_| {
        DataError::invalid(&opts.input, "frames", "more than 2^32 frames in one video")
    })?;
    if video.width > 0 && video.height > 0 && (video.width, video.height) != (w, h) {
        return Err(DataError::invalid(
            &opts.input,
            format!("video {:?}", video.name),
            format!(
                "declares {}x{} but its frames are {w}x{h}",
                video.width, video.height
            ),
        ));
    }
    let mut counts = ImportCounts::default();
    let mut objects = Vec::new();
    let mut ignore = Vec::new();
    if let Some(f) = video.frames.get(&index) {
        for (k, b) in f.boxes.iter().enumerate() {
            let record = format!(
                "video {:?} frame {index} box {}{}",
                video.name,
                k + 1,
                b.track.map_or(String::new(), |t| format!(" (track {t})"))
            );
            let bbox = place_box(&opts.input, &record, b.bbox, w, h, &mut counts)?;
            if b.ignore {
                // of a kept class: excuses that class's detections; of any other (MOT's
                // distractors): any detection, as the MOT devkit drops them
                counts.ignored_boxes += 1;
                ignore.push(IgnoreRegion {
                    class: class_of.get(b.class).copied().flatten(),
                    bbox,
                });
                continue;
            }
            if let Some(class) = class_of.get(b.class).copied().flatten() {
                objects.push(Object { class, bbox });
            }
        }
    }
    let file = staging.join(format!("{index:06}.jpg"));
    let path = dir.join(&file);
    let mut bytes = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 95)
        .encode_image(&frame.image)
        .map_err(|e| DataError::image(&path, e))?;
    std::fs::write(&path, bytes).map_err(|e| DataError::io(&path, e))?;
    Ok((
        Written {
            index,
            time_s: frame.time_s,
            file,
            width: w,
            height: h,
            objects,
            ignore,
        },
        counts,
    ))
}
