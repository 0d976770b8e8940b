//! Streaming evaluation: a simulated clock and streaming AP (Li, Wang, Ramanan,
//! "Towards Streaming Perception", ECCV 2020).
//!
//! Frames arrive at their timestamps (30 fps for the synthetic videos). Perception
//! works on one frame at a time; a frame's output is ready `compute_ms × slowdown`
//! after perception started on it, where `compute_ms` is what the replay charges the
//! frame (the variants' measured latencies and the tracker's measured medians) and
//! `slowdown` the device profile's. A frame that arrives while perception is busy is
//! handled by the [`FrameRule`]:
//!
//! - [`FrameRule::Latest`] (the default, what a drone does): when perception frees up,
//!   it takes the newest frame that has arrived and skips the older ones;
//! - [`FrameRule::Queue`]: every frame is processed in order, waiting its turn.
//!
//! Each ground-truth frame is then scored against the latest output that had
//! *finished* by the frame's own arrival time (an empty output before the first one
//! finishes), so a detector that is accurate but late is scored on the frames it was
//! late for. [`sap`] is COCO-style AP over those pairs: per class the 101-point
//! interpolated AP (as pycocotools), averaged over the classes that have ground truth;
//! `sAP@0.5` at IoU 0.5 and `sAP@[.5:.95]` averaged over IoU 0.50, 0.55, …, 0.95. The
//! test `stream_sap_matches_pycocotools` checks both against an independent Python
//! peer that applies the same rule and scores with pycocotools.

use crate::error::Result;
use frugal_models::metrics::{ImageResult, Interpolation, average_precision};
use frugal_runtime::forecast::MAX_FORECAST;
use frugal_runtime::{ClassId, Detection, ForecastParams, Forecaster};
use serde::{Deserialize, Serialize};

/// What happens to a frame that arrives while perception is busy.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FrameRule {
    /// Skip to the newest arrived frame when perception frees up (frames in between
    /// are never processed).
    #[default]
    Latest,
    /// Process every frame in order; a frame waits until perception is free.
    Queue,
}

/// One processed frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Output {
    /// The frame processed (index into the video's frames).
    pub frame: usize,
    /// When perception started on it, ms of video time.
    pub start_ms: f64,
    /// When its output was ready, ms of video time.
    pub finish_ms: f64,
    /// Compute charged on the device, ms (`finish_ms - start_ms`).
    pub device_ms: f64,
    /// What it showed.
    pub shown: Vec<Detection>,
}

/// One video streamed through a perception loop.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StreamRun {
    /// Processed frames in processing order.
    pub outputs: Vec<Output>,
    /// Frames never processed because the latest-frame rule skipped them (frames a
    /// step left alone are neither processed nor skipped).
    pub skipped: usize,
}

/// Arrival times (ms) of `n` frames at `fps`.
pub fn arrivals(n: usize, fps: f64) -> Vec<f64> {
    (0..n).map(|i| i as f64 * 1000.0 / fps).collect()
}

/// Stream frames arriving at `arrivals_ms` through `step`, which processes one frame
/// (its index) and returns what it shows and its compute time on the measuring machine
/// (ms); the device takes `slowdown` times as long. `step` is called on frames in
/// increasing order, each at most once. A step that returns `None` leaves its frame
/// alone (a schedule that detects every `N` frames with no tracker between): nothing
/// is output, the latest output stands, and perception stays free for the next frame.
pub fn simulate<F>(
    arrivals_ms: &[f64],
    rule: FrameRule,
    slowdown: f64,
    mut step: F,
) -> Result<StreamRun>
where
    F: FnMut(usize) -> Result<Option<(Vec<Detection>, f64)>>,
{
    let mut run = StreamRun::default();
    let mut free_at = f64::NEG_INFINITY;
    let mut next = 0;
    while next < arrivals_ms.len() {
        let (frame, start) = if arrivals_ms[next] >= free_at {
            (next, arrivals_ms[next])
        } else {
            match rule {
                FrameRule::Queue => (next, free_at),
                FrameRule::Latest => {
                    // the newest frame that has arrived by the time perception is free
                    let newest = next
                        + arrivals_ms[next..]
                            .iter()
                            .take_while(|&&a| a <= free_at)
                            .count()
                        - 1;
                    run.skipped += newest - next;
                    (newest, free_at)
                }
            }
        };
        let Some((shown, compute_ms)) = step(frame)? else {
            next = frame + 1;
            continue;
        };
        let device_ms = compute_ms.max(0.0) * slowdown;
        free_at = start + device_ms;
        run.outputs.push(Output {
            frame,
            start_ms: start,
            finish_ms: free_at,
            device_ms,
            shown,
        });
        next = frame + 1;
    }
    Ok(run)
}

