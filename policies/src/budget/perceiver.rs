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
use std::cell::RefCell;
use std::collections::HashMap;

/// An error of the tracker on frame `f` of `video`.
fn at<E: std::fmt::Display>(video: &VideoLog, f: usize) -> impl Fn(E) -> PolicyError + '_ {
    move |e| PolicyError::Tracker {
        video: video.id,
        frame: video.frames[f].index,
        message: e.to_string(),
    }
}

#[derive(Clone)]
struct Held {
    tracker: Tracker<TRACK_POINTS>,
    det: Detection,
}

/// One tracking step's outcome: the held boxes after it, what the controller is told,
/// the trackers' state and the compute charged.
#[derive(Clone)]
struct Step {
    held: Vec<Held>,
    status: Option<TrackStatus>,
    ms: f64,
}

/// What the perception loop of one video computes once for all its streams: each
/// frame's image pyramid, and each tracking step, keyed by what determines it (the
/// detection the trackers started from, its frame and variant, and every frame
/// tracked since). The trackers are deterministic, so a step taken again (another
/// clock run that processed the same frames, another strategy that detected the same
/// frame with the same variant) is read back instead of tracked again: the outputs
/// are those of an uncached perceiver, exactly.
#[derive(Default)]
pub struct VideoCache {
    pyramids: RefCell<HashMap<usize, Box<[u8]>>>,
    steps: RefCell<HashMap<Vec<u32>, Step>>,
}

impl VideoCache {
    /// Tracking steps (and tracker starts) held.
    pub fn steps(&self) -> usize {
        self.steps.borrow().len()
    }
}

/// The perception loop of the budget strategies over a replay log: the logged
/// detections, every reported box carried by a real KLT tracker on the real frames
/// (as the runtime's `Pilot::scheduled`), compute charged from the measured
/// latencies and the tracker's measured medians.
pub struct Perceiver<'a> {
    log: &'a ReplayLog,
    video: &'a VideoLog,
    frames: &'a dyn Frames,
    cache: &'a VideoCache,
    cost: TrackerCost,
    max_tracks: usize,
    params: TrackerParams,
    /// Pyramid buffers (previous, current) and the frames they hold.
    bufs: [Vec<u8>; 2],
    held_in: [Option<usize>; 2],
    gray: Vec<u8>,
    /// The frame processed last.
    last: Option<usize>,
    /// The frame whose pyramid was charged last (by [`Perceiver::track`]).
    charged: Option<usize>,
    /// The detection frame and variant the held boxes come from, then every frame
    /// tracked since: the key of the next step in [`VideoCache`].
    path: Vec<u32>,
    held: Vec<Held>,
    status: Option<TrackStatus>,
}

