//! The budget strategies' scores: streaming AP, F1 and clock figures per budget,
//! scenario and strategy; the budget policy's margins; tables and plots.

use crate::budget::BudgetPolicies;
use crate::error::Result;
use crate::replay::{ReplayLog, VideoLog};
use crate::scoring::{ground_truth, scenario_groups};
use crate::stream::{StreamRun, StreamTiming, sap, streaming_images_with, timing};
use frugal_models::metrics::{ImageResult, Interpolation, ap_of_records, class_records, evaluate};
use frugal_runtime::ClassId;
use frugal_runtime::ForecastParams;
use serde::{Deserialize, Serialize};

use super::interval::MarginInterval;
use super::{BudgetRun, BudgetStrategy};

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
    /// F1 of the processed frames' outputs against their own frames (no clock): the
    /// paper's figure. Frames a schedule without the tracker leaves alone have no
    /// output and are not scored, so it does not fall as such a schedule detects less
    /// often.
    pub f1: f64,
    /// Streaming F1 at IoU 0.5: every frame scored against the latest output finished
    /// by its arrival, as streaming AP scores it (the boxes the drone holds then, moved
    /// by the forecaster when it is on). 0 in scores written before it was kept.
    #[serde(default)]
    pub sf1: f64,
    /// Static's device ms per frame over this one's (same budget and scenario).
    pub speedup_vs_static: f64,
    /// Detections run.
    pub detections: usize,
    /// Clock figures.
    pub timing: StreamTiming,
}

/// What scoring a set of runs gives.
#[derive(Clone, Debug)]
pub(super) struct Scored {
    /// Streaming AP at IoU 0.5.
    pub sap50: f64,
    /// Streaming AP over IoU 0.50:0.95.
    pub sap: f64,
    /// F1 of the outputs against their own frames.
    pub f1: f64,
    /// Streaming F1 at IoU 0.5.
    pub sf1: f64,
    /// Detections run.
    pub detections: usize,
    /// Clock figures.
    pub timing: StreamTiming,
}

