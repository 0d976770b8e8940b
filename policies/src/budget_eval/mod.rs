//! The budget strategies, streamed on a simulated clock and scored by streaming AP
//! (`frugal policy budget`).
//!
//! Same variants, same videos, same clock for every strategy, at every budget:
//!
//! 1. `static`: the fixed (variant, every `N`) schedule without the tracker that
//!    streams best on the tuning videos while keeping the budget there, the last
//!    detection's boxes standing in between ([`BudgetPolicies::static_action`];
//!    without the search, the most accurate variant whose detection fits the budget,
//!    every frame, and when none does the cheapest at the shortest period that keeps
//!    the budget); `static+tracker`: the fixed
//!    (variant, every `N`) schedule that streams best on the tuning videos while keeping
//!    the budget there, in device ms per frame on the clock ([`search_tables`]; without
//!    the search, the best static variant at the shortest `N` whose segment cost fits);
//! 2. `random+tracker`: at every decision, an action drawn uniformly from those that
//!    fit the budget;
//! 3. `approxdet`: an ApproxDet-style scheduler (Xu et al., SenSys 2020): every 8
//!    frames, the action most accurate on the training videos in the current content
//!    whose latency is at most `budget / 1.3`;
//! 4. `mdp+tracker`: the paper's MDP (confidence bucket × variant, no budget, its
//!    accesses per image), run by the runtime's own [`Controller`] over the same
//!    bundle, every reported box carried by the tracker (the paper's rule); the seed's
//!    reference, the same at every budget but for the clock's jitter;
//! 5. `budget`: the learnt budget + content policy ([`crate::budget`]), run by the
//!    runtime's own [`Scheduler`] over a bundle holding its tables;
//! 6. `oracle`: per frame, the cheapest variant that gets the frame right (the replay's
//!    truth), detecting every frame;
//! 7. `hindsight`: per video, the fixed (variant, every `N`) schedule of those a budget
//!    table may hold (with the tracker, and without it when tables may run without it)
//!    chosen knowing the videos' truth, the choices together keeping the budget
//!    (module `hindsight`): how much choosing the right schedule per video could gain over
//!    static and static + tracker on these videos.
//!
//! The paper's MDP also keeps its offline (clock-free) evaluation in [`crate::eval`].

mod hindsight;
mod interval;
mod score;
mod search;

pub use interval::{LEVEL, MarginInterval, RESAMPLES, add_intervals};
pub use score::{
    BudgetScore, Margin, budget_csv, budget_margins, budget_scores, budget_table, plot_budget,
};
pub use search::{CrossFit, MIN_TUNING_VIDEOS, SearchTrace, TuneSet, search_tables};

use score::Tally;

use crate::budget::{BudgetPolicies, Perceiver, TrackState, VideoCache, largest};
use crate::error::{PolicyError, Result};
use crate::replay::{Frames, ReplayLog, VideoLog};
use crate::scoring::{TrackerCost, correct};
use crate::stream::{StreamRun, simulate};
use frugal_runtime::schedule::{ContentEdges, ContentTracker, Scheduler};
use frugal_runtime::{Access, Bundle, Controller, Decision, Detection, Observation};
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

/// A budget strategy.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BudgetStrategy {
    /// The fixed schedule without the tracker that streams best on the tuning videos
    /// while keeping the budget ([`BudgetPolicies::static_action`]).
    Static,
    /// The fixed (variant, every `N`) schedule, with the tracker, that streams best on
    /// the training videos.
    StaticTracker,
    /// A random action that fits the budget at every decision, with the tracker.
    RandomTracker,
    /// The ApproxDet-style scheduler.
    Approxdet,
    /// The paper's MDP with the tracker.
    MdpTracker,
    /// The learnt budget + content policy.
    Budget,
    /// The per-frame oracle.
    Oracle,
    /// Per video, the fixed schedule chosen knowing the truth, keeping the budget over
    /// all videos (module `hindsight`).
    Hindsight,
}

