//! CVAT for video 1.1 XML (`annotations.xml` of a task or job export).
//!
//! ```xml
//! <annotations><version>1.1</version>
//!   <meta><task><name>…</name><size>N</size>
//!     <labels><label><name>car</name>…</label>…</labels>
//!     <original_size><width>W</width><height>H</height></original_size></task></meta>
//!   <track id="0" label="car">
//!     <box frame="0" xtl="10" ytl="20" xbr="50" ybr="60" outside="0" occluded="0" keyframe="1"/>…
//!   </track>…
//! </annotations>
//! ```
//!
//! Frames are **0-based** task frames. `xtl ytl xbr ybr` are float pixel corners and
//! `xbr`/`ybr` are read as the exclusive right / bottom edges (CVAT draws a box from
//! `xtl` to `xbr`). A track's boxes expand into per-frame boxes exactly as CVAT does
//! (its `get_interpolated_shapes`):
//!
//! - every listed `<box>` is used as given, keyframe or not (exports that list the
//!   interpolated frames explicitly are taken at their word);
//! - between two consecutive listed boxes, when the first is not `outside`, each frame
//!   in between is interpolated linearly per coordinate (`p0 + (p1 - p0) · t`,
//!   `t = (f - f0) / (f1 - f0)`, in f64), taking `occluded` from the first box;
//! - a box with `outside="1"` hides the track from its frame until the next listed box;
//! - after the last box that is not outside, the track persists unchanged to the last
//!   frame of the task: `<size> - 1` for a task export, `<stop_frame>` for a job export
//!   (job frames are numbered as in their task; exact for tasks that start at frame 0
//!   with step 1), else [`ReadOptions::length`] - 1; a track that never ends in a file
//!   that declares none of these is an error.
//!
//! A file whose tracks expand to more than [`MAX_BOXES`] boxes (a corrupt `<size>` or
//! frame number) is an error rather than an exhausted memory.
//!
//! Classes are the `<labels>` in order (without `<labels>`, the track labels in order
//! of appearance); a track label outside `<labels>` is an error ("unknown track
//! class"). Track ids become [`AnnotatedBox::track`](super::AnnotatedBox::track);
//! attributes, `z_order`, groups and tracks of other shapes (polygons, points,
//! skeletons, …) are not read. A rotated box (`rotation` ≠ 0) is an error, as is a
//! CVAT for images file (`<image>` elements).
//!
//! [`AnnotatedVideo::length`](super::AnnotatedVideo::length) is the number of frames
//! in the numbering (`<size>`, or `<stop_frame> + 1` for a job); the frames have no
//! file names.
use super::{
    AnnotatedBox, AnnotatedVideo, AnnotationFormat, Limit, LineCounter, ReadOptions,
    VideoAnnotations, read_text,
};
use crate::{BBox, DataError};
use quick_xml::events::{BytesStart, Event};
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// The most boxes the tracks of one file may expand to (20 million, about 800 MB).
pub const MAX_BOXES: usize = 20_000_000;

#[derive(Debug, Default)]
struct Meta {
    /// `task`, `job` or `project`: the first element under `<meta>`.
    kind: String,
    name: Option<String>,
    size: Option<u32>,
    stop_frame: Option<u32>,
    width: u32,
    height: u32,
    labels: Vec<String>,
}

#[derive(Debug)]
struct Track {
    id: u64,
    label: String,
    line: usize,
    boxes: Vec<Shape>,
}

#[derive(Clone, Copy, Debug)]
struct Shape {
    frame: u32,
    p: [f64; 4],
    outside: bool,
    occluded: bool,
    line: usize,
}

/// The attributes of an element, unescaped.
fn attributes(
    path: &Path,
    line: usize,
    e: &BytesStart<'_>,
    decoder: quick_xml::encoding::Decoder,
) -> Result<BTreeMap<String, String>, DataError> {
    let mut out = BTreeMap::new();
    for a in e.attributes() {
        let a = a.map_err(|err| DataError::Xml {
            path: path.to_owned(),
            message: format!("line {line}: {err}"),
        })?;
        let value = a
            .decode_and_unescape_value(decoder)
            .map_err(|err| DataError::Xml {
                path: path.to_owned(),
                message: format!("line {line}: {err}"),
            })?;
        out.insert(
            String::from_utf8_lossy(a.key.local_name().as_ref()).into_owned(),
            value.into_owned(),
        );
    }
    Ok(out)
}

