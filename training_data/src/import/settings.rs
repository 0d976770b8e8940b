//! An import described as data: the `[import]` section of a run config, or the file
//! `frugal data import --config` reads. Paths are as given (relative to the folder the
//! command runs in).
use super::{ClassList, ClassMap, Format, ImportOptions};
use crate::media::Sampling;
use crate::{Clutter, DataError, Light, NavAction, Split};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn source() -> String {
    "source".into()
}

fn pedestrian() -> String {
    "pedestrian".into()
}

fn medium() -> Clutter {
    Clutter::Medium
}

fn normal() -> Light {
    Light::Normal
}

/// How to import a dataset (see [`ImportOptions`] for each value's meaning).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImportSettings {
    /// `coco`, `voc`, `gtsdb`, `mot`, `cvat`, `coco-video` or `imagenet-vid`.
    pub format: String,
    /// The annotation file (or VOC / ImageNet VID folder).
    pub annotations: PathBuf,
    /// Video formats: the video file or image folder with the frames.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub video: Option<PathBuf>,
    /// Folder the annotations' image paths are relative to.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub images: Option<PathBuf>,
    /// Frame rate of an image folder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fps: Option<f64>,
    /// Keep one frame in this many (0 or 1: all).
    #[serde(default)]
    pub every: u32,
    /// Keep at most this many frames per second.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_fps: Option<f64>,
    /// Start of the time window, seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start_s: Option<f64>,
    /// End of the time window, seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub end_s: Option<f64>,
    /// Fractions of each video for train, val and test, in time order.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_split: Option<[f64; 3]>,
    /// Everything into this split.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub split: Option<Split>,
    /// `source`, `signs`, or a file of class names.
    #[serde(default = "source")]
    pub classes: String,
    /// Source class → class it becomes.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub class_map: BTreeMap<String, String>,
    /// Keep only mapped classes / drop classes outside the list.
    #[serde(default)]
    pub drop_unmapped: bool,
    /// Class name → what the drone does on it.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub actions: BTreeMap<String, NavAction>,
    /// The class of formats without a class column.
    #[serde(default = "pedestrian")]
    pub default_class: String,
    /// MOT: boxes less visible than this are marked ignore.
    #[serde(default)]
    pub min_visibility: f32,
    /// Missing images are an error.
    #[serde(default)]
    pub strict: bool,
    /// Clutter level recorded for the videos.
    #[serde(default = "medium")]
    pub clutter: Clutter,
    /// Light level recorded for the videos.
    #[serde(default = "normal")]
    pub light: Light,
}

impl ImportSettings {
    /// Settings with defaults for `format` and an annotation file.
    pub fn new(format: &str, annotations: impl Into<PathBuf>) -> Self {
        Self {
            format: format.into(),
            annotations: annotations.into(),
            video: None,
            images: None,
            fps: None,
            every: 0,
            sample_fps: None,
            start_s: None,
            end_s: None,
            time_split: None,
            split: None,
            classes: source(),
            class_map: BTreeMap::new(),
            drop_unmapped: false,
            actions: BTreeMap::new(),
            default_class: pedestrian(),
            min_visibility: 0.0,
            strict: false,
            clutter: medium(),
            light: normal(),
        }
    }

    /// Read settings from a TOML or JSON file.
    pub fn from_file(path: &Path) -> Result<Self, DataError> {
        let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
        if path.extension().is_some_and(|e| e == "json") {
            serde_json::from_str(&text).map_err(|e| DataError::json(path, e))
        } else {
            toml::from_str(&text).map_err(|e| DataError::Config {
                path: path.to_owned(),
                message: e.to_string(),
            })
        }
    }

    /// The import options these settings describe.
    pub fn options(&self) -> Result<ImportOptions, DataError> {
        let format = Format::from_name(&self.format).ok_or_else(|| {
            DataError::invalid(
                &self.annotations,
                "format",
                format!(
                    "unknown format {:?} (one of {})",
                    self.format,
                    Format::ALL.map(Format::name).join(", ")
                ),
            )
        })?;
        let mut o = ImportOptions::new(format, &self.annotations);
        o.images.clone_from(&self.images);
        o.video.clone_from(&self.video);
        o.fps = self.fps;
        o.sampling = Sampling {
            every: self.every,
            fps: self.sample_fps,
            start_s: self.start_s,
            end_s: self.end_s,
            ..Sampling::default()
        };
        o.time_split = self.time_split;
        o.split = self.split;
        o.classes = ClassList::parse(&self.classes)?;
        o.class_map =
            ClassMap::from_pairs(self.class_map.iter().map(|(k, v)| (k.as_str(), v.as_str())));
        o.drop_unmapped = self.drop_unmapped;
        o.actions.clone_from(&self.actions);
        o.default_class.clone_from(&self.default_class);
        o.min_visibility = self.min_visibility;
        o.strict = self.strict;
        o.clutter = self.clutter;
        o.light = self.light;
        Ok(o)
    }
}