impl BudgetStrategy {
    /// Every strategy, baselines first.
    pub const ALL: [BudgetStrategy; 8] = [
        BudgetStrategy::Static,
        BudgetStrategy::StaticTracker,
        BudgetStrategy::RandomTracker,
        BudgetStrategy::Approxdet,
        BudgetStrategy::MdpTracker,
        BudgetStrategy::Budget,
        BudgetStrategy::Oracle,
        BudgetStrategy::Hindsight,
    ];

    /// Short name.
    pub fn name(self) -> &'static str {
        match self {
            BudgetStrategy::Static => "static",
            BudgetStrategy::StaticTracker => "static+tracker",
            BudgetStrategy::RandomTracker => "random+tracker",
            BudgetStrategy::Approxdet => "approxdet",
            BudgetStrategy::MdpTracker => "mdp+tracker",
            BudgetStrategy::Budget => "budget",
            BudgetStrategy::Oracle => "oracle",
            BudgetStrategy::Hindsight => "hindsight",
        }
    }

    fn tracker(self) -> bool {
        !matches!(self, BudgetStrategy::Static | BudgetStrategy::Oracle)
    }
}

/// What decides a strategy's stream under a budget besides the video and the clock
/// run: two (budget, strategy) pairs with equal behaviour stream identically.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Behaviour {
    /// A fixed action (static, static+tracker).
    Fixed(BudgetStrategy, usize),
    /// A uniform draw, at every decision, from these actions.
    Random(Vec<usize>),
    /// The ApproxDet-style choice among these actions.
    Approxdet(Vec<usize>),
    /// The paper's MDP (no budget).
    Mdp,
    /// The budget policy's table; with a budget keeper, also the budget it keeps (the
    /// bits of its ms; 0 without one).
    Table(Vec<u16>, u64),
    /// The oracle with this fallback variant.
    Oracle(usize),
    /// The hindsight bound under a budget (the bits of its ms), from this fixed action.
    Hindsight(u64, usize),
}

impl BudgetPolicies {
    /// The behaviour of `strategy` under budget `k`.
    pub fn behaviour(&self, k: usize, strategy: BudgetStrategy) -> Behaviour {
        let b = self.config.budgets_ms[k];
        let st = self.static_under(b);
        match strategy {
            BudgetStrategy::Static => Behaviour::Fixed(strategy, self.static_action(b)),
            BudgetStrategy::StaticTracker => Behaviour::Fixed(strategy, self.static_tracker(k)),
            BudgetStrategy::RandomTracker => Behaviour::Random(self.allowed(b)),
            BudgetStrategy::Approxdet => {
                Behaviour::Approxdet(self.allowed(b / self.config.approxdet_headroom))
            }
            BudgetStrategy::MdpTracker => Behaviour::Mdp,
            BudgetStrategy::Budget => Behaviour::Table(
                self.policies[k].actions.clone(),
                if self.config.keep_window > 0 {
                    b.to_bits()
                } else {
                    0
                },
            ),
            BudgetStrategy::Oracle => Behaviour::Oracle(st),
            BudgetStrategy::Hindsight => Behaviour::Hindsight(b.to_bits(), self.static_tracker(k)),
        }
    }
}

/// For every (budget, strategy) pair, the index of the first pair that behaves the
/// same ([`BudgetPolicies::behaviour`]; its own index when none before it does): the
/// pairs whose streams, and scores, are those of an earlier pair.
pub fn first_alike(pol: &BudgetPolicies, pairs: &[(usize, BudgetStrategy)]) -> Vec<usize> {
    let behaviour: Vec<Behaviour> = pairs.iter().map(|&(k, s)| pol.behaviour(k, s)).collect();
    (0..pairs.len())
        .map(|i| (0..i).find(|&j| behaviour[j] == behaviour[i]).unwrap_or(i))
        .collect()
}

/// [`first_alike`] of the (budget, strategy) pairs `runs` holds ([`stream_all`]'s).
pub(crate) fn first_alike_runs(
    pol: &BudgetPolicies,
    runs: &[(usize, BudgetStrategy, Vec<BudgetRun>)],
) -> Vec<usize> {
    let pairs: Vec<(usize, BudgetStrategy)> = runs.iter().map(|(k, s, _)| (*k, *s)).collect();
    first_alike(pol, &pairs)
}