/// Scores of runs, each with its video; every clock run's pairs are pooled.
pub(super) fn score_runs(
    classes: usize,
    runs: &[(&VideoLog, &BudgetRun)],
    fps: f64,
    iou: f32,
    forecast: Option<ForecastParams>,
) -> Scored {
    let mut images: Vec<ImageResult> = Vec::new();
    let mut offline: Vec<ImageResult> = Vec::new();
    // a run streamed from frame `start` is scored on the frames it streamed
    let arrs: Vec<Vec<f64>> = runs
        .iter()
        .map(|(v, r)| {
            let mut arr = v.arrivals_ms(fps);
            arr.split_off(r.start.min(arr.len()))
        })
        .collect();
    for ((video, r), arr) in runs.iter().zip(&arrs) {
        let tr: Vec<_> = (r.start..video.frames.len())
            .map(|f| ground_truth(video, f))
            .collect();
        images.extend(streaming_images_with(arr, &tr, &r.run, forecast));
        for o in &r.run.outputs {
            offline.push(ImageResult {
                detections: o.shown.clone(),
                ..tr[o.frame].clone()
            });
        }
    }
    let classes = classes.max(1);
    let (sap50, sap) = sap(&images, classes);
    // the outputs are the shown boxes, already cut at the confidence threshold
    let f1_of = |i: &[ImageResult]| {
        evaluate(i, classes, iou, f32::NEG_INFINITY, Interpolation::AllPoint).f1
    };
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
    // the budget bounds the compute charged, the clips' last cycles pro-rated
    let mut timing = timing(&pairs);
    timing.device_ms_per_frame = per_frame(
        runs.iter()
            .zip(&arrs)
            .map(|((_, r), arr)| r.charged(arr.len())),
    );
    Scored {
        sap50,
        sap,
        f1: f1_of(&offline),
        sf1: f1_of(&images),
        detections,
        timing,
    }
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
    // runs of equal behaviour are equal (`stream_all`): each is scored once
    let alike = super::first_alike_runs(pol, runs);
    let mut scored: std::collections::HashMap<(usize, &str), Scored> =
        std::collections::HashMap::new();
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
                .enumerate()
                .filter(|(_, (kk, _, _))| *kk == k)
                .map(|(i, (_, s, rs))| {
                    let sc = scored
                        .entry((alike[i], name.as_str()))
                        .or_insert_with(|| {
                            let sel: Vec<(&VideoLog, &BudgetRun)> = sel_videos
                                .iter()
                                .flat_map(|v| {
                                    rs.iter().filter(|r| r.video == v.id).map(move |r| (*v, r))
                                })
                                .collect();
                            score_runs(
                                log.classes,
                                &sel,
                                pol.config.fps,
                                iou,
                                pol.config.forecaster(),
                            )
                        })
                        .clone();
                    BudgetScore {
                        budget_ms: budget,
                        scenario: name.clone(),
                        strategy: s.name().into(),
                        videos: sel_videos.len(),
                        sap50: sc.sap50,
                        sap: sc.sap,
                        f1: sc.f1,
                        sf1: sc.sf1,
                        speedup_vs_static: 1.0,
                        detections: sc.detections,
                        timing: sc.timing,
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

/// The scores as CSV.
pub fn budget_csv(scores: &[BudgetScore]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from(
        "budget_ms,scenario,strategy,videos,sap50,sap,f1,sf1,speedup_vs_static,detections,frames,processed,skipped,deadline_misses,p50_latency_ms,p95_latency_ms,device_ms_per_frame,p95_device_ms\n",
    );
    for r in scores {
        let t = &r.timing;
        let _ = writeln!(
            s,
            "{},{},{},{},{:.6},{:.6},{:.6},{:.6},{:.4},{},{},{},{},{},{:.3},{:.3},{:.3},{:.3}",
            r.budget_ms,
            r.scenario,
            r.strategy,
            r.videos,
            r.sap50,
            r.sap,
            r.f1,
            r.sf1,
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
    /// The strongest simple baseline (static, static + tracker, random + tracker,
    /// ApproxDet-style) at this budget.
    pub best_baseline: String,
    /// Its sAP@0.5.
    pub best_baseline_sap50: f64,
    /// Budget policy minus each other strategy, sAP@0.5 (0–1), in [`BudgetStrategy::ALL`]
    /// order.
    pub versus: Vec<(String, f64)>,
    /// How sure the margins over the simple baselines are: a paired bootstrap over the
    /// videos ([`super::interval`]). Absent from margins written before it was kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interval: Option<MarginInterval>,
}

/// The simple baselines the headline compares against: every one keeps the budget.
pub(super) const SIMPLE: [BudgetStrategy; 4] = [
    BudgetStrategy::Static,
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
                interval: None,
            })
        })
        .collect()
}

/// The overall rows as a Markdown table, one block per budget, then the budget
/// policy's `margins` ([`budget_margins`] of the same scores), each over a simple
/// baseline with its interval where it has one.
pub fn budget_table(scores: &[BudgetScore], margins: &[Margin]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from(
        "| budget | strategy | sAP@0.5 | sAP@[.5:.95] | F1 | streaming F1 | speed-up vs static | device ms/frame | skipped | deadline misses | P50 / P95 latency, ms |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in scores.iter().filter(|r| r.scenario == "all") {
        let t = &r.timing;
        let _ = writeln!(
            s,
            "| {} ms | {} | {:.1} | {:.1} | {:.3} | {:.3} | {:.2}× | {:.1} | {} / {} | {} | {:.0} / {:.0} |",
            r.budget_ms,
            r.strategy,
            100.0 * r.sap50,
            100.0 * r.sap,
            r.f1,
            r.sf1,
            r.speedup_vs_static,
            t.device_ms_per_frame,
            t.skipped,
            t.frames,
            t.deadline_misses,
            t.p50_latency_ms,
            t.p95_latency_ms
        );
    }
    if let Some(first) = margins.first() {
        s.push_str("\nThe budget policy minus each strategy, sAP@0.5 points");
        if let Some(i) = margins.iter().find_map(|m| m.interval.as_ref()) {
            let _ = write!(
                s,
                " (in brackets, over a simple baseline: the central {:.0} % of {} paired \
                 resamples of the {} videos)",
                100.0 * i.level,
                i.resamples,
                i.videos
            );
        }
        s.push_str(":\n\n| budget | best simple baseline |");
        for (name, _) in &first.versus {
            let _ = write!(s, " vs {name} |");
        }
        s.push_str("\n|---|---|");
        s.push_str(&"---|".repeat(first.versus.len()));
        s.push('\n');
        for m in margins {
            let _ = write!(
                s,
                "| {} ms | {} ({:.1}) |",
                m.budget_ms,
                m.best_baseline,
                100.0 * m.best_baseline_sap50
            );
            for (name, d) in &m.versus {
                let _ = write!(s, " {:+.1}", 100.0 * d);
                let within = m
                    .interval
                    .iter()
                    .flat_map(|i| &i.versus)
                    .find(|(n, _)| n == name);
                if let Some((_, [lo, hi])) = within {
                    let _ = write!(s, " [{:+.1}, {:+.1}]", 100.0 * lo, 100.0 * hi);
                }
                s.push_str(" |");
            }
            s.push('\n');
        }
    }
    s
}

/// The two figures: sAP@0.5 against the budget per strategy, and speed against
/// streaming F1 per strategy (one point per budget). Speed is counted against static at
/// the largest budget, so that every budget's points share one scale (static at a
/// smaller budget is itself faster), and accuracy by streaming F1, which scores every
/// frame, so that a schedule that detects less often cannot look as accurate as one
/// that detects every frame.
pub fn plot_budget(stem: &std::path::Path, scores: &[BudgetScore]) -> Result<()> {
    let all: Vec<&BudgetScore> = scores.iter().filter(|r| r.scenario == "all").collect();
    let top = all
        .iter()
        .map(|r| r.budget_ms)
        .fold(f64::NEG_INFINITY, f64::max);
    let static_ms = all
        .iter()
        .find(|r| r.budget_ms == top && r.strategy == BudgetStrategy::Static.name())
        .map_or(f64::NAN, |r| r.timing.device_ms_per_frame);
    let series = |f: &dyn Fn(&BudgetScore) -> (f64, f64)| -> Vec<(String, Vec<(f64, f64)>)> {
        BudgetStrategy::ALL
            .iter()
            .map(|s| {
                let mut pts: Vec<(f64, f64)> = all
                    .iter()
                    .filter(|r| r.strategy == s.name())
                    .map(|r| f(r))
                    .filter(|p| p.0.is_finite() && p.1.is_finite())
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
        "speed against streaming F1, one point per budget",
        (
            &format!("speed-up vs static at {top} ms (device time per frame)"),
            "streaming F1 @ IoU 0.5",
        ),
        &series(&|r| (static_ms / r.timing.device_ms_per_frame, r.sf1)),
    )
}

/// What scoring needs of one or more streamed runs by sAP@0.5 and device time, without
/// streaming them again: per class, the truth boxes and the `(score, is_tp)` match
/// records of the streamed outputs at IoU 0.5 ([`class_records`]), and the device
/// compute and frames of video time as a budget charges them ([`BudgetRun::charged`]).
/// Tallies add up; sAP@0.5 of pooled tallies is [`crate::stream::sap`]'s first figure
/// on the same runs.
#[derive(Clone, Debug, Default)]
pub(super) struct Tally {
    records: Vec<(usize, Vec<(f32, bool)>)>,
    /// Device compute charged ([`BudgetRun::charged`]), ms.
    pub busy_ms: f64,
    /// Frames of video time it is charged over.
    pub frames: usize,
}

impl Tally {
    /// The tally of run `r` of video `v`, whose frames arrive at `arr` (the whole
    /// video's arrivals; the run is scored from its first frame streamed).
    pub fn of(
        classes: usize,
        v: &VideoLog,
        arr: &[f64],
        r: &BudgetRun,
        forecast: Option<ForecastParams>,
    ) -> Self {
        let arr = &arr[r.start.min(arr.len())..];
        let truth: Vec<_> = (r.start..v.frames.len())
            .map(|f| ground_truth(v, f))
            .collect();
        let images = streaming_images_with(arr, &truth, &r.run, forecast);
        let (busy_ms, frames) = r.charged(arr.len());
        Tally {
            records: (0..classes)
                .map(|c| class_records(&images, c as ClassId, 0.5))
                .collect(),
            busy_ms,
            frames,
        }
    }

    /// A tally of these per-class `(truth boxes, match records)`, device ms and frames.
    #[cfg(test)]
    pub fn of_parts(records: Vec<(usize, Vec<(f32, bool)>)>, busy_ms: f64, frames: usize) -> Self {
        Tally {
            records,
            busy_ms,
            frames,
        }
    }

    /// Adds `other` in.
    pub fn add(&mut self, other: &Tally) {
        if self.records.len() < other.records.len() {
            self.records
                .resize_with(other.records.len(), Default::default);
        }
        for (mine, (n, recs)) in self.records.iter_mut().zip(&other.records) {
            mine.0 += n;
            mine.1.extend_from_slice(recs);
        }
        self.busy_ms += other.busy_ms;
        self.frames += other.frames;
    }
}

/// sAP@0.5 of `tallies` pooled: the mean over classes with truth of each class's
/// COCO-interpolated AP.
pub(super) fn pooled_sap50<'t>(
    classes: usize,
    tallies: impl Iterator<Item = &'t Tally> + Clone,
) -> f64 {
    let aps: Vec<f64> = (0..classes)
        .filter_map(|c| {
            let mut n = 0;
            let mut recs = Vec::new();
            for t in tallies.clone() {
                if let Some((tn, tr)) = t.records.get(c) {
                    n += tn;
                    recs.extend_from_slice(tr);
                }
            }
            ap_of_records(n, recs, Interpolation::Coco101)
        })
        .collect();
    if aps.is_empty() {
        0.0
    } else {
        aps.iter().sum::<f64>() / aps.len() as f64
    }
}

/// Device ms per frame of `tallies` pooled (0 without frames).
pub(super) fn ms_per_frame<'t>(tallies: impl IntoIterator<Item = &'t Tally>) -> f64 {
    per_frame(tallies.into_iter().map(|t| (t.busy_ms, t.frames)))
}

/// Device ms per frame of `(busy ms, frames)` charges pooled (0 without frames).
fn per_frame(charges: impl Iterator<Item = (f64, usize)>) -> f64 {
    let (busy, frames) = charges.fold((0.0, 0), |(b, f), (cb, cf)| (b + cb, f + cf));
    if frames > 0 {
        busy / frames as f64
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::replay::{Det, FrameLog};
    use crate::stream::Output;
    use frugal_data::{Clutter, Light, Split};
    use frugal_runtime::{BBox, Detection};

    /// A box 24 px wide moving 5 px a frame: one frame stale it still matches at IoU
    /// 0.5 (0.66), two frames stale it no longer does (0.41).
    fn at(f: usize) -> [f32; 4] {
        let x = 5.0 * f as f32;
        [x, 10.0, x + 24.0, 34.0]
    }

    fn video(frames: usize) -> VideoLog {
        VideoLog {
            id: 0,
            clutter: Clutter::Low,
            light: Light::Normal,
            split: Split::Test,
            width: 160,
            height: 48,
            frames: (0..frames)
                .map(|f| FrameLog {
                    index: f as u32,
                    truth: vec![Det {
                        class: 0,
                        score: 1.0,
                        bbox: at(f),
                    }],
                    detections: Vec::new(),
                    ignore: Vec::new(),
                    time_s: None,
                })
                .collect(),
        }
    }

    /// Exact boxes on every `every`-th frame, each ready 1 ms after its frame arrives.
    fn detecting(v: &VideoLog, every: usize) -> BudgetRun {
        let arr = v.arrivals_ms(30.0);
        let outputs: Vec<Output> = (0..v.frames.len())
            .step_by(every)
            .map(|f| {
                let b = at(f);
                Output {
                    frame: f,
                    start_ms: arr[f],
                    finish_ms: arr[f] + 1.0,
                    device_ms: 1.0,
                    shown: vec![Detection {
                        bbox: BBox::new(b[0], b[1], b[2], b[3]),
                        score: 0.9,
                        class: 0,
                    }],
                }
            })
            .collect();
        BudgetRun {
            video: v.id,
            start: 0,
            detect: vec![Some(0); outputs.len()],
            run: StreamRun {
                outputs,
                skipped: 0,
            },
            queried: Vec::new(),
            last_period: every as u32,
        }
    }

    /// F1 scores only the frames a schedule processed, so exact boxes every fourth
    /// frame score as well as exact boxes every frame; streaming F1 scores every frame
    /// against the boxes held then, so the frames left alone count against it.
    #[test]
    fn streaming_f1_counts_the_frames_a_schedule_leaves_alone_and_f1_does_not() {
        let v = video(12);
        let score = |every: usize| {
            let r = detecting(&v, every);
            score_runs(1, &[(&v, &r)], 30.0, 0.5, None)
        };
        let (each, fourth) = (score(1), score(4));
        assert!((each.f1 - 1.0).abs() < 1e-12, "{each:?}");
        assert!((fourth.f1 - 1.0).abs() < 1e-12, "{fourth:?}");
        // every frame: frame 0 has nothing yet (a miss), every later frame holds the
        // previous frame's box, which still matches: 11 hits, 1 miss, no false box
        assert!((each.sf1 - 22.0 / 23.0).abs() < 1e-9, "{each:?}");
        // every fourth frame: frames 1, 5 and 9 hold a box one frame old (hits); 0 has
        // none (a miss); the other 8 hold older boxes (a miss and a false box each)
        let (tp, fp, fneg) = (3.0, 8.0, 9.0);
        assert!(
            (fourth.sf1 - 2.0 * tp / (2.0 * tp + fp + fneg)).abs() < 1e-9,
            "{fourth:?}"
        );
        assert!(fourth.sf1 < each.sf1);
        assert_eq!((each.detections, fourth.detections), (12, 3));
    }

    /// A schedule is charged as in flight: every 2 frames at 31.8 ms over a 59-frame
    /// clip is 15.9 ms per frame, not the 16.17 that charging the detection that opens
    /// the clip's last, cut-short cycle in full would give.
    #[test]
    fn a_clip_s_last_detection_is_charged_for_the_part_of_its_cycle_it_covers() {
        let v = video(59);
        let mut r = detecting(&v, 2);
        for o in &mut r.run.outputs {
            o.device_ms = 31.8;
        }
        assert_eq!(r.run.outputs.len(), 30);
        let arr = v.arrivals_ms(30.0);
        let t = Tally::of(1, &v, &arr, &r, None);
        assert_eq!(t.frames, 59);
        assert!((ms_per_frame([&t]) - 15.9).abs() < 1e-9);
        let scored = score_runs(1, &[(&v, &r)], 30.0, 0.5, None);
        assert!((scored.timing.device_ms_per_frame - 15.9).abs() < 1e-9);
        assert_eq!(scored.timing.frames, 59);
        // one detection every 118 frames: half of it over the clip's 59 frames
        let one = detecting(&v, 118);
        let t = Tally::of(1, &v, &arr, &one, None);
        assert!((ms_per_frame([&t]) - 0.5 / 59.0).abs() < 1e-12);
    }
}
