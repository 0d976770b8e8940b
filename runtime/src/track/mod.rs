//! A KLT tracker: Shi-Tomasi corners inside the box, pyramidal Lucas-Kanade with a
//! forward-backward check, and a median-flow box update.
//!
//! Every buffer is caller-provided or sized by the const generic `MAX_POINTS`: frames
//! come in as borrowed [`GrayImage`]s, pyramids live in caller byte workspaces
//! ([`Pyramid::required_len`]), the points live inside the [`Tracker`].
//!
//! ```
//! use frugal_runtime::track::{GrayImage, Pyramid, Tracker, TrackerParams};
//! use frugal_runtime::BBox;
//!
//! let (w, h) = (64, 48);
//! // A textured frame, and the same frame shifted right by two pixels.
//! let tex = |x: usize, y: usize| ((x * 7 + y * 13) % 23 * 11 + (x * y) % 17) as u8;
//! let a: Vec<u8> = (0..w * h).map(|i| tex(i % w, i / w)).collect();
//! let b: Vec<u8> = (0..w * h).map(|i| tex((i % w).saturating_sub(2), i / w)).collect();
//! let need = Pyramid::required_len(w, h, 3).unwrap();
//! let (mut wa, mut wb) = (vec![0u8; need], vec![0u8; need]);
//! let mut prev = Pyramid::new(&mut wa, w, h, 3)?;
//! let mut next = Pyramid::new(&mut wb, w, h, 3)?;
//! prev.build(&GrayImage::new(&a, w, h, w)?)?;
//! next.build(&GrayImage::new(&b, w, h, w)?)?;
//! let mut tracker = Tracker::<32>::new(TrackerParams::DEFAULT);
//! tracker.init(&prev, BBox::new(16.0, 12.0, 48.0, 36.0))?;
//! let out = tracker.track(&prev, &next)?;
//! assert!((out.bbox.x1 - 18.0).abs() < 0.5);
//! # Ok::<(), frugal_runtime::track::TrackError>(())
//! ```

mod corners;
mod image;
mod lk;

pub use corners::{Corner, CornerParams, good_features};
pub use image::{GrayImage, MAX_LEVELS, Pyramid, rgb_to_gray};
pub use lk::{LkParams, LkScratch, MAX_WIN_RADIUS, track_point, track_point_with};

use crate::geom::BBox;
use core::fmt;

/// A point in pixel coordinates (pixel centres at integers).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Point {
    /// Column.
    pub x: f32,
    /// Row.
    pub y: f32,
}

/// What went wrong in the tracker. Field-less and `Copy`.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrackError {
    /// Image sizes are zero, the stride is below the width, or the data is too short.
    BadImage,
    /// A workspace is smaller than [`Pyramid::required_len`] (or the gray buffer is small).
    WorkspaceTooSmall,
    /// The two pyramids (or a frame and its pyramid) differ in size.
    SizeMismatch,
    /// The box is degenerate, not finite, or outside the image.
    BadBox,
    /// Too few trackable points: none found at init, or too few survive tracking.
    TooFewPoints,
    /// `track` was called before a successful `init`, or after a failure.
    NotInitialised,
}

impl fmt::Display for TrackError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::BadImage => "bad image size, stride or data length",
            Self::WorkspaceTooSmall => "workspace smaller than required",
            Self::SizeMismatch => "image and pyramid sizes differ",
            Self::BadBox => "degenerate or out-of-image box",
            Self::TooFewPoints => "too few trackable points",
            Self::NotInitialised => "tracker not initialised",
        })
    }
}

impl core::error::Error for TrackError {}

/// Tracker parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackerParams {
    /// Lucas-Kanade parameters.
    pub lk: LkParams,
    /// Corner detection parameters.
    pub corners: CornerParams,
    /// Corners are searched in the box shrunk by this fraction of its size on each
    /// side, so that points sit on the object rather than on the background.
    pub box_margin: f32,
    /// Largest forward-backward error (pixels) for a point to survive.
    pub max_fb_error: f32,
    /// Fewest surviving points for the track to continue.
    pub min_points: usize,
}

impl TrackerParams {
    /// Defaults: 11×11 window, 3 levels, at most 10 iterations, ε = 0.03 px, quality
    /// 0.01, min distance 4 px, 10 % box margin, FB error ≤ 1 px, at least 4 points.
    ///
    /// The window and stopping rule were 15×15, 20 and 0.01 px until 2026-11-28: on
    /// the default run's validation videos the smaller window and earlier stop cost
    /// half as much per tracked sign, and as many boxes kept IoU ≥ 0.5 with the truth
    /// after four tracked frames, one, two or three frames apart
    /// (`docs/experiments/2026-11-28-device-anchor-and-cheaper-tracking.md`).
    pub const DEFAULT: TrackerParams = TrackerParams {
        lk: LkParams {
            win_radius: 5,
            levels: 3,
            max_iters: 10,
            epsilon: 0.03,
            min_eigen: 1e-3,
        },
        corners: CornerParams {
            quality_level: 0.01,
            min_distance: 4.0,
        },
        box_margin: 0.1,
        max_fb_error: 1.0,
        min_points: 4,
    };
}

