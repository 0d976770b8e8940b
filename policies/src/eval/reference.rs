//! The reference tracker: one fixed tracked frame, timed between the tracker's own
//! calls, so the tracker's costs can be put on a device by their ratio to it (the
//! tracker's anchor, as the reference detectors anchor the variants).

use crate::scoring::TRACK_POINTS;
use frugal_runtime::synth::{ClipSpec, make_clip};
use frugal_runtime::track::{Point, Pyramid, Tracker, TrackerParams, rgb_to_gray};
use frugal_runtime::{BBox, FrameRef};
use std::time::Instant;

/// Seed of the synthetic clip the reference tracks (`ClipSpec::standard`, 480×270).
const SEED: u64 = 5;

/// One tracked frame of a fixed synthetic 480×270 clip, as the replay tracks a frame:
/// RGB to gray, the 3-level pyramid, then one tracker of [`TRACK_POINTS`] points from
/// the previous frame's pyramid. Its work is the same on every call and on every
/// machine, so its time tells how fast this machine runs the tracker right now.
pub struct ReferenceTracker {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
    gray: Vec<u8>,
    prev: Vec<u8>,
    next: Vec<u8>,
    tracker: Tracker<TRACK_POINTS>,
    bbox: BBox,
    points: Vec<Point>,
}

impl ReferenceTracker {
    /// The clip rendered and its first frame whose sign holds every point.
    pub fn new() -> Option<Self> {
        let clip = make_clip(&ClipSpec::standard(SEED, 30));
        let (w, h) = (clip.width, clip.height);
        let params = TrackerParams::DEFAULT;
        let need = Pyramid::required_len(w, h, params.lk.levels)?;
        let mut prev = vec![0u8; need];
        let mut tracker = Tracker::<TRACK_POINTS>::new(params);
        let f = (0..clip.frames.len().saturating_sub(1)).find(|&f| {
            let gray = frugal_runtime::track::GrayImage::new(&clip.frames[f], w, h, w);
            let built = gray.ok().and_then(|g| {
                let mut p = Pyramid::new(&mut prev, w, h, params.lk.levels).ok()?;
                p.build(&g).ok()?;
                tracker.init(&p, clip.boxes[f]).ok()
            });
            built == Some(TRACK_POINTS)
        })?;
        Some(Self {
            width: w,
            height: h,
            rgb: clip.frames[f + 1].iter().flat_map(|&g| [g, g, g]).collect(),
            gray: vec![0u8; w * h],
            next: vec![0u8; need],
            prev,
            points: tracker.points().to_vec(),
            bbox: clip.boxes[f],
            tracker,
        })
    }

    /// Runs the reference once; its wall time, ms (`None` if a buffer did not fit,
    /// which the fixed clip never makes happen).
    pub fn time_ms(&mut self) -> Option<f64> {
        let (w, h) = (self.width, self.height);
        let levels = self.tracker.params().lk.levels;
        let t0 = Instant::now();
        self.tracker
            .init_with_points(self.bbox, &self.points)
            .ok()?;
        let frame = FrameRef::new(w as u32, h as u32, &self.rgb)?;
        let gray = rgb_to_gray(&frame, &mut self.gray).ok()?;
        let mut next = Pyramid::new(&mut self.next, w, h, levels).ok()?;
        next.build(&gray).ok()?;
        let prev = Pyramid::new(&mut self.prev, w, h, levels).ok()?;
        let out = self.tracker.track(&prev, &next);
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        // lost or not, the work is the same on every call
        let _ = std::hint::black_box(out);
        Some(ms)
    }
}
