//! The dataset form shared by the generator and the importers, and its on-disk layout:
//!
//! ```text
//! <root>/manifest.json                      format version, source (config), classes, videos, counts
//! <root>/annotations/{train,val,test}.json  COCO, one file per split
//! <root>/frames/v0007/000012.png            frame 12 of video 7
//! ```
//!
//! COCO conventions: `category_id = class id + 1` (0 stays free for "background"),
//! `bbox = [x, y, w, h]` in pixels with `x + w` the exclusive right edge (the same
//! convention as [`BBox`]), image ids are the frame ids, and images carry the extra
//! fields `video` and `index`.
use crate::coco::{CocoAnnotation, CocoCategory, CocoFile, CocoImage};
use crate::{BBox, ClassId, ClassInfo, DataError, GenConfig};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

/// The manifest's format name.
pub const FORMAT_NAME: &str = "frugal-data";
/// The manifest's format version; [`Dataset::load`] refuses any other.
pub const FORMAT_VERSION: u32 = 1;

/// A split of the dataset; videos (never single frames) are assigned to splits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    /// Training videos.
    Train,
    /// Validation videos (model selection, policy estimation).
    Val,
    /// Held-out test videos.
    Test,
}

impl Split {
    /// All splits in order.
    pub const ALL: [Split; 3] = [Split::Train, Split::Val, Split::Test];

    /// `train`, `val` or `test`.
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Val => "val",
            Split::Test => "test",
        }
    }
}

impl std::fmt::Display for Split {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How much is going on in the background.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Clutter {
    /// Few, low-contrast objects.
    Low,
    /// Some shelves, boxes, a person, a sign-like distractor or two.
    Medium,
    /// Dense shelving, people and many high-contrast sign-like distractors.
    High,
}

impl Clutter {
    /// Every level, lowest first.
    pub const ALL: [Clutter; 3] = [Clutter::Low, Clutter::Medium, Clutter::High];

    /// `low`, `medium` or `high`.
    pub fn name(self) -> &'static str {
        match self {
            Clutter::Low => "low",
            Clutter::Medium => "medium",
            Clutter::High => "high",
        }
    }
}

/// Illumination.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Light {
    /// Normal indoor light.
    Normal,
    /// Dim: darker, noisier, lower contrast.
    Low,
}

impl Light {
    /// Every level, normal first.
    pub const ALL: [Light; 2] = [Light::Normal, Light::Low];

    /// `normal` or `low`.
    pub fn name(self) -> &'static str {
        match self {
            Light::Normal => "normal",
            Light::Low => "low",
        }
    }
}

/// One video's metadata.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VideoMeta {
    /// Video id (unique in the dataset).
    pub id: u32,
    /// The seed the video was rendered from (0 for imported sets).
    pub seed: u64,
    /// Clutter level (for imported sets: as declared at import).
    pub clutter: Clutter,
    /// Illumination level (for imported sets: as declared at import).
    pub light: Light,
    /// The split every frame of this video belongs to.
    pub split: Split,
    /// Number of frames.
    pub frames: u32,
    /// The source video's name (imported sets; a time segment of a source video is
    /// named `<name>#<first>-<last>` with its source frame indices).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Frame rate in frames per second, when the source says (imported video); the
    /// synthetic videos and flight recordings run at 30.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fps: Option<f64>,
}

/// The frame rate of videos that do not state one (synthetic and flight videos).
pub const DEFAULT_FPS: f64 = 30.0;

impl VideoMeta {
    /// The video's frame rate: its own, else [`DEFAULT_FPS`].
    pub fn fps(&self) -> f64 {
        self.fps
            .filter(|f| f.is_finite() && *f > 0.0)
            .unwrap_or(DEFAULT_FPS)
    }
}

/// One annotated sign.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Object {
    /// Its class.
    pub class: ClassId,
    /// Its box (clipped to the frame).
    pub bbox: BBox,
}

/// A region where detections are not scored: a crowd (COCO `iscrowd`), a distractor
/// or a barely visible object (MOT), a `difficult` object (Pascal VOC). Evaluation
/// counts it neither as a miss when nothing is found there nor as a false alarm when
/// a detection falls in it (see `frugal_models::metrics`); training does not use it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IgnoreRegion {
    /// The class whose detections it excuses; `None`: detections of any class (an
    /// ignore box of a class the dataset does not keep, such as MOT's distractors).
    pub class: Option<ClassId>,
    /// Its box (clipped to the frame).
    pub bbox: BBox,
}

