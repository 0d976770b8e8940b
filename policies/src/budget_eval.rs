//! The budget strategies, streamed on a simulated clock and scored by streaming AP
//! (`frugal policy budget`).
//!
//! Same variants, same videos, same clock for every strategy, at every budget:
//!
//! 1. `static` / `static+tracker`: the best static variant under the budget (the most
//!    accurate, detecting every frame on the training videos, whose detection fits the
//!    budget; the cheapest when none does), detecting every frame, or every `N` frames
//!    with the tracker between (the shortest `N` that fits);
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
//!    truth), detecting every frame.
//!
//! The paper's MDP also keeps its offline (clock-free) evaluation in [`crate::eval`].

use crate::budget::{BudgetPolicies, Perceiver, TrackState, largest, truth};
use crate::error::{PolicyError, Result};
use crate::replay::{Frames, ReplayLog, VideoLog};
use crate::scoring::{TrackerCost, correct, scenario_groups};
use crate::stream::{StreamRun, StreamTiming, arrivals, sap, simulate, streaming_images, timing};
use frugal_models::metrics::{ImageResult, Interpolation, evaluate};
use frugal_runtime::schedule::{ContentEdges, ContentTracker, Scheduler};
use frugal_runtime::{Access, Bundle, Controller, Decision, Detection, Observation};
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

/// A budget strategy.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BudgetStrategy {
    /// The best static variant under the budget, every frame.
    Static,
    /// The same variant with the tracker, every `N` frames.
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
}

impl BudgetStrategy {
    /// Every strategy, baselines first.
    pub const ALL: [BudgetStrategy; 7] = [
        BudgetStrategy::Static,
        BudgetStrategy::StaticTracker,
        BudgetStrategy::RandomTracker,
        BudgetStrategy::Approxdet,
        BudgetStrategy::MdpTracker,
        BudgetStrategy::Budget,
        BudgetStrategy::Oracle,
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
        }
    }

    fn tracker(self) -> bool {
        !matches!(self, BudgetStrategy::Static | BudgetStrategy::Oracle)
    }
}