/// Who decides, frame by frame.
enum Brain<'a> {
    /// The runtime's scheduler over a bundle with the budget tables, and the table
    /// states it has looked up.
    Scheduler(Box<Scheduler<'a>>, Vec<u32>),
    /// The runtime's controller over the bundle's MDP table.
    Controller(Box<Controller<'a>>),
    /// A fixed, random or ApproxDet-style choice of (variant, period).
    Period {
        choose: Chooser,
        action: usize,
        started: bool,
        last_detection: u32,
        last_schedule: u32,
        content: ContentTracker,
    },
    /// The oracle.
    Oracle { fallback: usize },
}

enum Chooser {
    Fixed(usize),
    Random(Box<rand_chacha::ChaCha8Rng>, Vec<usize>),
    Approxdet,
}

struct Ctx<'a> {
    pol: &'a BudgetPolicies,
    budget_ms: f64,
    log: &'a ReplayLog,
    video: &'a VideoLog,
    iou: f32,
}

impl Brain<'_> {
    /// True when the next [`Brain::decide`] on frame `f` detects whatever the trackers
    /// report (the runtime's [`Scheduler::due`]; a period that has passed): the
    /// perception loop then skips tracking into `f`, as the runtime's `Pilot` does.
    /// The paper's controller reads the tracks before it decides: never due.
    fn due(&self, f: usize, ctx: &Ctx<'_>) -> bool {
        let frame = f as u32;
        match self {
            Brain::Scheduler(s, _) => s.due(frame),
            Brain::Period {
                action,
                started,
                last_detection,
                ..
            } => !*started || frame.wrapping_sub(*last_detection) >= ctx.pol.period_of(*action),
            Brain::Controller(_) | Brain::Oracle { .. } => false,
        }
    }

    /// Whether the current action tracks between detections: the budget table's
    /// ([`Scheduler::tracks`]) or the fixed one's; the others always track (when their
    /// strategy has the tracker at all).
    fn tracks(&self, ctx: &Ctx<'_>) -> bool {
        match self {
            Brain::Scheduler(s, _) => s.tracks(),
            Brain::Period {
                choose: Chooser::Fixed(a),
                ..
            } => ctx.pol.tracks(*a),
            _ => true,
        }
    }

    /// `Some(variant)` to detect, `None` to track. `track` is what the controller is
    /// told of the held boxes.
    fn decide(
        &mut self,
        f: usize,
        state: TrackState,
        track: Option<frugal_runtime::TrackStatus>,
        ctx: &Ctx<'_>,
    ) -> Option<usize> {
        let frame = f as u32;
        match self {
            Brain::Scheduler(s, queried) => {
                // the state the table is read at, if this step queries it
                let at = s.state();
                match s.step(frame, state) {
                    Decision::Detect { variant, reason } => {
                        // every detection reads the table (the first too, as the
                        // bundles written today say)
                        if reason != frugal_runtime::Trigger::Start
                            || s.schedules().first_from_table()
                        {
                            queried.push(at as u32);
                        }
                        Some(usize::from(variant))
                    }
                    Decision::Track => None,
                }
            }
            // the score went to the controller in `detected`, as the runtime's `Pilot`
            Brain::Controller(c) => match c.step(&Observation {
                frame,
                score: None,
                track,
            }) {
                Decision::Detect { variant, .. } => Some(usize::from(variant)),
                Decision::Track => None,
            },
            Brain::Oracle { fallback } => Some(
                (0..ctx.log.variants.len())
                    .filter(|&v| correct(ctx.log, ctx.video, f, v, ctx.iou))
                    .min_by(|&a, &b| {
                        ctx.log.variants[a]
                            .latency_ms
                            .total_cmp(&ctx.log.variants[b].latency_ms)
                    })
                    .unwrap_or(*fallback),
            ),
            Brain::Period {
                choose,
                action,
                started,
                last_detection,
                last_schedule,
                content,
            } => {
                let every = match choose {
                    Chooser::Approxdet => ctx.pol.config.approxdet_every,
                    _ => 0,
                };
                let period = ctx.pol.period_of(*action);
                let due = !*started
                    || state == TrackState::Lost
                    || frame.wrapping_sub(*last_detection) >= period;
                if !due {
                    return None;
                }
                let reschedule = match choose {
                    Chooser::Fixed(_) => !*started,
                    Chooser::Random(..) => true,
                    Chooser::Approxdet => !*started || frame.wrapping_sub(*last_schedule) >= every,
                };
                if reschedule {
                    *action = match choose {
                        Chooser::Fixed(a) => *a,
                        Chooser::Random(rng, fits) => fits[rng.random_range(0..fits.len())],
                        Chooser::Approxdet => ctx.pol.approxdet(ctx.budget_ms, content.content()),
                    };
                    *last_schedule = frame;
                }
                *started = true;
                *last_detection = frame;
                Some(ctx.pol.variant_of(*action))
            }
        }
    }

    /// The period (frames) of the current action: the budget table's or the chosen
    /// (variant, every `N`); 1 for the controller and the oracle, which have none.
    fn period(&self, ctx: &Ctx<'_>) -> u32 {
        match self {
            Brain::Scheduler(s, _) => s.period(),
            Brain::Period { action, .. } => ctx.pol.period_of(*action),
            Brain::Controller(_) | Brain::Oracle { .. } => 1,
        }
    }

    /// The best score of the detection just run; `Some(variant)` when the paper's MDP
    /// asks for another access on the same frame.
    fn detected(&mut self, score: Option<f32>) -> Option<usize> {
        match self {
            Brain::Scheduler(s, _) => {
                s.detected(score);
                None
            }
            Brain::Controller(c) => match c.detected(score) {
                Access::Again(next) => Some(usize::from(next)),
                Access::Done => None,
            },
            _ => None,
        }
    }

    /// The device compute the frame just decided took (the budget keeper's debit).
    fn spent(&mut self, device_ms: f64) {
        if let Brain::Scheduler(s, _) = self {
            s.spent(device_ms as f32);
        }
    }

    fn shown(&mut self, f: usize, shown: &[Detection]) {
        match self {
            Brain::Scheduler(s, _) => s.shown(f as u32, shown.len(), largest(shown)),
            Brain::Period { content, .. } => content.shown(f as u32, shown.len(), largest(shown)),
            Brain::Controller(_) | Brain::Oracle { .. } => {}
        }
    }
}

