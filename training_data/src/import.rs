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
//! Classes: a source class (name, or numeric id as a string) is looked up in the class
//! map first, then matched against frugal's class names and codes
//! (case-insensitive). Anything else is an error naming the record, unless unmapped
//! classes are dropped. Images without a `video` become one video each; splits come
//! from the source (`split` extra), from the `split` option, or else from a fixed hash
//! of the video id (≈70 % train, 15 % val, 15 % test), so splits never share a video.
//!
//! One file for three still-image formats that share the split, class-mapping and
//! writing code; each format moves to a module of its own when video annotation formats
//! join them.
use crate::coco::{CocoFile, check_box};
use crate::dataset::PartialDir;
use crate::generate::encode_png;
use crate::{
    BBox, ClassId, Clutter, DataError, Dataset, FrameRecord, Light, Object, Sign, Source, Split,
    VideoMeta, classes,
};
use rayon::prelude::*;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

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
}

impl Format {
    /// `coco`, `voc` or `gtsdb`.
    pub fn name(self) -> &'static str {
        match self {
            Format::Coco => "coco",
            Format::Voc => "voc",
            Format::Gtsdb => "gtsdb",
        }
    }
}

/// A map from source class (name or numeric id, as a string) to a frugal class.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ClassMap {
    map: BTreeMap<String, ClassId>,
}

impl ClassMap {
    /// Read a JSON (or `.toml`) object `{"source class": "frugal class name or code"}`.
    pub fn from_file(path: &Path) -> Result<Self, DataError> {
        let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
        let raw: BTreeMap<String, String> = if path.extension().is_some_and(|e| e == "toml") {
            toml::from_str(&text).map_err(|e| DataError::Config {
                path: path.to_owned(),
                message: e.to_string(),
            })?
        } else {
            serde_json::from_str(&text).map_err(|e| DataError::json(path, e))?
        };
        let mut map = BTreeMap::new();
        for (k, v) in raw {
            let sign = Sign::from_name(&v).ok_or_else(|| DataError::UnknownClass {
                path: path.to_owned(),
                record: format!("key {k:?}"),
                class: v.clone(),
            })?;
            map.insert(k, sign.id());
        }
        Ok(Self { map })
    }

    /// A map from pairs.
    pub fn from_pairs<'a>(pairs: impl IntoIterator<Item = (&'a str, Sign)>) -> Self {
        Self {
            map: pairs
                .into_iter()
                .map(|(k, s)| (k.to_owned(), s.id()))
                .collect(),
        }
    }

    /// Resolve a source class: the map (by name, then by id), then frugal's own names.
    pub fn resolve(&self, name: &str, id: Option<u64>) -> Option<ClassId> {
        self.map
            .get(name)
            .or_else(|| id.and_then(|i| self.map.get(&i.to_string())))
            .copied()
            .or_else(|| Sign::from_name(name).map(Sign::id))
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
    /// Source-class mapping.
    pub class_map: ClassMap,
    /// Drop objects of unmapped classes instead of failing.
    pub drop_unmapped: bool,
    /// Put everything into this split (default: from the source, else by video hash).
    pub split: Option<Split>,
    /// Scenario levels recorded for the imported videos.
    pub clutter: Clutter,
    /// Scenario levels recorded for the imported videos.
    pub light: Light,
}

