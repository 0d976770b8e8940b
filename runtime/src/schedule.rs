//! The budget policy with a content state (after ApproxDet and LiteReconfig): per
//! detection the drone picks a detector variant *and* how many frames to track before
//! the next detection (the period `N`), from a table indexed by
//! (confidence bucket, current variant, size bucket, motion bucket, count bucket).
//! The bundle holds one such table per latency budget ([`crate::bundle::Schedules`]);
//! [`Scheduler::set_budget`] switches between them in flight, without a new bundle.
//!
//! The content state describes what the last frame showed ([`Scheduler::shown`]):
//!
//! - size: the height in pixels of the largest box (the one with the greatest height,
//!   the first of equals), bucketed by [`ContentEdges::size_px`];
//! - motion: how far that box's centre moved per frame since the last frame that showed
//!   a box, bucketed by [`ContentEdges::motion_px`];
//! - count: how many boxes the frame showed, 0, 1 or 2 and more.
//!
//! The calling loop, per frame `t`:
//!
//! 1. track the carried boxes into frame `t` and say how that went ([`TrackState`]);
//! 2. `scheduler.step(t, track)`;
//! 3. on [`Decision::Detect`], run that variant on frame `t`, hand its best score to
//!    [`Scheduler::detected`] and (re)start the trackers on what it found; on
//!    [`Decision::Track`], keep the tracked boxes;
//! 4. `scheduler.shown(t, count, largest)` with what frame `t` shows (the detections
//!    on a detection frame, the tracked boxes otherwise; [`largest_box`] picks the box).
//!
//! [`crate::pilot::Pilot::scheduled`] runs that loop with its own trackers.
//!
//! Everything here is `Copy`, allocation-free, O(1) per frame and never panics.

use crate::bundle::{Bucket, Bundle, Schedules};
use crate::controller::{Decision, Stats, Trigger};
use crate::geom::{BBox, VariantId};
use core::fmt;

/// Number of size buckets of the content state.
pub const SIZE_BUCKETS: usize = 3;
/// Number of motion buckets of the content state.
pub const MOTION_BUCKETS: usize = 3;
/// Number of object-count buckets of the content state (0, 1, 2 and more).
pub const COUNT_BUCKETS: usize = 3;
/// Content states per (confidence bucket, variant): 27. A budget table holds
/// `BUCKET_COUNT * CONTENT_STATES` = 108 states per variant.
pub const CONTENT_STATES: usize = SIZE_BUCKETS * MOTION_BUCKETS * COUNT_BUCKETS;
/// Most detection periods a bundle's schedules may offer.
pub const MAX_PERIODS: usize = 4;
/// Most latency budgets (tables) a bundle's schedules may hold.
pub const MAX_BUDGETS: usize = 8;
/// Longest detection period a bundle may name, in frames.
pub const MAX_PERIOD: u32 = 255;

/// The bucket of `v` between edges `e0 <= e1`: below `e0` (or NaN, or `None`) 0,
/// below `e1` 1, else 2.
const fn edge_bucket(v: Option<f32>, edges: [f32; 2]) -> u8 {
    let [e0, e1] = edges;
    match v {
        Some(v) if v >= e0 => {
            if v < e1 {
                1
            } else {
                2
            }
        }
        _ => 0,
    }
}

/// True when both edges are finite and `0 <= e0 <= e1`.
const fn edges_valid(edges: [f32; 2]) -> bool {
    let [e0, e1] = edges;
    e0.is_finite() && e1.is_finite() && e0 >= 0.0 && e0 <= e1
}

/// The edges of the size and motion buckets, in pixels (stored in the bundle).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContentEdges {
    /// Height edges of the largest box: below `size_px[0]` small (0), below
    /// `size_px[1]` medium (1), else large (2).
    pub size_px: [f32; 2],
    /// Edges of its centre's motion in pixels per frame: below `motion_px[0]` still
    /// (0), below `motion_px[1]` moving (1), else fast (2).
    pub motion_px: [f32; 2],
}

impl ContentEdges {
    /// 24 and 64 px of height, 1 and 4 px per frame of motion.
    pub const DEFAULT: ContentEdges = ContentEdges {
        size_px: [24.0, 64.0],
        motion_px: [1.0, 4.0],
    };

    /// True when every edge is finite and each pair is `0 <= e0 <= e1`.
    pub const fn is_valid(&self) -> bool {
        edges_valid(self.size_px) && edges_valid(self.motion_px)
    }