fn flag(
    path: &Path,
    record: &str,
    attrs: &BTreeMap<String, String>,
    key: &str,
    default: bool,
) -> Result<bool, DataError> {
    match attrs.get(key).map(|s| s.trim()) {
        None => Ok(default),
        Some("1" | "true" | "True") => Ok(true),
        Some("0" | "false" | "False") => Ok(false),
        Some(v) => Err(DataError::invalid(
            path,
            record,
            format!("{key}={v:?} is not 0 or 1"),
        )),
    }
}

fn parse_box(
    path: &Path,
    track: &Track,
    line: usize,
    attrs: &BTreeMap<String, String>,
) -> Result<Shape, DataError> {
    let record = format!("line {line}: track {} box", track.id);
    let get = |key: &str| {
        attrs.get(key).map(|s| s.trim()).ok_or_else(|| {
            DataError::invalid(path, &record, format!("<box> has no {key} attribute"))
        })
    };
    let frame_text = get("frame")?;
    let frame: u32 = frame_text.parse().map_err(|_| {
        DataError::invalid(
            path,
            &record,
            format!("frame={frame_text:?} is not a frame number"),
        )
    })?;
    let record = format!("line {line}: track {} frame {frame}", track.id);
    let mut p = [0f64; 4];
    for (v, key) in p.iter_mut().zip(["xtl", "ytl", "xbr", "ybr"]) {
        let s = get(key)?;
        *v = s
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                DataError::invalid(path, &record, format!("{key}={s:?} is not a number"))
            })?;
    }
    if let Some(r) = attrs.get("rotation")
        && r.trim().parse::<f64>() != Ok(0.0)
    {
        return Err(DataError::invalid(
            path,
            &record,
            format!("rotated box (rotation={r:?}): only axis-aligned boxes are read"),
        ));
    }
    if p[2] < p[0] || p[3] < p[1] {
        return Err(DataError::invalid(
            path,
            &record,
            format!(
                "xbr/ybr ({}, {}) lie before xtl/ytl ({}, {})",
                p[2], p[3], p[0], p[1]
            ),
        ));
    }
    Ok(Shape {
        frame,
        p,
        outside: flag(path, &record, attrs, "outside", false)?,
        occluded: flag(path, &record, attrs, "occluded", false)?,
        line,
    })
}