impl ImportOptions {
    /// Options with defaults: no class map, unmapped classes are errors, automatic
    /// splits, scenario medium / normal.
    pub fn new(format: Format, input: impl Into<PathBuf>) -> Self {
        Self {
            format,
            input: input.into(),
            images: None,
            class_map: ClassMap::default(),
            drop_unmapped: false,
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
    /// (record, class, box); boxes are checked once the image size is known.
    objects: Vec<(String, ClassId, BBox)>,
}

fn resolve_class(
    opts: &ImportOptions,
    path: &Path,
    record: &str,
    name: &str,
    id: Option<u64>,
) -> Result<Option<ClassId>, DataError> {
    match opts.class_map.resolve(name, id) {
        Some(c) => Ok(Some(c)),
        None if opts.drop_unmapped => Ok(None),
        None => Err(DataError::UnknownClass {
            path: path.to_owned(),
            record: record.to_owned(),
            class: name.to_owned(),
        }),
    }
}

fn parse_split(s: &str) -> Option<Split> {
    Split::ALL.into_iter().find(|x| x.name() == s)
}

fn read_coco(opts: &ImportOptions, root: &Path) -> Result<Vec<SourceImage>, DataError> {
    let path = &opts.input;
    let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    // Parse twice: the typed form, and the raw images for the optional `split` extra.
    let coco: CocoFile = serde_json::from_str(&text).map_err(|e| DataError::json(path, e))?;
    #[derive(Deserialize)]
    struct SplitOnly {
        #[serde(default)]
        split: Option<String>,
        #[serde(default)]
        clutter: Option<Clutter>,
        #[serde(default)]
        light: Option<Light>,
    }
    #[derive(Deserialize)]
    struct Images {
        images: Vec<SplitOnly>,
    }
    let extra: Images = serde_json::from_str(&text).map_err(|e| DataError::json(path, e))?;
    let cats: BTreeMap<u64, String> = coco
        .categories
        .iter()
        .map(|c| (c.id, c.name.clone()))
        .collect();
    let mut index_of = BTreeMap::new();
    let mut out = Vec::new();
    for (img, ex) in coco.images.into_iter().zip(extra.images) {
        let record = format!("image id {}", img.id);
        if index_of.insert(img.id, out.len()).is_some() {
            return Err(DataError::invalid(path, record, "duplicate image id"));
        }
        let split = match ex.split.as_deref() {
            None => None,
            Some(s) => Some(parse_split(s).ok_or_else(|| {
                DataError::invalid(path, &record, format!("unknown split {s:?}"))
            })?),
        };
        out.push(SourceImage {
            ann_file: path.clone(),
            record,
            id: Some(img.id),
            image: root.join(&img.file_name),
            declared: Some((img.width, img.height)),
            scenario: ex.clutter.zip(ex.light),
            video: img.video,
            index: img.index,
            split,
            objects: Vec::new(),
        });
    }
    for ann in coco.annotations {
        let record = format!("annotation id {}", ann.id);
        let slot = index_of
            .get(&ann.image_id)
            .and_then(|&i| out.get_mut(i))
            .ok_or_else(|| {
                DataError::invalid(
                    path,
                    &record,
                    format!("image id {} does not exist", ann.image_id),
                )
            })?;
        let name = cats
            .get(&ann.category_id)
            .ok_or_else(|| DataError::UnknownClass {
                path: path.clone(),
                record: record.clone(),
                class: format!("category id {}", ann.category_id),
            })?;
        if let Some(class) = resolve_class(opts, path, &record, name, Some(ann.category_id))? {
            slot.objects.push((record, class, ann.to_bbox()));
        }
    }
    Ok(out)
}

#[derive(Deserialize)]
struct VocAnnotation {
    filename: String,
    size: Option<VocSize>,
    #[serde(default, rename = "object")]
    objects: Vec<VocObject>,
}

#[derive(Deserialize)]
struct VocSize {
    width: u32,
    height: u32,
}

#[derive(Deserialize)]
struct VocObject {
    name: String,
    bndbox: VocBox,
}

#[derive(Deserialize)]
struct VocBox {
    xmin: f32,
    ymin: f32,
    xmax: f32,
    ymax: f32,
}

fn read_voc(opts: &ImportOptions, root: &Path) -> Result<Vec<SourceImage>, DataError> {
    let input = &opts.input;
    let files: Vec<PathBuf> = if input.is_dir() {
        let mut v: Vec<PathBuf> = std::fs::read_dir(input)
            .map_err(|e| DataError::io(input, e))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("xml")))
            .collect();
        v.sort();
        v
    } else {
        vec![input.clone()]
    };
    let mut out = Vec::new();
    for file in files {
        let text = std::fs::read_to_string(&file).map_err(|e| DataError::io(&file, e))?;
        let ann: VocAnnotation = quick_xml::de::from_str(&text).map_err(|e| DataError::Xml {
            path: file.clone(),
            message: e.to_string(),
        })?;
        let mut objects = Vec::new();
        for (i, o) in ann.objects.iter().enumerate() {
            let record = format!("object {} ({})", i + 1, o.name);
            if let Some(class) = resolve_class(opts, &file, &record, &o.name, None)? {
                let b = &o.bndbox;
                objects.push((
                    record,
                    class,
                    BBox::new(b.xmin - 1.0, b.ymin - 1.0, b.xmax, b.ymax),
                ));
            }
        }
        out.push(SourceImage {
            ann_file: file.clone(),
            record: format!("filename {}", ann.filename),
            id: None,
            image: root.join(&ann.filename),
            declared: ann.size.map(|s| (s.width, s.height)),
            scenario: None,
            video: None,
            index: None,
            split: None,
            objects,
        });
    }
    Ok(out)
}

