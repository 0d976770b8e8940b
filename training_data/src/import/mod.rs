//! Importers (COCO JSON, Pascal VOC XML, GTSDB-style CSV) into frugal's dataset form,
//! and the COCO exporter.
//!
//! Conventions of the source formats:
//! - COCO: `bbox = [x, y, w, h]`, `x + w` exclusive. Images may carry frugal's extras
//!   `video`, `index` and `split`, which are kept (so export → import round-trips).
//! - VOC: `xmin … ymax` are 1-based inclusive pixel indices: `x1 = xmin - 1`,
//!   `x2 = xmax` (exclusive).
//! - GTSDB: `file;x1;y1;x2;y2;class` with 0-based inclusive corners: `x2 + 1` is the
//!   exclusive edge. No header (a first line starting with `file` / `filename` is
//!   skipped).
//!
//! Classes: see [`classes`](mod@classes); by default the source's own. Images without
//! a `video` become one video each; splits come from the source (`split` extra), from
//! the `split` option, or else from a fixed hash of the video id (≈70 % train, 15 % val,
//! 15 % test), so splits never share a video.
//!
//! Real-world quirks, handled as pycocotools and the MOT tools do: an image listed but
//! missing is skipped and counted (an error with `strict`); a box reaching past the
//! image is clipped to it and counted; a box of negative size, or wholly outside its
//! image, is an error naming the record; crowds (COCO `iscrowd`), VOC `difficult`
//! objects and the video formats' ignore boxes become the frame's ignore regions
//! ([`IgnoreRegion`]), which evaluation neither requires nor penalises.
//!
//! This file holds what every import shares (splits, checks, writing); the three
//! still-image readers are in `stills`, the video annotation formats in
//! [`video`](mod@video).
use crate::dataset::PartialDir;
use crate::generate::encode_png;
use crate::{
    BBox, ClassId, Clutter, DataError, Dataset, FrameRecord, IgnoreRegion, Light, NavAction,
    Object, Source, Split, VideoMeta,
};
use classes::ClassTable;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub mod classes;
mod export;
pub mod settings;
mod stills;
pub mod video;

use crate::annotations::AnnotationFormat;
use crate::media::Sampling;
pub use classes::{ClassList, ClassMap, parse_action};
pub use export::export_video;
pub use settings::ImportSettings;

/// A source annotation format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Format {
    /// COCO JSON (one file).
    Coco,
    /// Pascal VOC XML (one file, or a folder of `.xml` files).
    Voc,
    /// GTSDB-style CSV `file;x1;y1;x2;y2;class` (one file).
    Gtsdb,
    /// A video annotation format (MOT, CVAT for video, COCO with videos, ImageNet VID).
    Video(AnnotationFormat),
}

impl Format {
    /// Every format.
    pub const ALL: [Format; 7] = [
        Format::Coco,
        Format::Voc,
        Format::Gtsdb,
        Format::Video(AnnotationFormat::Mot),
        Format::Video(AnnotationFormat::Cvat),
        Format::Video(AnnotationFormat::CocoVideo),
        Format::Video(AnnotationFormat::ImagenetVid),
    ];

    /// `coco`, `voc`, `gtsdb`, `mot`, `cvat`, `coco-video` or `imagenet-vid`.
    pub fn name(self) -> &'static str {
        match self {
            Format::Coco => "coco",
            Format::Voc => "voc",
            Format::Gtsdb => "gtsdb",
            Format::Video(f) => f.name(),
        }
    }

    /// The format with this name.
    pub fn from_name(name: &str) -> Option<Format> {
        Format::ALL.into_iter().find(|f| f.name() == name)
    }
}

/// How to import.
#[derive(Clone, Debug)]
pub struct ImportOptions {
    /// Source format.
    pub format: Format,
    /// Annotation file (or VOC folder).
    pub input: PathBuf,
    /// Folder that image paths are relative to (default: the annotation file's folder,
    /// or the VOC folder).
    pub images: Option<PathBuf>,
    /// Source-class mapping (renames and merges).
    pub class_map: ClassMap,
    /// With a class map: keep only the mapped classes. With a class list other than
    /// the source's: drop objects of classes outside it instead of failing.
    pub drop_unmapped: bool,
    /// The class list the dataset gets.
    pub classes: ClassList,
    /// What the drone does on a class: class name → action.
    pub actions: BTreeMap<String, NavAction>,
    /// Images listed but missing are an error instead of skipped.
    pub strict: bool,
    /// Video formats: the video file or image folder holding the frames (default: the
    /// images the annotations name, or MOT's `img1/`).
    pub video: Option<PathBuf>,
    /// Video formats: the frame rate of an image folder (default: the annotations', else
    /// 30).
    pub fps: Option<f64>,
    /// Video formats: which frames to read (every N-th, at most F per second, a window).
    pub sampling: Sampling,
    /// Video formats: cut each video into consecutive train / val / test parts of these
    /// fractions (see [`video`](mod@video)).
    pub time_split: Option<[f64; 3]>,
    /// Video formats without a class column (MOT's 7- and 10-column layouts): the class.
    pub default_class: String,
    /// MOT: boxes less visible than this are marked ignore.
    pub min_visibility: f32,
    /// Draw a progress bar on stderr.
    pub progress: bool,
    /// Put everything into this split (default: from the source, else by video hash).
    pub split: Option<Split>,
    /// Scenario levels recorded for the imported videos.
    pub clutter: Clutter,
    /// Scenario levels recorded for the imported videos.
    pub light: Light,
}

