//! Flight footage as a dataset: the frames a flight processed, with the renderer's
//! exact sign boxes, written in the frugal-data format (`frugal fly --record DIR`).
//!
//! The replay (`frugal policy record`) runs every variant on these frames like on any
//! dataset, so the policy can learn from footage that looks like a flight — long
//! stretches with no sign in reach, signs growing from far away — on training mazes
//! that no evaluation flies. Each flight is one video of the `val` split (the split
//! the policy learns from); its illumination is the maze's, its clutter `low` (plain
//! warehouse walls). A sign is annotated when the ground-truth perception would report
//! it ([`GroundTruthPerception::reports`]): at least 8 px tall and half visible.
//!
//! Beside the frames, each flight's [`FlightLog`] (`logs/flight_<video>.csv`: per kept
//! frame, the decision time, distance flown, heading, pedestrian proximity and the
//! command issued), with which the drone-side program replays the footage on the
//! navigator's own inputs (`frugal-pilot --odometry`), and what the flight's
//! perception returned on each kept frame (`logs/percepts_<video>.jsonl`, in the
//! format of `frugal-pilot --detections`: the boxes, detected or tracked, and what the
//! reference detector read when the navigator asked it to confirm), with which the
//! pilot replays the flight's perception, or is checked against it.
use crate::flight::FrameView;
use crate::maze::{Lighting, Maze};
use crate::perception::GroundTruthPerception;
use frugal_data::dataset::PartialDir;
use frugal_data::generate::{encode_png, frame_file};
use frugal_data::{
    Clutter, DataError, Dataset, FrameRecord, Light, Object, Source, Split, VideoMeta, classes,
};
use frugal_nav::{DetectionRecord, FlightLog, LogRow};
use frugal_runtime::Detection;
use std::path::{Path, PathBuf};

/// Writes the frames of one or more flights into a dataset folder, swapped into place
/// only by [`FootageRecorder::finish`] (an interrupted recording leaves the old folder).
pub struct FootageRecorder {
    out: PathBuf,
    partial: PartialDir,
    every: u64,
    filter: GroundTruthPerception,
    videos: Vec<VideoMeta>,
    frames: Vec<FrameRecord>,
    logs: Vec<FlightLog>,
    /// Per flight, its perception record's JSON lines.
    percepts: Vec<String>,
}

/// The flight log of video `id` inside a recording folder.
pub fn flight_log_file(id: u32) -> String {
    format!("logs/flight_{id}.csv")
}

/// The perception record of video `id` inside a recording folder (JSON lines, the
/// format of `frugal-pilot --detections`).
pub fn percepts_file(id: u32) -> String {
    format!("logs/percepts_{id}.jsonl")
}

/// Detections as the pilot's JSON boxes: class, score, `[x1, y1, x2, y2]`.
fn boxes_json(detections: &[Detection]) -> serde_json::Value {
    serde_json::json!(
        detections
            .iter()
            .map(DetectionRecord::from)
            .collect::<Vec<_>>()
    )
}

/// One frame's perception as a `frugal-pilot --detections` line: `confirm` is present
/// when the navigator asked for a reading, `null` when perception had none to give.
fn percept_line(frame: u32, view: &FrameView<'_>) -> serde_json::Value {
    let mut line = serde_json::json!({
        "frame": frame,
        "decision": if view.tracked { "track" } else { "detect" },
        "boxes": boxes_json(view.detections),
    });
    if let Some(read) = view.confirm {
        line["confirm"] = read.map_or(serde_json::Value::Null, boxes_json);
    }
    line
}

impl FootageRecorder {
    /// Start recording into `out`, keeping one processed frame in `every` (at least 1).
    pub fn create(out: &Path, every: u64) -> Result<Self, DataError> {
        Ok(Self {
            out: out.to_owned(),
            partial: PartialDir::new(out)?,
            every: every.max(1),
            filter: GroundTruthPerception::default(),
            videos: Vec::new(),
            frames: Vec::new(),
            logs: Vec::new(),
            percepts: Vec::new(),
        })
    }