/// One strategy streamed over one video.
#[derive(Clone, Debug)]
pub struct BudgetRun {
    /// The video.
    pub video: u32,
    /// The video's first frame streamed ([`crate::budget::BudgetConfig::start_frame`]):
    /// the stream's frame `i` is the video's frame `start + i`.
    pub start: usize,
    /// The stream.
    pub run: StreamRun,
    /// Per processed frame, the variant that detected it (`None`: tracked).
    pub detect: Vec<Option<u16>>,
    /// The budget table's states the budget policy looked its actions up at, in order
    /// (empty for the other strategies).
    pub queried: Vec<u32>,
    /// The period (frames) of the action of the last detection: how many frames its
    /// cycle would have run had the stream gone on (1 for the paper's controller and
    /// the oracle, which have none).
    pub last_period: u32,
}

impl BudgetRun {
    /// Its device compute as a budget is charged, a stream of `frames` frames
    /// ([`crate::stream::charged`]): `(busy ms, frames)`, the last detection pro-rated
    /// by the part of its cycle the stream covers. A clip cuts that cycle short, and
    /// its detection would otherwise be charged in full.
    pub fn charged(&self, frames: usize) -> (f64, usize) {
        let opens = |i: usize| self.detect.get(i).is_some_and(Option::is_some);
        crate::stream::charged(&self.run, frames, opens, self.last_period)
    }
}

/// What [`stream_strategy`] streams: a strategy, or one fixed (variant, every `N`)
/// action (as static + tracker runs its own).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plan {
    /// A strategy under the budget.
    Strategy(BudgetStrategy),
    /// This fixed action: with the tracker when it tracks ([`BudgetPolicies::tracks`]).
    Fixed(usize),
}

impl From<BudgetStrategy> for Plan {
    fn from(s: BudgetStrategy) -> Self {
        Plan::Strategy(s)
    }
}