impl ImportOptions {
    /// Options with defaults: the source's classes, no class map, no actions, missing
    /// images skipped, automatic splits, scenario medium / normal.
    pub fn new(format: Format, input: impl Into<PathBuf>) -> Self {
        Self {
            format,
            input: input.into(),
            images: None,
            class_map: ClassMap::default(),
            drop_unmapped: false,
            classes: ClassList::Source,
            actions: BTreeMap::new(),
            strict: false,
            video: None,
            fps: None,
            sampling: Sampling::default(),
            time_split: None,
            default_class: "pedestrian".into(),
            min_visibility: 0.0,
            progress: false,
            split: None,
            clutter: Clutter::Medium,
            light: Light::Normal,
        }
    }
}

/// One source image and its objects, before pixels are converted.
#[derive(Debug)]
struct SourceImage {
    /// Annotation file and record, for errors.
    ann_file: PathBuf,
    record: String,
    /// The source's image id (COCO), kept as the frame id.
    id: Option<u64>,
    image: PathBuf,
    declared: Option<(u32, u32)>,
    /// Scenario levels carried by a frugal COCO export.
    scenario: Option<(Clutter, Light)>,
    video: Option<u32>,
    index: Option<u32>,
    split: Option<Split>,
    /// Boxes, checked once the image size is known.
    objects: Vec<SourceBox>,
}

/// One box of a still-image source.
#[derive(Debug)]
struct SourceBox {
    /// Its record, for errors.
    record: String,
    class: ClassId,
    bbox: BBox,
    /// An ignore region (COCO `iscrowd`, VOC `difficult`), not an object.
    ignore: bool,
}

/// The split of an imported video without a given split: a fixed hash of its id.
pub fn hashed_split(video: u32) -> Split {
    let h = (u64::from(video).wrapping_add(1)).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 32;
    match h % 20 {
        0..=13 => Split::Train,
        14..=16 => Split::Val,
        _ => Split::Test,
    }
}

/// What an import skipped or changed, recorded in the manifest.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImportCounts {
    /// Images (or frames) the annotations list but the source lacks, skipped.
    pub missing_images: u64,
    /// Boxes reaching past their image, clipped to it.
    pub clipped_boxes: u64,
    /// Boxes marked ignore (crowd, distractor, too little visible), not kept as objects.
    pub ignored_boxes: u64,
}

impl ImportCounts {
    /// Whether nothing was skipped or changed.
    pub fn is_zero(&self) -> bool {
        *self == ImportCounts::default()
    }
}

/// A source box placed in a `width × height` image: a negative size or a box wholly
/// outside is an error naming the record; a box reaching past the image is clipped and
/// counted.
pub(crate) fn place_box(
    path: &Path,
    record: &str,
    bbox: BBox,
    width: u32,
    height: u32,
    counts: &mut ImportCounts,
) -> Result<BBox, DataError> {
    let finite = [bbox.x1, bbox.y1, bbox.x2, bbox.y2]
        .iter()
        .all(|v| v.is_finite());
    if !finite || bbox.x2 < bbox.x1 || bbox.y2 < bbox.y1 {
        return Err(DataError::invalid(
            path,
            record,
            format!(
                "negative or undefined box size: [{}, {}, {}, {}] (x1, y1, x2, y2)",
                bbox.x1, bbox.y1, bbox.x2, bbox.y2
            ),
        ));
    }
    let clipped = bbox.clip(width as f32, height as f32);
    if !clipped.is_valid() {
        return Err(DataError::BoxOutside {
            path: path.to_owned(),
            record: record.to_owned(),
            x1: bbox.x1,
            y1: bbox.y1,
            x2: bbox.x2,
            y2: bbox.y2,
            width,
            height,
        });
    }
    if clipped != bbox {
        counts.clipped_boxes += 1;
    }
    Ok(clipped)
}