/// Who decides, frame by frame.
enum Brain<'a> {
    /// The runtime's scheduler over a bundle with the budget tables.
    Scheduler(Box<Scheduler<'a>>),
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
            Brain::Scheduler(s) => match s.step(frame, state) {
                Decision::Detect { variant, .. } => Some(usize::from(variant)),
                Decision::Track => None,
            },
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
                let p_n = ctx.pol.config.periods.len();
                let every = match choose {
                    Chooser::Approxdet => ctx.pol.config.approxdet_every,
                    _ => 0,
                };
                let period = ctx.pol.config.periods[*action % p_n];
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
                Some(*action / p_n)
            }
        }
    }

    /// The best score of the detection just run; `Some(variant)` when the paper's MDP
    /// asks for another access on the same frame.
    fn detected(&mut self, score: Option<f32>) -> Option<usize> {
        match self {
            Brain::Scheduler(s) => {
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

    fn shown(&mut self, f: usize, shown: &[Detection]) {
        match self {
            Brain::Scheduler(s) => s.shown(f as u32, shown.len(), largest(shown)),
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
    /// The stream.
    pub run: StreamRun,
    /// Per processed frame, the variant that detected it (`None`: tracked).
    pub detect: Vec<Option<u16>>,
}

/// Stream `strategy` under budget `k` of `pol` over `video`. `bundle` holds the
/// budget tables (for [`BudgetStrategy::Budget`]).
#[allow(clippy::too_many_arguments)]
pub fn stream_strategy(
    log: &ReplayLog,
    video: &VideoLog,
    frames: &dyn Frames,
    cost: TrackerCost,
    pol: &BudgetPolicies,
    k: usize,
    bundle: &[u8],
    strategy: BudgetStrategy,
    iou: f32,
    clock_run: u32,
) -> Result<BudgetRun> {
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
    let mut brain = match strategy {
        BudgetStrategy::Static => period(Chooser::Fixed(cfg.action(st, 0))),
        BudgetStrategy::StaticTracker => period(Chooser::Fixed(
            cfg.action(st, pol.period_under(st, budget_ms)),
        )),
        BudgetStrategy::RandomTracker => {
            let fits = pol.allowed(budget_ms);
            let rng = rand_chacha::ChaCha8Rng::seed_from_u64(
                cfg.seed ^ u64::from(video.id) ^ (k as u64) << 32,
            );
            period(Chooser::Random(Box::new(rng), fits))
        }
        BudgetStrategy::Approxdet => period(Chooser::Approxdet),
        BudgetStrategy::MdpTracker => Brain::Controller(Box::new(Controller::new(
            Bundle::parse(bundle).map_err(|e| PolicyError::Bundle {
                path: "<memory>".into(),
                message: e.to_string(),
            })?,
        ))),
        BudgetStrategy::Budget => {
            let b = Bundle::parse(bundle).map_err(|e| PolicyError::Bundle {
                path: "<memory>".into(),
                message: e.to_string(),
            })?;
            Brain::Scheduler(Box::new(Scheduler::new(b, k).map_err(|e| {
                PolicyError::Bundle {
                    path: "<memory>".into(),
                    message: e.to_string(),
                }
            })?))
        }
        BudgetStrategy::Oracle => Brain::Oracle { fallback: st },
    };
    let ctx = Ctx {
        pol,
        budget_ms,
        log,
        video,
        iou,
    };
    let mut p = Perceiver::new(log, video, frames, cost, cfg.max_tracks);
    let tracker = strategy.tracker();
    let mut detect = Vec::new();
    let arr = arrivals(video.frames.len(), cfg.fps);
    let run = simulate(&arr, cfg.rule, cfg.slowdown, |f| {
        let (state, mut ms) = if tracker {
            p.track(f)?
        } else {
            (TrackState::Idle, 0.0)
        };
        let status = if tracker { p.status() } else { None };
        let shown = match brain.decide(f, state, status, &ctx) {
            Some(mut v) => loop {
                let (dets, score, dms) = if tracker {
                    p.detect(f, v)?
                } else {
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
        Ok((shown, jittered(ms)))
    })?;
    Ok(BudgetRun {
        video: video.id,
        run,
        detect,
    })
}

/// One strategy at one budget on one scenario.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BudgetScore {
    /// Budget, device ms per frame.
    pub budget_ms: f64,
    /// Scenario (`all` for every video).
    pub scenario: String,
    /// Strategy.
    pub strategy: String,
    /// Videos.
    pub videos: usize,
    /// Streaming AP at IoU 0.5.
    pub sap50: f64,
    /// Streaming AP averaged over IoU 0.50:0.95.
    pub sap: f64,
    /// F1 of the processed frames' outputs against their own frames (no clock).
    pub f1: f64,
    /// Static's device ms per frame over this one's (same budget and scenario).
    pub speedup_vs_static: f64,
    /// Detections run.
    pub detections: usize,
    /// Clock figures.
    pub timing: StreamTiming,
}

/// Scores of runs, each with its video; every clock run's pairs are pooled.
fn score_runs(
    log: &ReplayLog,
    runs: &[(&VideoLog, &BudgetRun)],
    fps: f64,
    iou: f32,
) -> (f64, f64, f64, usize, StreamTiming) {
    let mut images: Vec<ImageResult> = Vec::new();
    let mut offline: Vec<ImageResult> = Vec::new();
    let arrs: Vec<Vec<f64>> = runs
        .iter()
        .map(|(v, _)| arrivals(v.frames.len(), fps))
        .collect();
    for ((video, r), arr) in runs.iter().zip(&arrs) {
        let tr: Vec<_> = (0..video.frames.len()).map(|f| truth(video, f)).collect();
        images.extend(streaming_images(arr, &tr, &r.run));
        for o in &r.run.outputs {
            offline.push(ImageResult {
                detections: o.shown.clone(),
                truth: tr[o.frame].clone(),
            });
        }
    }
    let classes = log.classes.max(1);
    let (s50, s) = sap(&images, classes);
    let f1 = evaluate(
        &offline,
        classes,
        iou,
        f32::NEG_INFINITY,
        Interpolation::AllPoint,
    )
    .f1;
    let detections = runs
        .iter()
        .flat_map(|(_, r)| &r.detect)
        .filter(|d| d.is_some())
        .count();
    let pairs: Vec<(&[f64], &StreamRun)> = arrs
        .iter()
        .map(Vec::as_slice)
        .zip(runs.iter().map(|(_, r)| &r.run))
        .collect();
    (s50, s, f1, detections, timing(&pairs))
}

/// Score every (budget, strategy) run per scenario and overall.
pub fn budget_scores(
    log: &ReplayLog,
    videos: &[&VideoLog],
    pol: &BudgetPolicies,
    runs: &[(usize, BudgetStrategy, Vec<BudgetRun>)],
    iou: f32,
) -> Vec<BudgetScore> {
    let groups = scenario_groups(videos);
    let mut out = Vec::new();
    for (k, &budget) in pol.config.budgets_ms.iter().enumerate() {
        for (name, ids) in &groups {
            let sel_videos: Vec<&VideoLog> = videos
                .iter()
                .copied()
                .filter(|v| ids.contains(&v.id))
                .collect();
            let mut group: Vec<BudgetScore> = runs
                .iter()
                .filter(|(kk, _, _)| *kk == k)
                .map(|(_, s, rs)| {
                    let sel: Vec<(&VideoLog, &BudgetRun)> = sel_videos
                        .iter()
                        .flat_map(|v| rs.iter().filter(|r| r.video == v.id).map(move |r| (*v, r)))
                        .collect();
                    let (sap50, sap, f1, detections, timing) =
                        score_runs(log, &sel, pol.config.fps, iou);
                    BudgetScore {
                        budget_ms: budget,
                        scenario: name.clone(),
                        strategy: s.name().into(),
                        videos: sel_videos.len(),
                        sap50,
                        sap,
                        f1,
                        speedup_vs_static: 1.0,
                        detections,
                        timing,
                    }
                })
                .collect();
            if let Some(st) = group
                .iter()
                .find(|s| s.strategy == "static")
                .map(|s| s.timing.device_ms_per_frame)
            {
                for s in &mut group {
                    s.speedup_vs_static = if s.timing.device_ms_per_frame > 0.0 {
                        st / s.timing.device_ms_per_frame
                    } else {
                        f64::INFINITY
                    };
                }
            }
            out.extend(group);
        }
    }
    out
}

/// Every strategy at every budget over `videos`: the runs, keyed by budget index.
/// Each video's frames are decoded once for all its streams, and videos run in
/// parallel (rayon); the result does not depend on the thread count.
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
    // per video, per (budget, strategy), its clock runs
    let per_video: Vec<Vec<Vec<BudgetRun>>> = videos
        .par_iter()
        .map(|v| {
            let cached = crate::replay::MemoryFrames::of_video(frames, v)?;
            combos
                .iter()
                .map(|&(k, s)| {
                    let runs = (0..pol.config.clock_runs)
                        .map(|c| stream_strategy(log, v, &cached, cost, pol, k, bundle, s, iou, c))
                        .collect::<Result<Vec<_>>>();
                    progress();
                    runs
                })
                .collect()
        })
        .collect::<Result<_>>()?;
    Ok(combos
        .iter()
        .enumerate()
        .map(|(i, &(k, s))| {
            let runs = per_video
                .iter()
                .flat_map(|v| v[i].iter().cloned())
                .collect();
            (k, s, runs)
        })
        .collect())
}

/// The scores as CSV.
pub fn budget_csv(scores: &[BudgetScore]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from(
        "budget_ms,scenario,strategy,videos,sap50,sap,f1,speedup_vs_static,detections,frames,processed,skipped,deadline_misses,p50_latency_ms,p95_latency_ms,device_ms_per_frame,p95_device_ms\n",
    );
    for r in scores {
        let t = &r.timing;
        let _ = writeln!(
            s,
            "{},{},{},{},{:.6},{:.6},{:.6},{:.4},{},{},{},{},{},{:.3},{:.3},{:.3},{:.3}",
            r.budget_ms,
            r.scenario,
            r.strategy,
            r.videos,
            r.sap50,
            r.sap,
            r.f1,
            r.speedup_vs_static,
            r.detections,
            t.frames,
            t.processed,
            t.skipped,
            t.deadline_misses,
            t.p50_latency_ms,
            t.p95_latency_ms,
            t.device_ms_per_frame,
            t.p95_device_ms
        );
    }
    s
}

/// The budget policy against the others at one budget, over every video.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Margin {
    /// Budget, device ms per frame.
    pub budget_ms: f64,
    /// The budget policy's sAP@0.5.
    pub budget_sap50: f64,
    /// The strongest simple baseline (static + tracker, random + tracker, ApproxDet-style)
    /// at this budget.
    pub best_baseline: String,
    /// Its sAP@0.5.
    pub best_baseline_sap50: f64,
    /// Budget policy minus each other strategy, sAP@0.5 (0–1), in [`BudgetStrategy::ALL`]
    /// order.
    pub versus: Vec<(String, f64)>,
}

/// The simple baselines the headline compares against.
const SIMPLE: [BudgetStrategy; 3] = [
    BudgetStrategy::StaticTracker,
    BudgetStrategy::RandomTracker,
    BudgetStrategy::Approxdet,
];

/// The budget policy's margins at every budget (overall rows).
pub fn budget_margins(scores: &[BudgetScore]) -> Vec<Margin> {
    let mut budgets: Vec<f64> = scores.iter().map(|r| r.budget_ms).collect();
    budgets.sort_by(|a, b| b.total_cmp(a));
    budgets.dedup();
    budgets
        .into_iter()
        .filter_map(|b| {
            let row = |s: BudgetStrategy| {
                scores
                    .iter()
                    .find(|r| r.budget_ms == b && r.scenario == "all" && r.strategy == s.name())
            };
            let ours = row(BudgetStrategy::Budget)?.sap50;
            let best = SIMPLE
                .iter()
                .filter_map(|&s| row(s))
                .max_by(|x, y| x.sap50.total_cmp(&y.sap50))?;
            Some(Margin {
                budget_ms: b,
                budget_sap50: ours,
                best_baseline: best.strategy.clone(),
                best_baseline_sap50: best.sap50,
                versus: BudgetStrategy::ALL
                    .iter()
                    .filter(|&&s| s != BudgetStrategy::Budget)
                    .filter_map(|&s| row(s).map(|r| (s.name().to_string(), ours - r.sap50)))
                    .collect(),
            })
        })
        .collect()
}

/// The overall rows as a Markdown table, one block per budget, then the budget
/// policy's margins.
pub fn budget_table(scores: &[BudgetScore]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from(
        "| budget | strategy | sAP@0.5 | sAP@[.5:.95] | F1 | speed-up vs static | device ms/frame | skipped | deadline misses | P50 / P95 latency, ms |\n|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in scores.iter().filter(|r| r.scenario == "all") {
        let t = &r.timing;
        let _ = writeln!(
            s,
            "| {} ms | {} | {:.1} | {:.1} | {:.3} | {:.2}× | {:.1} | {} / {} | {} | {:.0} / {:.0} |",
            r.budget_ms,
            r.strategy,
            100.0 * r.sap50,
            100.0 * r.sap,
            r.f1,
            r.speedup_vs_static,
            t.device_ms_per_frame,
            t.skipped,
            t.frames,
            t.deadline_misses,
            t.p50_latency_ms,
            t.p95_latency_ms
        );
    }
    let margins = budget_margins(scores);
    if let Some(first) = margins.first() {
        s.push_str("\nThe budget policy minus each strategy, sAP@0.5 points:\n\n| budget | best simple baseline |");
        for (name, _) in &first.versus {
            let _ = write!(s, " vs {name} |");
        }
        s.push_str("\n|---|---|");
        s.push_str(&"---|".repeat(first.versus.len()));
        s.push('\n');
        for m in &margins {
            let _ = write!(
                s,
                "| {} ms | {} ({:.1}) |",
                m.budget_ms,
                m.best_baseline,
                100.0 * m.best_baseline_sap50
            );
            for (_, d) in &m.versus {
                let _ = write!(s, " {:+.1} |", 100.0 * d);
            }
            s.push('\n');
        }
    }
    s
}

/// The two figures: sAP@0.5 against the budget per strategy, and speed-up against F1
/// per strategy (one point per budget).
pub fn plot_budget(stem: &std::path::Path, scores: &[BudgetScore]) -> Result<()> {
    let all: Vec<&BudgetScore> = scores.iter().filter(|r| r.scenario == "all").collect();
    let series = |f: &dyn Fn(&BudgetScore) -> (f64, f64)| -> Vec<(String, Vec<(f64, f64)>)> {
        BudgetStrategy::ALL
            .iter()
            .map(|s| {
                let mut pts: Vec<(f64, f64)> = all
                    .iter()
                    .filter(|r| r.strategy == s.name())
                    .map(|r| f(r))
                    .collect();
                pts.sort_by(|a, b| a.0.total_cmp(&b.0));
                (s.name().to_string(), pts)
            })
            .collect()
    };
    let dir = stem.parent().unwrap_or(std::path::Path::new("."));
    let name = stem
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    crate::plot::plot_lines(
        &dir.join(format!("{name}-sap")),
        "streaming AP against the latency budget",
        ("budget, device ms per frame", "sAP@0.5 (%)"),
        &series(&|r| (r.budget_ms, 100.0 * r.sap50)),
    )?;
    crate::plot::plot_lines(
        &dir.join(format!("{name}-speed-f1")),
        "speed against accuracy, one point per budget",
        ("speed-up vs static (device time per frame)", "F1 @ IoU 0.5"),
        &series(&|r| (r.speedup_vs_static, r.f1)),
    )
}
