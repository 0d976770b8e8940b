//! The still-image readers: COCO JSON, Pascal VOC XML and GTSDB-style CSV, each into
//! the shared source records that [`super::import`] checks and writes.
use super::classes::ClassTable;
use super::{ImportOptions, SourceBox, SourceImage};
use crate::coco::CocoFile;
use crate::{BBox, ClassId, Clutter, DataError, Light, Split};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn parse_split(s: &str) -> Option<Split> {
    Split::ALL.into_iter().find(|x| x.name() == s)
}

pub(super) fn read_coco(
    opts: &ImportOptions,
    root: &Path,
    table: &mut ClassTable,
) -> Result<Vec<SourceImage>, DataError> {
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
    // Categories in id order (id 0 is as valid as any), so the class list follows the
    // source's declaration; a dropped category maps to `None`.
    let mut cats: BTreeMap<u64, (String, Option<ClassId>)> = BTreeMap::new();
    let mut sorted: Vec<_> = coco.categories.iter().collect();
    sorted.sort_by_key(|c| c.id);
    for c in sorted {
        let record = format!("category id {}", c.id);
        if cats.contains_key(&c.id) {
            return Err(DataError::invalid(path, record, "duplicate category id"));
        }
        let class = table.resolve(path, &record, &c.name, Some(c.id))?;
        if let (Some(id), Some(code)) = (class, &c.code) {
            table.note_code(id, code);
        }
        cats.insert(c.id, (c.name.clone(), class));
    }
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
        let at = index_of.get(&ann.image_id).copied();
        let slot = crate::coco::annotated_image(&mut out, at, path, &record, ann.image_id)?;
        let (_, class) = cats
            .get(&ann.category_id)
            .ok_or_else(|| DataError::UnknownClass {
                path: path.clone(),
                record: record.clone(),
                class: format!("category id {}", ann.category_id),
            })?;
        if let Some(class) = *class {
            slot.objects.push(SourceBox {
                record,
                class,
                bbox: ann.to_bbox(),
                ignore: ann.iscrowd != 0,
            });
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
    /// 1: not scored by the VOC devkit (an ignore region here).
    #[serde(default)]
    difficult: Option<String>,
}

#[derive(Deserialize)]
struct VocBox {
    xmin: f32,
    ymin: f32,
    xmax: f32,
    ymax: f32,
}

pub(super) fn read_voc(
    opts: &ImportOptions,
    root: &Path,
    table: &mut ClassTable,
) -> Result<Vec<SourceImage>, DataError> {
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
            if let Some(class) = table.resolve(&file, &record, &o.name, None)? {
                let b = &o.bndbox;
                let ignore = o.difficult.as_deref().is_some_and(|d| d.trim() == "1");
                objects.push(SourceBox {
                    record,
                    class,
                    bbox: BBox::new(b.xmin - 1.0, b.ymin - 1.0, b.xmax, b.ymax),
                    ignore,
                });
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

pub(super) fn read_gtsdb(
    opts: &ImportOptions,
    root: &Path,
    table: &mut ClassTable,
) -> Result<Vec<SourceImage>, DataError> {
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
        if let Some(class) = table.resolve(path, &record, class_name, class_name.parse().ok())? {
            let bbox = BBox::new(coords[0], coords[1], coords[2] + 1.0, coords[3] + 1.0);
            out[slot].objects.push(SourceBox {
                record,
                class,
                bbox,
                ignore: false,
            });
        }
    }
    Ok(out)
}