/// One frame and its annotations.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameRecord {
    /// Frame id, unique in the dataset (the COCO image id).
    pub id: u64,
    /// PNG file, relative to the dataset root.
    pub file: PathBuf,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The video it belongs to.
    pub video: u32,
    /// Its index within the video.
    pub index: u32,
    /// Its split (that of its video).
    pub split: Split,
    /// The signs in it.
    pub objects: Vec<Object>,
    /// Its ignore regions (imported sets; empty for synthetic frames).
    pub ignore: Vec<IgnoreRegion>,
    /// Its presentation time in seconds from the start of its video, when the source
    /// gives real time (imported video); otherwise `index / fps` (see
    /// [`Dataset::frame_time`]).
    pub time_s: Option<f64>,
}

/// Where a dataset came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum Source {
    /// Made by [`crate::generate`](fn@crate::generate).
    Synthetic {
        /// The generator's configuration.
        config: GenConfig,
        /// [`GenConfig::hash`] of it.
        config_hash: String,
        /// [`crate::GENERATOR_VERSION`] at the time.
        generator_version: u32,
    },
    /// Made by an importer.
    Imported {
        /// `coco`, `voc`, `gtsdb`, `mot`, `cvat`, `coco-video` or `imagenet-vid`.
        format: String,
        /// The file or folder it was imported from, as given.
        from: String,
        /// What the import skipped or changed.
        #[serde(default, skip_serializing_if = "crate::import::ImportCounts::is_zero")]
        counts: crate::import::ImportCounts,
    },
    /// Recorded from simulated maze flights (`frugal fly --record`): one video per
    /// flight, the renderer's exact boxes as annotations.
    Flight {
        /// The maze files flown, as given.
        mazes: Vec<String>,
        /// The flights' seeds.
        seeds: Vec<u64>,
        /// One frame kept every this many processed frames.
        every: u64,
        /// The perception that flew (it sets which frames were processed).
        perception: String,
    },
}

/// Frame and object counts of one split.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Counts {
    /// Videos.
    pub videos: u32,
    /// Frames.
    pub frames: u64,
    /// Annotated objects.
    pub objects: u64,
}

/// `manifest.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Always [`FORMAT_NAME`].
    pub format: String,
    /// [`FORMAT_VERSION`].
    pub format_version: u32,
    /// Where the data came from.
    pub source: Source,
    /// The classes, in id order.
    pub classes: Vec<ClassInfo>,
    /// The videos, in id order.
    pub videos: Vec<VideoMeta>,
    /// Counts per split.
    pub counts: BTreeMap<Split, Counts>,
}

/// A loaded dataset: metadata and annotations (pixels are read on demand).
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// The dataset folder.
    pub root: PathBuf,
    /// The classes, in id order.
    pub classes: Vec<ClassInfo>,
    /// The videos, in id order.
    pub videos: Vec<VideoMeta>,
    /// Every frame, in id order.
    pub frames: Vec<FrameRecord>,
}

impl Dataset {
    /// Read `manifest.json` and the three COCO files under `root`, checking that every
    /// reference (class, video, image) resolves and every box lies inside its frame.
    pub fn load(root: &Path) -> Result<Dataset, DataError> {
        let manifest = read_manifest(root)?;
        let mut frames = Vec::new();
        for split in Split::ALL {
            let path = root.join("annotations").join(format!("{split}.json"));
            let coco = CocoFile::read(&path)?;
            frames.extend(coco.into_frames(&path, &manifest.classes, split)?);
        }
        frames.sort_by_key(|f| f.id);
        let videos: HashMap<u32, &VideoMeta> = manifest.videos.iter().map(|v| (v.id, v)).collect();
        let manifest_path = root.join("manifest.json");
        for pair in frames.windows(2) {
            if pair[0].id == pair[1].id {
                return Err(DataError::invalid(
                    &manifest_path,
                    format!("frame id {}", pair[0].id),
                    "appears in more than one split",
                ));
            }
        }
        for f in &frames {
            let video = videos.get(&f.video).ok_or_else(|| {
                DataError::invalid(
                    &manifest_path,
                    format!("frame {} ({})", f.id, f.file.display()),
                    format!("video {} is not in the manifest", f.video),
                )
            })?;
            if video.split != f.split {
                return Err(DataError::invalid(
                    &manifest_path,
                    format!("frame {} ({})", f.id, f.file.display()),
                    format!(
                        "is in {} but its video {} is in {}",
                        f.split, f.video, video.split
                    ),
                ));
            }
        }
        Ok(Dataset {
            root: root.to_owned(),
            classes: manifest.classes,
            videos: manifest.videos,
            frames,
        })
    }

