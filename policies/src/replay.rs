//! The replay log: every variant run once on every frame of the chosen videos, the
//! top detections and the ground truth stored per frame, saved as JSON so that
//! `policy train` and `policy eval` never re-run a detector.

use crate::error::{PolicyError, Result};
use crate::variants::{Buckets, FamilyInfo, FrameContext, VariantInfo, VariantSet};
use frugal_data::{Clutter, Dataset, IgnoreRegion, Light, Split};
use frugal_runtime::{BBox, ClassId, Detection, FrameRef};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The log's format name.
pub const LOG_FORMAT: &str = "frugal-replay";
/// The log's format version.
pub const LOG_VERSION: u32 = 1;
/// Default cap on detections kept per frame and variant.
pub const DEFAULT_MAX_DETECTIONS: usize = 8;

/// A detection or object in the log: class, score, box `[x1, y1, x2, y2]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Det {
    /// Class.
    pub class: ClassId,
    /// Score on the variant's family scale (1 for ground truth).
    pub score: f32,
    /// Box corners.
    pub bbox: [f32; 4],
}

impl Det {
    /// The box.
    pub fn bbox(&self) -> BBox {
        BBox::new(self.bbox[0], self.bbox[1], self.bbox[2], self.bbox[3])
    }

    /// As a runtime detection.
    pub fn detection(&self) -> Detection {
        Detection {
            bbox: self.bbox(),
            score: self.score,
            class: self.class,
        }
    }

    /// From a runtime detection.
    pub fn from_detection(d: &Detection) -> Self {
        Self {
            class: d.class,
            score: d.score,
            bbox: [d.bbox.x1, d.bbox.y1, d.bbox.x2, d.bbox.y2],
        }
    }
}

/// One frame: its truth and every variant's detections.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameLog {
    /// Index in the video.
    pub index: u32,
    /// Ground-truth objects (score 1).
    pub truth: Vec<Det>,
    /// `detections[v]`: variant `v`'s detections, best first (empty before recording).
    pub detections: Vec<Vec<Det>>,
    /// Ignore regions (see [`frugal_data::IgnoreRegion`]): detections there are not
    /// scored.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ignore: Vec<IgnoreBox>,
    /// Presentation time in seconds from the start of the video, when the source gives
    /// real time (imported video): the streaming clock then runs on it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_s: Option<f64>,
}

/// An ignore region in the log: the class whose detections it excuses (`None`: any)
/// and its box `[x1, y1, x2, y2]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct IgnoreBox {
    /// Class, or any.
    pub class: Option<ClassId>,
    /// Box corners.
    pub bbox: [f32; 4],
}

impl IgnoreBox {
    /// The region.
    pub fn region(&self) -> IgnoreRegion {
        IgnoreRegion {
            class: self.class,
            bbox: BBox::new(self.bbox[0], self.bbox[1], self.bbox[2], self.bbox[3]),
        }
    }
}

impl FrameLog {
    /// The best score of variant `v` on this frame (`None`: it found nothing).
    pub fn best_score(&self, v: usize) -> Option<f32> {
        self.detections
            .get(v)
            .and_then(|d| d.iter().map(|d| d.score).reduce(f32::max))
    }
}

/// One video.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VideoLog {
    /// Video id.
    pub id: u32,
    /// Clutter level.
    pub clutter: Clutter,
    /// Illumination.
    pub light: Light,
    /// Split.
    pub split: Split,
    /// Frame width.
    pub width: u32,
    /// Frame height.
    pub height: u32,
    /// Frames in order.
    pub frames: Vec<FrameLog>,
}

impl VideoLog {
    /// When each frame reaches the perception (ms from the first): the frames' own
    /// times when every frame has one (imported video), else one frame every
    /// `1 / fps` seconds.
    pub fn arrivals_ms(&self, fps: f64) -> Vec<f64> {
        let times: Option<Vec<f64>> = self.frames.iter().map(|f| f.time_s).collect();
        match times {
            Some(t) if !t.is_empty() => t.iter().map(|s| (s - t[0]) * 1000.0).collect(),
            _ => crate::stream::arrivals(self.frames.len(), fps),
        }
    }
}

