//! Accuracy and latency of exported variants through ONNX Runtime. Latency comes from
//! one interleaved pass over the timed frames (an even spread of the validation
//! frames): for every such frame, every variant detects it in turn and is timed, so
//! the shared machine's load changes hit all variants alike, and nothing else of the
//! measurement runs meanwhile. The other frames are then scored for accuracy only,
//! split over the cores; detections do not depend on which worker made them.
//!
//! The fronts in the report are noise-aware ([`front_within_noise`]): each variant's
//! latency noise is [`Latency::noise_ms`] of its timed runs, and each accuracy's
//! standard error comes from a bootstrap over the validation videos
//! ([`BOOTSTRAP_RESAMPLES`] resamples, seed [`BOOTSTRAP_SEED`]).
//!
//! Given a device ([`DeviceSpeed`]: how long its reference detectors take, fp32 and
//! int8), the fronts are drawn on the device's latencies: each variant's cost (and
//! noise) scaled by the slowdown of its precision, the device's reference over this
//! machine's (timed in the same rotation). A machine whose int8 runs relatively faster
//! or slower than the device's then draws the device's front, not its own.
//!
//! Over 600 lines with its unit tests (the last 210); the measuring pass itself is one
//! loop that must stay interleaved.
use crate::files::{write_atomic, write_json};
use crate::front::{NoisyPoint, Point, covered_by, front, front_within_noise, merged_into};
use crate::plot::{FrontPlot, plot_front};
use crate::stats::{Latency, cluster_resamples, std_dev};
use crate::variants::{VariantDir, write_variants_file};
use crate::{ParetoError, measure};
use frugal_data::{Dataset, FrameRecord, Split};
use frugal_models::metrics::{ImageResult, Interpolation, evaluate};
use frugal_models::onnx::OrtDetector;
use frugal_models::train::{frame_truth, scenario, spread};
use frugal_runtime::{Detection, FrameRef};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// An accuracy metric: key, axis label, getter of the value and of its standard error.
type Metric = (
    &'static str,
    &'static str,
    fn(&VariantResult) -> f64,
    fn(&VariantResult) -> f64,
);

/// Bootstrap resamples of the validation videos behind each standard error.
pub const BOOTSTRAP_RESAMPLES: usize = 200;

/// Seed of the bootstrap (the same resamples for every variant and every run).
pub const BOOTSTRAP_SEED: u64 = 0x5EED_F00D;

/// Bins of the confidence histograms (over `[0, 1]`).
pub const CONFIDENCE_BINS: usize = 20;

/// Distribution of the best detection score per frame in one scenario.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ConfidenceHistogram {
    /// Frames.
    pub frames: usize,
    /// Frames without any detection.
    pub no_detection: usize,
    /// Counts of the top score in [`CONFIDENCE_BINS`] equal bins over `[0, 1]`.
    pub counts: Vec<usize>,
    /// Mean top score over frames with a detection.
    pub mean_top_score: f64,
}

/// Everything measured for one variant.
#[derive(Clone, Debug, Serialize)]
pub struct VariantResult {
    /// Name.
    pub name: String,
    /// Parent.
    pub parent: Option<String>,
    /// Technique (as in `variant.json`).
    pub technique: serde_json::Value,
    /// Its folder.
    pub dir: PathBuf,
    /// Input size `width × height` of its graphs.
    pub input: String,
    /// Parameters.
    pub parameters: usize,
    /// Non-zero parameters.
    pub nonzero_parameters: usize,
    /// Size of the ONNX files, bytes.
    pub file_bytes: u64,
    /// mAP@0.5 (all-point) on the validation frames.
    pub map: f64,
    /// F1 at the score threshold.
    pub f1: f64,
    /// Mean IoU of true positives.
    pub mean_iou: f64,
    /// Standard error of `map`: standard deviation over bootstrap resamples of the
    /// validation videos (0 with a single video).
    pub map_se: f64,
    /// Standard error of `f1`, the same way.
    pub f1_se: f64,
    /// Standard error of `mean_iou`, the same way.
    pub mean_iou_se: f64,
    /// Precision.
    pub precision: f64,
    /// Recall.
    pub recall: f64,
    /// Latency per frame (whole detector, ONNX Runtime, fixed threads).
    pub latency: Latency,
    /// Latency differences up to this are noise ([`Latency::noise_ms`]).
    pub latency_noise_ms: f64,
    /// Quantized to int8 (scaled by the device's int8 slowdown).
    pub int8: bool,
    /// Cost on the device (`latency`'s fastest run × the slowdown of its precision),
    /// when a device was given: what the fronts are drawn on.
    pub device_ms: Option<f64>,
    /// `latency_noise_ms` on the device, the same way.
    pub device_noise_ms: Option<f64>,
    /// Per scenario `"<clutter>-clutter/<light>-light"`: top-score distribution.
    pub confidence: BTreeMap<String, ConfidenceHistogram>,
    /// On the noise-aware front of each metric (`map`, `f1`, `iou`).
    pub on_front: BTreeMap<String, bool>,
    /// On the plain front of each metric (non-dominated, however small the margin).
    pub on_plain_front: BTreeMap<String, bool>,
    /// Per metric: the front variants that make this one redundant, fastest first:
    /// neither clearly slower nor clearly less accurate than it. Empty on the front;
    /// never empty off it.
    pub dominated_by: BTreeMap<String, Vec<String>>,
    /// Per metric: the front variant this one was merged into, being within noise of
    /// it in both latency and accuracy (`null` on the front, and off it when every
    /// front variant that covers it is clearly better in one coordinate).
    pub merged_into: BTreeMap<String, Option<String>>,
}