    /// The content state of a frame.
    ///
    /// - size: `largest_height`, the height in pixels of the largest box shown (`None`:
    ///   no box, bucket 0); below edge 0 (or NaN) 0, below edge 1 1, else 2;
    /// - motion: `motion_px_per_frame`, how far that box's centre moved per frame since
    ///   the previous output that had a box (`None`: bucket 0); the same rule;
    /// - count: the number of boxes shown, `min(count, 2)`.
    pub const fn content(
        &self,
        largest_height: Option<f32>,
        motion_px_per_frame: Option<f32>,
        count: usize,
    ) -> Content {
        let max_count = COUNT_BUCKETS - 1;
        Content {
            size: edge_bucket(largest_height, self.size_px),
            motion: edge_bucket(motion_px_per_frame, self.motion_px),
            count: if count < max_count {
                count as u8
            } else {
                max_count as u8
            },
        }
    }
}

impl Default for ContentEdges {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The content part of a schedule state: size, motion and count buckets.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Content {
    /// Size bucket, `< SIZE_BUCKETS`.
    pub size: u8,
    /// Motion bucket, `< MOTION_BUCKETS`.
    pub motion: u8,
    /// Count bucket, `< COUNT_BUCKETS`.
    pub count: u8,
}

/// `v` as an index below `n` (the last bucket for anything above).
const fn clamp_bucket(v: u8, n: usize) -> usize {
    let v = v as usize;
    if v < n { v } else { n - 1 }
}

impl Content {
    /// The index of this content state, `(size · MOTION_BUCKETS + motion) ·
    /// COUNT_BUCKETS + count`, below [`CONTENT_STATES`] (a bucket out of range counts
    /// as the last one).
    pub const fn index(self) -> usize {
        let size = clamp_bucket(self.size, SIZE_BUCKETS);
        let motion = clamp_bucket(self.motion, MOTION_BUCKETS);
        let count = clamp_bucket(self.count, COUNT_BUCKETS);
        (size * MOTION_BUCKETS + motion) * COUNT_BUCKETS + count
    }

    /// The content state of index `i` (the inverse of [`Content::index`]); `None` for
    /// `i >= CONTENT_STATES`.
    pub const fn from_index(i: usize) -> Option<Content> {
        if i >= CONTENT_STATES {
            return None;
        }
        Some(Content {
            size: (i / (MOTION_BUCKETS * COUNT_BUCKETS)) as u8,
            motion: ((i / COUNT_BUCKETS) % MOTION_BUCKETS) as u8,
            count: (i % COUNT_BUCKETS) as u8,
        })
    }
}

/// The index of a state in one budget table of a bundle with `variants` variants:
/// `(bucket.index() · variants + variant) · CONTENT_STATES + content.index()`.
///
/// A table has `BUCKET_COUNT · variants · CONTENT_STATES` states. For
/// `variant >= variants` the answer is `usize::MAX`, outside every table.
pub const fn state_index(
    bucket: Bucket,
    variant: VariantId,
    content: Content,
    variants: usize,
) -> usize {
    let v = variant as usize;
    if v >= variants {
        return usize::MAX;
    }
    bucket
        .index()
        .saturating_mul(variants)
        .saturating_add(v)
        .saturating_mul(CONTENT_STATES)
        .saturating_add(content.index())
}

/// The largest of `boxes`: the one with the greatest height, the first of equals.
pub fn largest_box(boxes: impl IntoIterator<Item = BBox>) -> Option<BBox> {
    boxes
        .into_iter()
        .fold(None, |best: Option<BBox>, b| match best {
            Some(best) if b.height() <= best.height() => Some(best),
            _ => Some(b),
        })
}

/// The content state of what the last frames showed: the size bucket of the largest
/// box, the motion bucket of its centre (distance from the centre of the largest box
/// of the last frame that showed one, divided by the frames elapsed, at least one),
/// and the count bucket. The [`Scheduler`] keeps one; so can any other scheduler that
/// needs the same state (the workbench's ApproxDet-style baseline does).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContentTracker {
    edges: ContentEdges,
    /// The last frame that showed a box, and that box's centre.
    last_box: Option<(u32, f32, f32)>,
    content: Content,
}

impl ContentTracker {
    /// Nothing shown yet.
    pub const fn new(edges: ContentEdges) -> Self {
        Self {
            edges,
            last_box: None,
            content: Content {
                size: 0,
                motion: 0,
                count: 0,
            },
        }
    }

