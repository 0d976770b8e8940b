//! The content state and the vocabulary of a budget schedule table: the size, motion
//! and count buckets of what a frame shows ([`Content`], [`ContentTracker`]), the
//! table's limits, and its entries ([`ScheduleAction`], [`BudgetInfo`]). The bundle
//! format stores these ([`crate::bundle`]) and the scheduler reads them
//! ([`crate::schedule`]); neither needs the other to know them.
//!
//! Everything here is `Copy`, allocation-free and never panics.

use crate::geom::{BBox, VariantId};

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
/// and the count bucket. The [`Scheduler`](crate::schedule::Scheduler) keeps one; so can any other scheduler that
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

/// A schedule's action: run `variant` now, then, for `period - 1` frames, track its
/// boxes (`track`) or leave the frames alone, the detection's boxes standing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ScheduleAction {
    /// The variant to run.
    pub variant: VariantId,
    /// Detect every `period` frames (`N >= 1`; 1 detects on every frame).
    pub period: u32,
    /// Track the detection's boxes into the frames before the next detection (the
    /// trackers start on them); `false`: start no tracker and leave those frames alone,
    /// the detection's boxes standing until the next one (format version 7 on; every
    /// action of an older bundle tracks).
    pub track: bool,
}

impl ScheduleAction {
    /// Run `variant` every `period` frames, tracking its boxes in between.
    pub const fn tracked(variant: VariantId, period: u32) -> Self {
        Self {
            variant,
            period,
            track: true,
        }
    }
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
