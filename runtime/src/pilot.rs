//! The whole per-frame perception loop around the [`Controller`]: up to `TRACKS` KLT
//! trackers (one per detected sign, since a frame can hold several), the score
//! hand-over, and the box the drone acts on. No allocation, no panics.
//!
//! Per frame `t`, with the frame's pyramid built into a caller buffer:
//!
//! 1. [`Pilot::decide`] tracks every held box from the previous pyramid into this one,
//!    tells the controller the worst IoU against its detection and the worst point
//!    quality, and returns its [`Decision`]. A reported detection that has no tracker
//!    counts as a lost track (quality 0), so the controller detects again on this frame
//!    rather than drop that sign until the next re-initialisation: a detection below
//!    its variant's optimal bucket (`c_opt`) is reported on its own frame but never
//!    carried (a false or misread box would be repeated for up to `M` frames; see
//!    [`Carry`] for the other choice), and a tracker may fail to start (too few
//!    corners on a small box);
//! 2. on [`Decision::Detect`], run that variant on the frame and hand its detections
//!    (best first) to [`Pilot::detected`], which re-initialises the trackers; while it
//!    answers [`Access::Again`] (the detection scored below `T_c`), run the variant it
//!    names on the same frame and hand those detections over too ([`Pilot::detect_with`]
//!    runs that loop around a detector closure);
//! 3. on [`Decision::Track`], [`Pilot::tracked`] gives the tracked boxes with the
//!    class and score of the detection each one started from.
//!
//! [`Pilot::scheduled`] runs a [`Scheduler`] (the bundle's budget schedules) in place
//! of the controller, over the same trackers: every reported detection is carried
//! ([`Carry::Reported`]), the scheduler is told [`TrackState::Lost`] when the pilot
//! held tracks before a frame and none survives it, each image gets one detection
//! ([`Pilot::detected`] answers [`Access::Done`]), and the pilot reports to
//! [`Scheduler::shown`] what each frame shows: the reported detections on a detection
//! frame, the tracked boxes on a tracked one. Under a table action that does not track
//! ([`crate::schedule::ScheduleAction::track`]) the pilot starts no tracker on what the
//! detection reported: those boxes stand ([`Pilot::standing`]), the frames before the
//! next detection are left alone (no tracking, nothing reported to the scheduler) and
//! [`Pilot::tracked`] gives the standing boxes, so a caller may skip building their
//! pyramids ([`Pilot::tracks_between`]).
//!
//! ```
//! use frugal_runtime::bundle::write::{BundleWriter, FamilySpec, VariantSpec};
//! use frugal_runtime::bundle::{ScoreBuckets, Thresholds};
//! use frugal_runtime::pilot::Pilot;
//! use frugal_runtime::track::Pyramid;
//! use frugal_runtime::{Access, Bundle, Decision};
//!
//! let bytes = BundleWriter::new(Thresholds::PAPER)
//!     .family(FamilySpec { name: "cnn".into(), buckets: ScoreBuckets::PAPER_SVM })
//!     .variant(VariantSpec::new("only", 0, 1.0, 10.0))
//!     .policy(0, vec![0; 4])
//!     .finish()?;
//! let bundle = Bundle::parse(&bytes)?;
//! let mut pilot: Pilot<'_, 4, 64> = Pilot::new(bundle);
//! let (w, h) = (64, 48);
//! let mut buf = vec![0u8; Pyramid::required_len(w, h, 3).unwrap()];
//! let pyr = Pyramid::new(&mut buf, w, h, 3)?;
//! assert!(matches!(pilot.decide(0, None, &pyr), Decision::Detect { variant: 0, .. }));
//! // the detector found nothing; the policy keeps the only variant, so the image is done
//! assert_eq!(pilot.detected(&pyr, &[]), Access::Done);
//! assert_eq!(pilot.tracked().count(), 0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::bundle::{Bundle, ScoreBuckets};
use crate::controller::{Access, Controller, Decision, Observation, Stats, TrackStatus};
use crate::geom::{BBox, Detection, VariantId};
use crate::schedule::{ScheduleError, Scheduler, TrackState, largest_box};
use crate::track::{Pyramid, Tracker, TrackerParams};