/// For every frame, the index into `run.outputs` of the latest output finished by
/// the frame's arrival (`finish_ms <= arrival`; of outputs finishing at the same time,
/// the later processed), `None` before the first output is ready.
pub fn latest_outputs(arrivals_ms: &[f64], run: &StreamRun) -> Vec<Option<usize>> {
    // outputs finish in processing order (one at a time), so a sweep suffices
    let mut used = None;
    let mut o = 0;
    arrivals_ms
        .iter()
        .map(|&t| {
            while o < run.outputs.len() && run.outputs[o].finish_ms <= t {
                used = Some(o);
                o += 1;
            }
            used
        })
        .collect()
}

/// The streaming pairs of one video: every frame's truth with the detections of the
/// output [`latest_outputs`] picks for it.
pub fn streaming_images(
    arrivals_ms: &[f64],
    truth: &[ImageResult],
    run: &StreamRun,
) -> Vec<ImageResult> {
    streaming_images_with(arrivals_ms, truth, run, None)
}

/// [`streaming_images`], with every output's boxes moved by the runtime's
/// [`Forecaster`] (fed every output in processing order) to the frame they are scored
/// on, when `forecast` is given. The frames of `truth` are those of `run`'s outputs
/// (index 0 is frame 0 of the run).
pub fn streaming_images_with(
    arrivals_ms: &[f64],
    truth: &[ImageResult],
    run: &StreamRun,
    forecast: Option<ForecastParams>,
) -> Vec<ImageResult> {
    let mut fc = forecast.map(Forecaster::new);
    let mut fed = 0;
    let mut moved = [Detection::default(); MAX_FORECAST];
    latest_outputs(arrivals_ms, run)
        .into_iter()
        .zip(truth)
        .enumerate()
        .map(|(f, (o, t))| ImageResult {
            detections: o.map_or_else(Vec::new, |o| {
                let out = &run.outputs[o];
                match fc.as_mut() {
                    Some(fc) => {
                        while fed <= o {
                            let u = &run.outputs[fed];
                            fc.update(frame_u32(u.frame), &u.shown);
                            fed += 1;
                        }
                        let n = fc.at(frame_u32(f), &mut moved);
                        let mut d = moved[..n].to_vec();
                        // boxes beyond what the forecaster keeps are shown as they are
                        d.extend_from_slice(out.shown.get(n..).unwrap_or(&[]));
                        d
                    }
                    None => out.shown.clone(),
                }
            }),
            truth: t.truth.clone(),
            ignore: t.ignore.clone(),
        })
        .collect()
}

fn frame_u32(f: usize) -> u32 {
    u32::try_from(f).unwrap_or(u32::MAX)
}

/// The IoU thresholds of COCO's AP@[.5:.95]: numpy's `linspace(0.5, 0.95, 10)`.
pub fn coco_iou_thresholds() -> [f32; 10] {
    let mut t = [0.0f32; 10];
    for (i, x) in t.iter_mut().enumerate() {
        *x = (0.5 + i as f64 * 0.05) as f32;
    }
    t
}

/// COCO-style AP over `images` (each a truth frame paired with the detections it is
/// scored against): `(AP@0.5, AP@[.5:.95])`, the mean over classes `< classes` with
/// ground truth of the 101-point interpolated AP. `(0, 0)` when there is no truth.
pub fn sap(images: &[ImageResult], classes: usize) -> (f64, f64) {
    let per_iou = |iou: f32| {
        let aps: Vec<f64> = (0..classes)
            .filter_map(|c| average_precision(images, c as ClassId, iou, Interpolation::Coco101))
            .collect();
        if aps.is_empty() {
            0.0
        } else {
            aps.iter().sum::<f64>() / aps.len() as f64
        }
    };
    let per: Vec<f64> = coco_iou_thresholds().iter().map(|&t| per_iou(t)).collect();
    let all = per.iter().sum::<f64>() / per.len() as f64;
    (per[0], all)
}

