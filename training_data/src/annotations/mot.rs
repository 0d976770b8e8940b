//! MOT Challenge ground truth, `<seq>/gt/gt.txt` (2D MOT 2015, MOT16, MOT17, MOT20).
//!
//! One box per line, comma-separated. Frames are **1-based** in the file and read as
//! `frame - 1`. A box is its top-left corner and size in pixels: `x2 = x + w`
//! (exclusive edge). Three layouts, told apart by the column count of the first line
//! (every line must have the same count):
//!
//! - 7 columns `frame,id,x,y,w,h,conf` (TUD-Campus as distributed with 2D MOT 2015);
//! - 9 columns `frame,id,x,y,w,h,flag,class,visibility` (MOT16, MOT17, MOT20);
//! - 10 columns `frame,id,x,y,w,h,conf,x3d,y3d,z3d` (2D MOT 2015).
//!
//! Track id `-1` means no track. Any column may be written as a float (`1.000`);
//! frames, ids and classes must be whole numbers.
//!
//! Classes and ignore regions in the 9-column layout follow the MOT17 devkit's
//! preprocessing:
//! - class ids are MOT's ([`MOT_CLASSES`], 1 pedestrian … 12 reflection), and the
//!   class list read is the MOT list (class index = id - 1). When a `labels.txt` sits
//!   next to `gt.txt` (one name per line, as CVAT and Datumaro write MOT, and as
//!   [`write_mot`](super::write_mot) does), class id `k` names its line `k` instead;
//! - a box is an ignore region when its flag (column 7) is 0, when its class is one of
//!   the devkit's distractors [`MOT_DISTRACTORS`] (person_on_vehicle, static_person,
//!   distractor, reflection: a pedestrian detection on them is neither a true nor a
//!   false positive), or when its visibility is below
//!   [`ReadOptions::min_visibility`]. Distractors keep their own class rather than
//!   becoming pedestrians, so nothing is lost and a multi-class user can still tell a
//!   reflection from a person;
//! - a negative visibility (MOT's `-1` placeholder) reads as unknown.
//!
//! The 7- and 10-column layouts have no class column: every box is of class
//! [`ReadOptions::default_class`], and the class list is the MOT list when that is a
//! MOT name (so every MOT read shares one list), else that one name. `conf` and the 3D
//! columns are not used and no box is ignored (the 2D MOT 2015 devkit does not
//! preprocess either).
//!
//! `<seq>/seqinfo.ini` (read when `gt.txt` is in a folder called `gt`) gives the
//! name, `imWidth`, `imHeight`, `seqLength`, `frameRate`, and with `imDir` and `imExt`
//! each frame's image `<imDir>/<frame:06><imExt>`. Without it the name is the sequence
//! folder's (else the file stem), the size 0 and the frames have no file.
//!
//! Errors name the line: a column count other than 7, 9 or 10 or other than the first
//! line's, a field that is not a number, a duplicate (frame, track id) pair (both
//! lines), a negative width or height, a frame below 1, a frame past `seqLength` or
//! [`ReadOptions::length`].
use super::{
    AnnotatedBox, AnnotatedFrame, AnnotatedVideo, AnnotationFormat, Limit, ReadOptions,
    VideoAnnotations, read_text,
};
use crate::{BBox, DataError};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// MOT16/17/20 class names; class id `k` is entry `k - 1`.
pub const MOT_CLASSES: [&str; 12] = [
    "pedestrian",
    "person_on_vehicle",
    "car",
    "bicycle",
    "motorbike",
    "non_motorized_vehicle",
    "static_person",
    "distractor",
    "occluder",
    "occluder_on_ground",
    "occluder_full",
    "reflection",
];

/// Classes the MOT17 devkit treats as ignore regions when evaluating pedestrians.
pub const MOT_DISTRACTORS: [&str; 4] = [
    "person_on_vehicle",
    "static_person",
    "distractor",
    "reflection",
];

/// What `seqinfo.ini` says.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct SeqInfo {
    pub name: Option<String>,
    pub im_dir: Option<String>,
    pub im_ext: Option<String>,
    pub fps: Option<f64>,
    pub length: Option<u32>,
    pub width: u32,
    pub height: u32,
}

/// `<seq>/seqinfo.ini` for `<seq>/gt/<file>`; `None` when the file is not in `gt/`.
pub(crate) fn seqinfo_path(gt: &Path) -> Option<PathBuf> {
    let dir = gt.parent()?;
    (dir.file_name()? == "gt").then(|| dir.parent().unwrap_or(Path::new("")).join("seqinfo.ini"))
}

/// `labels.txt` beside `gt.txt`.
pub(crate) fn labels_path(gt: &Path) -> PathBuf {
    gt.parent().unwrap_or(Path::new("")).join("labels.txt")
}