fn read_gtsdb(opts: &ImportOptions, root: &Path) -> Result<Vec<SourceImage>, DataError> {
    let path = &opts.input;
    let text = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    // Physical line of a byte offset (the csv crate does not count skipped blank lines).
    // A record's position may point at blank lines before it: skip those.
    let line_of = |byte: u64| {
        let mut at = byte as usize;
        while matches!(text.get(at), Some(b'\n' | b'\r')) {
            at += 1;
        }
        1 + text.iter().take(at).filter(|&&b| b == b'\n').count()
    };
    let mut reader = csv::ReaderBuilder::new()
        .delimiter(b';')
        .has_headers(false)
        .flexible(true)
        .from_reader(text.as_slice());
    let mut by_file: BTreeMap<String, usize> = BTreeMap::new();
    let mut out: Vec<SourceImage> = Vec::new();
    for (n, rec) in reader.records().enumerate() {
        let rec = rec.map_err(|e| DataError::Csv {
            path: path.clone(),
            record: e.position().map_or_else(
                || format!("record {}", n + 1),
                |p| format!("line {}", line_of(p.byte())),
            ),
            message: e.to_string(),
        })?;
        let line = rec.position().map_or(n + 1, |p| line_of(p.byte()));
        let record = format!("line {line}");
        let first = rec.get(0).unwrap_or("").trim();
        if n == 0 && (first.eq_ignore_ascii_case("file") || first.eq_ignore_ascii_case("filename"))
        {
            continue;
        }
        if rec.len() != 6 {
            return Err(DataError::Csv {
                path: path.clone(),
                record,
                message: format!(
                    "expected 6 fields file;x1;y1;x2;y2;class, found {}",
                    rec.len()
                ),
            });
        }
        let mut coords = [0f32; 4];
        for (k, name) in ["x1", "y1", "x2", "y2"].iter().enumerate() {
            let field = rec.get(k + 1).unwrap_or("").trim();
            coords[k] = field.parse().map_err(|_| DataError::Csv {
                path: path.clone(),
                record: record.clone(),
                message: format!("field {name} is not a number: {field:?}"),
            })?;
        }
        let class_name = rec.get(5).unwrap_or("").trim();
        let slot = *by_file.entry(first.to_owned()).or_insert_with(|| {
            out.push(SourceImage {
                ann_file: path.clone(),
                record: record.clone(),
                id: None,
                image: root.join(first),
                declared: None,
                scenario: None,
                video: None,
                index: None,
                split: None,
                objects: Vec::new(),
            });
            out.len() - 1
        });
        if let Some(class) =
            resolve_class(opts, path, &record, class_name, class_name.parse().ok())?
        {
            let bbox = BBox::new(coords[0], coords[1], coords[2] + 1.0, coords[3] + 1.0);
            out[slot].objects.push((record, class, bbox));
        }
    }
    Ok(out)
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

/// Import a dataset into `out` (written to `<out>.partial-XXXX`, then swapped in).
/// Images are decoded, checked against their annotations and stored as PNG frames.
pub fn import(opts: &ImportOptions, out: &Path) -> Result<Dataset, DataError> {
    let root = match &opts.images {
        Some(r) => r.clone(),
        None if opts.format == Format::Voc && opts.input.is_dir() => opts.input.clone(),
        None => opts.input.parent().map(Path::to_owned).unwrap_or_default(),
    };
    let sources = match opts.format {
        Format::Coco => read_coco(opts, &root)?,
        Format::Voc => read_voc(opts, &root)?,
        Format::Gtsdb => read_gtsdb(opts, &root)?,
    };
    if sources.is_empty() {
        return Err(DataError::Empty {
            path: opts.input.clone(),
            reason: "no images".into(),
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
    let converted: Vec<Result<FrameRecord, DataError>> = sources
        .par_iter()
        .zip(plan.par_iter())
        .enumerate()
        .map(|(n, (s, &(video, index, split)))| {
            convert(s, &dir, s.id.unwrap_or(n as u64), video, index, split)
        })
        .collect();
    let mut frames = Vec::with_capacity(converted.len());
    for f in converted {
        frames.push(f?);
    }
    let mut videos: BTreeMap<u32, VideoMeta> = BTreeMap::new();
    for (f, s) in frames.iter().zip(&sources) {
        let (clutter, light) = s.scenario.unwrap_or((opts.clutter, opts.light));
        let v = videos.entry(f.video).or_insert(VideoMeta {
            id: f.video,
            seed: 0,
            clutter,
            light,
            split: f.split,
            frames: 0,
        });
        if v.split != f.split {
            return Err(DataError::invalid(
                &opts.input,
                format!("video {}", f.video),
                format!("has frames in both {} and {}", v.split, f.split),
            ));
        }
        v.frames += 1;
    }
    let mut seen = std::collections::BTreeSet::new();
    for f in &frames {
        if !seen.insert((f.video, f.index)) {
            return Err(DataError::invalid(
                &opts.input,
                format!("image {}", f.file.display()),
                format!("video {} frame {} appears twice", f.video, f.index),
            ));
        }
    }
    let mut dataset = Dataset {
        root: dir.clone(),
        classes: classes(),
        videos: videos.into_values().collect(),
        frames,
    };
    dataset.write_metadata(
        &dir,
        Source::Imported {
            format: opts.format.name().to_owned(),
            from: opts.input.display().to_string(),
        },
    )?;
    partial.commit()?;
    dataset.root = out.to_owned();
    Ok(dataset)
}

fn convert(
    s: &SourceImage,
    dir: &Path,
    id: u64,
    video: u32,
    index: u32,
    split: Split,
) -> Result<FrameRecord, DataError> {
    if !s.image.is_file() {
        return Err(DataError::MissingImage {
            path: s.ann_file.clone(),
            record: s.record.clone(),
            image: s.image.clone(),
        });
    }
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
    let mut objects = Vec::with_capacity(s.objects.len());
    for (record, class, bbox) in &s.objects {
        check_box(&s.ann_file, record, *bbox, w, h)?;
        objects.push(Object {
            class: *class,
            bbox: *bbox,
        });
    }
    let file = crate::generate::frame_file(video, index);
    let path = dir.join(&file);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| DataError::io(parent, e))?;
    }
    std::fs::write(&path, encode_png(&img, &path)?).map_err(|e| DataError::io(&path, e))?;
    Ok(FrameRecord {
        id,
        file,
        width: w,
        height: h,
        video,
        index,
        split,
        objects,
    })
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