/// Which reported detections the [`Pilot`] carries with a tracker between detections.
///
/// The default, [`Carry::Optimal`], keeps a misread box from being repeated for up to
/// `M` frames, at the cost of detecting again after every merely good-enough detection.
/// [`Carry::GoodEnough`] is for a caller that checks a reading before acting on it
/// (the maze flights confirm a sign with the most accurate variant before turning) and
/// would rather spend the compute on frames: it carries every detection of the
/// good-enough bucket up. [`Carry::Reported`] is the paper's rule: every reported
/// detection (at least `T_c`) is carried, and only a weak score, a lost track or a
/// drifted box brings the detector back; it suits a caller that never acts on a
/// carried box alone. Either way a reported detection that is not carried makes the
/// next frame a detection frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "kebab-case")
)]
pub enum Carry {
    /// From the variant's optimal bucket up (`c_opt`).
    #[default]
    Optimal,
    /// From the variant's good-enough bucket up (`c_ge`).
    GoodEnough,
    /// Every reported detection: from the family's `T_c` up (the paper's rule).
    Reported,
}

impl Carry {
    /// The lowest score carried, on the scale of `buckets`.
    pub const fn edge(self, buckets: &ScoreBuckets) -> f32 {
        match self {
            Carry::Optimal => buckets.c_opt,
            Carry::GoodEnough => buckets.c_ge,
            Carry::Reported => buckets.t_c,
        }
    }
}

/// What became of the boxes the [`Pilot`] was handed, counted since it was made
/// (wrapping `u32`s): why a frame after a detection could not be a tracked frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TrackStats {
    /// Reported boxes whose tracker started.
    pub started: u32,
    /// Reported boxes scoring below [`Pilot::track_score`], so not carried.
    pub not_carried: u32,
    /// Reported boxes whose tracker could not start (too few corners, or a box that
    /// does not fit the frame).
    pub failed_to_start: u32,
    /// Tracks that ended between detections (too few points survived a frame).
    pub lost: u32,
}

/// One held track: its tracker and the detection it started from.
#[derive(Clone, Debug)]
struct Held<const POINTS: usize> {
    tracker: Tracker<POINTS>,
    detection: Detection,
}

/// What decides the frames: the bundle's policy or its budget schedules.
#[derive(Clone, Copy, Debug)]
enum Engine<'b> {
    Controller(Controller<'b>),
    Scheduler(Scheduler<'b>),
}

impl<'b> Engine<'b> {
    const fn bundle(&self) -> &Bundle<'b> {
        match self {
            Engine::Controller(c) => c.bundle(),
            Engine::Scheduler(s) => s.bundle(),
        }
    }

    const fn current_variant(&self) -> VariantId {
        match self {
            Engine::Controller(c) => c.current_variant(),
            Engine::Scheduler(s) => s.current_variant(),
        }
    }
}

/// The per-frame loop: a [`Controller`] (or a [`Scheduler`]) plus up to `TRACKS`
/// trackers of up to `POINTS` points each.
#[derive(Clone, Debug)]
pub struct Pilot<'b, const TRACKS: usize, const POINTS: usize> {
    engine: Engine<'b>,
    /// The frame of the last [`Pilot::decide`].
    frame: u32,
    held: [Held<POINTS>; TRACKS],
    active: usize,
    limit: usize,
    carry: Carry,
    /// A reported detection of the last detection frame has no tracker.
    untracked: bool,
    stats: TrackStats,
}

impl<'b, const TRACKS: usize, const POINTS: usize> Pilot<'b, TRACKS, POINTS> {
    /// A pilot over `bundle`'s policy, with the default tracker parameters.
    pub const fn new(bundle: Bundle<'b>) -> Self {
        Self::with_engine(Engine::Controller(Controller::new(bundle)), Carry::Optimal)
    }

    /// A pilot over `bundle`'s budget schedules, on budget table `budget`, with the
    /// default tracker parameters. It carries every reported detection
    /// ([`Carry::Reported`]) and runs one detection per image.
    pub const fn scheduled(bundle: Bundle<'b>, budget: usize) -> Result<Self, ScheduleError> {
        match Scheduler::new(bundle, budget) {
            Ok(s) => Ok(Self::with_engine(Engine::Scheduler(s), Carry::Reported)),
            Err(e) => Err(e),
        }
    }