/// Parse the XML into meta and tracks (boxes as listed).
fn parse(path: &Path, text: &str) -> Result<(Meta, Vec<Track>), DataError> {
    let mut lines = LineCounter::new(text.as_bytes());
    let mut track_line: HashMap<u64, usize> = HashMap::new();
    let mut reader = quick_xml::Reader::from_str(text);
    let mut stack: Vec<String> = Vec::new();
    let mut meta = Meta::default();
    let mut tracks: Vec<Track> = Vec::new();
    let mut saw_root = false;
    let mut content = String::new();
    loop {
        let pos = reader.buffer_position() as usize;
        let line = lines.line(pos);
        let xml_err = |e: &dyn std::fmt::Display| DataError::Xml {
            path: path.to_owned(),
            message: format!("line {line}: {e}"),
        };
        let event = reader.read_event().map_err(|e| xml_err(&e))?;
        let (start, empty) = match &event {
            Event::Start(e) => (Some(e), false),
            Event::Empty(e) => (Some(e), true),
            _ => (None, false),
        };
        if let Some(e) = start {
            let name = String::from_utf8_lossy(e.local_name().as_ref()).into_owned();
            content.clear();
            let path_here: Vec<&str> = stack.iter().map(String::as_str).collect();
            match (path_here.as_slice(), name.as_str()) {
                ([], root) if root != "annotations" => {
                    return Err(DataError::invalid(
                        path,
                        format!("line {line}"),
                        format!(
                            "root element <{root}>, expected <annotations> (CVAT for video 1.1)"
                        ),
                    ));
                }
                (["annotations"], "image") => {
                    return Err(DataError::invalid(
                        path,
                        format!("line {line}: <image>"),
                        "this is CVAT for images (per-image boxes), not CVAT for video: \
                         export the task as \"CVAT for video 1.1\"",
                    ));
                }
                (["annotations", "meta"], kind) if meta.kind.is_empty() => {
                    meta.kind = kind.to_owned();
                }
                (["annotations"], "track") => {
                    let attrs = attributes(path, line, e, reader.decoder())?;
                    let record = format!("line {line}: <track>");
                    let id = attrs.get("id").ok_or_else(|| {
                        DataError::invalid(path, &record, "track without an id attribute")
                    })?;
                    let id = id.trim().parse::<u64>().map_err(|_| {
                        DataError::invalid(
                            path,
                            &record,
                            format!("track id {id:?} is not a number"),
                        )
                    })?;
                    let label = attrs.get("label").cloned().ok_or_else(|| {
                        DataError::invalid(
                            path,
                            format!("line {line}: track {id}"),
                            "track without a label attribute",
                        )
                    })?;
                    if let Some(first) = track_line.insert(id, line) {
                        return Err(DataError::invalid(
                            path,
                            format!("line {line}: track {id}"),
                            format!("track id {id} is already used on line {first}"),
                        ));
                    }
                    tracks.push(Track {
                        id,
                        label,
                        line,
                        boxes: Vec::new(),
                    });
                }
                (["annotations", "track"], "box") => {
                    let attrs = attributes(path, line, e, reader.decoder())?;
                    if let Some(track) = tracks.last_mut() {
                        let shape = parse_box(path, track, line, &attrs)?;
                        track.boxes.push(shape);
                    }
                }
                _ => {}
            }
            saw_root = true;
            if !empty {
                stack.push(name);
            }
            continue;
        }
        match event {
            Event::Text(t) => content.push_str(&t.decode().map_err(|e| xml_err(&e))?),
            Event::CData(t) => content.push_str(&t.decode().map_err(|e| xml_err(&e))?),
            Event::GeneralRef(r) => {
                if let Some(c) = r.resolve_char_ref().map_err(|e| xml_err(&e))? {
                    content.push(c);
                } else {
                    let name = r.decode().map_err(|e| xml_err(&e))?;
                    let s = quick_xml::escape::resolve_predefined_entity(&name)
                        .ok_or_else(|| xml_err(&format!("unknown entity &{name};")))?;
                    content.push_str(s);
                }
            }
            Event::End(_) => {
                let path_here: Vec<&str> = stack.iter().map(String::as_str).collect();
                let value = content.trim();
                let number = || {
                    value.parse::<u32>().map_err(|_| {
                        DataError::invalid(
                            path,
                            format!("line {line}: <{}>", path_here.last().copied().unwrap_or("")),
                            format!("{value:?} is not a whole number"),
                        )
                    })
                };
                match path_here.as_slice() {
                    ["annotations", "meta", _, "name"] => meta.name = Some(value.to_owned()),
                    ["annotations", "meta", _, "size"] => meta.size = Some(number()?),
                    ["annotations", "meta", _, "stop_frame"] => meta.stop_frame = Some(number()?),
                    ["annotations", "meta", .., "original_size", "width"] => meta.width = number()?,
                    ["annotations", "meta", .., "original_size", "height"] => {
                        meta.height = number()?
                    }
                    ["annotations", "meta", .., "labels", "label", "name"]
                        if !meta.labels.iter().any(|l| l == value) =>
                    {
                        meta.labels.push(value.to_owned());
                    }
                    _ => {}
                }
                stack.pop();
                content.clear();
            }
            Event::Eof => break,
            _ => {}
        }
    }
    if !saw_root {
        return Err(DataError::invalid(
            path,
            "line 1",
            "no XML element (expected <annotations>, CVAT for video 1.1)",
        ));
    }
    Ok((meta, tracks))
}

