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
//!    [`Decision::Track`], keep the tracked boxes. An action that does not track
//!    ([`ScheduleAction::track`], [`Scheduler::tracks`]) starts no tracker: step 1
//!    tracks nothing ([`TrackState::Idle`]) and a [`Decision::Track`] frame is left
//!    alone (no output, no compute, step 4 skipped), the detection's boxes standing;
//! 4. `scheduler.shown(t, count, largest)` with what frame `t` shows (the detections
//!    on a detection frame, the tracked boxes otherwise; [`largest_box`] picks the box);
//! 5. with a budget keeper ([`Scheduler::keep_budget`]), `scheduler.spent(ms)` with the
//!    device compute frame `t` took, so that the table keeps its budget on this device
//!    ([`BudgetKeeper`]).
//!
//! [`crate::pilot::Pilot::scheduled`] runs that loop with its own trackers.
//!
//! Everything here is `Copy`, allocation-free, O(1) per frame and never panics.

use crate::bundle::{Bucket, Bundle, Schedules};
use crate::controller::{Decision, Stats, Trigger};
use crate::geom::{BBox, VariantId};
use core::fmt;

pub use crate::content::{
    BudgetInfo, CONTENT_STATES, COUNT_BUCKETS, Content, ContentEdges, ContentTracker, MAX_BUDGETS,
    MAX_PERIOD, MAX_PERIODS, MOTION_BUCKETS, SIZE_BUCKETS, ScheduleAction, largest_box,
};

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
/// A detection is asked for on the first frame ([`Trigger::Start`]), when the trackers
/// lost everything they held ([`Trigger::TrackerLost`]), and when the current period
/// has passed since the last detection ([`Trigger::Periodic`]). Every detection looks
/// its action up in the current budget's table at [`Scheduler::state`] and adopts its
/// variant and period; on the first frame that state is the miss bucket, the
/// schedules' initial variant and nothing shown. (A version-4 bundle runs the
/// schedules' initial action on the first frame instead, under every budget:
/// [`Schedules::first_from_table`].)
#[derive(Clone, Copy, Debug)]
pub struct Scheduler<'a> {
    bundle: Bundle<'a>,
    schedules: Schedules<'a>,
    budget: usize,
    variants: usize,
    variant: VariantId,
    period: u32,
    track: bool,
    score: Option<f32>,
    content: ContentTracker,
    started: bool,
    last_detection: u32,
    stats: Stats,
    keeper: Option<BudgetKeeper>,
}

/// Numbers a camera's frames on the clock a bundle's budget tables count
/// ([`Schedules::frame_ms`]), by their capture times: the frame captured `t` ms after
/// the first is frame `⌊t / F + 1/4⌋` of interval `F` (a frame up to a quarter interval
/// early is on time). Frames the camera took while perception was busy are counted, as
/// the tables' periods and budgets count them. A frame that falls on a frame already
/// numbered (a camera faster than the tables' rate), or that was captured before the
/// last one, gets no number: the caller drops it, so a 60 fps camera flies a table made
/// at 30 fps every other frame, as the table was made, instead of detecting twice as
/// often and spending twice its budget. `Copy`, allocation-free, never panics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameClock {
    frame_ms: f64,
    /// Capture time of frame 0, ms.
    start_ms: Option<f64>,
    /// The last number given.
    last: u32,
}

impl FrameClock {
    /// A clock of `frame_ms` per frame; `None` unless it is finite and positive.
    pub fn new(frame_ms: f32) -> Option<Self> {
        (frame_ms.is_finite() && frame_ms > 0.0).then_some(Self {
            frame_ms: frame_ms as f64,
            start_ms: None,
            last: 0,
        })
    }

    /// The interval between the frames it numbers, ms.
    pub const fn frame_ms(&self) -> f64 {
        self.frame_ms
    }

    /// The number of the frame captured at `time_ms` (any origin, the same for every
    /// frame): 0 for the first frame, then strictly ascending; `None` when the frame
    /// is to be dropped (its number is taken, it was captured before the last frame
    /// numbered, or its time is not finite). The first frame's number is 0 whatever
    /// its time, once that time is finite.
    pub fn frame(&mut self, time_ms: f64) -> Option<u32> {
        let n = self.peek(time_ms)?;
        if self.start_ms.is_none() {
            self.start_ms = Some(time_ms);
        }
        self.last = n;
        Some(n)
    }

