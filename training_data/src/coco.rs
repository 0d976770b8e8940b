//! COCO JSON, as written into `annotations/<split>.json` and by `export`, and as read
//! by `import --format coco`. Unknown COCO fields (`info`, `licenses`,
//! `segmentation`, …) are ignored on reading.
use crate::{BBox, ClassInfo, DataError, FrameRecord, Object, Split};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// A COCO detection file.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CocoFile {
    /// Images.
    pub images: Vec<CocoImage>,
    /// Box annotations.
    #[serde(default)]
    pub annotations: Vec<CocoAnnotation>,
    /// Categories.
    pub categories: Vec<CocoCategory>,
}

/// One COCO image, with frugal's optional `video` / `index` extras.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CocoImage {
    /// Image id.
    pub id: u64,
    /// Path relative to the image root.
    pub file_name: String,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// frugal extra: the video id.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub video: Option<u32>,
    /// frugal extra: the frame index within the video.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub index: Option<u32>,
    /// frugal extra: the frame's time in seconds from the start of its video (imported
    /// video only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<f64>,
}

/// One COCO box annotation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CocoAnnotation {
    /// Annotation id.
    pub id: u64,
    /// The image it belongs to.
    pub image_id: u64,
    /// The category (`class id + 1` in frugal's files).
    pub category_id: u64,
    /// `[x, y, w, h]` in pixels.
    pub bbox: [f64; 4],
    /// `w * h`.
    #[serde(default)]
    pub area: f64,
    /// 1 for a crowd: an ignore region ([`crate::IgnoreRegion`]) of its category.
    #[serde(default)]
    pub iscrowd: u8,
}

/// One COCO category.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CocoCategory {
    /// Category id (`class id + 1` in frugal's files).
    pub id: u64,
    /// Name.
    pub name: String,
    /// frugal writes `"sign"` for the synthetic signs, `"object"` otherwise.
    #[serde(default)]
    pub supercategory: String,
    /// frugal extra: the road sign code.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub code: Option<String>,
}

impl CocoAnnotation {
    /// The COCO form of an object.
    pub fn from_object(id: u64, image_id: u64, o: &Object) -> Self {
        // width and height in f64: exact differences of the f32 corners
        let (x, y) = (f64::from(o.bbox.x1), f64::from(o.bbox.y1));
        let (w, h) = (f64::from(o.bbox.x2) - x, f64::from(o.bbox.y2) - y);
        CocoAnnotation {
            id,
            image_id,
            category_id: u64::from(o.class) + 1,
            bbox: [x, y, w, h],
            area: w * h,
            iscrowd: 0,
        }
    }

    /// The box as a [`BBox`].
    pub fn to_bbox(&self) -> BBox {
        // the right and bottom edges are summed in f64, so a box written by
        // [`CocoAnnotation::from_object`] reads back to the same f32 corners
        let [x, y, w, h] = self.bbox;
        BBox::new(x as f32, y as f32, (x + w) as f32, (y + h) as f32)
    }
}

impl CocoCategory {
    /// The COCO form of a class.
    pub fn from_class(c: &ClassInfo) -> Self {
        CocoCategory {
            id: u64::from(c.id) + 1,
            name: c.name.clone(),
            supercategory: if c.code.is_empty() { "object" } else { "sign" }.to_owned(),
            code: (!c.code.is_empty()).then(|| c.code.clone()),
        }
    }
}

/// Check that `bbox` is a proper box inside a `width × height` image.
pub fn check_box(
    path: &Path,
    record: &str,
    bbox: BBox,
    width: u32,
    height: u32,
) -> Result<(), DataError> {
    let ok = bbox.is_valid()
        && bbox.x1 >= 0.0
        && bbox.y1 >= 0.0
        && bbox.x2 <= width as f32
        && bbox.y2 <= height as f32;
    if ok {
        Ok(())
    } else {
        Err(DataError::BoxOutside {
            path: path.to_owned(),
            record: record.to_owned(),
            x1: bbox.x1,
            y1: bbox.y1,
            x2: bbox.x2,
            y2: bbox.y2,
            width,
            height,
        })
    }
}

/// The image an annotation names: `items[at]`, where `at` is the image's position
/// (`None`: no image has that id, an error naming the annotation's `record`).
pub(crate) fn annotated_image<'a, T>(
    items: &'a mut [T],
    at: Option<usize>,
    path: &Path,
    record: &str,
    image_id: u64,
) -> Result<&'a mut T, DataError> {
    at.and_then(|i| items.get_mut(i)).ok_or_else(|| {
        DataError::invalid(path, record, format!("image id {image_id} does not exist"))
    })
}

impl CocoFile {
    /// Parse a COCO file.
    pub fn read(path: &Path) -> Result<CocoFile, DataError> {
        let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
        serde_json::from_str(&text).map_err(|e| DataError::json(path, e))
    }

    /// The frames of a frugal annotation file: categories must be `class id + 1` with
    /// the manifest's names, images must carry `video` and `index`, boxes must lie
    /// inside their images.
    pub fn into_frames(
        self,
        path: &Path,
        classes: &[ClassInfo],
        split: Split,
    ) -> Result<Vec<FrameRecord>, DataError> {
        for cat in &self.categories {
            let ok = cat
                .id
                .checked_sub(1)
                .and_then(|i| classes.get(i as usize))
                .is_some_and(|c| c.name == cat.name);
            if !ok {
                return Err(DataError::UnknownClass {
                    path: path.to_owned(),
                    record: format!("category id {}", cat.id),
                    class: cat.name.clone(),
                });
            }
        }
        let mut index_of: HashMap<u64, usize> = HashMap::new();
        let mut frames = Vec::with_capacity(self.images.len());
        for img in self.images {
            let record = format!("image id {}", img.id);
            let (Some(video), Some(index)) = (img.video, img.index) else {
                return Err(DataError::invalid(
                    path,
                    record,
                    "lacks the `video` / `index` fields",
                ));
            };
            if index_of.insert(img.id, frames.len()).is_some() {
                return Err(DataError::invalid(path, record, "duplicate image id"));
            }
            frames.push(FrameRecord {
                id: img.id,
                file: PathBuf::from(img.file_name),
                width: img.width,
                height: img.height,
                video,
                index,
                split,
                objects: Vec::new(),
                ignore: Vec::new(),
                time_s: img.time,
            });
        }
        for ann in self.annotations {
            let record = format!("annotation id {}", ann.id);
            let at = index_of.get(&ann.image_id).copied();
            let frame = annotated_image(&mut frames, at, path, &record, ann.image_id)?;
            let class = ann
                .category_id
                .checked_sub(1)
                .filter(|&c| (c as usize) < classes.len())
                .ok_or_else(|| DataError::UnknownClass {
                    path: path.to_owned(),
                    record: record.clone(),
                    class: ann.category_id.to_string(),
                })?;
            let bbox = ann.to_bbox();
            check_box(path, &record, bbox, frame.width, frame.height)?;
            let class = class as crate::ClassId;
            if ann.iscrowd != 0 {
                frame.ignore.push(crate::IgnoreRegion {
                    class: Some(class),
                    bbox,
                });
            } else {
                frame.objects.push(Object { class, bbox });
            }
        }
        Ok(frames)
    }
}