/// The videos of a set of frames (in id order), checking that a video lies in one split
/// and no (video, index) pair repeats; `meta` gives each new video's metadata.
pub(crate) fn collect_videos(
    frames: &[FrameRecord],
    input: &Path,
    mut meta: impl FnMut(&FrameRecord) -> VideoMeta,
) -> Result<Vec<VideoMeta>, DataError> {
    let mut videos: BTreeMap<u32, VideoMeta> = BTreeMap::new();
    let mut seen = std::collections::BTreeSet::new();
    for f in frames {
        let v = videos.entry(f.video).or_insert_with(|| VideoMeta {
            frames: 0,
            ..meta(f)
        });
        if v.split != f.split {
            return Err(DataError::invalid(
                input,
                format!("video {}", f.video),
                format!("has frames in both {} and {}", v.split, f.split),
            ));
        }
        v.frames += 1;
        if !seen.insert((f.video, f.index)) {
            return Err(DataError::invalid(
                input,
                format!("image {}", f.file.display()),
                format!("video {} frame {} appears twice", f.video, f.index),
            ));
        }
    }
    Ok(videos.into_values().collect())
}

/// The [`Source`] of an import.
pub(crate) fn imported(format: &str, input: &Path, counts: ImportCounts) -> Source {
    Source::Imported {
        format: format.to_owned(),
        from: input.display().to_string(),
        counts,
    }
}

/// Write the metadata of an imported dataset into its partial folder and move it to
/// `out`.
pub(crate) fn finish(
    partial: PartialDir,
    out: &Path,
    classes: Vec<crate::ClassInfo>,
    videos: Vec<VideoMeta>,
    frames: Vec<FrameRecord>,
    source: Source,
) -> Result<Dataset, DataError> {
    let mut dataset = Dataset {
        root: partial.path().to_owned(),
        classes,
        videos,
        frames,
    };
    dataset.write_metadata(partial.path(), source)?;
    partial.commit()?;
    dataset.root = out.to_owned();
    Ok(dataset)
}

/// Import a dataset into `out` (written to `<out>.partial-XXXX`, then swapped in).
/// Images are decoded, checked against their annotations and stored as PNG frames.
pub fn import(opts: &ImportOptions, out: &Path) -> Result<Dataset, DataError> {
    opts.sampling.check(&opts.input)?;
    if let Some(t) = opts.time_split
        && (t.iter().any(|v| !(v.is_finite() && *v >= 0.0)) || t[0] <= 0.0)
    {
        return Err(DataError::invalid(
            &opts.input,
            "time split",
            format!("{t:?}: fractions must be ≥ 0 with a non-zero train part"),
        ));
    }
    let root = match &opts.images {
        Some(r) => r.clone(),
        None if opts.format == Format::Voc && opts.input.is_dir() => opts.input.clone(),
        None => opts.input.parent().map(Path::to_owned).unwrap_or_default(),
    };
    let mut table = ClassTable::new(&opts.classes, &opts.class_map, opts.drop_unmapped);
    let mut sources = match opts.format {
        Format::Coco => stills::read_coco(opts, &root, &mut table)?,
        Format::Voc => stills::read_voc(opts, &root, &mut table)?,
        Format::Gtsdb => stills::read_gtsdb(opts, &root, &mut table)?,
        Format::Video(f) => return video::import_video(opts, f, out),
    };
    let classes = table.finish(&opts.actions, &opts.input)?;
    let mut counts = ImportCounts::default();
    let listed = sources.len();
    if let Some(missing) = sources.iter().find(|s| !s.image.is_file()) {
        if opts.strict {
            return Err(DataError::MissingImage {
                path: missing.ann_file.clone(),
                record: missing.record.clone(),
                image: missing.image.clone(),
            });
        }
        sources.retain(|s| s.image.is_file());
        counts.missing_images = (listed - sources.len()) as u64;
    }
    if sources.is_empty() {
        return Err(DataError::Empty {
            path: opts.input.clone(),
            reason: if listed == 0 {
                "no images".into()
            } else {
                format!("none of the {listed} images it lists exists")
            },
        });
    }

    // Videos: the source's, else one per image, numbered in order of appearance.
    let mut next_free = sources
        .iter()
        .filter_map(|s| s.video)
        .max()
        .map_or(0, |m| m + 1);
    let mut plan = Vec::with_capacity(sources.len());
    let mut counters: BTreeMap<u32, u32> = BTreeMap::new();
    for s in &sources {
        let video = s.video.unwrap_or_else(|| {
            next_free += 1;
            next_free - 1
        });
        let counter = counters.entry(video).or_default();
        let index = s.index.unwrap_or(*counter);
        *counter = (*counter).max(index + 1);
        let split = opts
            .split
            .or(s.split)
            .unwrap_or_else(|| hashed_split(video));
        plan.push((video, index, split));
    }

    let partial = PartialDir::new(out)?;
    let dir = partial.path().to_owned();
    let converted: Vec<Result<(FrameRecord, ImportCounts), DataError>> = sources
        .par_iter()
        .zip(plan.par_iter())
        .enumerate()
        .map(|(n, (s, &(video, index, split)))| {
            convert(s, &dir, s.id.unwrap_or(n as u64), video, index, split)
        })
        .collect();
    let mut frames = Vec::with_capacity(converted.len());
    for f in converted {
        let (frame, c) = f?;
        counts.clipped_boxes += c.clipped_boxes;
        counts.ignored_boxes += c.ignored_boxes;
        frames.push(frame);
    }
    let scenario: BTreeMap<u32, (Clutter, Light)> = frames
        .iter()
        .zip(&sources)
        .map(|(f, s)| (f.video, s.scenario.unwrap_or((opts.clutter, opts.light))))
        .collect();
    let videos = collect_videos(&frames, &opts.input, |f| {
        let (clutter, light) = scenario[&f.video];
        VideoMeta {
            id: f.video,
            seed: 0,
            clutter,
            light,
            split: f.split,
            frames: 0,
            name: None,
            fps: None,
        }
    })?;
    let source = imported(opts.format.name(), &opts.input, counts);
    finish(partial, out, classes, videos, frames, source)
}