fn read_seqinfo(path: &Path) -> Result<SeqInfo, DataError> {
    let text = read_text(path)?;
    let mut info = SeqInfo::default();
    for (n, raw) in text.lines().enumerate() {
        let l = raw.trim_start_matches('\u{feff}').trim();
        if l.is_empty() || l.starts_with([';', '#', '[']) {
            continue;
        }
        let record = format!("line {}", n + 1);
        let (key, value) = l
            .split_once('=')
            .map(|(k, v)| (k.trim(), v.trim()))
            .ok_or_else(|| DataError::invalid(path, &record, format!("not key=value: {l:?}")))?;
        let whole = |what: &str| {
            value.parse::<u32>().map_err(|_| {
                DataError::invalid(
                    path,
                    &record,
                    format!("{what} is not a whole number: {value:?}"),
                )
            })
        };
        match key.to_ascii_lowercase().as_str() {
            "name" if !value.is_empty() => info.name = Some(value.to_owned()),
            "imdir" => info.im_dir = Some(value.to_owned()),
            "imext" => info.im_ext = Some(value.to_owned()),
            "seqlength" => info.length = Some(whole(key)?),
            "imwidth" => info.width = whole(key)?,
            "imheight" => info.height = whole(key)?,
            "framerate" => {
                info.fps = Some(
                    value
                        .parse::<f64>()
                        .ok()
                        .filter(|f| f.is_finite() && *f > 0.0)
                        .ok_or_else(|| {
                            DataError::invalid(
                                path,
                                &record,
                                format!("frameRate is not a positive number: {value:?}"),
                            )
                        })?,
                );
            }
            _ => {}
        }
    }
    Ok(info)
}

/// Class names of `labels.txt`, one per line (blank lines at the end are dropped).
fn read_labels(path: &Path) -> Result<Vec<String>, DataError> {
    let text = read_text(path)?;
    let mut names: Vec<String> = text
        .lines()
        .map(|l| l.trim_start_matches('\u{feff}').trim().to_owned())
        .collect();
    while names.last().is_some_and(String::is_empty) {
        names.pop();
    }
    if let Some(n) = names.iter().position(String::is_empty) {
        return Err(DataError::invalid(
            path,
            format!("line {}", n + 1),
            "empty class name (class id k is the name on line k)",
        ));
    }
    Ok(names)
}

/// A column as a finite number.
fn number(path: &Path, record: &str, what: &str, s: &str) -> Result<f64, DataError> {
    s.parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| DataError::Csv {
            path: path.to_owned(),
            record: record.to_owned(),
            message: format!("column {what} is not a number: {s:?}"),
        })
}

/// A column as a whole number (`3` or `3.0`).
fn whole(path: &Path, record: &str, what: &str, s: &str) -> Result<i64, DataError> {
    if let Ok(i) = s.parse::<i64>() {
        return Ok(i);
    }
    let v = number(path, record, what, s)?;
    if v.fract() != 0.0 || v.abs() > 9.0e15 {
        return Err(DataError::invalid(
            path,
            record,
            format!("{what} {s:?} is not a whole number"),
        ));
    }
    Ok(v as i64)
}

/// The sequence name: `seqinfo.ini`'s, else the folder holding `gt/`, else the stem.
fn sequence_name(path: &Path, info: &SeqInfo) -> String {
    if let Some(n) = &info.name {
        return n.clone();
    }
    let seq_dir = seqinfo_path(path).and_then(|p| p.parent().map(Path::to_owned));
    let from_dir = seq_dir.and_then(|d| {
        let d = if d.as_os_str().is_empty() {
            std::fs::canonicalize(".").ok()?
        } else {
            d
        };
        d.file_name().map(|n| n.to_string_lossy().into_owned())
    });
    from_dir.unwrap_or_else(|| {
        path.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    })
}