    /// The current content.
    pub const fn content(&self) -> Content {
        self.content
    }

    /// Frame `frame` showed `count` boxes, the largest of them `largest`
    /// ([`largest_box`]).
    pub fn shown(&mut self, frame: u32, count: usize, largest: Option<BBox>) {
        let height = largest.map(|b| b.height());
        let centre = largest
            .map(|b| b.center())
            .filter(|(x, y)| x.is_finite() && y.is_finite());
        let motion = match (centre, self.last_box) {
            (Some((x, y)), Some((then, px, py))) => {
                let elapsed = frame.wrapping_sub(then).max(1) as f32;
                let (dx, dy) = (x - px, y - py);
                Some(libm::sqrtf(dx * dx + dy * dy) / elapsed)
            }
            _ => None,
        };
        if let Some((x, y)) = centre {
            self.last_box = Some((frame, x, y));
        }
        self.content = self.edges.content(height, motion, count);
    }
}

/// A schedule's action: run `variant` now, then track for `period - 1` frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ScheduleAction {
    /// The variant to run.
    pub variant: VariantId,
    /// Detect every `period` frames (`N >= 1`; 1 detects on every frame).
    pub period: u32,
}

/// What a budget table was made for, and what it was measured to cost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BudgetInfo {
    /// The latency budget per frame, in milliseconds (finite, `> 0`).
    pub budget_ms: f32,
    /// The slowdown of the target hardware versus the machine the latencies were
    /// measured on (finite, `> 0`).
    pub slowdown: f32,
    /// The table's expected latency per frame, in milliseconds (finite, `>= 0`).
    pub expected_ms: f32,
    /// Its 95th percentile latency per frame, in milliseconds (finite, `>= 0`).
    pub p95_ms: f32,
}

impl BudgetInfo {
    /// True when every field is finite, the budget and slowdown are positive and the
    /// latencies are not negative.
    pub const fn is_valid(&self) -> bool {
        self.budget_ms.is_finite()
            && self.budget_ms > 0.0
            && self.slowdown.is_finite()
            && self.slowdown > 0.0
            && self.expected_ms.is_finite()
            && self.expected_ms >= 0.0
            && self.p95_ms.is_finite()
            && self.p95_ms >= 0.0
    }
}

/// How the caller's trackers fared on this frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrackState {
    /// Nothing has been carried since the last detection.
    Idle,
    /// At least one track is alive.
    Held,
    /// There was at least one track, and none is alive now.
    Lost,
}

/// Why a [`Scheduler`] could not be made or switched.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScheduleError {
    /// The bundle has no schedules section.
    NoSchedules,
    /// The budget index is not one of the bundle's budgets.
    NoSuchBudget,
}

impl fmt::Display for ScheduleError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::NoSchedules => "policy bundle has no schedules",
            Self::NoSuchBudget => "policy bundle has no such budget",
        })
    }
}

impl core::error::Error for ScheduleError {}

/// The per-frame scheduler over a bundle's [`Schedules`]. `Copy`, allocation-free.
///
/// A detection is asked for on the first frame ([`Trigger::Start`]: the schedules'
/// initial action), when the trackers lost everything they held
/// ([`Trigger::TrackerLost`]), and when the current period has passed since the last
/// detection ([`Trigger::Periodic`]). Every detection but the first looks its action
/// up in the current budget's table at [`Scheduler::state`] and adopts its variant
/// and period.
#[derive(Clone, Copy, Debug)]
pub struct Scheduler<'a> {
    bundle: Bundle<'a>,
    schedules: Schedules<'a>,
    budget: usize,
    variants: usize,
    variant: VariantId,
    period: u32,
    score: Option<f32>,
    content: ContentTracker,
    started: bool,
    last_detection: u32,
    stats: Stats,
}

impl<'a> Scheduler<'a> {
    /// A scheduler on budget table `budget`, before its first frame (the current action
    /// is the schedules' initial one).
    pub const fn new(bundle: Bundle<'a>, budget: usize) -> Result<Self, ScheduleError> {
        let Some(schedules) = bundle.schedules() else {
            return Err(ScheduleError::NoSchedules);
        };
        if budget >= schedules.budget_count() {
            return Err(ScheduleError::NoSuchBudget);
        }
        let initial = schedules.initial();
        Ok(Self {
            bundle,
            schedules,
            budget,
            variants: bundle.variant_count(),
            variant: initial.variant,
            period: if initial.period > 0 {
                initial.period
            } else {
                1
            },
            score: None,
            content: ContentTracker::new(schedules.edges()),
            started: false,
            last_detection: 0,
            stats: Stats {
                frames: 0,
                detections: 0,
                queries: 0,
            },
        })
    }