    /// The frames of one split, in id order.
    pub fn split(&self, split: Split) -> impl Iterator<Item = &FrameRecord> {
        self.frames.iter().filter(move |f| f.split == split)
    }

    /// A video's metadata.
    pub fn video(&self, id: u32) -> Option<&VideoMeta> {
        self.videos.iter().find(|v| v.id == id)
    }

    /// A frame's time in seconds from the start of its video: the recorded
    /// presentation time, else its index over the video's frame rate.
    pub fn frame_time(&self, frame: &FrameRecord) -> f64 {
        frame.time_s.unwrap_or_else(|| {
            let fps = self.video(frame.video).map_or(DEFAULT_FPS, VideoMeta::fps);
            f64::from(frame.index) / fps
        })
    }

    /// The absolute path of a frame's image.
    pub fn frame_path(&self, frame: &FrameRecord) -> PathBuf {
        self.root.join(&frame.file)
    }

    /// Decode a frame as RGB8, checking its size against the annotation.
    pub fn load_rgb(&self, frame: &FrameRecord) -> Result<image::RgbImage, DataError> {
        let path = self.frame_path(frame);
        let img = image::open(&path).map_err(|e| match e {
            image::ImageError::IoError(io) => DataError::io(&path, io),
            other => DataError::image(&path, other),
        })?;
        let rgb = img.to_rgb8();
        if rgb.dimensions() != (frame.width, frame.height) {
            return Err(DataError::invalid(
                &path,
                format!("frame {}", frame.id),
                format!(
                    "image is {}x{} but the annotation says {}x{}",
                    rgb.width(),
                    rgb.height(),
                    frame.width,
                    frame.height
                ),
            ));
        }
        Ok(rgb)
    }

    /// Counts per split.
    pub fn counts(&self) -> BTreeMap<Split, Counts> {
        let mut counts: BTreeMap<Split, Counts> = Split::ALL
            .into_iter()
            .map(|s| (s, Counts::default()))
            .collect();
        for v in &self.videos {
            if let Some(c) = counts.get_mut(&v.split) {
                c.videos += 1;
            }
        }
        for f in &self.frames {
            if let Some(c) = counts.get_mut(&f.split) {
                c.frames += 1;
                c.objects += f.objects.len() as u64;
            }
        }
        counts
    }

    /// The COCO form of one split (`category_id = class id + 1`).
    pub fn to_coco(&self, split: Option<Split>) -> CocoFile {
        let frames: Vec<&FrameRecord> = self
            .frames
            .iter()
            .filter(|f| split.is_none_or(|s| f.split == s))
            .collect();
        let mut annotations = Vec::new();
        for f in &frames {
            for o in &f.objects {
                annotations.push(CocoAnnotation::from_object(
                    annotations.len() as u64 + 1,
                    f.id,
                    o,
                ));
            }
            // ignore regions are COCO crowds, which excuse detections of their own
            // category only: a region of any class is one crowd per class
            for r in &f.ignore {
                let classes = match r.class {
                    Some(c) => c..c + 1,
                    None => 0..self.classes.len() as ClassId,
                };
                for class in classes {
                    let o = Object {
                        class,
                        bbox: r.bbox,
                    };
                    let mut a = CocoAnnotation::from_object(annotations.len() as u64 + 1, f.id, &o);
                    a.iscrowd = 1;
                    annotations.push(a);
                }
            }
        }
        CocoFile {
            images: frames
                .iter()
                .map(|f| CocoImage {
                    id: f.id,
                    file_name: f.file.to_string_lossy().replace('\\', "/"),
                    width: f.width,
                    height: f.height,
                    video: Some(f.video),
                    index: Some(f.index),
                    time: f.time_s,
                })
                .collect(),
            annotations,
            categories: self.classes.iter().map(CocoCategory::from_class).collect(),
        }
    }