/// Read a CVAT for video 1.1 XML file (see the module documentation).
pub(crate) fn read(path: &Path, opts: &ReadOptions) -> Result<VideoAnnotations, DataError> {
    let text = read_text(path)?;
    let (meta, tracks) = parse(path, &text)?;
    let mut classes = meta.labels.clone();
    let declared = !classes.is_empty();
    let mut class_of = Vec::with_capacity(tracks.len());
    for t in &tracks {
        let class = match classes.iter().position(|c| *c == t.label) {
            Some(c) => c,
            None if declared => {
                return Err(DataError::invalid(
                    path,
                    format!("line {}: track {}", t.line, t.id),
                    format!(
                        "unknown track class {:?} (the labels in <meta> are {classes:?})",
                        t.label
                    ),
                ));
            }
            None => {
                classes.push(t.label.clone());
                classes.len() - 1
            }
        };
        class_of.push(class);
    }
    // The last frame of the numbering, and what says so.
    let (last, source) = match (meta.kind.as_str(), meta.size, meta.stop_frame) {
        ("job", _, Some(stop)) => (Some(stop), "<stop_frame>"),
        (_, Some(size), _) => (size.checked_sub(1), "<size>"),
        (_, None, Some(stop)) => (Some(stop), "<stop_frame>"),
        _ => (None, ""),
    };
    let length = match (meta.kind.as_str(), meta.size, meta.stop_frame) {
        ("job", _, Some(stop)) => stop.checked_add(1),
        (_, size, _) => size,
    };
    let limit = Limit::new(opts, None, "");
    let end = last.or(opts.length.and_then(|n| n.checked_sub(1)));
    let mut video = AnnotatedVideo {
        name: meta.name.clone().unwrap_or_else(|| {
            path.file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default()
        }),
        width: meta.width,
        height: meta.height,
        length,
        fps: None,
        frames: BTreeMap::new(),
    };
    let mut total = 0usize;
    for (t, &class) in tracks.iter().zip(&class_of) {
        let mut shapes = t.boxes.clone();
        shapes.sort_by_key(|s| s.frame);
        for w in shapes.windows(2) {
            if w[0].frame == w[1].frame {
                return Err(DataError::invalid(
                    path,
                    format!("line {}: track {} frame {}", w[1].line, t.id, w[1].frame),
                    format!(
                        "a second box at this frame (the first is on line {})",
                        w[0].line
                    ),
                ));
            }
        }
        if let Some(l) = last
            && let Some(s) = shapes.iter().find(|s| !s.outside && s.frame > l)
        {
            return Err(DataError::invalid(
                path,
                format!("line {}: track {} frame {}", s.line, t.id, s.frame),
                format!("box past the last frame {l} ({source})"),
            ));
        }
        let mut emit = |frame: u32, p: [f64; 4], occluded: bool, line: usize| {
            let record = format!("line {line}: track {} frame {frame}", t.id);
            Limit::check(limit, path, &record, frame, u64::from(frame))?;
            total += 1;
            if total > MAX_BOXES {
                return Err(DataError::invalid(
                    path,
                    &record,
                    format!("the tracks expand to more than {MAX_BOXES} boxes: is <size> right?"),
                ));
            }
            let mut b = AnnotatedBox::new(
                class,
                BBox::new(p[0] as f32, p[1] as f32, p[2] as f32, p[3] as f32),
            );
            b.track = Some(t.id);
            b.occluded = occluded;
            video.frames.entry(frame).or_default().boxes.push(b);
            Ok(())
        };
        for (i, s) in shapes.iter().enumerate() {
            if s.outside {
                continue;
            }
            emit(s.frame, s.p, s.occluded, s.line)?;
            if let Some(next) = shapes.get(i + 1) {
                // Towards an outside box past the end, CVAT keeps the frames up to the end.
                let stop = end.map_or(next.frame, |e| next.frame.min(e.saturating_add(1)));
                let span = f64::from(next.frame - s.frame);
                for f in s.frame.saturating_add(1)..stop {
                    let t = f64::from(f - s.frame) / span;
                    let p = std::array::from_fn(|k| s.p[k] + (next.p[k] - s.p[k]) * t);
                    emit(f, p, s.occluded, s.line)?;
                }
            } else {
                let Some(end) = end else {
                    return Err(DataError::invalid(
                        path,
                        format!("line {}: track {} frame {}", s.line, t.id, s.frame),
                        "the track is never outside after this box and the file declares \
                         no <size> or <stop_frame>: pass the video length",
                    ));
                };
                if let Some(first) = s.frame.checked_add(1) {
                    for f in first..=end {
                        emit(f, s.p, s.occluded, s.line)?;
                    }
                }
            }
        }
    }
    Ok(VideoAnnotations {
        format: AnnotationFormat::Cvat,
        classes,
        videos: vec![video],
    })
}