/// The whole log.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplayLog {
    /// [`LOG_FORMAT`].
    pub format: String,
    /// [`LOG_VERSION`].
    pub version: u32,
    /// The dataset folder the frames come from (empty for in-memory clips). A dataset
    /// inside the log's own folder is saved relative to that folder, so the two can
    /// move together (a run stage's folder is renamed when it finishes); [`Self::load`]
    /// resolves it again.
    pub dataset: PathBuf,
    /// Number of classes.
    pub classes: usize,
    /// Detector families.
    pub families: Vec<FamilyInfo>,
    /// Variants, cheapest first.
    pub variants: Vec<VariantInfo>,
    /// Detections kept per frame and variant.
    pub max_detections: usize,
    /// Median latency (ms, the measuring machine) of the reference detector, timed with
    /// the variants (`frugal pareto`): what a device profile's speed is scaled from
    /// ([`crate::budget::BudgetConfig::device_slowdown`]). `None` when the variants
    /// file gave none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_ms: Option<f64>,
    /// The same for the int8 reference detector: what the device's int8 speed is scaled
    /// from ([`crate::budget::BudgetConfig::device_slowdown_int8`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_int8_ms: Option<f64>,
    /// The videos.
    pub videos: Vec<VideoLog>,
}

impl ReplayLog {
    /// The bucket edges of variant `v`.
    pub fn buckets(&self, v: usize) -> Buckets {
        self.families[self.variants[v].family].buckets
    }

    /// The videos of one split.
    pub fn split(&self, split: Split) -> impl Iterator<Item = &VideoLog> {
        self.videos.iter().filter(move |v| v.split == split)
    }

    /// Add the training videos of `other` (another log of the same variants, in the
    /// same order, e.g. replayed on recorded flight footage) to this log's training
    /// videos, with fresh ids. This log's families and buckets stay: the scores are the
    /// variants' own, so this log's (calibrated) edges apply to `other`'s detections.
    /// `other_path` names `other` in errors. Returns how many videos were added.
    ///
    /// The added videos' frames live in `other`'s dataset: train on the result, but
    /// evaluate on this log alone.
    pub fn absorb_training(&mut self, other: ReplayLog, other_path: &Path) -> Result<usize> {
        let names = |l: &ReplayLog| {
            l.variants
                .iter()
                .map(|v| v.name.clone())
                .collect::<Vec<_>>()
        };
        if names(self) != names(&other) {
            return Err(PolicyError::invalid(
                other_path,
                "variants",
                format!(
                    "[{}] differ from the main log's [{}]",
                    names(&other).join(", "),
                    names(self).join(", ")
                ),
            ));
        }
        if other.classes != self.classes {
            return Err(PolicyError::invalid(
                other_path,
                "classes",
                format!(
                    "{} classes, the main log has {}",
                    other.classes, self.classes
                ),
            ));
        }
        let first = self.videos.iter().map(|v| v.id + 1).max().unwrap_or(0);
        let before = self.videos.len();
        let training = other.videos.into_iter().filter(|v| v.split == Split::Train);
        for (id, mut video) in (first..).zip(training) {
            video.id = id;
            self.videos.push(video);
        }
        let added = self.videos.len() - before;
        if added == 0 {
            return Err(PolicyError::invalid(
                other_path,
                "videos",
                "no training videos (replay it with --train-split set to its split)",
            ));
        }
        Ok(added)
    }

    /// Save as JSON through a temporary file and a rename (a dataset inside the log's
    /// folder relative to it).
    pub fn save(&self, path: &Path) -> Result<()> {
        let folder = path.parent().unwrap_or(Path::new(""));
        let inside = match (
            std::path::absolute(&self.dataset),
            std::path::absolute(folder),
        ) {
            (Ok(data), Ok(folder)) if !self.dataset.as_os_str().is_empty() => data
                .strip_prefix(&folder)
                .ok()
                .filter(|rel| !rel.as_os_str().is_empty())
                .map(|rel| Path::new(".").join(rel)),
            _ => None,
        };
        // `./…` marks a path relative to the log's folder: any other path is saved
        // without a leading `./` (it means the same from the working directory)
        let dataset = inside.or_else(|| self.dataset.strip_prefix(".").ok().map(Path::to_path_buf));
        match dataset {
            Some(dataset) => {
                let mut log = self.clone();
                log.dataset = dataset;
                frugal_data::dataset::write_json_atomic(path, &log)
            }
            None => frugal_data::dataset::write_json_atomic(path, self),
        }
        .map_err(PolicyError::from)
    }