    /// Write `manifest.json` and the three COCO files into `dir` (frames must already be
    /// there). Each file is written to a temporary name first and renamed.
    pub fn write_metadata(&self, dir: &Path, source: Source) -> Result<(), DataError> {
        let ann = dir.join("annotations");
        std::fs::create_dir_all(&ann).map_err(|e| DataError::io(&ann, e))?;
        for split in Split::ALL {
            let path = ann.join(format!("{split}.json"));
            write_json_atomic(&path, &self.to_coco(Some(split)))?;
        }
        let manifest = Manifest {
            format: FORMAT_NAME.to_owned(),
            format_version: FORMAT_VERSION,
            source,
            classes: self.classes.clone(),
            videos: self.videos.clone(),
            counts: self.counts(),
        };
        write_json_atomic(&dir.join("manifest.json"), &manifest)
    }
}

/// Read and check `<root>/manifest.json`.
pub fn read_manifest(root: &Path) -> Result<Manifest, DataError> {
    let path = root.join("manifest.json");
    let text = std::fs::read_to_string(&path).map_err(|e| DataError::io(&path, e))?;
    let manifest: Manifest = serde_json::from_str(&text).map_err(|e| DataError::json(&path, e))?;
    if manifest.format != FORMAT_NAME || manifest.format_version != FORMAT_VERSION {
        return Err(DataError::invalid(
            &path,
            "format",
            format!(
                "is {:?} version {}, this build reads {FORMAT_NAME:?} version {FORMAT_VERSION}",
                manifest.format, manifest.format_version
            ),
        ));
    }
    for (i, c) in manifest.classes.iter().enumerate() {
        if usize::from(c.id) != i {
            return Err(DataError::invalid(
                &path,
                format!("class {i}"),
                format!("has id {}", c.id),
            ));
        }
    }
    Ok(manifest)
}

/// Serialize `value` as pretty JSON into `path` through a temporary file in the same
/// folder, so a crash never leaves a half-written file under the final name.
pub fn write_json_atomic<T: Serialize>(path: &Path, value: &T) -> Result<(), DataError> {
    let mut bytes = serde_json::to_vec_pretty(value).map_err(|e| DataError::json(path, e))?;
    bytes.push(b'\n');
    write_atomic(path, &bytes)
}

/// Write `bytes` into `path` through a temporary file in the same folder and a rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), DataError> {
    use std::io::Write;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir).map_err(|e| DataError::io(&dir, e))?;
    let mut tmp = tempfile::NamedTempFile::new_in(&dir).map_err(|e| DataError::io(&dir, e))?;
    tmp.write_all(bytes).map_err(|e| DataError::io(path, e))?;
    // Temporary files are created private (0600); results are ordinary files.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644))
            .map_err(|e| DataError::io(path, e))?;
    }
    tmp.persist(path)
        .map_err(|e| DataError::io(path, e.error))?;
    Ok(())
}

/// A dataset folder under construction: everything is written into
/// `<out>.partial-XXXX` beside `out`, and [`PartialDir::commit`] swaps it into place,
/// so an interrupted run never replaces a good dataset. Dropped without commit, the
/// partial folder is removed.
pub struct PartialDir {
    dir: tempfile::TempDir,
    out: PathBuf,
}

impl PartialDir {
    /// Start a partial folder for `out`.
    pub fn new(out: &Path) -> Result<Self, DataError> {
        let parent = match out.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent).map_err(|e| DataError::io(&parent, e))?;
        let name = out
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "dataset".into());
        let dir = tempfile::Builder::new()
            .prefix(&format!("{name}.partial-"))
            .tempdir_in(&parent)
            .map_err(|e| DataError::io(&parent, e))?;
        Ok(Self {
            dir,
            out: out.to_owned(),
        })
    }

    /// The folder to write into.
    pub fn path(&self) -> &Path {
        self.dir.path()
    }

    /// Move the finished folder to `out`, replacing what was there.
    pub fn commit(self) -> Result<(), DataError> {
        let partial = self.dir.keep();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&partial, std::fs::Permissions::from_mode(0o755))
                .map_err(|e| DataError::io(&partial, e))?;
        }
        if self.out.exists() {
            let old = partial.with_extension("old");
            std::fs::rename(&self.out, &old).map_err(|e| DataError::io(&self.out, e))?;
            std::fs::rename(&partial, &self.out).map_err(|e| DataError::io(&self.out, e))?;
            std::fs::remove_dir_all(&old).map_err(|e| DataError::io(&old, e))?;
        } else {
            std::fs::rename(&partial, &self.out).map_err(|e| DataError::io(&self.out, e))?;
        }
        Ok(())
    }
}