/// Stream `plan` (a strategy, or a fixed action) under budget `k` of `pol` over
/// `video`. `bundle` holds the budget tables (for [`BudgetStrategy::Budget`]).
/// [`BudgetStrategy::Hindsight`] is chosen over a set of videos, not streamed on one:
/// [`stream_all`] makes it, and here it is an error.
#[allow(clippy::too_many_arguments)]
pub fn stream_strategy(
    log: &ReplayLog,
    video: &VideoLog,
    frames: &dyn Frames,
    cost: TrackerCost,
    pol: &BudgetPolicies,
    k: usize,
    bundle: &[u8],
    plan: impl Into<Plan>,
    iou: f32,
    clock_run: u32,
    cache: &VideoCache,
) -> Result<BudgetRun> {
    let plan = plan.into();
    let cfg = &pol.config;
    // clock run 0 charges the measured times; the others jitter them
    let mut jitter = rand_chacha::ChaCha8Rng::seed_from_u64(
        cfg.seed ^ 0x5eed ^ u64::from(video.id) << 16 ^ u64::from(clock_run) << 40,
    );
    let mut jittered = move |ms: f64| {
        if clock_run == 0 || cfg.jitter == 0.0 {
            ms
        } else {
            ms * (1.0 + jitter.random_range(-cfg.jitter..=cfg.jitter))
        }
    };
    let budget_ms = cfg.budgets_ms[k];
    let edges = ContentEdges {
        size_px: cfg.size_px,
        motion_px: cfg.motion_px,
    };
    let period = |choose| Brain::Period {
        choose,
        action: 0,
        started: false,
        last_detection: 0,
        last_schedule: 0,
        content: ContentTracker::new(edges),
    };
    let st = pol.static_under(budget_ms);
    let strategy = match plan {
        Plan::Strategy(s) => s,
        Plan::Fixed(_) => BudgetStrategy::StaticTracker,
    };
    let mut brain = match plan {
        Plan::Fixed(a) => period(Chooser::Fixed(a)),
        Plan::Strategy(BudgetStrategy::Hindsight) => {
            return Err(PolicyError::invalid(
                std::path::Path::new("<budget strategies>"),
                "strategy",
                "the hindsight bound is chosen over a set of videos (stream_all), not streamed on one"
                    .to_string(),
            ));
        }
        Plan::Strategy(BudgetStrategy::Static) => {
            period(Chooser::Fixed(pol.static_action(budget_ms)))
        }
        Plan::Strategy(BudgetStrategy::StaticTracker) => {
            period(Chooser::Fixed(pol.static_tracker(k)))
        }
        Plan::Strategy(BudgetStrategy::RandomTracker) => {
            let fits = pol.allowed(budget_ms);
            // seeded by the video alone: the same choices draw the same stream under
            // every budget that allows them ([`BudgetPolicies::behaviour`])
            let rng = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed ^ u64::from(video.id));
            period(Chooser::Random(Box::new(rng), fits))
        }
        Plan::Strategy(BudgetStrategy::Approxdet) => period(Chooser::Approxdet),
        Plan::Strategy(BudgetStrategy::MdpTracker) => Brain::Controller(Box::new(Controller::new(
            Bundle::parse(bundle).map_err(|e| PolicyError::Bundle {
                path: "<memory>".into(),
                message: e.to_string(),
            })?,
        ))),
        Plan::Strategy(BudgetStrategy::Budget) => {
            let b = Bundle::parse(bundle).map_err(|e| PolicyError::Bundle {
                path: "<memory>".into(),
                message: e.to_string(),
            })?;
            let mut s = Scheduler::new(b, k).map_err(|e| PolicyError::Bundle {
                path: "<memory>".into(),
                message: e.to_string(),
            })?;
            s.keep_budget(cfg.keep_window);
            Brain::Scheduler(Box::new(s), Vec::new())
        }
        Plan::Strategy(BudgetStrategy::Oracle) => Brain::Oracle { fallback: st },
    };
    let ctx = Ctx {
        pol,
        budget_ms,
        log,
        video,
        iou,
    };
    let mut p = Perceiver::new(log, video, frames, cache, cost, cfg.max_tracks);
    // the strategy's tracker; the current action says whether it runs (the budget
    // table's, or a fixed action without it)
    let tracker = strategy.tracker();
    let mut detect = Vec::new();
    let mut last_period = 1;
    let arr = video.arrivals_ms(cfg.fps);
    let start = cfg.start_frame(clock_run).min(arr.len().saturating_sub(1));
    let run = simulate(&arr[start..], cfg.rule, cfg.slowdown, |i| {
        let f = start + i;
        let tracking = tracker && brain.tracks(&ctx);
        // a frame detected on anyway is not tracked into (as the runtime's `Pilot`)
        let track = tracking && !brain.due(f, &ctx);
        let (state, mut ms) = if track {
            p.track(f)?
        } else {
            (TrackState::Idle, 0.0)
        };
        let status = if track { p.status() } else { None };
        let decision = brain.decide(f, state, status, &ctx);
        if decision.is_none() && !tracking {
            // no tracker to run between detections: the frame is left alone
            return Ok(None);
        }
        let shown = match decision {
            Some(mut v) => loop {
                // the action just taken says whether its boxes are tracked
                let (dets, score, dms) = if tracker && brain.tracks(&ctx) {
                    p.detect(f, v)?
                } else {
                    p.forget(f);
                    (
                        crate::budget::reported(log, video, f, v),
                        video.frames[f].best_score(v),
                        log.variants[v].latency_ms,
                    )
                };
                ms += dms;
                // every access on the frame is charged; the last one's boxes are shown
                match brain.detected(score) {
                    Some(next) => v = next,
                    None => {
                        detect.push(Some(v as u16));
                        last_period = brain.period(&ctx);
                        break dets;
                    }
                }
            },
            None => {
                detect.push(None);
                p.tracked()
            }
        };
        brain.shown(f, &shown);
        let ms = jittered(ms);
        brain.spent(ms * cfg.slowdown);
        Ok(Some((shown, ms)))
    })?;
    let queried = match brain {
        Brain::Scheduler(_, queried) => queried,
        _ => Vec::new(),
    };
    Ok(BudgetRun {
        video: video.id,
        start,
        run,
        detect,
        queried,
        last_period,
    })
}

