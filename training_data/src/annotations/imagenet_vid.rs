//! ImageNet VID (ILSVRC 2015 VID) annotations: one XML file per frame,
//! `Annotations/VID/<split>/<snippet>/000000.xml`, …
//!
//! ```xml
//! <annotation><folder>ILSVRC2015_VID_train_0000/ILSVRC2015_train_00000000</folder>
//!   <filename>000000</filename><size><width>1280</width><height>720</height></size>
//!   <object><trackid>0</trackid><name>n02691156</name>
//!     <bndbox><xmax>1050</xmax><xmin>263</xmin><ymax>636</ymax><ymin>91</ymin></bndbox>
//!     <occluded>0</occluded><generated>0</generated></object>
//! </annotation>
//! ```
//!
//! Input: a snippet folder of such files (one video), or a folder of snippet folders
//! (one video each, in name order), or a single file. The frame index is the number in
//! the file name (`000000.xml` is frame 0, already **0-based**); files are read in name
//! order. Corners are 0-based **inclusive** pixel indices, as in the ILSVRC devkit
//! (`width = xmax - xmin + 1`), so `x1 = xmin`, `x2 = xmax + 1` (exclusive).
//!
//! Classes are the WordNet ids as written (`n02691156`), sorted. `trackid` is the
//! track, `occluded` is kept, `generated` (box made by the annotation tool's tracker)
//! is not used. The video is named after its folder, sized by `<size>` (every frame
//! must agree), and each frame's `file` is `<folder>/<filename>` as written (the image
//! is that path plus `.JPEG` under `Data/VID/<split>/`). Frames without objects are
//! kept.
//!
//! Errors name the file: malformed XML, a file name without a number, two files with
//! the same number, an object without `trackid`, two objects with one `trackid`,
//! `xmax < xmin` or `ymax < ymin`, a size different from the first frame's, a frame
//! past [`ReadOptions::length`].
use super::{
    AnnotatedBox, AnnotatedFrame, AnnotatedVideo, AnnotationFormat, Limit, ReadOptions,
    VideoAnnotations, is_xml, list_dir,
};
use crate::{BBox, DataError};
use serde::Deserialize;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

#[derive(Deserialize)]
struct VidAnnotation {
    #[serde(default)]
    folder: String,
    #[serde(default)]
    filename: String,
    size: Option<VidSize>,
    #[serde(default, rename = "object")]
    objects: Vec<VidObject>,
}

#[derive(Deserialize)]
struct VidSize {
    width: u32,
    height: u32,
}

#[derive(Deserialize)]
struct VidObject {
    trackid: Option<u64>,
    name: String,
    bndbox: VidBox,
    #[serde(default)]
    occluded: u8,
}

#[derive(Deserialize)]
struct VidBox {
    xmin: f64,
    ymin: f64,
    xmax: f64,
    ymax: f64,
}

/// The number at the end of a file stem (`000012` → 12, `frame_7` → 7).
fn frame_number(file: &Path) -> Option<u32> {
    let stem = file.file_stem()?.to_str()?;
    let digits = stem.len() - stem.trim_end_matches(|c: char| c.is_ascii_digit()).len();
    stem[stem.len() - digits..].parse().ok()
}

