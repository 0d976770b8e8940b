//! The perception loop the budget strategies replay: the logged detections, every
//! reported box carried by the real KLT tracker on the real frames, compute charged
//! from the measured latencies.

use super::TrackState;
use crate::error::{PolicyError, Result};
use crate::replay::{Frames, ReplayLog, VideoLog};
use crate::scoring::reported;
use crate::scoring::{TRACK_POINTS, TrackerCost};
use frugal_runtime::track::{Pyramid, Tracker, TrackerParams, rgb_to_gray};
use frugal_runtime::{Detection, TrackStatus};

/// An error of the tracker on frame `f` of `video`.
fn at<E: std::fmt::Display>(video: &VideoLog, f: usize) -> impl Fn(E) -> PolicyError + '_ {
    move |e| PolicyError::Tracker {
        video: video.id,
        frame: video.frames[f].index,
        message: e.to_string(),
    }
}

struct Held {
    tracker: Tracker<TRACK_POINTS>,
    det: Detection,
}

/// The perception loop of the budget strategies over a replay log: the logged
/// detections, every reported box carried by a real KLT tracker on the real frames
/// (as the runtime's `Pilot::scheduled`), compute charged from the measured
/// latencies and the tracker's measured medians.
pub struct Perceiver<'a> {
    log: &'a ReplayLog,
    video: &'a VideoLog,
    frames: &'a dyn Frames,
    cost: TrackerCost,
    max_tracks: usize,
    params: TrackerParams,
    prev: Vec<u8>,
    cur: Vec<u8>,
    gray: Vec<u8>,
    have_prev: bool,
    loaded: Option<usize>,
    held: Vec<Held>,
    status: Option<TrackStatus>,
}

impl<'a> Perceiver<'a> {
    /// A perceiver over one video.
    pub fn new(
        log: &'a ReplayLog,
        video: &'a VideoLog,
        frames: &'a dyn Frames,
        cost: TrackerCost,
        max_tracks: usize,
    ) -> Self {
        let params = TrackerParams::DEFAULT;
        let (w, h) = (video.width as usize, video.height as usize);
        let need = Pyramid::required_len(w, h, params.lk.levels).unwrap_or(0);
        Self {
            log,
            video,
            frames,
            cost,
            max_tracks,
            params,
            prev: vec![0; need],
            cur: vec![0; need],
            gray: vec![0; w * h],
            have_prev: false,
            loaded: None,
            held: Vec::new(),
            status: None,
        }
    }

    /// Loads frame `f` into the current pyramid (the previous one is kept for tracking).
    pub(super) fn load(&mut self, f: usize) -> Result<()> {
        let (w, h) = (self.video.width as usize, self.video.height as usize);
        let img = self
            .frames
            .load(self.video.id, self.video.frames[f].index)?;
        if img.width as usize != w || img.height as usize != h {
            return Err(at(self.video, f)(format!(
                "frame is {}x{}, the log says {w}x{h}",
                img.width, img.height
            )));
        }
        std::mem::swap(&mut self.prev, &mut self.cur);
        self.have_prev = self.loaded.is_some();
        let video = self.video;
        let gray = rgb_to_gray(&img.view(), &mut self.gray).map_err(at(video, f))?;
        Pyramid::new(&mut self.cur, w, h, self.params.lk.levels)
            .and_then(|mut p| p.build(&gray))
            .map_err(at(video, f))?;
        self.loaded = Some(f);
        Ok(())
    }

    /// Frame `f`, step 1: load it and carry the held boxes into it. Returns how the
    /// trackers fared and the compute charged (ms, measuring machine).
    pub fn track(&mut self, f: usize) -> Result<(TrackState, f64)> {
        self.load(f)?;
        self.status = None;
        if self.held.is_empty() {
            return Ok((TrackState::Idle, 0.0));
        }
        let (w, h, levels) = (
            self.video.width as usize,
            self.video.height as usize,
            self.params.lk.levels,
        );
        let mut ms = self.cost.pyramid_ms;
        if self.have_prev {
            let prev = Pyramid::new(&mut self.prev, w, h, levels).map_err(at(self.video, f))?;
            let cur = Pyramid::new(&mut self.cur, w, h, levels).map_err(at(self.video, f))?;
            // as the runtime's `Pilot` reports it: the box that drifted most from its
            // detection, the worst tracking quality (0 for a track lost on this frame)
            let (mut iou, mut quality, mut bbox) = (f32::INFINITY, f32::INFINITY, None);
            for t in &mut self.held {
                ms += self.cost.track_ms;
                match t.tracker.track(&prev, &cur) {
                    Ok(o) => {
                        let i = o.bbox.iou(&t.det.bbox);
                        if i < iou {
                            iou = i;
                            bbox = Some(o.bbox);
                        }
                        quality = quality.min(o.quality);
                    }
                    Err(_) => quality = 0.0,
                }
            }
            self.status = bbox.map(|bbox| TrackStatus { bbox, iou, quality });
        }
        self.held.retain(|t| t.tracker.is_active());
        Ok((
            if self.held.is_empty() {
                TrackState::Lost
            } else {
                TrackState::Held
            },
            ms,
        ))
    }

    /// How the held boxes fared on the last [`Perceiver::track`], as the runtime's
    /// controller is told (`None`: nothing tracked into that frame).
    pub fn status(&self) -> Option<TrackStatus> {
        self.status
    }

    /// Frame `f`, step 2 on a detection: variant `v`'s reported detections, every one
    /// carried (up to the most tracks). Returns them, their best score and the compute.
    pub fn detect(&mut self, f: usize, v: usize) -> Result<(Vec<Detection>, Option<f32>, f64)> {
        // best first, as the runtime's `Pilot` is handed them
        let mut dets = reported(self.log, self.video, f, v);
        dets.sort_by(|a, b| b.score.total_cmp(&a.score));
        let score = self.video.frames[f].best_score(v);
        let (w, h, levels) = (
            self.video.width as usize,
            self.video.height as usize,
            self.params.lk.levels,
        );
        let mut ms = self.log.variants[v].latency_ms;
        let tracked_before = !self.held.is_empty();
        self.held.clear();
        let cur = Pyramid::new(&mut self.cur, w, h, levels).map_err(at(self.video, f))?;
        for d in dets.iter().take(self.max_tracks) {
            let mut tracker = Tracker::new(self.params);
            ms += self.cost.init_ms;
            if tracker.init(&cur, d.bbox).is_ok() {
                self.held.push(Held { tracker, det: *d });
            }
        }
        if !dets.is_empty() && !tracked_before {
            // the pyramid was built for the trackers' start, not charged by `track`
            ms += self.cost.pyramid_ms;
        }
        Ok((dets, score, ms))
    }

    /// Frame `f`, step 2 on a tracked frame: the carried boxes with their detection's
    /// class and score.
    pub fn tracked(&self) -> Vec<Detection> {
        self.held
            .iter()
            .map(|t| Detection {
                bbox: t.tracker.bbox(),
                ..t.det
            })
            .collect()
    }
}