/// The fixed actions the hindsight bound chooses among: every budget's actions a table
/// may hold ([`BudgetPolicies::table_choices`]), ascending.
fn hindsight_actions(pol: &BudgetPolicies) -> Vec<usize> {
    let mut fixed: Vec<usize> = pol
        .config
        .budgets_ms
        .iter()
        .flat_map(|&b| pol.table_choices(b))
        .collect();
    fixed.sort_unstable();
    fixed.dedup();
    fixed
}

/// The streams [`stream_all`] runs per video, each reported to its `progress` once.
pub fn stream_steps(pol: &BudgetPolicies) -> usize {
    pol.config.budgets_ms.len() * BudgetStrategy::ALL.len() + hindsight_actions(pol).len()
}

/// Every strategy at every budget over `videos`: the runs, keyed by budget index.
/// Each video's frames are decoded once for all its streams, and videos run in
/// parallel (rayon); the result does not depend on the thread count. `progress` is
/// called [`stream_steps`] times per video.
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
pub fn stream_all(
    log: &ReplayLog,
    videos: &[&VideoLog],
    frames: &dyn Frames,
    cost: TrackerCost,
    pol: &BudgetPolicies,
    bundle: &[u8],
    iou: f32,
    progress: &(dyn Fn() + Sync),
) -> Result<Vec<(usize, BudgetStrategy, Vec<BudgetRun>)>> {
    use rayon::prelude::*;
    let combos: Vec<(usize, BudgetStrategy)> = (0..pol.config.budgets_ms.len())
        .flat_map(|k| BudgetStrategy::ALL.map(|s| (k, s)))
        .collect();
    let alike = first_alike(pol, &combos);
    let fixed = hindsight_actions(pol);
    // per fixed action, the (budget, strategy) pair whose runs are its own, if any:
    // static + tracker's schedule, or static's (the same action without the tracker),
    // under some budget
    let streamed: Vec<Option<usize>> = {
        let behaviours: Vec<Behaviour> = combos.iter().map(|&(k, s)| pol.behaviour(k, s)).collect();
        let a_n = pol.tracked_actions();
        fixed
            .iter()
            .map(|&a| {
                let own = if pol.tracks(a) {
                    Behaviour::Fixed(BudgetStrategy::StaticTracker, a)
                } else {
                    Behaviour::Fixed(BudgetStrategy::Static, a - a_n)
                };
                behaviours.iter().position(|b| *b == own)
            })
            .collect()
    };
    let fps = pol.config.fps;
    let forecast = pol.config.forecaster();
    // per video: per (budget, strategy), its clock runs (none for the hindsight bound,
    // chosen below); per fixed action, its clock runs, and their tally
    type PerVideo = (Vec<Vec<BudgetRun>>, Vec<Vec<BudgetRun>>, Vec<Tally>);
    let per_video: Vec<PerVideo> = videos
        .par_iter()
        .map(|v| {
            let cached = crate::replay::MemoryFrames::of_video(frames, v)?;
            let cache = VideoCache::default();
            let stream = |plan: Plan, k: usize| {
                (0..pol.config.clock_runs)
                    .map(|c| {
                        stream_strategy(log, v, &cached, cost, pol, k, bundle, plan, iou, c, &cache)
                    })
                    .collect::<Result<Vec<_>>>()
            };
            let mut out: Vec<Vec<BudgetRun>> = Vec::with_capacity(combos.len());
            for (i, &(k, s)) in combos.iter().enumerate() {
                // a strategy that behaves the same under an earlier budget (the paper's
                // MDP knows none; the same static variant; the same actions to draw
                // from) streams the same: its runs stand for this budget too
                let runs = match alike[i] {
                    _ if s == BudgetStrategy::Hindsight => Vec::new(),
                    j if j < i => out[j].clone(),
                    _ => stream(Plan::Strategy(s), k)?,
                };
                progress();
                out.push(runs);
            }
            let arr = v.arrivals_ms(fps);
            let mut fixed_runs = Vec::with_capacity(fixed.len());
            let mut tallies = Vec::with_capacity(fixed.len());
            for (&a, done) in fixed.iter().zip(&streamed) {
                let runs = match *done {
                    Some(i) => out[i].clone(),
                    None => stream(Plan::Fixed(a), 0)?,
                };
                let mut tally = Tally::default();
                for r in &runs {
                    tally.add(&Tally::of(log.classes, v, &arr, r, forecast));
                }
                progress();
                fixed_runs.push(runs);
                tallies.push(tally);
            }
            Ok((out, fixed_runs, tallies))
        })
        .collect::<Result<_>>()?;
    // the hindsight bound, per budget: the runs of each video's chosen schedule
    let (per_video, tallies): (Vec<_>, Vec<Vec<Tally>>) = per_video
        .into_iter()
        .map(|(out, fixed_runs, t)| ((out, fixed_runs), t))
        .unzip();
    let hindsight: Vec<Vec<usize>> = (0..pol.config.budgets_ms.len())
        .map(|k| {
            let b = pol.config.budgets_ms[k];
            let allowed: Vec<usize> = pol
                .table_choices(b)
                .iter()
                .filter_map(|a| fixed.iter().position(|f| f == a))
                .collect();
            // from the better of static + tracker's and static's schedules
            let starts: Vec<usize> = [pol.static_tracker(k), pol.untracked(pol.static_action(b))]
                .iter()
                .filter_map(|s| fixed.iter().position(|a| a == s))
                .collect();
            hindsight::bound(log.classes, &tallies, &allowed, &starts, b).0
        })
        .collect();
    Ok(combos
        .iter()
        .enumerate()
        .map(|(i, &(k, s))| {
            let runs = match s {
                BudgetStrategy::Hindsight => per_video
                    .iter()
                    .zip(&hindsight[k])
                    .flat_map(|((_, f), &j)| f.get(j).into_iter().flatten().cloned())
                    .collect(),
                _ => per_video
                    .iter()
                    .flat_map(|(v, _)| v[i].iter().cloned())
                    .collect(),
            };
            (k, s, runs)
        })
        .collect())
}