impl VariantResult {
    /// The cost the fronts are drawn on: on the device when one was given, else here.
    fn front_ms(&self) -> f64 {
        self.device_ms.unwrap_or(self.latency.cost_ms())
    }

    /// Its latency noise, the same way.
    fn front_noise_ms(&self) -> f64 {
        self.device_noise_ms.unwrap_or(self.latency_noise_ms)
    }
}

/// Every timed run (`timings.json`), ms: per timed validation frame (`frames`, indices
/// into the frames measured), each variant's run and then the reference detectors'
/// (fp32, then int8), in that order, so that any estimator of a variant's cost, or of its ratio to the
/// reference, can be tried on a pass without timing it again.
#[derive(Serialize)]
struct Timings<'a> {
    frames: &'a [usize],
    reference_ms: &'a [f64],
    reference_int8_ms: &'a [f64],
    variants: BTreeMap<&'a str, &'a [f64]>,
}

/// The device the fronts are drawn for: how long its reference detectors take, ms
/// (fp32 and int8; the tx2-like profile's are in the budget config).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct DeviceSpeed {
    /// The reference detector's time on the device.
    pub reference_ms: f64,
    /// The int8 reference detector's time on the device.
    pub reference_int8_ms: f64,
}

/// The device's slowdowns over this machine, fp32 and int8, from the reference
/// detectors' costs here; an error naming the bad time when one is not a positive,
/// finite number.
fn slowdowns(
    device: DeviceSpeed,
    reference: &Latency,
    reference_int8: &Latency,
) -> Result<[f64; 2], ParetoError> {
    let pairs = [
        ("reference", device.reference_ms, reference.cost_ms()),
        (
            "int8 reference",
            device.reference_int8_ms,
            reference_int8.cost_ms(),
        ),
    ];
    let mut out = [0.0; 2];
    for (o, (what, on_device, here)) in out.iter_mut().zip(pairs) {
        let ok = |ms: f64| ms.is_finite() && ms > 0.0;
        if !ok(on_device) || !ok(here) {
            return Err(ParetoError::Input(format!(
                "the {what} detector's time must be a positive number of ms (device {on_device}, measured here {here})"
            )));
        }
        *o = on_device / here;
    }
    Ok(out)
}

/// Puts every variant on the device of `slowdowns` (fp32, int8): its cost and noise
/// scaled by its precision's slowdown (`None`: off any device).
fn put_on_device(out: &mut [VariantResult], slowdowns: Option<[f64; 2]>) {
    for r in out {
        let scale = slowdowns.map(|[fp32, int8]| if r.int8 { int8 } else { fp32 });
        r.device_ms = scale.map(|k| r.latency.cost_ms() * k);
        r.device_noise_ms = scale.map(|k| r.latency_noise_ms * k);
    }
}

/// What `frugal pareto` is asked to do.
#[derive(Clone, Debug)]
pub struct ParetoOptions {
    /// Folder of variant folders.
    pub variants: PathBuf,
    /// Dataset.
    pub data: PathBuf,
    /// Output folder.
    pub out: PathBuf,
    /// ONNX Runtime intra-op threads.
    pub threads: usize,
    /// Validation frames (spread evenly; 0 = all).
    pub frames: usize,
    /// Of those, the frames timed (spread evenly; 0 = all): one worker detects them
    /// with the other cores idle. The rest are scored for accuracy only, split over
    /// `workers`.
    pub timed_frames: usize,
    /// Workers (each with its own sessions of `threads` threads) for the untimed frames.
    pub workers: usize,
    /// Untimed warm-up detections per variant.
    pub warmup: usize,
    /// Score threshold of P/R/F1/IoU.
    pub score_threshold: f32,
    /// Where to copy the mAP plot (PNG), if anywhere.
    pub docs_png: Option<PathBuf>,
    /// Print progress.
    pub progress: bool,
    /// Draw the fronts on this device's latencies (`None`: on this machine's).
    pub device: Option<DeviceSpeed>,
}

/// The whole report (`pareto.json`).
#[derive(Clone, Debug, Serialize)]
pub struct ParetoReport {
    /// Validation frames scored per variant.
    pub frames: usize,
    /// Of those, the frames timed per variant.
    pub timed_frames: usize,
    /// Validation videos those frames come from (the bootstrap's clusters).
    pub videos: usize,
    /// Bootstrap resamples behind the standard errors.
    pub bootstrap_resamples: usize,
    /// Relative floor of the latency noise ([`crate::stats::LATENCY_NOISE_FLOOR`]).
    pub latency_noise_floor: f64,
    /// Relative ceiling of the latency noise ([`crate::stats::LATENCY_NOISE_CEILING`]).
    pub latency_noise_ceiling: f64,
    /// ONNX Runtime threads.
    pub threads: usize,
    /// Latency of the reference detector ([`frugal_models::onnx::export_reference`]),
    /// timed on the same frames in turn with the variants: what a device profile scales
    /// from.
    pub reference: Latency,
    /// Latency of the int8 reference detector
    /// ([`frugal_models::onnx::export_reference_int8`]), timed with them too: what a
    /// device profile scales the int8 variants from.
    pub reference_int8: Latency,
    /// The device the fronts were drawn for, if any.
    pub device: Option<DeviceSpeed>,
    /// Its slowdowns over this machine, fp32 and int8 (with `device`).
    pub slowdowns: Option<[f64; 2]>,
    /// Every variant.
    pub variants: Vec<VariantResult>,
    /// Per metric: names on the noise-aware front, fastest first (`variants.json`
    /// lists the `map` one).
    pub fronts: BTreeMap<String, Vec<String>>,
    /// Per metric: names on the plain front, fastest first, for comparison.
    pub plain_fronts: BTreeMap<String, Vec<String>>,
}