    /// What [`FrameClock::frame`] would answer for a frame captured at `time_ms`,
    /// without numbering it.
    pub fn peek(&self, time_ms: f64) -> Option<u32> {
        if !time_ms.is_finite() {
            return None;
        }
        let Some(start) = self.start_ms else {
            return Some(0);
        };
        // the cast saturates: a time before the first frame's gives 0, a number
        // already taken; one beyond u32 frames the last number; for the rest it is the
        // floor
        let n = ((time_ms - start) / self.frame_ms + 0.25) as u32;
        (n > self.last).then_some(n)
    }

    /// The last number given (0 before the first frame).
    pub const fn last(&self) -> u32 {
        self.last
    }
}

/// Holds the current budget table to its budget on the device it runs on: a token
/// bucket of device milliseconds, empty at the start. Every frame that arrives credits
/// one frame's budget (frames skipped while perception was busy too), up to `window`
/// frames of it; every frame's measured compute ([`Scheduler::spent`]) is debited.
/// While the bucket is in debt, a periodic detection is postponed (the boxes are
/// tracked instead), for at most one more period. A table made for a device 15 %
/// faster than this one then costs its budget on average (from the start, but for
/// the debt of the last detection) instead of 15 % more. The first detection and one
/// after every track was lost are never postponed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BudgetKeeper {
    /// The budget credited per frame, device ms (the current table's).
    budget_ms: f32,
    /// Most credit, in frames of budget.
    window: u32,
    /// Credit in device ms (negative: debt), within `±window` frames of budget.
    credit_ms: f32,
    /// The last frame credited.
    last: Option<u32>,
    /// Periodic detections postponed so far.
    postponed: u32,
}

impl BudgetKeeper {
    /// An empty bucket of `budget_ms` per frame holding at most `window` frames of
    /// budget (at least one).
    pub const fn new(budget_ms: f32, window: u32) -> Self {
        Self {
            budget_ms,
            window: if window > 0 { window } else { 1 },
            credit_ms: 0.0,
            last: None,
            postponed: 0,
        }
    }

    /// The credit after crediting every frame up to `frame`.
    fn credit_at(&self, frame: u32) -> f32 {
        let frames = match self.last {
            Some(last) => frame.wrapping_sub(last).min(self.window),
            None => 1,
        };
        let cap = self.budget_ms * self.window as f32;
        (self.credit_ms + self.budget_ms * frames as f32).min(cap)
    }

    /// Credits every frame up to `frame`.
    fn credit(&mut self, frame: u32) {
        self.credit_ms = self.credit_at(frame);
        self.last = Some(frame);
    }

    /// Debits `ms` of compute (a negative or NaN `ms` debits nothing); the debt stays
    /// within `window` frames of budget.
    fn debit(&mut self, ms: f32) {
        let ms = if ms > 0.0 { ms } else { 0.0 };
        let floor = -self.budget_ms * self.window as f32;
        self.credit_ms = (self.credit_ms - ms).max(floor);
    }

    /// The credit, in device ms (negative: debt).
    pub const fn credit_ms(&self) -> f32 {
        self.credit_ms
    }