/// Read a MOT Challenge `gt.txt` (see the module documentation).
pub(crate) fn read(path: &Path, opts: &ReadOptions) -> Result<VideoAnnotations, DataError> {
    let text = read_text(path)?;
    let info = match seqinfo_path(path) {
        Some(p) if p.is_file() => read_seqinfo(&p)?,
        _ => SeqInfo::default(),
    };
    let limit = Limit::new(opts, info.length, "seqinfo.ini seqLength");
    // (line number, line) of the non-empty lines; the first one sets the layout.
    let lines = || {
        text.lines()
            .enumerate()
            .map(|(n, l)| (n + 1, l.trim_start_matches('\u{feff}').trim()))
            .filter(|(_, l)| !l.is_empty())
    };
    let (first_line, columns) = lines()
        .next()
        .map_or((1, 7), |(n, l)| (n, l.split(',').count()));
    if !matches!(columns, 7 | 9 | 10) {
        return Err(DataError::Csv {
            path: path.to_owned(),
            record: format!("line {first_line}"),
            message: format!(
                "{columns} columns; a MOT Challenge gt.txt has 7 (frame,id,x,y,w,h,conf), \
                 9 (…,flag,class,visibility) or 10 (…,conf,x,y,z)"
            ),
        });
    }
    // The class list, and for the 7/10-column layouts the one class of every box.
    let mut classes: Vec<String> = MOT_CLASSES.iter().map(|s| (*s).to_owned()).collect();
    let mut default_class = MOT_CLASSES.iter().position(|c| *c == opts.default_class);
    if columns == 9 {
        let labels = labels_path(path);
        if labels.is_file() {
            classes = read_labels(&labels)?;
        }
    } else if default_class.is_none() {
        classes = vec![opts.default_class.clone()];
        default_class = Some(0);
    }
    let distractor: Vec<bool> = classes
        .iter()
        .map(|c| MOT_DISTRACTORS.contains(&c.as_str()))
        .collect();
    let labels_note = if columns == 9 && labels_path(path).is_file() {
        "labels.txt"
    } else {
        "MOT ids 1-12"
    };
    let mut f: Vec<&str> = Vec::with_capacity(10);

    let mut video = AnnotatedVideo {
        name: sequence_name(path, &info),
        width: info.width,
        height: info.height,
        length: info.length,
        fps: info.fps,
        frames: Default::default(),
    };
    let mut seen: HashMap<(u32, u64), usize> = HashMap::new();
    for (line, l) in lines() {
        f.clear();
        f.extend(l.split(',').map(str::trim));
        let record = format!("line {line}");
        if f.len() != columns {
            return Err(DataError::Csv {
                path: path.to_owned(),
                record,
                message: format!(
                    "{} columns, but line {first_line} has {columns} (one layout per file)",
                    f.len()
                ),
            });
        }
        let frame = whole(path, &record, "frame", f[0])?;
        if frame < 1 || frame > i64::from(u32::MAX) {
            return Err(DataError::invalid(
                path,
                &record,
                format!("frame {frame} is out of range (MOT frames are 1-based)"),
            ));
        }
        let index = (frame - 1) as u32;
        Limit::check(limit, path, &record, index, frame as u64)?;
        let id = whole(path, &record, "id", f[1])?;
        let track = match id {
            -1 => None,
            i if i >= 0 => Some(i as u64),
            i => {
                return Err(DataError::invalid(
                    path,
                    &record,
                    format!("track id {i} is negative (only -1, no track, is allowed)"),
                ));
            }
        };
        if let Some(t) = track
            && let Some(prev) = seen.insert((index, t), line)
        {
            return Err(DataError::invalid(
                path,
                &record,
                format!("frame {frame} track {t} is already on line {prev}"),
            ));
        }
        let [x, y, w, h] = [("x", f[2]), ("y", f[3]), ("w", f[4]), ("h", f[5])]
            .map(|(what, s)| number(path, &record, what, s));
        let (x, y, w, h) = (x?, y?, w?, h?);
        if w < 0.0 || h < 0.0 {
            return Err(DataError::invalid(
                path,
                &record,
                format!("negative width or height (w = {w}, h = {h})"),
            ));
        }
        let bbox = BBox::new(x as f32, y as f32, (x + w) as f32, (y + h) as f32);
        let mut b = AnnotatedBox::new(default_class.unwrap_or(0), bbox);
        b.track = track;
        if columns == 9 {
            let flag = number(path, &record, "flag", f[6])?;
            let class = whole(path, &record, "class", f[7])?;
            if class < 1 || class as u64 > classes.len() as u64 {
                return Err(DataError::invalid(
                    path,
                    &record,
                    format!(
                        "class {class} is not one of the {} classes ({labels_note})",
                        classes.len()
                    ),
                ));
            }
            b.class = (class - 1) as usize;
            let vis = number(path, &record, "visibility", f[8])?;
            b.visibility = (vis >= 0.0).then_some(vis as f32);
            b.ignore = flag == 0.0
                || distractor[b.class]
                || b.visibility.is_some_and(|v| v < opts.min_visibility);
        }
        let file = match (&info.im_dir, &info.im_ext) {
            (Some(dir), Some(ext)) if dir.is_empty() => Some(format!("{frame:06}{ext}")),
            (Some(dir), Some(ext)) => Some(format!("{dir}/{frame:06}{ext}")),
            _ => None,
        };
        video
            .frames
            .entry(index)
            .or_insert_with(|| AnnotatedFrame {
                file,
                boxes: Vec::new(),
            })
            .boxes
            .push(b);
    }
    Ok(VideoAnnotations {
        format: AnnotationFormat::Mot,
        classes,
        videos: vec![video],
    })
}