/// One video from its frame files; boxes carry indices into `names` (first seen).
fn read_snippet(
    name: String,
    files: &[PathBuf],
    opts: &ReadOptions,
    names: &mut Vec<String>,
) -> Result<AnnotatedVideo, DataError> {
    let limit = Limit::new(opts, None, "");
    let mut video = AnnotatedVideo::new(name);
    let mut size_from: Option<&Path> = None;
    let mut file_of: BTreeMap<u32, &Path> = BTreeMap::new();
    for file in files {
        let index = frame_number(file).ok_or_else(|| {
            DataError::invalid(file, "file name", "has no frame number (000000.xml, …)")
        })?;
        if let Some(other) = file_of.insert(index, file) {
            return Err(DataError::invalid(
                file,
                format!("frame {index}"),
                format!("{} has the same frame number", other.display()),
            ));
        }
        Limit::check(
            limit,
            file,
            &format!("frame {index}"),
            index,
            u64::from(index),
        )?;
        let text = std::fs::read_to_string(file).map_err(|e| DataError::io(file, e))?;
        let ann: VidAnnotation = quick_xml::de::from_str(&text).map_err(|e| DataError::Xml {
            path: file.clone(),
            message: e.to_string(),
        })?;
        if let Some(s) = &ann.size {
            match size_from {
                None => {
                    (video.width, video.height) = (s.width, s.height);
                    size_from = Some(file);
                }
                Some(first) if (s.width, s.height) != (video.width, video.height) => {
                    return Err(DataError::invalid(
                        file,
                        "<size>",
                        format!(
                            "{}x{}, but {} is {}x{}",
                            s.width,
                            s.height,
                            first.display(),
                            video.width,
                            video.height
                        ),
                    ));
                }
                Some(_) => {}
            }
        }
        let mut tracks = BTreeSet::new();
        let mut boxes = Vec::with_capacity(ann.objects.len());
        for (i, o) in ann.objects.iter().enumerate() {
            let record = format!("object {} ({})", i + 1, o.name);
            let track = o
                .trackid
                .ok_or_else(|| DataError::invalid(file, &record, "has no <trackid>"))?;
            if !tracks.insert(track) {
                return Err(DataError::invalid(
                    file,
                    &record,
                    format!("trackid {track} appears twice in this frame"),
                ));
            }
            let b = &o.bndbox;
            let coords = [b.xmin, b.ymin, b.xmax, b.ymax];
            if coords.iter().any(|v| !v.is_finite()) || b.xmax < b.xmin || b.ymax < b.ymin {
                return Err(DataError::invalid(
                    file,
                    &record,
                    format!(
                        "bndbox xmin {} ymin {} xmax {} ymax {} is empty",
                        b.xmin, b.ymin, b.xmax, b.ymax
                    ),
                ));
            }
            let class = names.iter().position(|n| *n == o.name).unwrap_or_else(|| {
                names.push(o.name.clone());
                names.len() - 1
            });
            let mut abox = AnnotatedBox::new(
                class,
                BBox::new(
                    b.xmin as f32,
                    b.ymin as f32,
                    (b.xmax + 1.0) as f32,
                    (b.ymax + 1.0) as f32,
                ),
            );
            abox.track = Some(track);
            abox.occluded = o.occluded != 0;
            boxes.push(abox);
        }
        let image = match (ann.folder.trim(), ann.filename.trim()) {
            (_, "") => None,
            ("", f) => Some(f.to_owned()),
            (d, f) => Some(format!("{}/{f}", d.trim_end_matches('/'))),
        };
        video
            .frames
            .insert(index, AnnotatedFrame { file: image, boxes });
    }
    Ok(video)
}

fn dir_name(dir: &Path) -> String {
    dir.file_name()
        .map(|n| n.to_owned())
        .or_else(|| {
            std::fs::canonicalize(dir)
                .ok()?
                .file_name()
                .map(|n| n.to_owned())
        })
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Read ImageNet VID annotations (see the module documentation).
pub(crate) fn read(path: &Path, opts: &ReadOptions) -> Result<VideoAnnotations, DataError> {
    let mut snippets: Vec<(String, Vec<PathBuf>)> = Vec::new();
    if path.is_file() {
        let dir = path.parent().unwrap_or(Path::new("."));
        snippets.push((dir_name(dir), vec![path.to_owned()]));
    } else {
        let own = list_dir(path, is_xml)?;
        if !own.is_empty() {
            snippets.push((dir_name(path), own));
        } else {
            for sub in list_dir(path, Path::is_dir)? {
                let files = list_dir(&sub, is_xml)?;
                if !files.is_empty() {
                    snippets.push((dir_name(&sub), files));
                }
            }
        }
    }
    if snippets.is_empty() {
        return Err(DataError::Empty {
            path: path.to_owned(),
            reason: "no .xml files in the folder or its subfolders (ImageNet VID snippets)".into(),
        });
    }
    let mut names = Vec::new();
    let mut videos = Vec::with_capacity(snippets.len());
    for (name, files) in snippets {
        videos.push(read_snippet(name, &files, opts, &mut names)?);
    }
    // Classes in sorted order; boxes were numbered in order of first appearance.
    let mut order: Vec<usize> = (0..names.len()).collect();
    order.sort_by(|&a, &b| names[a].cmp(&names[b]));
    let mut new_index = vec![0; names.len()];
    for (new, &old) in order.iter().enumerate() {
        new_index[old] = new;
    }
    for v in &mut videos {
        for f in v.frames.values_mut() {
            for b in &mut f.boxes {
                b.class = new_index[b.class];
            }
        }
    }
    let classes = order.into_iter().map(|i| names[i].clone()).collect();
    Ok(VideoAnnotations {
        format: AnnotationFormat::ImagenetVid,
        classes,
        videos,
    })
}