    /// Periodic detections postponed so far.
    pub const fn postponed(&self) -> u32 {
        self.postponed
    }
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
            track: initial.track,
            score: None,
            content: ContentTracker::new(schedules.edges()),
            started: false,
            last_detection: 0,
            stats: Stats {
                frames: 0,
                detections: 0,
                queries: 0,
            },
            keeper: None,
        })
    }

    /// Back to the state of [`Scheduler::new`], on the current budget (a budget keeper
    /// starts again empty).
    pub fn reset(&mut self) {
        let keeper = self
            .keeper
            .map(|k| BudgetKeeper::new(k.budget_ms, k.window));
        if let Ok(fresh) = Self::new(self.bundle, self.budget) {
            *self = Self { keeper, ..fresh };
        }
    }

    /// Keeps the current table's budget on this device with a [`BudgetKeeper`] of
    /// `window` frames (0: no keeper, every period as the table says). The caller then
    /// reports each frame's measured compute to [`Scheduler::spent`].
    pub fn keep_budget(&mut self, window: u32) {
        self.keeper = (window > 0).then(|| BudgetKeeper::new(self.read_budget_ms(), window));
    }

    /// The budget keeper, if any.
    pub const fn keeper(&self) -> Option<BudgetKeeper> {
        self.keeper
    }

    /// The current table's budget in device ms, as the bundle says (0 if it cannot).
    fn read_budget_ms(&self) -> f32 {
        self.schedules
            .budget(self.budget)
            .map_or(0.0, |b| b.budget_ms)
    }

    /// The device compute frame `frame` took, in ms (detection and tracking): debited
    /// from the budget keeper, if any; ignored otherwise.
    pub fn spent(&mut self, ms: f32) {
        if let Some(k) = self.keeper.as_mut() {
            k.debit(ms);
        }
    }

    /// True when a periodic detection on `frame` waits for the budget keeper: it is in
    /// debt after crediting `frame`, and less than twice the period has passed.
    fn postpone(&self, frame: u32) -> bool {
        self.keeper.is_some_and(|k| {
            k.credit_at(frame) < 0.0
                && frame.wrapping_sub(self.last_detection) < self.period.saturating_mul(2)
        })
    }

    /// Switches to budget table `budget`; it takes effect at the next query (and the
    /// budget keeper, if any, credits the new budget from the next frame).
    pub fn set_budget(&mut self, budget: usize) -> Result<(), ScheduleError> {
        if budget >= self.schedules.budget_count() {
            return Err(ScheduleError::NoSuchBudget);
        }
        self.budget = budget;
        let budget_ms = self.read_budget_ms();
        if let Some(k) = self.keeper.as_mut() {
            k.budget_ms = budget_ms;
        }
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

    /// Whether the current action tracks the last detection's boxes into the frames
    /// before the next detection; `false` (an action of a version-7 table): no tracker
    /// runs, and on [`Decision::Track`] the frame is left alone, the last detection's
    /// boxes standing. Read it after a [`Decision::Detect`] to know whether to start
    /// trackers on what the detection found, and before a frame to know whether to
    /// track into it.
    pub const fn tracks(&self) -> bool {
        self.track
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

    /// The current action's period: frames from one periodic detection to the next
    /// (at least 1).
    pub const fn period(&self) -> u32 {
        self.period
    }

    const fn adopt(&mut self, action: ScheduleAction) {
        self.variant = action.variant;
        self.period = if action.period > 0 { action.period } else { 1 };
        self.track = action.track;
    }

    /// True when [`Scheduler::step`] on `frame` detects whatever the trackers report:
    /// the first frame, or the current period has passed since the last detection (and
    /// the budget keeper, if any, does not postpone it). A caller may then skip
    /// tracking into `frame` (its boxes would be replaced by the detection's);
    /// [`crate::pilot::Pilot::scheduled`] does.
    pub fn due(&self, frame: u32) -> bool {
        !self.started
            || (frame.wrapping_sub(self.last_detection) >= self.period && !self.postpone(frame))
    }

    /// Decides frame `frame`. O(1), allocation-free, never panics.
    ///
    /// [`Trigger::Start`] on the first call; [`Trigger::TrackerLost`] when `track` is
    /// [`TrackState::Lost`]; [`Trigger::Periodic`] when `frame - last detection >=
    /// current period` and the budget keeper, if any, does not postpone it; otherwise
    /// [`Decision::Track`]. Every detection adopts the action of the current budget's
    /// table at [`Scheduler::state`] (a version-4 bundle's first detection, the
    /// schedules' initial action).
    pub fn step(&mut self, frame: u32, track: TrackState) -> Decision {
        self.stats.frames = self.stats.frames.wrapping_add(1);
        // (postpone before crediting: it credits up to `frame` itself, as `due` does)
        let postpone = self.postpone(frame);
        if let Some(k) = self.keeper.as_mut() {
            k.credit(frame);
        }
        let reason = if !self.started {
            Trigger::Start
        } else if track == TrackState::Lost {
            Trigger::TrackerLost
        } else if frame.wrapping_sub(self.last_detection) >= self.period {
            if postpone {
                if let Some(k) = self.keeper.as_mut() {
                    k.postponed = k.postponed.wrapping_add(1);
                }
                return Decision::Track;
            }
            Trigger::Periodic
        } else {
            return Decision::Track;
        };
        if reason == Trigger::Start && !self.schedules.first_from_table() {
            // a version-4 bundle: the initial action, whatever the budget
            self.adopt(self.schedules.initial());
        } else {
            // (on the first frame: the miss bucket, the initial variant, nothing shown)
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
