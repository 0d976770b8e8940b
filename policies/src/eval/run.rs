//! One strategy over one video: the runtime's controller over the strategy's bundle,
//! the logged detections, and the real KLT tracker on the real frames between them.

use super::{EvalConfig, FrameTrace, Strategy, VideoRun};
use crate::error::{PolicyError, Result};
use crate::replay::{Frames, ReplayLog, VideoLog};
use crate::scoring::{TRACK_POINTS, correct, ground_truth, reported};
use frugal_models::metrics::{ImageResult, image_counts};
use frugal_runtime::track::{Pyramid, Tracker, TrackerParams, rgb_to_gray};
use frugal_runtime::{BBox, Bundle, Controller, Decision, Detection, Observation, TrackStatus};
use rand::{Rng, SeedableRng};
use std::time::Instant;

/// The tracker's measured times, ms, every sample, and the reference tracker's,
/// timed once after every pyramid so that both see the machine in the same state.
#[derive(Default)]
pub(super) struct Timings {
    pub(super) pyramid: Vec<f64>,
    pub(super) track: Vec<f64>,
    pub(super) init: Vec<f64>,
    pub(super) reference: Vec<f64>,
    reference_tracker: Option<super::reference::ReferenceTracker>,
}

impl Timings {
    /// Times the reference tracker once (built on first use).
    fn time_reference(&mut self) {
        if self.reference_tracker.is_none() {
            self.reference_tracker = super::reference::ReferenceTracker::new();
        }
        if let Some(ms) = self.reference_tracker.as_mut().and_then(|r| r.time_ms()) {
            self.reference.push(ms);
        }
    }
}

struct Track {
    tracker: Tracker<TRACK_POINTS>,
    init: BBox,
    det: Detection,
}

fn tracker_err(
    video: u32,
    frame: u32,
) -> impl Fn(frugal_runtime::track::TrackError) -> PolicyError {
    move |e| PolicyError::Tracker {
        video,
        frame,
        message: e.to_string(),
    }
}

/// Run one strategy over one video with the controller over `bundle`. `frames` is
/// needed when `tracker` is set; `random` overrides the variant at every policy query.
#[allow(clippy::too_many_arguments)]
fn run_controlled(
    log: &ReplayLog,
    video: &VideoLog,
    bundle: &[u8],
    tracker: Option<&dyn Frames>,
    random: Option<u64>,
    cfg: &EvalConfig,
    timings: &mut Timings,
) -> Result<VideoRun> {
    let bundle = Bundle::parse(bundle).map_err(|e| PolicyError::Bundle {
        path: "<memory>".into(),
        message: e.to_string(),
    })?;
    let v_n = log.variants.len();
    let mut ctl = Controller::new(bundle);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(random.unwrap_or(0) ^ u64::from(video.id));
    let mut random_variant: u16 = 0;
    let (w, h) = (video.width as usize, video.height as usize);
    let params = TrackerParams::DEFAULT;
    let levels = params.lk.levels;
    let need = Pyramid::required_len(w, h, levels).unwrap_or(0);
    let (mut prev_buf, mut cur_buf, mut gray_buf) = if tracker.is_some() {
        (vec![0u8; need], vec![0u8; need], vec![0u8; w * h])
    } else {
        (Vec::new(), Vec::new(), Vec::new())
    };
    let mut have_prev = false;
    let mut tracks: Vec<Track> = Vec::new();
    // a reported detection of the last detection frame has no tracker (as in the
    // runtime's `Pilot`: the controller is told the track is lost, and detects again)
    let mut untracked = false;
    let mut score: Option<f32> = None;
    let mut out = VideoRun {
        video: video.id,
        frames: Vec::with_capacity(video.frames.len()),
        images: Vec::with_capacity(video.frames.len()),
    };
    for (fi, f) in video.frames.iter().enumerate() {
        let err = tracker_err(video.id, f.index);
        let mut trace = FrameTrace {
            frame: f.index,
            detect: None,
            tried: Vec::new(),
            reason: None,
            state: 0,
            tracked: 0,
            inits: 0,
            pyramid: false,
            counts: (0, 0, 0),
            time_ms: 0.0,
        };
        let mut status: Option<TrackStatus> = None;
        if let Some(frames) = tracker {
            let img = frames.load(video.id, f.index)?;
            if img.width as usize != w || img.height as usize != h {
                return Err(PolicyError::Tracker {
                    video: video.id,
                    frame: f.index,
                    message: format!(
                        "frame is {}x{}, the log says {w}x{h}",
                        img.width, img.height
                    ),
                });
            }
            let t0 = Instant::now();
            let gray = rgb_to_gray(&img.view(), &mut gray_buf).map_err(&err)?;
            Pyramid::new(&mut cur_buf, w, h, levels)
                .and_then(|mut p| p.build(&gray))
                .map_err(&err)?;
            timings.pyramid.push(t0.elapsed().as_secs_f64() * 1e3);
            timings.time_reference();
            if have_prev && !tracks.is_empty() {
                let prev = Pyramid::new(&mut prev_buf, w, h, levels).map_err(&err)?;
                let cur = Pyramid::new(&mut cur_buf, w, h, levels).map_err(&err)?;
                let (mut iou, mut quality, mut bbox) = (f32::INFINITY, f32::INFINITY, None);
                for t in &mut tracks {
                    let t0 = Instant::now();
                    let r = t.tracker.track(&prev, &cur);
                    timings.track.push(t0.elapsed().as_secs_f64() * 1e3);
                    trace.tracked += 1;
                    match r {
                        Ok(o) => {
                            let i = o.bbox.iou(&t.init);
                            if i < iou {
                                iou = i;
                                bbox = Some(o.bbox);
                            }
                            quality = quality.min(o.quality);
                        }
                        Err(_) => quality = 0.0,
                    }
                }
                trace.pyramid = true;
                tracks.retain(|t| t.tracker.is_active());
                if untracked {
                    quality = 0.0;
                }
                status = bbox.map(|bbox| TrackStatus { bbox, iou, quality });
            }
        }
        let decision = ctl.step(&Observation {
            frame: f.index,
            score,
            track: status,
        });
        let shown: Vec<Detection> = match decision {
            Decision::Detect { variant, reason } => {
                let mut variant = match random {
                    Some(_) => {
                        if reason != frugal_runtime::Trigger::Reinit {
                            random_variant = rng.random_range(0..v_n) as u16;
                        }
                        random_variant
                    }
                    None => variant,
                };
                trace.reason = Some(format!("{reason:?}"));
                // the paper's MDP accesses per image: while the detection scores below
                // T_c, the policy's next choice runs on the same frame (the random
                // strategy has no policy to ask)
                loop {
                    score = video.frames[fi].best_score(usize::from(variant));
                    match ctl.detected(score) {
                        frugal_runtime::Access::Again(next) if random.is_none() => {
                            trace.tried.push(variant);
                            variant = next;
                        }
                        _ => break,
                    }
                }
                let v = usize::from(variant);
                trace.detect = Some(variant);
                let dets = reported(log, video, fi, v);
                if tracker.is_some() {
                    tracks.clear();
                    untracked = false;
                    // only a detection in the optimal bucket (by default) is carried
                    // for up to M frames; a good-enough one is reported on its frame
                    // alone. The edges are the bundle's, as the runtime's `Pilot` reads
                    // them (a policy's calibrated edges even on an uncalibrated log).
                    let carry = bundle
                        .variant_buckets(variant)
                        .map_or(f32::INFINITY, |b| cfg.carry.edge(&b));
                    let cur = Pyramid::new(&mut cur_buf, w, h, levels).map_err(&err)?;
                    for d in dets.iter().take(cfg.max_tracks) {
                        if d.score < carry {
                            untracked = true;
                            continue;
                        }
                        let mut t = Track {
                            tracker: Tracker::new(params),
                            init: d.bbox,
                            det: *d,
                        };
                        let t0 = Instant::now();
                        let ok = t.tracker.init(&cur, d.bbox).is_ok();
                        timings.init.push(t0.elapsed().as_secs_f64() * 1e3);
                        trace.inits += 1;
                        trace.pyramid = true;
                        if ok {
                            tracks.push(t);
                        } else {
                            untracked = true;
                        }
                    }
                }
                dets
            }
            Decision::Track => tracks
                .iter()
                .map(|t| Detection {
                    bbox: t.tracker.bbox(),
                    ..t.det
                })
                .collect(),
        };
        let shown_variant = trace.detect.map_or(ctl.current_variant(), |v| v);
        let bucket = log
            .buckets(usize::from(shown_variant))
            .to_runtime()
            .bucket(score);
        trace.state = bucket.index() * v_n + usize::from(shown_variant);
        let im = ImageResult {
            detections: shown,
            ..ground_truth(video, fi)
        };
        trace.counts = image_counts(&im, cfg.eval_iou, f32::NEG_INFINITY);
        out.images.push(im);
        out.frames.push(trace);
        if tracker.is_some() {
            std::mem::swap(&mut prev_buf, &mut cur_buf);
            have_prev = true;
        }
    }
    Ok(out)
}