impl Default for TrackerParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The result of tracking one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackOutcome {
    /// The updated box.
    pub bbox: BBox,
    /// Points that survived this frame.
    pub points: usize,
    /// Surviving points over the points selected at `init`, in `[0, 1]` (the
    /// controller's `T_m` quality).
    pub quality: f32,
}

/// A KLT tracker holding up to `MAX_POINTS` points; a `const fn new`, no allocation.
#[derive(Clone, Debug)]
pub struct Tracker<const MAX_POINTS: usize> {
    params: TrackerParams,
    pts: [Point; MAX_POINTS],
    n: usize,
    initial: usize,
    bbox: BBox,
    active: bool,
    fwd: [Point; MAX_POINTS],
    scratch: [f32; MAX_POINTS],
    scratch2: [f32; MAX_POINTS],
    corners: [Corner; MAX_POINTS],
    lk: LkScratch,
}

const ZERO: Point = Point { x: 0.0, y: 0.0 };

/// The median of `v` (upper median for even lengths); reorders `v`.
fn median(v: &mut [f32]) -> Option<f32> {
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f32::total_cmp);
    Some(*m)
}

impl<const MAX_POINTS: usize> Tracker<MAX_POINTS> {
    /// An idle tracker.
    pub const fn new(params: TrackerParams) -> Self {
        Self {
            params,
            pts: [ZERO; MAX_POINTS],
            n: 0,
            initial: 0,
            bbox: BBox::new(0.0, 0.0, 0.0, 0.0),
            active: false,
            fwd: [ZERO; MAX_POINTS],
            scratch: [0.0; MAX_POINTS],
            scratch2: [0.0; MAX_POINTS],
            corners: [Corner {
                pos: ZERO,
                response: 0.0,
            }; MAX_POINTS],
            lk: LkScratch::new(),
        }
    }

    /// The parameters.
    pub const fn params(&self) -> &TrackerParams {
        &self.params
    }

    /// True after a successful `init` and until tracking fails.
    pub const fn is_active(&self) -> bool {
        self.active
    }

    /// The current box.
    pub const fn bbox(&self) -> BBox {
        self.bbox
    }

    /// The current points (level-0 coordinates).
    pub fn points(&self) -> &[Point] {
        self.pts.get(..self.n).unwrap_or(&[])
    }

    /// Forgets the track.
    pub fn reset(&mut self) {
        self.active = false;
        self.n = 0;
    }

    /// Starts a track on `bbox` in the frame of `pyr`: selects up to `MAX_POINTS`
    /// corners inside it. Returns how many.
    pub fn init(&mut self, pyr: &Pyramid<'_>, bbox: BBox) -> Result<usize, TrackError> {
        self.active = false;
        self.n = 0;
        let (w, h) = (pyr.width() as f32, pyr.height() as f32);
        let clipped = bbox.clip(w, h);
        if !bbox.is_valid() || !clipped.is_valid() {
            return Err(TrackError::BadBox);
        }
        let img = pyr.level(0).ok_or(TrackError::BadImage)?;
        let m = self.params.box_margin.clamp(0.0, 0.45);
        let (mx, my) = (bbox.width() * m, bbox.height() * m);
        let region = BBox::new(
            clipped.x1 + mx,
            clipped.y1 + my,
            clipped.x2 - mx,
            clipped.y2 - my,
        );
        let found = good_features(&img, &region, &self.params.corners, &mut self.corners);
        for (p, c) in self.pts.iter_mut().zip(self.corners.iter().take(found)) {
            *p = c.pos;
        }
        if found < self.params.min_points.max(1) {
            return Err(TrackError::TooFewPoints);
        }
        self.n = found;
        self.initial = found;
        self.bbox = bbox;
        self.active = true;
        Ok(found)
    }

    /// Starts a track on `bbox` from given points (e.g. to compare with another tracker
    /// on identical points). Points beyond `MAX_POINTS` are ignored.
    pub fn init_with_points(&mut self, bbox: BBox, points: &[Point]) -> Result<usize, TrackError> {
        self.active = false;
        if !bbox.is_valid() {
            return Err(TrackError::BadBox);
        }
        let n = points.len().min(MAX_POINTS);
        for (d, s) in self.pts.iter_mut().zip(points) {
            *d = *s;
        }
        if n < self.params.min_points.max(1) {
            self.n = 0;
            return Err(TrackError::TooFewPoints);
        }
        self.n = n;
        self.initial = n;
        self.bbox = bbox;
        self.active = true;
        Ok(n)
    }