    /// Back to the state of [`Scheduler::new`], on the current budget.
    pub fn reset(&mut self) {
        if let Ok(fresh) = Self::new(self.bundle, self.budget) {
            *self = fresh;
        }
    }

    /// Switches to budget table `budget`; it takes effect at the next query.
    pub const fn set_budget(&mut self, budget: usize) -> Result<(), ScheduleError> {
        if budget >= self.schedules.budget_count() {
            return Err(ScheduleError::NoSuchBudget);
        }
        self.budget = budget;
        Ok(())
    }

    /// The current budget table.
    pub const fn budget(&self) -> usize {
        self.budget
    }

    /// The bundle this scheduler reads.
    pub const fn bundle(&self) -> &Bundle<'a> {
        &self.bundle
    }

    /// The bundle's schedules.
    pub const fn schedules(&self) -> Schedules<'a> {
        self.schedules
    }

    /// The variant the scheduler currently runs.
    pub const fn current_variant(&self) -> VariantId {
        self.variant
    }

    /// The current detection period `N`.
    pub const fn current_period(&self) -> u32 {
        self.period
    }

    /// The last detection's best score as the scheduler saw it.
    pub const fn last_score(&self) -> Option<f32> {
        self.score
    }

    /// The content state of the last frame reported to [`Scheduler::shown`].
    pub const fn content(&self) -> Content {
        self.content.content()
    }

    /// Counters.
    pub const fn stats(&self) -> Stats {
        self.stats
    }

    /// The confidence bucket of the last detection's score on the current variant's
    /// family scale ([`Bucket::Miss`] when it found nothing).
    pub fn bucket(&self) -> Bucket {
        self.bundle
            .variant_buckets(self.variant)
            .map_or(Bucket::Miss, |b| b.bucket(self.score))
    }

    /// The index of the current state (bucket, current variant, content) in a budget
    /// table ([`state_index`]).
    pub fn state(&self) -> usize {
        state_index(
            self.bucket(),
            self.variant,
            self.content.content(),
            self.variants,
        )
    }

    const fn adopt(&mut self, action: ScheduleAction) {
        self.variant = action.variant;
        self.period = if action.period > 0 { action.period } else { 1 };
    }

    /// Decides frame `frame`. O(1), allocation-free, never panics.
    ///
    /// [`Trigger::Start`] on the first call (the schedules' initial action);
    /// [`Trigger::TrackerLost`] when `track` is [`TrackState::Lost`];
    /// [`Trigger::Periodic`] when `frame - last detection >= current period`;
    /// otherwise [`Decision::Track`]. Every detection but the first adopts the action
    /// of the current budget's table at [`Scheduler::state`].
    pub fn step(&mut self, frame: u32, track: TrackState) -> Decision {
        self.stats.frames = self.stats.frames.wrapping_add(1);
        let reason = if !self.started {
            Trigger::Start
        } else if track == TrackState::Lost {
            Trigger::TrackerLost
        } else if frame.wrapping_sub(self.last_detection) >= self.period {
            Trigger::Periodic
        } else {
            return Decision::Track;
        };
        if reason == Trigger::Start {
            self.adopt(self.schedules.initial());
        } else {
            if let Some(action) = self.schedules.action(self.budget, self.state()) {
                self.adopt(action);
            }
            self.stats.queries = self.stats.queries.wrapping_add(1);
        }
        self.started = true;
        self.last_detection = frame;
        self.stats.detections = self.stats.detections.wrapping_add(1);
        Decision::Detect {
            variant: self.variant,
            reason,
        }
    }

    /// The best score of the detection just run (`None`: it found nothing).
    pub const fn detected(&mut self, score: Option<f32>) {
        self.score = score;
    }

    /// What frame `frame` showed, after detection or tracking: `count` boxes, the
    /// largest of them `largest` ([`largest_box`]). Updates the content state; the
    /// motion is the distance between `largest`'s centre and the centre of the largest
    /// box of the last frame that showed one, divided by the frames elapsed (at least
    /// one).
    pub fn shown(&mut self, frame: u32, count: usize, largest: Option<BBox>) {
        self.content.shown(frame, count, largest);
    }
}