impl<'a> Perceiver<'a> {
    /// A perceiver over one video; `cache` is shared by every perceiver of the video.
    pub fn new(
        log: &'a ReplayLog,
        video: &'a VideoLog,
        frames: &'a dyn Frames,
        cache: &'a VideoCache,
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
            cache,
            cost,
            max_tracks,
            params,
            bufs: [vec![0; need], vec![0; need]],
            held_in: [None, None],
            gray: vec![0; w * h],
            last: None,
            charged: None,
            path: Vec::new(),
            held: Vec::new(),
            status: None,
        }
    }

    /// The video's (width, height) and the pyramid's levels.
    fn dims(&self) -> (usize, usize, usize) {
        let v = self.video;
        (v.width as usize, v.height as usize, self.params.lk.levels)
    }

    /// Puts frame `f`'s pyramid into buffer `which` (0 previous, 1 current): from the
    /// cache, or built from the frame (and cached).
    fn fill(&mut self, which: usize, f: usize) -> Result<()> {
        if self.held_in[which] == Some(f) {
            return Ok(());
        }
        if let Some(p) = self.cache.pyramids.borrow().get(&f) {
            self.bufs[which].copy_from_slice(p);
            self.held_in[which] = Some(f);
            return Ok(());
        }
        let (w, h, levels) = self.dims();
        let img = self
            .frames
            .load(self.video.id, self.video.frames[f].index)?;
        if img.width as usize != w || img.height as usize != h {
            return Err(at(self.video, f)(format!(
                "frame is {}x{}, the log says {w}x{h}",
                img.width, img.height
            )));
        }
        let video = self.video;
        let gray = rgb_to_gray(&img.view(), &mut self.gray).map_err(at(video, f))?;
        Pyramid::new(&mut self.bufs[which], w, h, levels)
            .and_then(|mut p| p.build(&gray))
            .map_err(at(video, f))?;
        self.held_in[which] = Some(f);
        self.cache
            .pyramids
            .borrow_mut()
            .insert(f, self.bufs[which].clone().into_boxed_slice());
        Ok(())
    }

    /// Frame `p`'s pyramid as the previous one and `f`'s as the current one.
    fn ready(&mut self, p: usize, f: usize) -> Result<()> {
        if self.held_in[1] == Some(p) && self.held_in[0] != Some(p) {
            self.bufs.swap(0, 1);
            self.held_in.swap(0, 1);
        }
        self.fill(0, p)?;
        self.fill(1, f)
    }

    /// Frame `f`, step 1: carry the held boxes into it. Returns how the trackers fared
    /// and the compute charged (ms, measuring machine).
    pub fn track(&mut self, f: usize) -> Result<(TrackState, f64)> {
        let prev = self.last.replace(f);
        self.status = None;
        if self.held.is_empty() {
            return Ok((TrackState::Idle, 0.0));
        }
        let mut ms = self.cost.pyramid_ms;
        self.charged = Some(f);
        if let Some(p) = prev {
            self.path.push(f as u32);
            let hit = self.cache.steps.borrow().get(&self.path).cloned();
            match hit {
                Some(step) => {
                    self.held = step.held;
                    self.status = step.status;
                    ms = step.ms;
                }
                None => {
                    self.ready(p, f)?;
                    let (w, h, levels) = self.dims();
                    let [b0, b1] = &mut self.bufs;
                    let prev = Pyramid::new(b0, w, h, levels).map_err(at(self.video, f))?;
                    let cur = Pyramid::new(b1, w, h, levels).map_err(at(self.video, f))?;
                    // as the runtime's `Pilot` reports it: the box that drifted most from
                    // its detection, the worst tracking quality (0 for a track lost on
                    // this frame)
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
                    self.held.retain(|t| t.tracker.is_active());
                    self.cache.steps.borrow_mut().insert(
                        self.path.clone(),
                        Step {
                            held: self.held.clone(),
                            status: self.status,
                            ms,
                        },
                    );
                }
            }
        }
        // (the held boxes are those still tracked: retained when the step was taken)
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
        let mut ms = self.log.variants[v].latency_ms;
        self.last = Some(f);
        self.path.clear();
        self.path.extend([f as u32, v as u32]);
        let started = self
            .cache
            .steps
            .borrow()
            .get(&self.path)
            .map(|s| s.held.clone());
        self.held = match started {
            Some(held) => held,
            None => {
                self.fill(1, f)?;
                let (w, h, levels) = self.dims();
                let cur =
                    Pyramid::new(&mut self.bufs[1], w, h, levels).map_err(at(self.video, f))?;
                let mut held = Vec::new();
                for d in dets.iter().take(self.max_tracks) {
                    let mut tracker = Tracker::new(self.params);
                    if tracker.init(&cur, d.bbox).is_ok() {
                        held.push(Held { tracker, det: *d });
                    }
                }
                self.cache.steps.borrow_mut().insert(
                    self.path.clone(),
                    Step {
                        held: held.clone(),
                        status: None,
                        ms: 0.0,
                    },
                );
                held
            }
        };
        ms += self.cost.init_ms * dets.len().min(self.max_tracks) as f64;
        if !dets.is_empty() && self.charged != Some(f) {
            // the pyramid is built for the trackers' start: charged here unless
            // `track` charged it on this frame
            ms += self.cost.pyramid_ms;
            self.charged = Some(f);
        }
        Ok((dets, score, ms))
    }

    /// Frame `f`, step 2 on a detection whose boxes are not tracked (an action without
    /// the tracker): the held boxes are dropped, and no tracker starts.
    pub fn forget(&mut self, f: usize) {
        self.last = Some(f);
        self.path.clear();
        self.held.clear();
        self.status = None;
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