/// Standard errors of (mAP, F1, mean IoU) over `resamples` of `images` (each a list
/// of indices into `images`): their standard deviations.
fn bootstrap_se(
    images: &[ImageResult],
    resamples: &[Vec<usize>],
    score: impl Fn(&[ImageResult]) -> [f64; 3],
) -> [f64; 3] {
    let mut values: [Vec<f64>; 3] = Default::default();
    for r in resamples {
        let picked: Vec<ImageResult> = r.iter().map(|&i| images[i].clone()).collect();
        for (v, x) in values.iter_mut().zip(score(&picked)) {
            v.push(x);
        }
    }
    values.map(|v| std_dev(&v))
}

fn histogram(scores: &[Option<f32>]) -> ConfidenceHistogram {
    let mut h = ConfidenceHistogram {
        frames: scores.len(),
        counts: vec![0; CONFIDENCE_BINS],
        ..Default::default()
    };
    let mut sum = 0.0;
    for s in scores {
        match s {
            None => h.no_detection += 1,
            Some(s) => {
                let b = ((s.clamp(0.0, 1.0) * CONFIDENCE_BINS as f32) as usize)
                    .min(CONFIDENCE_BINS - 1);
                h.counts[b] += 1;
                sum += f64::from(*s);
            }
        }
    }
    let n = h.frames - h.no_detection;
    h.mean_top_score = if n > 0 { sum / n as f64 } else { 0.0 };
    h
}

/// The fronts of one metric (`key`; `get` its value, `get_se` its standard error):
/// fills each variant's `on_front`, `on_plain_front`, `dominated_by` and
/// `merged_into` under `key`, and returns the noise-aware front and the plain one
/// (indices into `out`, fastest first).
fn mark_fronts(
    out: &mut [VariantResult],
    key: &str,
    get: fn(&VariantResult) -> f64,
    get_se: fn(&VariantResult) -> f64,
) -> (Vec<usize>, Vec<usize>) {
    let noisy: Vec<NoisyPoint> = out
        .iter()
        .map(|r| NoisyPoint {
            accuracy: get(r),
            accuracy_se: get_se(r),
            latency: r.front_ms(),
            latency_noise: r.front_noise_ms(),
        })
        .collect();
    let points: Vec<Point> = noisy
        .iter()
        .map(|p| Point {
            accuracy: p.accuracy,
            latency: p.latency,
        })
        .collect();
    let f = front_within_noise(&noisy);
    let plain = front(&points);
    let by = covered_by(&noisy, &f);
    let merged = merged_into(&noisy, &f);
    let names: Vec<String> = out.iter().map(|r| r.name.clone()).collect();
    for (i, r) in out.iter_mut().enumerate() {
        r.on_front.insert(key.into(), f.contains(&i));
        r.on_plain_front.insert(key.into(), plain.contains(&i));
        r.dominated_by.insert(
            key.into(),
            by[i].iter().map(|&j| names[j].clone()).collect(),
        );
        r.merged_into
            .insert(key.into(), merged[i].map(|j| names[j].clone()));
    }
    (f, plain)
}

/// Per variant, what it found on a frame and (timed frames) how long it took, ms.
type FrameOutcome = Vec<(Vec<Detection>, Option<f64>)>;

/// Every variant detects frame `f` (the `fi`-th of the pass) in turn: what each found
/// and, when `timed`, how long it took (ms). The starting variant rotates with `fi` so
/// that none always runs right after the frame load. `warmup`: untimed detections per
/// variant first.
fn detect_frame(
    ds: &Dataset,
    f: &FrameRecord,
    dets: &mut [OrtDetector],
    fi: usize,
    timed: bool,
    warmup: Option<usize>,
) -> Result<FrameOutcome, ParetoError> {
    let ort_err = |e: frugal_models::onnx::OrtError| ParetoError::Input(e.to_string());
    let rgb = ds
        .load_rgb(f)
        .map_err(|e| ParetoError::Input(e.to_string()))?;
    let frame = FrameRef::new(rgb.width(), rgb.height(), rgb.as_raw())
        .ok_or_else(|| ParetoError::Input(format!("{}: bad pixel buffer", f.file.display())))?;
    if let Some(w) = warmup {
        for d in dets.iter_mut() {
            measure(w, 0, |_| d.detect(frame).map(|_| ())).map_err(ort_err)?;
        }
    }
    let k = dets.len();
    let mut out = vec![(Vec::new(), None); k];
    for j in 0..k {
        let i = (j + fi) % k;
        out[i] = if timed {
            let mut found = Vec::new();
            let lat = measure(0, 1, |_| {
                found = dets[i].detect(frame)?;
                Ok(())
            })
            .map_err(ort_err)?;
            (found, lat.map(|l| l.median_ms))
        } else {
            (dets[i].detect(frame).map_err(ort_err)?, None)
        };
    }
    Ok(out)
}