/// Timing figures of a set of streamed videos.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StreamTiming {
    /// Frames in the videos.
    pub frames: usize,
    /// Frames processed.
    pub processed: usize,
    /// Frames skipped by the latest-frame rule.
    pub skipped: usize,
    /// Processed frames whose output was not ready when the next frame arrived.
    pub deadline_misses: usize,
    /// Median time from a processed frame's arrival to its output, ms.
    pub p50_latency_ms: f64,
    /// 95th percentile of the same, ms.
    pub p95_latency_ms: f64,
    /// Mean device compute per processed frame, ms.
    pub mean_device_ms: f64,
    /// 95th percentile of the device compute per processed frame, ms.
    pub p95_device_ms: f64,
    /// Device compute per frame of video time (busy time over the videos' frames), ms:
    /// what a per-frame latency budget bounds. The budget evaluation pro-rates the
    /// last detection by the part of its cycle the clip covers ([`charged`]).
    pub device_ms_per_frame: f64,
}

/// The nearest-rank `q` quantile of `sorted` (ascending); 0 when it is empty.
pub(crate) fn nearest_rank(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let rank = (q * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

/// Timing figures of `runs`, each with its frames' arrival times.
pub fn timing(runs: &[(&[f64], &StreamRun)]) -> StreamTiming {
    let mut latency = Vec::new();
    let mut device = Vec::new();
    let mut t = StreamTiming::default();
    for (arr, run) in runs {
        t.frames += arr.len();
        t.skipped += run.skipped;
        t.processed += run.outputs.len();
        let period = if arr.len() > 1 {
            (arr[arr.len() - 1] - arr[0]) / (arr.len() - 1) as f64
        } else {
            f64::INFINITY
        };
        for o in &run.outputs {
            let arrival = arr[o.frame];
            let next = arr.get(o.frame + 1).copied().unwrap_or(arrival + period);
            if o.finish_ms > next {
                t.deadline_misses += 1;
            }
            latency.push(o.finish_ms - arrival);
            device.push(o.device_ms);
        }
    }
    latency.sort_by(f64::total_cmp);
    device.sort_by(f64::total_cmp);
    t.p50_latency_ms = nearest_rank(&latency, 0.5);
    t.p95_latency_ms = nearest_rank(&latency, 0.95);
    let busy: f64 = device.iter().sum();
    t.mean_device_ms = if device.is_empty() {
        0.0
    } else {
        busy / device.len() as f64
    };
    t.p95_device_ms = nearest_rank(&device, 0.95);
    t.device_ms_per_frame = if t.frames == 0 {
        0.0
    } else {
        busy / t.frames as f64
    };
    t
}

/// Device compute charged to `run`, a stream of `frames` frames whose outputs `i` with
/// `opens(i)` open a detection cycle: `(busy ms, frames)` from the first detection to
/// the end of the stream, the last detection pro-rated by the part of its cycle, of
/// `last_period` frames, that the stream covers. A clip cuts that cycle short while
/// its detection would be charged in full: detecting every 2 frames over 59 frames
/// runs 30 detections, `30 / 59` of a detection per frame where a flight runs `1 / 2`;
/// charged half its last one, it is `29.5 / 59`. A stream that detects nothing is
/// charged every output's compute over all its frames.
pub fn charged(
    run: &StreamRun,
    frames: usize,
    opens: impl Fn(usize) -> bool,
    last_period: u32,
) -> (f64, usize) {
    let mut detections = run
        .outputs
        .iter()
        .enumerate()
        .filter(|&(i, _)| opens(i))
        .map(|(i, out)| (i, out.frame));
    let Some((first, from)) = detections.next() else {
        return (run.outputs.iter().map(|o| o.device_ms).sum(), frames);
    };
    let (last, at) = detections.next_back().unwrap_or((first, from));
    let busy: f64 = run.outputs[first..].iter().map(|o| o.device_ms).sum();
    let covered = frames.saturating_sub(at) as f64 / f64::from(last_period.max(1));
    let unused = run.outputs[last].device_ms * (1.0 - covered.min(1.0));
    (busy - unused, frames.saturating_sub(from))
}

#[cfg(test)]
mod tests {
    use super::*;
    use frugal_runtime::BBox;

    fn det(x: f32) -> Detection {
        Detection {
            bbox: BBox {
                x1: x,
                y1: 10.0,
                x2: x + 20.0,
                y2: 30.0,
            },
            score: 0.9,
            class: 0,
        }
    }

    /// `n` frames of one box moving `speed` px per frame to the right.
    fn moving_truth(n: usize, speed: f32) -> Vec<ImageResult> {
        (0..n)
            .map(|f| ImageResult {
                truth: vec![frugal_models::metrics::Truth {
                    class: 0,
                    bbox: det(speed * f as f32).bbox,
                }],
                ..ImageResult::default()
            })
            .collect()
    }

    #[test]
    fn the_latest_frame_rule_skips_what_arrived_while_busy() {
        let arr = arrivals(6, 10.0); // 0, 100, ..., 500 ms
        // every frame takes 150 ms on the device
        let run = simulate(&arr, FrameRule::Latest, 1.5, |f| {
            Ok(Some((vec![det(f as f32)], 100.0)))
        })
        .unwrap();
        let frames: Vec<usize> = run.outputs.iter().map(|o| o.frame).collect();
        // 0 runs 0-150; at 150 the newest is 1 (100); 1 runs 150-300, when the newest is
        // 3 (2 is skipped); 3 runs 300-450; 4 runs 450-600; 5 runs 600-750
        assert_eq!(frames, vec![0, 1, 3, 4, 5]);
        assert_eq!(run.skipped, 1);
        // 4 ran 450-600, so 5 (arrived at 500) waited until 600
        assert_eq!(run.outputs.last().unwrap().finish_ms, 750.0);
        let q = simulate(&arr, FrameRule::Queue, 1.5, |f| {
            Ok(Some((vec![det(f as f32)], 100.0)))
        })
        .unwrap();
        assert_eq!(q.outputs.len(), 6);
        assert_eq!(q.skipped, 0);
        assert_eq!(q.outputs[5].finish_ms, 900.0);
        let used = latest_outputs(&arr, &run);
        assert_eq!(used, vec![None, None, Some(0), Some(1), Some(1), Some(2)]);
    }

    #[test]
    fn a_frame_left_alone_outputs_nothing_and_keeps_perception_free() {
        let arr = arrivals(8, 10.0); // 0, 100, ..., 700 ms
        // detect every 3rd frame (150 ms on the device), leave the others alone
        let run = simulate(&arr, FrameRule::Latest, 1.5, |f| {
            Ok((f % 3 == 0).then(|| (vec![det(f as f32)], 100.0)))
        })
        .unwrap();
        let frames: Vec<usize> = run.outputs.iter().map(|o| o.frame).collect();
        // 0 runs 0-150; then 1 (the newest) and 2 are left alone, not skipped; 3 starts
        // on its arrival (300), 6 on its own (600)
        assert_eq!(frames, vec![0, 3, 6]);
        assert_eq!(run.skipped, 0);
        assert_eq!(run.outputs[1].start_ms, 300.0);
        assert_eq!(run.outputs[2].start_ms, 600.0);
        // the frames between two detections are scored against the earlier one
        let used = latest_outputs(&arr, &run);
        let (a, b) = (Some(0), Some(1));
        assert_eq!(used, vec![None, None, a, a, a, b, b, b]);
        let t = timing(&[(&arr, &run)]);
        assert_eq!((t.frames, t.processed, t.skipped), (8, 3, 0));
        assert!((t.device_ms_per_frame - 450.0 / 8.0).abs() < 1e-9);
    }

    #[test]
    fn a_clip_charges_its_last_detection_for_the_part_of_its_cycle_it_covers() {
        // 31.8 ms every 2 frames over 59 frames: 30 detections, the last one's cycle
        // cut short by the clip
        let arr = arrivals(59, 30.0);
        let run = simulate(&arr, FrameRule::Latest, 1.0, |f| {
            Ok((f % 2 == 0).then(|| (vec![det(f as f32)], 31.8)))
        })
        .unwrap();
        assert_eq!(run.outputs.len(), 30);
        let t = timing(&[(&arr, &run)]);
        assert!((t.device_ms_per_frame - 30.0 * 31.8 / 59.0).abs() < 1e-9);
        let opens = vec![true; run.outputs.len()];
        let (busy, frames) = charged(&run, arr.len(), |i| opens[i], 2);
        assert_eq!(frames, 59);
        assert!((busy / frames as f64 - 15.9).abs() < 1e-9);
        // over 60 frames the last cycle is whole: charged in full
        let arr60 = arrivals(60, 30.0);
        let (busy, frames) = charged(&run, arr60.len(), |i| opens[i], 2);
        assert!((busy / frames as f64 - 15.9).abs() < 1e-9);
        // with a tracker step (2 ms) between: the detection is pro-rated, the steps
        // the clip holds are charged as they ran
        let run = simulate(&arr, FrameRule::Latest, 1.0, |f| {
            Ok(Some((
                vec![det(f as f32)],
                if f % 2 == 0 { 31.8 } else { 2.0 },
            )))
        })
        .unwrap();
        let opens: Vec<bool> = run.outputs.iter().map(|o| o.frame % 2 == 0).collect();
        let (busy, frames) = charged(&run, arr.len(), |i| opens[i], 2);
        assert_eq!(frames, 59);
        assert!((busy - (29.5 * 31.8 + 29.0 * 2.0)).abs() < 1e-9);
        // one detection every 8 frames on a 3-frame clip: 3/8 of it
        let short = arrivals(3, 30.0);
        let run = simulate(&short, FrameRule::Latest, 1.0, |f| {
            Ok((f == 0).then(|| (vec![det(0.0)], 51.2)))
        })
        .unwrap();
        let (busy, frames) = charged(&run, short.len(), |i| i == 0, 8);
        assert_eq!(frames, 3);
        assert!((busy / frames as f64 - 6.4).abs() < 1e-9);
        // nothing detected: every output over every frame
        assert_eq!(charged(&run, 3, |_| false, 8), (51.2, 3));
    }

    #[test]
    fn forecasting_gives_a_late_detector_back_what_the_motion_took() {
        // a box moving 6 px per frame, a perfect detector whose output is ready 2.5
        // frame periods later: shown 3 frames late, 18 px behind (IoU < 0.5)
        let n = 40;
        let arr = arrivals(n, 30.0);
        let truth = moving_truth(n, 6.0);
        let run = simulate(&arr, FrameRule::Latest, 1.0, |f| {
            Ok(Some((vec![det(6.0 * f as f32)], 2.5 * 1000.0 / 30.0)))
        })
        .unwrap();
        let plain = sap(&streaming_images(&arr, &truth, &run), 1).0;
        let boxes = |images: &[ImageResult]| -> Vec<Vec<Detection>> {
            images.iter().map(|i| i.detections.clone()).collect()
        };
        assert_eq!(
            boxes(&streaming_images_with(&arr, &truth, &run, None)),
            boxes(&streaming_images(&arr, &truth, &run))
        );
        let params = ForecastParams {
            alpha: 1.0,
            ..ForecastParams::DEFAULT
        };
        let images = streaming_images_with(&arr, &truth, &run, Some(params));
        let forecast = sap(&images, 1).0;
        assert!(plain < 0.2, "unforecast sAP@0.5 {plain}");
        // frames 0, 2, 5, 7, ... are processed; frames 0-2 come before the first output
        // and 3-4 get it unmoved (no velocity yet): 35 of 40 frames can match
        assert!(forecast > 0.8, "forecast sAP@0.5 {forecast}");
        // from the second output on, every frame's box is where the truth is
        let exact = images
            .iter()
            .filter(|i| i.detections.first().map(|d| d.bbox) == i.truth.first().map(|t| t.bbox))
            .count();
        assert_eq!(exact, n - 5, "frames forecast exactly");
    }

    #[test]
    fn an_accurate_but_late_detector_scores_lower_in_sap_than_in_ap() {
        // a box moving 10 px per frame; a perfect detector that takes 2.5 frame periods
        let n = 30;
        let arr = arrivals(n, 30.0);
        let truth = moving_truth(n, 10.0);
        let perfect = |f: usize| Ok(Some((vec![det(10.0 * f as f32)], 2.5 * 1000.0 / 30.0)));
        let offline: Vec<ImageResult> = truth
            .iter()
            .enumerate()
            .map(|(f, t)| ImageResult {
                detections: vec![det(10.0 * f as f32)],
                ..t.clone()
            })
            .collect();
        let (ap50, ap) = sap(&offline, 1);
        assert!((ap50 - 1.0).abs() < 1e-12 && (ap - 1.0).abs() < 1e-12);
        let run = simulate(&arr, FrameRule::Latest, 1.0, perfect).unwrap();
        let (sap50, sap_all) = sap(&streaming_images(&arr, &truth, &run), 1);
        assert!(sap50 < 0.5 * ap50, "late: sAP@0.5 {sap50} vs AP {ap50}");
        assert!(sap_all <= sap50);
        // the same detector with no delay on the device scores close to its AP
        let fast = simulate(&arr, FrameRule::Latest, 0.0, perfect).unwrap();
        let (fast50, _) = sap(&streaming_images(&arr, &truth, &fast), 1);
        assert!((fast50 - 1.0).abs() < 1e-12, "{fast50}");
        let t = timing(&[(&arr, &run)]);
        assert_eq!(t.frames, n);
        assert!(t.skipped > 0 && t.deadline_misses == t.processed);
    }
}