    /// Load and check a saved log; a dataset saved relative to the log's folder
    /// (`./…`) is found there again.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| PolicyError::io(path, e))?;
        let mut log: ReplayLog = serde_json::from_str(&text).map_err(|e| PolicyError::Parse {
            path: path.into(),
            message: e.to_string(),
        })?;
        log.check(path)?;
        if let Ok(rel) = log.dataset.strip_prefix(".") {
            log.dataset = path.parent().unwrap_or(Path::new("")).join(rel);
        }
        Ok(log)
    }

    /// Check the format, version and shapes; `path` names the file in errors.
    pub fn check(&self, path: &Path) -> Result<()> {
        if self.format != LOG_FORMAT || self.version != LOG_VERSION {
            return Err(PolicyError::invalid(
                path,
                "format",
                format!(
                    "expected {LOG_FORMAT} version {LOG_VERSION}, found {} version {}",
                    self.format, self.version
                ),
            ));
        }
        if self.variants.is_empty() {
            return Err(PolicyError::invalid(path, "variants", "no variants"));
        }
        for (i, v) in self.variants.iter().enumerate() {
            if v.family >= self.families.len() || v.relative_cost.is_nan() || v.relative_cost < 1.0
            {
                return Err(PolicyError::invalid(
                    path,
                    format!("variants[{i}] ({})", v.name),
                    "unknown family or relative cost below 1",
                ));
            }
        }
        for video in &self.videos {
            for f in &video.frames {
                if f.detections.len() != self.variants.len() {
                    return Err(PolicyError::invalid(
                        path,
                        format!("video {} frame {}", video.id, f.index),
                        format!(
                            "has detections of {} variants, the log has {}",
                            f.detections.len(),
                            self.variants.len()
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// An RGB8 frame.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbFrame {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// `RGBRGB…`, row by row.
    pub rgb: Vec<u8>,
}

impl RgbFrame {
    /// A borrowed view.
    pub fn view(&self) -> FrameRef<'_> {
        FrameRef {
            width: self.width,
            height: self.height,
            rgb: &self.rgb,
        }
    }
}

/// Where the pixels of a video frame come from.
pub trait Frames: Sync {
    /// Frame `index` of video `video`.
    fn load(&self, video: u32, index: u32) -> Result<RgbFrame>;
}

/// The frames of a [`Dataset`] on disk.
#[derive(Debug)]
pub struct DatasetFrames<'a> {
    dataset: &'a Dataset,
    index: HashMap<(u32, u32), usize>,
}

impl<'a> DatasetFrames<'a> {
    /// Index the dataset's frames.
    pub fn new(dataset: &'a Dataset) -> Self {
        let index = dataset
            .frames
            .iter()
            .enumerate()
            .map(|(i, f)| ((f.video, f.index), i))
            .collect();
        Self { dataset, index }
    }

    /// Empty logs (truth, no detections) of the dataset's videos in `splits`.
    pub fn skeleton(&self, splits: &[Split]) -> Vec<VideoLog> {
        let mut out: Vec<VideoLog> = Vec::new();
        for meta in self
            .dataset
            .videos
            .iter()
            .filter(|v| splits.contains(&v.split))
        {
            let mut frames: Vec<_> = self
                .dataset
                .frames
                .iter()
                .filter(|f| f.video == meta.id)
                .collect();
            frames.sort_by_key(|f| f.index);
            let Some(first) = frames.first() else {
                continue;
            };
            out.push(VideoLog {
                id: meta.id,
                clutter: meta.clutter,
                light: meta.light,
                split: meta.split,
                width: first.width,
                height: first.height,
                frames: frames
                    .iter()
                    .map(|f| FrameLog {
                        index: f.index,
                        truth: f
                            .objects
                            .iter()
                            .map(|o| Det {
                                class: o.class,
                                score: 1.0,
                                bbox: [o.bbox.x1, o.bbox.y1, o.bbox.x2, o.bbox.y2],
                            })
                            .collect(),
                        detections: Vec::new(),
                        ignore: f
                            .ignore
                            .iter()
                            .map(|r| IgnoreBox {
                                class: r.class,
                                bbox: [r.bbox.x1, r.bbox.y1, r.bbox.x2, r.bbox.y2],
                            })
                            .collect(),
                        time_s: f.time_s,
                    })
                    .collect(),
            });
        }
        out
    }
}

impl Frames for DatasetFrames<'_> {
    fn load(&self, video: u32, index: u32) -> Result<RgbFrame> {
        let i = *self.index.get(&(video, index)).ok_or_else(|| {
            PolicyError::invalid(
                self.dataset.root.join("manifest.json"),
                format!("video {video} frame {index}"),
                "not in the dataset",
            )
        })?;
        let rec = &self.dataset.frames[i];
        let img = self.dataset.load_rgb(rec)?;
        Ok(RgbFrame {
            width: img.width(),
            height: img.height(),
            rgb: img.into_raw(),
        })
    }
}

/// Frames held in memory (tests, hand-made clips).
#[derive(Clone, Debug, Default)]
pub struct MemoryFrames {
    /// `(video, index) → frame`.
    pub frames: HashMap<(u32, u32), RgbFrame>,
}

impl MemoryFrames {
    /// Every frame of `video`, decoded once from `frames` (for work that reads each
    /// frame many times).
    pub fn of_video(frames: &dyn Frames, video: &VideoLog) -> Result<Self> {
        let mut out = Self::default();
        for f in &video.frames {
            out.frames
                .insert((video.id, f.index), frames.load(video.id, f.index)?);
        }
        Ok(out)
    }
}

impl Frames for MemoryFrames {
    fn load(&self, video: u32, index: u32) -> Result<RgbFrame> {
        self.frames.get(&(video, index)).cloned().ok_or_else(|| {
            PolicyError::invalid(
                "<memory>",
                format!("video {video} frame {index}"),
                "no such frame",
            )
        })
    }
}

/// Run every variant of `set` once on every frame of `videos` (skeletons from
/// [`DatasetFrames::skeleton`] or hand-made), keeping the best `max_detections` per
/// frame and variant. Frames are decoded once; the variants of a frame run in
/// parallel. A progress bar is drawn when `progress`.
#[allow(clippy::too_many_arguments)]
pub fn record(
    set: &mut VariantSet,
    frames: &dyn Frames,
    mut videos: Vec<VideoLog>,
    dataset: PathBuf,
    classes: usize,
    max_detections: usize,
    progress: bool,
) -> Result<ReplayLog> {
    let total: u64 = videos.iter().map(|v| v.frames.len() as u64).sum();
    let bar = if progress {
        indicatif::ProgressBar::new(total)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "replay {bar:40} {pos}/{len} frames, {per_sec}, eta {eta}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let names: Vec<String> = set.variants.iter().map(|v| v.name.clone()).collect();
    for video in &mut videos {
        for f in &mut video.frames {
            let img = frames.load(video.id, f.index)?;
            let truth: Vec<(ClassId, BBox)> = f.truth.iter().map(|d| (d.class, d.bbox())).collect();
            let ctx = FrameContext {
                video: video.id,
                index: f.index,
                clutter: video.clutter,
                light: video.light,
                truth: &truth,
            };
            let view = img.view();
            let results: Vec<std::result::Result<Vec<Detection>, String>> = set
                .detectors
                .par_iter_mut()
                .map(|d| d.detect(view, &ctx, max_detections))
                .collect();
            f.detections = results
                .into_iter()
                .zip(&names)
                .map(|(r, name)| {
                    let mut dets = r.map_err(|message| PolicyError::Detector {
                        variant: name.clone(),
                        video: video.id,
                        frame: f.index,
                        message,
                    })?;
                    dets.sort_by(|a, b| b.score.total_cmp(&a.score));
                    dets.truncate(max_detections);
                    Ok(dets.iter().map(Det::from_detection).collect())
                })
                .collect::<Result<Vec<_>>>()?;
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    Ok(ReplayLog {
        format: LOG_FORMAT.into(),
        version: LOG_VERSION,
        dataset,
        classes,
        families: set.families.clone(),
        variants: set.variants.clone(),
        max_detections,
        reference_ms: None,
        reference_int8_ms: None,
        videos,
    })
}

/// Wall time (ms) of each detector on `count` frames spread evenly over `videos`, run
/// on the calling thread: the fastest of its runs, as the Pareto stage charges a
/// variant (other work on a shared machine only adds time). The detectors take turns on
/// every frame (one untimed warm-up round first), so a change of machine load while
/// timing hits them alike and their ratios hold.
pub fn time_detectors(
    dets: &mut [(&str, &mut dyn crate::variants::FrameDetector)],
    frames: &dyn Frames,
    videos: &[VideoLog],
    count: usize,
    max_detections: usize,
) -> Result<Vec<f64>> {
    let all: Vec<(&VideoLog, &FrameLog)> = videos
        .iter()
        .flat_map(|v| v.frames.iter().map(move |f| (v, f)))
        .collect();
    if all.is_empty() {
        return Err(PolicyError::invalid(
            "<videos>",
            "frames",
            "no frames to time on",
        ));
    }
    let n = count.clamp(1, all.len());
    let picks: Vec<usize> = (0..n).map(|i| i * all.len() / n).collect();
    let mut times = vec![Vec::with_capacity(n); dets.len()];
    for (k, &i) in std::iter::once(&picks[0]).chain(&picks).enumerate() {
        let (video, f) = all[i];
        let img = frames.load(video.id, f.index)?;
        let truth: Vec<(ClassId, BBox)> = f.truth.iter().map(|d| (d.class, d.bbox())).collect();
        let ctx = FrameContext {
            video: video.id,
            index: f.index,
            clutter: video.clutter,
            light: video.light,
            truth: &truth,
        };
        for ((name, det), times) in dets.iter_mut().zip(&mut times) {
            let t0 = std::time::Instant::now();
            det.detect(img.view(), &ctx, max_detections)
                .map_err(|message| PolicyError::Detector {
                    variant: (*name).to_string(),
                    video: video.id,
                    frame: f.index,
                    message,
                })?;
            if k > 0 {
                times.push(t0.elapsed().as_secs_f64() * 1e3);
            }
        }
    }
    Ok(times
        .into_iter()
        .map(|t| t.into_iter().fold(f64::INFINITY, f64::min))
        .collect())
}