    const fn with_engine(engine: Engine<'b>, carry: Carry) -> Self {
        Self {
            engine,
            frame: 0,
            held: [const {
                Held {
                    tracker: Tracker::new(TrackerParams::DEFAULT),
                    detection: Detection {
                        bbox: BBox::new(0.0, 0.0, 0.0, 0.0),
                        score: 0.0,
                        class: 0,
                    },
                }
            }; TRACKS],
            active: 0,
            limit: TRACKS,
            carry,
            untracked: false,
            stats: TrackStats {
                started: 0,
                not_carried: 0,
                failed_to_start: 0,
                lost: 0,
            },
        }
    }

    /// Carry detections from `carry`'s bucket up (the default is [`Carry::Optimal`]).
    pub const fn with_carry(mut self, carry: Carry) -> Self {
        self.carry = carry;
        self
    }

    /// Which detections are carried.
    pub const fn carry(&self) -> Carry {
        self.carry
    }

    /// Track at most `n` boxes (at most `TRACKS`; the default is `TRACKS`).
    pub fn with_max_tracks(mut self, n: usize) -> Self {
        self.limit = n.min(TRACKS);
        self
    }

    /// A pilot with given tracker parameters.
    pub fn with_params(bundle: Bundle<'b>, params: TrackerParams) -> Self {
        Self::new(bundle).with_tracker_params(params)
    }

    /// The same pilot with tracker parameters `params`.
    pub fn with_tracker_params(mut self, params: TrackerParams) -> Self {
        for h in &mut self.held {
            h.tracker = Tracker::new(params);
        }
        self
    }