/// Measure every variant in `opts.variants` and write `pareto.json`, `pareto.csv`,
/// `confidence.json`, `timings.json`, the plots `pareto_{map,f1,iou}.{png,svg}` and `variants.json`
/// (the mAP front, for `frugal policy record`).
pub fn run(opts: &ParetoOptions) -> Result<ParetoReport, ParetoError> {
    let variants = crate::variants::read_variants(&opts.variants)?;
    let ds = Dataset::load(&opts.data).map_err(|e| ParetoError::Input(e.to_string()))?;
    let all: Vec<&FrameRecord> = ds.split(Split::Val).collect();
    if all.is_empty() {
        return Err(ParetoError::Input(format!(
            "{}: the val split is empty",
            opts.data.display()
        )));
    }
    let frames = spread(all, opts.frames);
    let n = frames.len();
    let open_all = || -> Result<Vec<OrtDetector>, ParetoError> {
        variants
            .iter()
            .map(|v| {
                OrtDetector::open(&v.dir, opts.threads)
                    .map_err(|e| ParetoError::Input(e.to_string()))
            })
            .collect()
    };
    let mut dets = open_all()?;
    let k = variants.len();
    // the reference detectors, fp32 then int8, timed with the variants (last in the
    // rotation) and scored by nobody: how fast this machine runs the detectors a device
    // profile's speed is stated in
    let reference_dirs = [
        opts.out.join(".reference"),
        opts.out.join(".reference-int8"),
    ];
    frugal_models::onnx::export_reference(&reference_dirs[0])
        .map_err(|e| ParetoError::Input(format!("the reference detector: {e}")))?;
    frugal_models::onnx::export_reference_int8(&reference_dirs[1])
        .map_err(|e| ParetoError::Input(format!("the int8 reference detector: {e}")))?;
    for dir in &reference_dirs {
        dets.push(
            OrtDetector::open(dir, opts.threads).map_err(|e| ParetoError::Input(e.to_string()))?,
        );
    }
    // the frames to time, spread evenly (ascending), and the others
    let timed = spread((0..n).collect(), opts.timed_frames);
    let untimed: Vec<usize> = (0..n).filter(|i| timed.binary_search(i).is_err()).collect();
    let workers = opts.workers.clamp(1, untimed.len().max(1));
    let t0 = std::time::Instant::now();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let tick = || {
        let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        if opts.progress && d.is_multiple_of(20) {
            eprintln!(
                "pareto: frame {d}/{n} ({:.0} s)",
                t0.elapsed().as_secs_f64()
            );
        }
    };
    // per frame, per variant: what it found and (timed frames) how long it took
    let mut found: Vec<Option<FrameOutcome>> = vec![None; n];
    // 1. the timed frames, one worker, the other cores idle: latency as deployed
    for (j, &fi) in timed.iter().enumerate() {
        found[fi] = Some(detect_frame(
            &ds,
            frames[fi],
            &mut dets,
            fi,
            true,
            (j == 0).then_some(opts.warmup),
        )?);
        tick();
    }
    // the references' sessions, then their files
    dets.truncate(k);
    for dir in &reference_dirs {
        std::fs::remove_dir_all(dir).map_err(|e| ParetoError::io(dir, e))?;
    }
    let mut reference_ms = Vec::with_capacity(timed.len());
    let mut reference_int8_ms = Vec::with_capacity(timed.len());
    for f in found.iter_mut().flatten() {
        // the last two timed, in rotation order: the fp32 reference, then the int8 one
        if let (Some((_, Some(int8))), Some((_, Some(fp32)))) = (f.pop(), f.pop()) {
            reference_int8_ms.push(int8);
            reference_ms.push(fp32);
        }
    }
    let reference = Latency::from_samples(&reference_ms)
        .ok_or_else(|| ParetoError::Input("no timings of the reference detector".into()))?;
    let reference_int8 = Latency::from_samples(&reference_int8_ms)
        .ok_or_else(|| ParetoError::Input("no timings of the int8 reference detector".into()))?;
    let slowdowns = opts
        .device
        .map(|d| slowdowns(d, &reference, &reference_int8))
        .transpose()?;
    // 2. the other frames, accuracy only, split over the workers
    let parts: Vec<Vec<(usize, FrameOutcome)>> = std::thread::scope(|sc| {
        let mut own = Some(&mut dets);
        let handles: Vec<_> = (0..workers)
            .map(|w| {
                let mine: Vec<usize> = untimed.iter().copied().skip(w).step_by(workers).collect();
                let reuse = if w == 0 { own.take() } else { None };
                let (ds, frames, tick, open_all) = (&ds, &frames, &tick, &open_all);
                sc.spawn(move || -> Result<_, ParetoError> {
                    let mut opened;
                    let d = match reuse {
                        Some(d) => d,
                        None => {
                            opened = open_all()?;
                            &mut opened
                        }
                    };
                    mine.into_iter()
                        .map(|fi| {
                            let r = detect_frame(ds, frames[fi], d, fi, false, None)?;
                            tick();
                            Ok((fi, r))
                        })
                        .collect()
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join().unwrap_or_else(|_| {
                    Err(ParetoError::Input("a measuring worker panicked".into()))
                })
            })
            .collect::<Result<_, _>>()
    })?;
    for (fi, r) in parts.into_iter().flatten() {
        found[fi] = Some(r);
    }
    let mut samples = vec![Vec::with_capacity(timed.len()); k];
    let mut results: Vec<Vec<ImageResult>> = vec![Vec::with_capacity(n); k];
    let mut tops: Vec<BTreeMap<String, Vec<Option<f32>>>> = vec![BTreeMap::new(); k];
    for (fi, per_variant) in found.into_iter().enumerate() {
        let f = frames[fi];
        let sc = scenario(&ds, f);
        for (i, (dets, ms)) in per_variant.unwrap_or_default().into_iter().enumerate() {
            if let Some(ms) = ms {
                samples[i].push(ms);
            }
            tops[i]
                .entry(sc.clone())
                .or_default()
                .push(dets.first().map(|d| d.score));
            results[i].push(ImageResult {
                detections: dets,
                truth: frame_truth(f),
                ignore: f.ignore.clone(),
            });
        }
    }
    let num_classes = dets.first().map_or(1, |d| d.spec().num_classes);
    let score = |images: &[ImageResult]| {
        let s = evaluate(
            images,
            num_classes,
            0.5,
            opts.score_threshold,
            Interpolation::AllPoint,
        );
        [s.map, s.f1, s.mean_iou]
    };
    // Frames of one video are correlated: resample videos, not frames.
    let video_of: Vec<u32> = frames.iter().map(|f| f.video).collect();
    let videos = video_of
        .iter()
        .collect::<std::collections::BTreeSet<_>>()
        .len();
    let resamples = cluster_resamples(&video_of, BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED);
    if opts.progress {
        eprintln!(
            "pareto: standard errors from {} resamples of {videos} validation videos",
            resamples.len()
        );
    }
    let mut out = Vec::new();
    for (i, v) in variants.iter().enumerate() {
        let s = evaluate(
            &results[i],
            num_classes,
            0.5,
            opts.score_threshold,
            Interpolation::AllPoint,
        );
        let [map_se, f1_se, mean_iou_se] = bootstrap_se(&results[i], &resamples, score);
        let latency = Latency::from_samples(&samples[i])
            .ok_or_else(|| ParetoError::Input("no timings".into()))?;
        let r = &v.record;
        out.push(VariantResult {
            name: r.name.clone(),
            parent: r.parent.clone(),
            technique: serde_json::to_value(&r.technique).unwrap_or_default(),
            dir: v.dir.clone(),
            input: format!("{}×{}", r.input_width, r.input_height),
            parameters: r.parameters,
            nonzero_parameters: r.nonzero_parameters,
            file_bytes: r.files.iter().map(|f| f.bytes).sum(),
            map: s.map,
            f1: s.f1,
            mean_iou: s.mean_iou,
            map_se,
            f1_se,
            mean_iou_se,
            precision: s.precision,
            recall: s.recall,
            latency,
            latency_noise_ms: latency.noise_ms(),
            int8: r.int8,
            device_ms: None,
            device_noise_ms: None,
            confidence: tops[i]
                .iter()
                .map(|(k, v)| (k.clone(), histogram(v)))
                .collect(),
            on_front: BTreeMap::new(),
            on_plain_front: BTreeMap::new(),
            dominated_by: BTreeMap::new(),
            merged_into: BTreeMap::new(),
        });
    }
    put_on_device(&mut out, slowdowns);
    std::fs::create_dir_all(&opts.out).map_err(|e| ParetoError::io(&opts.out, e))?;
    let (mut fronts, mut plain_fronts) = (BTreeMap::new(), BTreeMap::new());
    let metrics: [Metric; 3] = [
        ("map", "mAP@0.5", |r| r.map, |r| r.map_se),
        ("f1", "F1", |r| r.f1, |r| r.f1_se),
        ("iou", "mean IoU", |r| r.mean_iou, |r| r.mean_iou_se),
    ];
    let lat_label = match slowdowns {
        None => format!(
            "latency per frame, fastest of the timed runs, ms (ONNX Runtime, {} thread(s))",
            opts.threads
        ),
        Some([fp32, int8]) => format!(
            "latency per frame on the device, ms (fastest run here × {fp32:.2} fp32, × {int8:.2} int8)"
        ),
    };
    for (key, label, get, get_se) in metrics {
        let (f, plain) = mark_fronts(&mut out, key, get, get_se);
        let labelled: Vec<(String, Point)> = out
            .iter()
            .map(|r| {
                let p = Point {
                    accuracy: get(r),
                    latency: r.front_ms(),
                };
                (r.name.clone(), p)
            })
            .collect();
        let stem = opts.out.join(format!("pareto_{key}"));
        plot_front(
            &stem,
            &FrontPlot {
                title: &format!("{label} vs latency on the validation split"),
                accuracy_label: label,
                latency_label: &lat_label,
                points: &labelled,
                front: &f,
            },
        )?;
        fronts.insert(
            key.to_string(),
            f.iter().map(|&i| out[i].name.clone()).collect::<Vec<_>>(),
        );
        plain_fronts.insert(
            key.to_string(),
            plain
                .iter()
                .map(|&i| out[i].name.clone())
                .collect::<Vec<_>>(),
        );
    }
    let report = ParetoReport {
        frames: n,
        timed_frames: timed.len(),
        videos,
        bootstrap_resamples: resamples.len(),
        latency_noise_floor: crate::stats::LATENCY_NOISE_FLOOR,
        latency_noise_ceiling: crate::stats::LATENCY_NOISE_CEILING,
        threads: opts.threads,
        reference,
        reference_int8,
        device: opts.device,
        slowdowns,
        variants: out,
        fronts,
        plain_fronts,
    };
    write_json(&opts.out.join("pareto.json"), &report)?;
    let conf: BTreeMap<&str, &BTreeMap<String, ConfidenceHistogram>> = report
        .variants
        .iter()
        .map(|r| (r.name.as_str(), &r.confidence))
        .collect();
    write_json(&opts.out.join("confidence.json"), &conf)?;
    let timings = Timings {
        frames: &timed,
        reference_ms: &reference_ms,
        reference_int8_ms: &reference_int8_ms,
        variants: report
            .variants
            .iter()
            .zip(&samples)
            .map(|(r, s)| (r.name.as_str(), s.as_slice()))
            .collect(),
    };
    write_json(&opts.out.join("timings.json"), &timings)?;
    write_atomic(&opts.out.join("pareto.csv"), csv(&report).as_bytes())?;
    let on_map: Vec<(&VariantDir, f64)> = report.fronts["map"]
        .iter()
        .filter_map(|n| {
            let i = variants.iter().position(|v| &v.record.name == n)?;
            Some((&variants[i], report.variants[i].latency.cost_ms()))
        })
        .collect();
    write_variants_file(
        &opts.out.join("variants.json"),
        &on_map,
        report.reference.cost_ms(),
        report.reference_int8.cost_ms(),
    )?;
    if let Some(docs) = &opts.docs_png {
        let src = opts.out.join("pareto_map.png");
        std::fs::copy(&src, docs).map_err(|e| ParetoError::io(docs, e))?;
    }
    Ok(report)
}

/// The table as CSV (one row per variant).
pub fn csv(r: &ParetoReport) -> String {
    let mut s = String::from(
        "name,parent,technique,input,parameters,nonzero_parameters,file_bytes,map,f1,mean_iou,map_se,f1_se,mean_iou_se,precision,recall,latency_ms,latency_median_ms,latency_p90_ms,latency_spread_ms,latency_noise_ms,front_map,front_f1,front_iou,plain_front_map,dominated_by_map,merged_into_map,int8,device_ms\n",
    );
    for v in &r.variants {
        let tech = v.technique.to_string().replace(',', ";").replace('"', "");
        s += &format!(
            "{},{},{},{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.3},{:.3},{:.3},{:.3},{:.3},{},{},{},{},{},{},{},{}\n",
            v.name,
            v.parent.clone().unwrap_or_default(),
            tech,
            v.input,
            v.parameters,
            v.nonzero_parameters,
            v.file_bytes,
            v.map,
            v.f1,
            v.mean_iou,
            v.map_se,
            v.f1_se,
            v.mean_iou_se,
            v.precision,
            v.recall,
            v.latency.cost_ms(),
            v.latency.median_ms,
            v.latency.p90_ms,
            v.latency.spread_ms,
            v.latency_noise_ms,
            v.on_front["map"],
            v.on_front["f1"],
            v.on_front["iou"],
            v.on_plain_front["map"],
            v.dominated_by["map"].join(" "),
            v.merged_into["map"].as_deref().unwrap_or_default(),
            v.int8,
            v.device_ms.map(|ms| format!("{ms:.3}")).unwrap_or_default(),
        );
    }
    s
}

/// A text table for the terminal.
pub fn table(r: &ParetoReport) -> String {
    let mut s = format!(
        "{:<14} {:<34} {:>9} {:>6} {:>6} {:>6} {:>6} {:>8} {:>8} {:>8} {:>7} {:<5}\n",
        "variant",
        "technique",
        "params",
        "mAP",
        "± se",
        "F1",
        "IoU",
        "ms",
        "med ms",
        "p90 ms",
        "noise",
        "front"
    );
    for v in &r.variants {
        let mut tech = v.technique.to_string().replace('"', "");
        tech.truncate(34);
        s += &format!(
            "{:<14} {:<34} {:>9} {:>6.3} {:>6.3} {:>6.3} {:>6.3} {:>8.2} {:>8.2} {:>8.2} {:>7.2} {}\n",
            v.name,
            tech,
            v.parameters,
            v.map,
            v.map_se,
            v.f1,
            v.mean_iou,
            v.latency.cost_ms(),
            v.latency.median_ms,
            v.latency.p90_ms,
            v.latency_noise_ms,
            match (v.on_front["map"], &v.merged_into["map"]) {
                (true, _) => "yes".to_string(),
                (false, Some(m)) => format!("= {m}"),
                (false, None) => String::new(),
            }
        );
    }
    s.push_str(&format!(
        "reference detector (default architecture, fp32, 480×270): {:.2} ms fastest, {:.2} median, {:.2} p90\n",
        r.reference.cost_ms(), r.reference.median_ms, r.reference.p90_ms
    ));
    s.push_str(&format!(
        "reference detector, int8 (the same, quantized as the int8 variants): {:.2} ms fastest, {:.2} median, {:.2} p90\n",
        r.reference_int8.cost_ms(), r.reference_int8.median_ms, r.reference_int8.p90_ms
    ));
    if let (Some(d), Some([fp32, int8])) = (r.device, r.slowdowns) {
        s.push_str(&format!(
            "fronts drawn on the device (references {:.1} / {:.1} ms, fp32 / int8): slowdowns {fp32:.2} / {int8:.2}; device ms: {}\n",
            d.reference_ms,
            d.reference_int8_ms,
            r.variants
                .iter()
                .filter_map(|v| Some(format!("{} {:.1}", v.name, v.device_ms?)))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use frugal_models::metrics::Truth;
    use frugal_runtime::{BBox, Detection};

    fn image(hit: bool) -> ImageResult {
        let truth = BBox {
            x1: 10.0,
            y1: 10.0,
            x2: 30.0,
            y2: 30.0,
        };
        let found = if hit {
            truth
        } else {
            BBox {
                x1: 60.0,
                y1: 60.0,
                x2: 80.0,
                y2: 80.0,
            }
        };
        ImageResult {
            detections: vec![Detection {
                bbox: found,
                score: 0.9,
                class: 0,
            }],
            truth: vec![Truth {
                class: 0,
                bbox: truth,
            }],
            ignore: Vec::new(),
        }
    }

    fn score(images: &[ImageResult]) -> [f64; 3] {
        let s = evaluate(images, 1, 0.5, 0.5, Interpolation::AllPoint);
        [s.map, s.f1, s.mean_iou]
    }

    #[test]
    fn bootstrap_over_videos_gives_an_error_only_when_videos_differ() {
        // video 1 found every sign, video 2 none, video 3 half
        let images: Vec<ImageResult> = [true, true, false, false, true, false]
            .iter()
            .map(|&h| image(h))
            .collect();
        let videos = [1, 1, 2, 2, 3, 3];
        let resamples = cluster_resamples(&videos, BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED);
        let [map_se, f1_se, iou_se] = bootstrap_se(&images, &resamples, score);
        assert!(map_se > 0.05 && f1_se > 0.05, "{map_se} {f1_se}");
        // every true positive is an exact match, so the mean IoU is 1, or 0 in the
        // resamples that drew video 2 three times (1 in 27)
        assert!(iou_se > 0.0 && iou_se < 0.5, "{iou_se}");
        assert_eq!(
            bootstrap_se(&images, &resamples, score),
            [map_se, f1_se, iou_se]
        );
        // one video: every resample is the whole set, no error
        let one = cluster_resamples(&[4; 6], BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED);
        assert_eq!(bootstrap_se(&images, &one, score), [0.0; 3]);
        // frames that all agree: no error however many videos
        let same: Vec<ImageResult> = (0..6).map(|_| image(true)).collect();
        assert!(
            bootstrap_se(&same, &resamples, score)
                .iter()
                .all(|&se| se < 1e-12)
        );
    }

    fn variant(name: &str, ms: f64, map: f64, se: f64) -> VariantResult {
        let latency = Latency {
            median_ms: ms,
            p90_ms: ms * 1.04,
            min_ms: ms * 0.95,
            runs: 720,
            p10_ms: ms * 0.97,
            spread_ms: ms * 0.035,
        };
        VariantResult {
            name: name.into(),
            parent: None,
            technique: serde_json::json!({ "kind": "base" }),
            dir: PathBuf::from(name),
            input: "480×270".into(),
            parameters: 100,
            nonzero_parameters: 100,
            file_bytes: 400,
            map,
            f1: map - 0.05,
            mean_iou: 0.9,
            map_se: se,
            f1_se: se,
            mean_iou_se: 0.01,
            precision: 0.9,
            recall: 0.9,
            latency,
            latency_noise_ms: latency.noise_ms(),
            int8: name.ends_with("int8"),
            device_ms: None,
            device_noise_ms: None,
            confidence: BTreeMap::new(),
            on_front: BTreeMap::new(),
            on_plain_front: BTreeMap::new(),
            dominated_by: BTreeMap::new(),
            merged_into: BTreeMap::new(),
        }
    }

    /// The map front of `out` (names, fastest first) after putting it on the device of
    /// `slowdowns`.
    fn map_front(out: &mut [VariantResult], slowdowns: Option<[f64; 2]>) -> Vec<String> {
        put_on_device(out, slowdowns);
        let (f, _) = mark_fronts(out, "map", |r| r.map, |r| r.map_se);
        f.iter().map(|&i| out[i].name.clone()).collect()
    }

    #[test]
    fn machines_that_differ_in_int8_speed_draw_the_same_device_front() {
        let device = DeviceSpeed {
            reference_ms: 194.4,
            reference_int8_ms: 140.1,
        };
        // a machine whose int8 runs against its fp32 as the device's does, and one
        // whose int8 is no faster than its fp32 (AVX2 without 8-bit dot products)
        let (xeon, avx2) = ([24.75, 17.835], [32.0, 32.0]);
        let variants = |[fp32_ref, int8_ref]: [f64; 2]| {
            let (fp32, int8) = (fp32_ref / 24.75, int8_ref / 17.835);
            vec![
                variant("ch50-p10", 4.0 * fp32, 0.951, 0.003),
                variant("ch50-p10-int8", 3.0 * int8, 0.940, 0.003),
                variant("ch75-p20-int8", 6.0 * int8, 0.970, 0.003),
            ]
        };
        let on = |refs: [f64; 2]| {
            let reference = Latency::from_samples(&[refs[0]]).unwrap();
            let reference_int8 = Latency::from_samples(&[refs[1]]).unwrap();
            slowdowns(device, &reference, &reference_int8).unwrap()
        };
        let everything = ["ch50-p10-int8", "ch50-p10", "ch75-p20-int8"];
        // on their own latencies the two machines draw different fronts: on the
        // second the int8 variant is slower than its fp32 parent and less accurate
        assert_eq!(map_front(&mut variants(xeon), None), everything);
        assert_eq!(
            map_front(&mut variants(avx2), None),
            ["ch50-p10", "ch75-p20-int8"]
        );
        // on the device both draw the device's, at the same device costs
        let (mut a, mut b) = (variants(xeon), variants(avx2));
        assert_eq!(map_front(&mut a, Some(on(xeon))), everything);
        assert_eq!(map_front(&mut b, Some(on(avx2))), everything);
        for (x, y) in a.iter().zip(&b) {
            let (dx, dy) = (x.device_ms.unwrap(), y.device_ms.unwrap());
            assert!((dx - dy).abs() < 1e-9 * dx, "{}: {dx} {dy}", x.name);
            let k = dx / x.latency.cost_ms();
            assert!((x.device_noise_ms.unwrap() - k * x.latency_noise_ms).abs() < 1e-9);
        }
        // the device is the tx2-like one: 4.0 ms of fp32 here is 4.0 × 194.4 / 24.75
        let fp32 = a.iter().find(|v| v.name == "ch50-p10").unwrap();
        let expected = fp32.latency.cost_ms() * 194.4 / 24.75;
        assert!((fp32.device_ms.unwrap() - expected).abs() < 1e-9);
        // a time that is not a positive number is refused, naming the detector
        let zero = Latency::from_samples(&[0.0]).unwrap();
        let ok = Latency::from_samples(&[20.0]).unwrap();
        let e = slowdowns(device, &ok, &zero).unwrap_err().to_string();
        assert!(e.contains("int8 reference"), "{e}");
        let nan = DeviceSpeed {
            reference_ms: f64::NAN,
            ..device
        };
        let e = slowdowns(nan, &ok, &ok).unwrap_err().to_string();
        assert!(e.contains("the reference detector"), "{e}");
    }

    #[test]
    fn report_marks_fronts_merges_and_what_covers_each_variant() {
        let mut out = vec![
            variant("mag30", 32.7, 0.979, 0.005),
            variant("base", 32.6, 0.978, 0.005),
            variant("ch50-p20-int8", 3.1, 0.925, 0.009),
            variant("mag50", 32.8, 0.980, 0.006),
            variant("mag70", 32.5, 0.975, 0.006),
        ];
        let metrics: [Metric; 3] = [
            ("map", "mAP@0.5", |r| r.map, |r| r.map_se),
            ("f1", "F1", |r| r.f1, |r| r.f1_se),
            ("iou", "mean IoU", |r| r.mean_iou, |r| r.mean_iou_se),
        ];
        let (mut fronts, mut plain_fronts) = (BTreeMap::new(), BTreeMap::new());
        for (key, _, get, get_se) in metrics {
            let (f, plain) = mark_fronts(&mut out, key, get, get_se);
            let names = |idx: &[usize]| -> Vec<String> {
                idx.iter().map(|&i| out[i].name.clone()).collect()
            };
            fronts.insert(key.to_string(), names(&f));
            plain_fronts.insert(key.to_string(), names(&plain));
        }
        let report = ParetoReport {
            frames: 720,
            timed_frames: 180,
            videos: 12,
            bootstrap_resamples: BOOTSTRAP_RESAMPLES,
            latency_noise_floor: crate::stats::LATENCY_NOISE_FLOOR,
            latency_noise_ceiling: crate::stats::LATENCY_NOISE_CEILING,
            threads: 1,
            reference: Latency::from_samples(&[32.0, 33.0]).unwrap(),
            reference_int8: Latency::from_samples(&[20.0, 21.0]).unwrap(),
            device: None,
            slowdowns: None,
            variants: out,
            fronts,
            plain_fronts,
        };
        assert_eq!(report.fronts["map"], ["ch50-p20-int8", "mag70"]);
        assert_eq!(
            report.plain_fronts["map"],
            ["ch50-p20-int8", "mag70", "base", "mag30", "mag50"]
        );
        // every mean IoU is 0.9: the fastest covers the rest
        assert_eq!(report.fronts["iou"], ["ch50-p20-int8"]);
        let v = |n: &str| report.variants.iter().find(|v| v.name == n).unwrap();
        for n in ["base", "mag30", "mag50"] {
            assert_eq!(v(n).merged_into["map"].as_deref(), Some("mag70"), "{n}");
            assert_eq!(v(n).dominated_by["map"], ["mag70"], "{n}");
            assert_eq!(v(n).dominated_by["iou"], ["ch50-p20-int8"], "{n}");
            assert_eq!(v(n).merged_into["iou"], None, "{n}");
        }
        // the invariant the CLI test checks: on a front exactly when nothing covers it
        for r in &report.variants {
            for key in ["map", "f1", "iou"] {
                assert_eq!(
                    r.on_front[key],
                    r.dominated_by[key].is_empty(),
                    "{key} {}",
                    r.name
                );
                assert_eq!(r.on_front[key], report.fronts[key].contains(&r.name));
                assert_eq!(
                    r.on_plain_front[key],
                    report.plain_fronts[key].contains(&r.name)
                );
            }
        }
        let json = serde_json::to_value(&report).unwrap();
        assert_eq!(json["variants"][1]["merged_into"]["map"], "mag70");
        assert!(json["variants"][4]["merged_into"]["map"].is_null());
        assert_eq!(json["variants"][3]["map_se"], 0.006);
        assert!(
            (json["variants"][0]["latency"]["spread_ms"]
                .as_f64()
                .unwrap()
                - 1.1445)
                .abs()
                < 1e-9
        );
        let table = csv(&report);
        let rows: Vec<&str> = table.lines().collect();
        assert_eq!(rows.len(), 6);
        let columns = rows[0].split(',').count();
        assert!(rows.iter().all(|r| r.split(',').count() == columns));
        let col = |name: &str| rows[0].split(',').position(|c| c == name).unwrap();
        let base: Vec<&str> = rows[2].split(',').collect();
        assert_eq!(base[0], "base");
        assert_eq!(base[col("map_se")], "0.0050");
        assert_eq!(base[col("front_map")], "false");
        assert_eq!(base[col("plain_front_map")], "true");
        assert_eq!(base[col("merged_into_map")], "mag70");
        assert!(super::table(&report).contains("= mag70"));
    }

    #[test]
    fn confidence_histogram_counts_top_scores_and_misses() {
        let h = histogram(&[Some(0.0), Some(0.96), Some(1.0), None, Some(0.52), None]);
        assert_eq!(h.frames, 6);
        assert_eq!(h.no_detection, 2);
        assert_eq!(h.counts.len(), CONFIDENCE_BINS);
        assert_eq!(h.counts.iter().sum::<usize>(), 4);
        // 1.0 falls in the last bin, 0.96 too, 0.52 in bin 10, 0.0 in bin 0
        assert_eq!((h.counts[0], h.counts[10], h.counts[19]), (1, 1, 2));
        assert!((h.mean_top_score - (0.0 + 0.96 + 1.0 + 0.52) / 4.0).abs() < 1e-6);
        assert_eq!(histogram(&[]).mean_top_score, 0.0);
    }
}