pub(super) fn run_oracle(
    log: &ReplayLog,
    video: &VideoLog,
    fallback: usize,
    cfg: &EvalConfig,
) -> VideoRun {
    let v_n = log.variants.len();
    let mut out = VideoRun {
        video: video.id,
        frames: Vec::new(),
        images: Vec::new(),
    };
    for (fi, f) in video.frames.iter().enumerate() {
        let v = (0..v_n)
            .find(|&v| correct(log, video, fi, v, cfg.eval_iou))
            .unwrap_or(fallback);
        let im = ImageResult {
            detections: reported(log, video, fi, v),
            ..ground_truth(video, fi)
        };
        let bucket = log.buckets(v).to_runtime().bucket(f.best_score(v));
        out.frames.push(FrameTrace {
            frame: f.index,
            detect: Some(v as u16),
            tried: Vec::new(),
            reason: Some("Oracle".into()),
            state: bucket.index() * v_n + v,
            tracked: 0,
            inits: 0,
            pyramid: false,
            counts: image_counts(&im, cfg.eval_iou, f32::NEG_INFINITY),
            time_ms: log.variants[v].latency_ms,
        });
        out.images.push(im);
    }
    out
}

pub(super) fn run_timed(
    log: &ReplayLog,
    videos: &[&VideoLog],
    strategy: Strategy,
    bundle: &[u8],
    frames: Option<&dyn Frames>,
    cfg: &EvalConfig,
    timings: &mut Timings,
) -> Result<Vec<VideoRun>> {
    let tracker = if strategy.uses_tracker() {
        Some(frames.ok_or_else(|| {
            PolicyError::invalid(
                &log.dataset,
                "frames",
                format!("strategy {} needs the video frames", strategy.name()),
            )
        })?)
    } else {
        None
    };
    let random = (strategy == Strategy::RandomTracker).then_some(cfg.seed);
    videos
        .iter()
        .map(|video| {
            let mut run = run_controlled(log, video, bundle, tracker, random, cfg, timings)?;
            for t in &mut run.frames {
                t.time_ms = t
                    .detect
                    .iter()
                    .chain(&t.tried)
                    .map(|&v| log.variants[usize::from(v)].latency_ms)
                    .sum();
            }
            Ok(run)
        })
        .collect()
}