    /// The controller (current variant, counters, bundle); `None` for a pilot over a
    /// scheduler ([`Pilot::scheduled`]).
    pub const fn controller(&self) -> Option<&Controller<'b>> {
        match &self.engine {
            Engine::Controller(c) => Some(c),
            Engine::Scheduler(_) => None,
        }
    }

    /// The scheduler (current variant and period, budget, content state, counters);
    /// `None` for a pilot over the controller ([`Pilot::new`]).
    pub const fn scheduler(&self) -> Option<&Scheduler<'b>> {
        match &self.engine {
            Engine::Controller(_) => None,
            Engine::Scheduler(s) => Some(s),
        }
    }

    /// Switches a scheduled pilot to budget table `budget` from its next detection;
    /// [`ScheduleError::NoSchedules`] for a pilot over the controller.
    pub fn set_budget(&mut self, budget: usize) -> Result<(), ScheduleError> {
        match &mut self.engine {
            Engine::Controller(_) => Err(ScheduleError::NoSchedules),
            Engine::Scheduler(s) => s.set_budget(budget),
        }
    }

    /// A scheduled pilot that keeps its table's budget on this device
    /// ([`Scheduler::keep_budget`], `window` frames; 0: none): report each frame's
    /// measured compute to [`Pilot::spent`]. A pilot over the controller is unchanged.
    pub fn with_budget_keeper(mut self, window: u32) -> Self {
        if let Engine::Scheduler(s) = &mut self.engine {
            s.keep_budget(window);
        }
        self
    }

    /// The device compute the last frame took, in ms (detections and tracking), for a
    /// scheduled pilot's budget keeper ([`Scheduler::spent`]); ignored otherwise.
    pub fn spent(&mut self, ms: f32) {
        if let Engine::Scheduler(s) = &mut self.engine {
            s.spent(ms);
        }
    }

    /// The bundle the pilot flies.
    pub const fn bundle(&self) -> &Bundle<'b> {
        self.engine.bundle()
    }

    /// The variant currently run.
    pub const fn current_variant(&self) -> VariantId {
        self.engine.current_variant()
    }

    /// The controller's or scheduler's counters.
    pub const fn stats(&self) -> Stats {
        match &self.engine {
            Engine::Controller(c) => c.stats(),
            Engine::Scheduler(s) => s.stats(),
        }
    }

    /// What became of the boxes handed over so far.
    pub const fn track_stats(&self) -> TrackStats {
        self.stats
    }

    /// How many boxes are being tracked (or stand, [`Pilot::standing`]).
    pub const fn tracking(&self) -> usize {
        self.active
    }

    /// Whether the boxes held are the last detection's, standing untracked: its table
    /// action does not track ([`Scheduler::tracks`]), so until the next detection the
    /// frames are left alone and [`Pilot::tracked`] gives those boxes as they were found.
    pub const fn standing(&self) -> bool {
        !self.tracks_between()
    }

    /// Whether the pilot tracks between detections under its current action: always
    /// with the controller; with a scheduler, as its current action says
    /// ([`Scheduler::tracks`]). When it does not, the next [`Pilot::decide`] reads no
    /// pyramid, and [`Pilot::detected`] reads one only if the detection's new action
    /// tracks (ask again after [`Decision::Detect`]): a caller may build pyramids only
    /// then, passing an unbuilt one otherwise.
    pub const fn tracks_between(&self) -> bool {
        match &self.engine {
            Engine::Controller(_) => true,
            Engine::Scheduler(s) => s.tracks(),
        }
    }

    /// Track the held boxes from `prev` into `cur` (skipped when `prev` is `None`) and
    /// ask the controller (or scheduler) what to do with frame `frame`. A scheduled
    /// pilot that held tracks and has no `prev`, or whose tracks all ended, tells the
    /// scheduler [`TrackState::Lost`]; on [`Decision::Track`] it reports the tracked
    /// boxes to [`Scheduler::shown`]. A scheduled pilot does not track into a frame
    /// its scheduler detects on anyway ([`Scheduler::due`]): the detection replaces
    /// the boxes, so the tracking would be wasted compute; nor, under an action that
    /// does not track, into any frame ([`Pilot::standing`]): the scheduler is told
    /// [`TrackState::Idle`] and a [`Decision::Track`] frame is left alone.
    pub fn decide(
        &mut self,
        frame: u32,
        prev: Option<&Pyramid<'_>>,
        cur: &Pyramid<'_>,
    ) -> Decision {
        self.frame = frame;
        let held_before = self.active > 0;
        let mut status: Option<TrackStatus> = None;
        let due = match &self.engine {
            Engine::Scheduler(s) => s.due(frame) || !s.tracks(),
            Engine::Controller(_) => false,
        };
        if let (Some(prev), false) = (prev, due) {
            let mut worst = (f32::INFINITY, f32::INFINITY);
            let mut kept = 0;
            for i in 0..self.active.min(TRACKS) {
                let Some(h) = self.held.get_mut(i) else { break };
                match h.tracker.track(prev, cur) {
                    Ok(o) => {
                        let iou = o.bbox.iou(&h.detection.bbox);
                        if iou < worst.0 {
                            worst.0 = iou;
                            status = Some(TrackStatus {
                                bbox: o.bbox,
                                iou,
                                quality: 0.0,
                            });
                        }
                        worst.1 = worst.1.min(o.quality);
                    }
                    Err(_) => {
                        worst.1 = 0.0;
                        self.stats.lost = self.stats.lost.wrapping_add(1);
                    }
                }
                if h.tracker.is_active() {
                    self.held.swap(kept, i);
                    kept += 1;
                }
            }
            self.active = kept;
            if let Some(s) = status.as_mut() {
                s.quality = if self.untracked { 0.0 } else { worst.1 };
            }
        }
        match &mut self.engine {
            // the score went to the controller in `detected`
            Engine::Controller(c) => c.step(&Observation {
                frame,
                score: None,
                track: status,
            }),
            Engine::Scheduler(s) => {
                // without `prev` the held boxes could not follow into this frame (on
                // a due frame they were not tracked: the step detects anyway)
                let standing = !s.tracks();
                let track = if standing {
                    TrackState::Idle
                } else if due || (prev.is_some() && self.active > 0) {
                    TrackState::Held
                } else if held_before {
                    TrackState::Lost
                } else {
                    TrackState::Idle
                };
                let decision = s.step(frame, track);
                if decision == Decision::Track && !standing {
                    let held = self.held.iter().take(self.active);
                    s.shown(
                        frame,
                        self.active,
                        largest_box(held.map(|h| h.tracker.bbox())),
                    );
                }
                decision
            }
        }
    }

    /// The score at which the current variant's detections are reported: its
    /// family's `T_c`.
    pub fn report_score(&self) -> f32 {
        self.engine
            .bundle()
            .variant_buckets(self.engine.current_variant())
            .map_or(f32::NEG_INFINITY, |b| b.t_c)
    }

    /// The score at which the current variant's detections are tracked: the lower edge
    /// of its family's optimal bucket, `c_opt` (good-enough bucket, `c_ge`, under
    /// [`Carry::GoodEnough`]; `T_c` under [`Carry::Reported`]).
    pub fn track_score(&self) -> f32 {
        self.engine
            .bundle()
            .variant_buckets(self.engine.current_variant())
            .map_or(f32::INFINITY, |b| self.carry.edge(&b))
    }

    /// Hand over the detections (best first) that the last [`Decision::Detect`] (or
    /// [`Access::Again`]) asked for, found on the frame whose pyramid is `cur`: up to
    /// `TRACKS` (or [`Pilot::with_max_tracks`]) of the reported boxes (those scoring at
    /// least [`Pilot::report_score`] of the variant that found them) are tracked from
    /// here if they score at least [`Pilot::track_score`], and the best score goes to
    /// the controller, whose answer is returned: [`Access::Again`] asks for another
    /// variant on the same frame. A reported box that is not tracked (below
    /// `track_score`, or its tracker cannot start) makes the next [`Pilot::decide`]
    /// detect again. A scheduled pilot answers [`Access::Done`] and reports the
    /// reported boxes to [`Scheduler::shown`]; under an action that does not track it
    /// starts no tracker (`cur` is not read) and holds the reported boxes as they are
    /// ([`Pilot::standing`]).
    pub fn detected(&mut self, cur: &Pyramid<'_>, detections: &[Detection]) -> Access {
        self.active = 0;
        self.untracked = false;
        // the action the detection just adopted says whether its boxes are tracked
        let standing = self.standing();
        let t_c = self.report_score();
        let carry = self.track_score();
        for d in detections
            .iter()
            .filter(|d| d.score >= t_c)
            .take(self.limit)
        {
            let Some(h) = self.held.get_mut(self.active) else {
                break;
            };
            if standing {
                h.tracker.reset();
                h.detection = *d;
                self.active += 1;
                continue;
            }
            if d.score < carry {
                self.untracked = true;
                self.stats.not_carried = self.stats.not_carried.wrapping_add(1);
                continue;
            }
            h.tracker.reset();
            if h.tracker.init(cur, d.bbox).is_ok() {
                h.detection = *d;
                self.active += 1;
                self.stats.started = self.stats.started.wrapping_add(1);
            } else {
                self.untracked = true;
                self.stats.failed_to_start = self.stats.failed_to_start.wrapping_add(1);
            }
        }
        let best = detections.first().map(|d| d.score);
        match &mut self.engine {
            Engine::Controller(c) => c.detected(best),
            Engine::Scheduler(s) => {
                s.detected(best);
                let reported = detections.iter().filter(|d| d.score >= t_c);
                s.shown(
                    self.frame,
                    reported.clone().count(),
                    largest_box(reported.map(|d| d.bbox)),
                );
                Access::Done
            }
        }
    }

    /// The whole detection of one frame: `run` the variant of [`Decision::Detect`]
    /// (`first`), hand its detections to [`Pilot::detected`], and run every variant it
    /// asks for on the same frame in turn. Returns the last variant run and what it
    /// found (filter with [`Pilot::report_score`] for what to report); `run`'s error
    /// stops the frame.
    pub fn detect_with<D: AsRef<[Detection]>, E>(
        &mut self,
        cur: &Pyramid<'_>,
        first: VariantId,
        mut run: impl FnMut(VariantId) -> Result<D, E>,
    ) -> Result<(VariantId, D), E> {
        let mut variant = first;
        loop {
            let found = run(variant)?;
            match self.detected(cur, found.as_ref()) {
                Access::Again(next) => variant = next,
                Access::Done => return Ok((variant, found)),
            }
        }
    }

    /// The tracked boxes, with the class and score of the detection each started from
    /// (the standing boxes as they were found, [`Pilot::standing`]).
    pub fn tracked(&self) -> impl Iterator<Item = Detection> + '_ {
        let standing = self.standing();
        self.held.iter().take(self.active).map(move |h| Detection {
            bbox: if standing {
                h.detection.bbox
            } else {
                h.tracker.bbox()
            },
            ..h.detection
        })
    }
}