    /// Tracks the points from `prev` into `next` (forward, then backward to check),
    /// drops points whose forward-backward error exceeds the limit, and moves and scales
    /// the box by median flow. On failure the tracker becomes inactive.
    pub fn track(
        &mut self,
        prev: &Pyramid<'_>,
        next: &Pyramid<'_>,
    ) -> Result<TrackOutcome, TrackError> {
        if !self.active {
            return Err(TrackError::NotInitialised);
        }
        if prev.width() != next.width() || prev.height() != next.height() {
            self.active = false;
            return Err(TrackError::SizeMismatch);
        }
        let prm = self.params;
        let max_fb2 = prm.max_fb_error * prm.max_fb_error;
        // Forward and backward; survivors are compacted to the front, old positions
        // in `pts`, new ones in `fwd`.
        let mut kept = 0;
        for i in 0..self.n {
            let Some(p) = self.pts.get(i).copied() else {
                break;
            };
            let Some(q) = track_point_with(&mut self.lk, prev, next, p, p, &prm.lk) else {
                continue;
            };
            let Some(back) = track_point_with(&mut self.lk, next, prev, q, q, &prm.lk) else {
                continue;
            };
            let (ex, ey) = (back.x - p.x, back.y - p.y);
            let fb2 = ex * ex + ey * ey;
            if fb2.is_nan() || fb2 > max_fb2 {
                continue;
            }
            if let (Some(old), Some(new)) = (self.pts.get_mut(kept), self.fwd.get_mut(kept)) {
                *old = p;
                *new = q;
                kept += 1;
            }
        }
        if kept < prm.min_points.max(2) {
            self.active = false;
            self.n = 0;
            return Err(TrackError::TooFewPoints);
        }
        let old = self.pts.get(..kept).ok_or(TrackError::TooFewPoints)?;
        let new = self.fwd.get(..kept).ok_or(TrackError::TooFewPoints)?;
        // Scale: median over points i of the median over j of |q_i q_j| / |p_i p_j|.
        let mut n_ratios = 0;
        for (i, (pi, qi)) in old.iter().zip(new).enumerate() {
            let mut m = 0;
            for (j, (pj, qj)) in old.iter().zip(new).enumerate() {
                let d0 = libm::hypotf(pi.x - pj.x, pi.y - pj.y);
                if i == j || d0 < 1.0 {
                    continue;
                }
                if let Some(s) = self.scratch2.get_mut(m) {
                    *s = libm::hypotf(qi.x - qj.x, qi.y - qj.y) / d0;
                    m += 1;
                }
            }
            let med = median(self.scratch2.get_mut(..m).unwrap_or(&mut []));
            if let (Some(med), Some(s)) = (med, self.scratch.get_mut(n_ratios)) {
                *s = med;
                n_ratios += 1;
            }
        }
        let s = median(self.scratch.get_mut(..n_ratios).unwrap_or(&mut []))
            .filter(|s| s.is_finite() && *s > 0.0)
            .unwrap_or(1.0);
        // Translation of the similarity q = s p + t, per axis, by median.
        for (d, (p, q)) in self.scratch.iter_mut().zip(old.iter().zip(new)) {
            *d = q.x - s * p.x;
        }
        let tx = median(self.scratch.get_mut(..kept).unwrap_or(&mut [])).unwrap_or(0.0);
        for (d, (p, q)) in self.scratch.iter_mut().zip(old.iter().zip(new)) {
            *d = q.y - s * p.y;
        }
        let ty = median(self.scratch.get_mut(..kept).unwrap_or(&mut [])).unwrap_or(0.0);
        let b = self.bbox;
        let bbox = BBox::new(s * b.x1 + tx, s * b.y1 + ty, s * b.x2 + tx, s * b.y2 + ty);
        // Keep the survivors' new positions for the next frame.
        for (dst, src) in self.pts.iter_mut().zip(self.fwd.iter().take(kept)) {
            *dst = *src;
        }
        self.n = kept;
        let (w, h) = (next.width() as f32, next.height() as f32);
        if !bbox.is_valid() || !bbox.clip(w, h).is_valid() {
            self.active = false;
            return Err(TrackError::BadBox);
        }
        self.bbox = bbox;
        Ok(TrackOutcome {
            bbox,
            points: kept,
            quality: kept as f32 / self.initial.max(1) as f32,
        })
    }
}