fn convert(
    s: &SourceImage,
    dir: &Path,
    id: u64,
    video: u32,
    index: u32,
    split: Split,
) -> Result<(FrameRecord, ImportCounts), DataError> {
    let img = image::open(&s.image)
        .map_err(|e| DataError::image(&s.image, e))?
        .to_rgb8();
    let (w, h) = img.dimensions();
    if let Some((dw, dh)) = s.declared
        && (dw, dh) != (w, h)
    {
        return Err(DataError::invalid(
            &s.ann_file,
            &s.record,
            format!("declares {dw}x{dh} but {} is {w}x{h}", s.image.display()),
        ));
    }
    let mut counts = ImportCounts::default();
    let mut objects = Vec::with_capacity(s.objects.len());
    let mut ignore = Vec::new();
    for b in &s.objects {
        let bbox = place_box(&s.ann_file, &b.record, b.bbox, w, h, &mut counts)?;
        if b.ignore {
            counts.ignored_boxes += 1;
            ignore.push(IgnoreRegion {
                class: Some(b.class),
                bbox,
            });
        } else {
            objects.push(Object {
                class: b.class,
                bbox,
            });
        }
    }
    let file = crate::generate::frame_file(video, index);
    let path = dir.join(&file);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| DataError::io(parent, e))?;
    }
    std::fs::write(&path, encode_png(&img, &path)?).map_err(|e| DataError::io(&path, e))?;
    let frame = FrameRecord {
        id,
        file,
        width: w,
        height: h,
        video,
        index,
        split,
        objects,
        ignore,
        time_s: None,
    };
    Ok((frame, counts))
}

/// Export `ds` (all splits, or one) as a self-contained COCO folder: `out/annotations.json`
/// (with frugal's `video`, `index` and `split` extras on images,
/// `category_id = class id + 1`) and the frames copied under `out/frames/…`.
/// Returns the path of the JSON file.
pub fn export_coco(ds: &Dataset, split: Option<Split>, out: &Path) -> Result<PathBuf, DataError> {
    let partial = PartialDir::new(out)?;
    let coco = ds.to_coco(split);
    let mut value = serde_json::to_value(&coco).map_err(|e| DataError::json(out, e))?;
    if let Some(images) = value.get_mut("images").and_then(|v| v.as_array_mut()) {
        for (img, f) in images.iter_mut().zip(
            ds.frames
                .iter()
                .filter(|f| split.is_none_or(|s| f.split == s)),
        ) {
            if let Some(obj) = img.as_object_mut() {
                obj.insert("split".into(), f.split.name().into());
                if let Some(v) = ds.video(f.video) {
                    obj.insert("clutter".into(), v.clutter.name().into());
                    obj.insert("light".into(), v.light.name().into());
                }
            }
        }
    }
    for f in ds
        .frames
        .iter()
        .filter(|f| split.is_none_or(|s| f.split == s))
    {
        let src = ds.frame_path(f);
        let dst = partial.path().join(&f.file);
        if let Some(parent) = dst.parent() {
            std::fs::create_dir_all(parent).map_err(|e| DataError::io(parent, e))?;
        }
        if std::fs::hard_link(&src, &dst).is_err() {
            std::fs::copy(&src, &dst).map_err(|e| DataError::io(&src, e))?;
        }
    }
    crate::dataset::write_json_atomic(&partial.path().join("annotations.json"), &value)?;
    partial.commit()?;
    Ok(out.join("annotations.json"))
}