    /// Start the video of one flight of `maze` with `seed`.
    pub fn begin_flight(&mut self, maze: &Maze, seed: u64) {
        let id = self.videos.len() as u32;
        self.videos.push(VideoMeta {
            id,
            seed,
            clutter: Clutter::Low,
            light: match maze.lighting {
                Lighting::Normal => Light::Normal,
                Lighting::Low => Light::Low,
            },
            split: Split::Val,
            frames: 0,
            name: None,
            fps: None,
        });
        self.logs.push(FlightLog::default());
        self.percepts.push(String::new());
    }

    /// Keep `view` if its index is a multiple of `every`: its PNG and its annotations.
    /// Frames before the first [`FootageRecorder::begin_flight`] are ignored.
    pub fn observe(&mut self, view: &FrameView<'_>) -> Result<(), DataError> {
        if !view.index.is_multiple_of(self.every) {
            return Ok(());
        }
        let Some(video) = self.videos.last_mut() else {
            return Ok(());
        };
        let (w, h) = (view.image.width, view.image.height);
        let file = frame_file(video.id, video.frames);
        let path = self.partial.path().join(&file);
        let img = image::RgbImage::from_raw(w, h, view.image.rgb.to_vec())
            .ok_or_else(|| DataError::invalid(&path, "frame", format!("not {w}x{h} RGB pixels")))?;
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|e| DataError::io(dir, e))?;
        }
        std::fs::write(&path, encode_png(&img, &path)?).map_err(|e| DataError::io(&path, e))?;
        let objects = view
            .truth
            .signs
            .iter()
            .filter(|s| self.filter.reports(s))
            .map(|s| Object {
                class: s.class,
                bbox: s.bbox.clip(w as f32, h as f32),
            })
            .filter(|o| o.bbox.is_valid())
            .collect();
        self.frames.push(FrameRecord {
            id: self.frames.len() as u64,
            file,
            width: w,
            height: h,
            video: video.id,
            index: video.frames,
            split: Split::Val,
            objects,
            ignore: Vec::new(),
            time_s: None,
        });
        if let Some(log) = self.logs.last_mut() {
            log.rows.push(LogRow {
                frame: u64::from(video.frames),
                capture_s: view.time_s,
                decision_s: view.decision_s,
                odometer_m: view.odometer,
                yaw_rad: view.yaw,
                pedestrian_close: view.pedestrian_close,
                command: view.command,
            });
        }
        if let Some(lines) = self.percepts.last_mut() {
            lines.push_str(&percept_line(video.frames, view).to_string());
            lines.push('\n');
        }
        video.frames += 1;
        Ok(())
    }

    /// Frames kept so far.
    pub fn frames(&self) -> usize {
        self.frames.len()
    }

    /// Write the annotations and the manifest and move the folder into place.
    pub fn finish(self, source: Source) -> Result<Dataset, DataError> {
        let mut dataset = Dataset {
            root: self.partial.path().to_owned(),
            classes: classes(),
            videos: self.videos,
            frames: self.frames,
        };
        dataset.write_metadata(self.partial.path(), source)?;
        let dir = self.partial.path().join("logs");
        std::fs::create_dir_all(&dir).map_err(|e| DataError::io(&dir, e))?;
        for ((video, log), percepts) in dataset.videos.iter().zip(&self.logs).zip(&self.percepts) {
            let path = self.partial.path().join(flight_log_file(video.id));
            log.write(&path)
                .map_err(|e| DataError::invalid(&path, "flight log", e.message))?;
            let path = self.partial.path().join(percepts_file(video.id));
            std::fs::write(&path, percepts).map_err(|e| DataError::io(&path, e))?;
        }
        self.partial.commit()?;
        dataset.root = self.out;
        Ok(dataset)
    }
}
