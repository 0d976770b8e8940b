//! Accuracy and latency of exported variants through ONNX Runtime, measured in one
//! interleaved pass: for every validation frame, every variant detects it in turn and
//! is timed, so the shared machine's load changes hit all variants alike.
use crate::front::{Point, dominators, front};
use crate::plot::{FrontPlot, plot_front};
use crate::stats::Latency;
use crate::variants::{VariantDir, write_variants_file};
use crate::{ParetoError, measure};
use frugal_data::{Dataset, FrameRecord, Split};
use frugal_models::metrics::{ImageResult, Interpolation, Truth, evaluate};
use frugal_models::onnx::OrtDetector;
use frugal_runtime::FrameRef;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// An accuracy metric: key, axis label, getter.
type Metric = (&'static str, &'static str, fn(&VariantResult) -> f64);

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
    /// Precision.
    pub precision: f64,
    /// Recall.
    pub recall: f64,
    /// Latency per frame (whole detector, ONNX Runtime, fixed threads).
    pub latency: Latency,
    /// Per scenario `"<clutter>-clutter/<light>-light"`: top-score distribution.
    pub confidence: BTreeMap<String, ConfidenceHistogram>,
    /// On the front of each metric (`map`, `f1`, `iou`).
    pub on_front: BTreeMap<String, bool>,
    /// Per metric: the variants that dominate this one.
    pub dominated_by: BTreeMap<String, Vec<String>>,
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
    /// Untimed warm-up detections per variant.
    pub warmup: usize,
    /// Score threshold of P/R/F1/IoU.
    pub score_threshold: f32,
    /// Where to copy the mAP plot (PNG), if anywhere.
    pub docs_png: Option<PathBuf>,
    /// Print progress.
    pub progress: bool,
}

/// The whole report (`pareto.json`).
#[derive(Clone, Debug, Serialize)]
pub struct ParetoReport {
    /// Validation frames scored per variant.
    pub frames: usize,
    /// ONNX Runtime threads.
    pub threads: usize,
    /// Every variant.
    pub variants: Vec<VariantResult>,
    /// Per metric: names on the front, fastest first.
    pub fronts: BTreeMap<String, Vec<String>>,
}

pub(crate) fn write_json<T: Serialize>(path: &Path, v: &T) -> Result<(), ParetoError> {
    let json = serde_json::to_vec_pretty(v).map_err(|e| ParetoError::Input(e.to_string()))?;
    write_atomic(path, &json)
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ParetoError> {
    let tmp = path.with_extension("partial");
    std::fs::write(&tmp, bytes).map_err(|e| ParetoError::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| ParetoError::io(path, e))
}

fn scenario(ds: &Dataset, f: &FrameRecord) -> String {
    ds.video(f.video).map_or_else(
        || "unknown".into(),
        |v| format!("{}-clutter/{}-light", v.clutter.name(), v.light.name()),
    )
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

/// Measure every variant in `opts.variants` and write `pareto.json`, `pareto.csv`,
/// `confidence.json`, the plots `pareto_{map,f1,iou}.{png,svg}` and `variants.json`
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
    let n = if opts.frames == 0 || opts.frames >= all.len() {
        all.len()
    } else {
        opts.frames
    };
    let frames: Vec<&FrameRecord> = (0..n).map(|i| all[i * all.len() / n]).collect();
    let mut dets = Vec::new();
    for v in &variants {
        dets.push(
            OrtDetector::open(&v.dir, opts.threads)
                .map_err(|e| ParetoError::Input(e.to_string()))?,
        );
    }
    let ort_err = |e: frugal_models::onnx::OrtError| ParetoError::Input(e.to_string());
    let k = variants.len();
    let mut samples = vec![Vec::with_capacity(n); k];
    let mut results: Vec<Vec<ImageResult>> = vec![Vec::with_capacity(n); k];
    let mut tops: Vec<BTreeMap<String, Vec<Option<f32>>>> = vec![BTreeMap::new(); k];
    let t0 = std::time::Instant::now();
    for (fi, f) in frames.iter().enumerate() {
        let rgb = ds
            .load_rgb(f)
            .map_err(|e| ParetoError::Input(e.to_string()))?;
        let frame = FrameRef::new(rgb.width(), rgb.height(), rgb.as_raw())
            .ok_or_else(|| ParetoError::Input(format!("{}: bad pixel buffer", f.file.display())))?;
        if fi == 0 {
            for d in dets.iter_mut() {
                measure(opts.warmup, 0, |_| d.detect(frame).map(|_| ())).map_err(ort_err)?;
            }
        }
        let sc = scenario(&ds, f);
        // rotate the starting variant so none always runs right after the frame load
        for j in 0..k {
            let i = (j + fi) % k;
            let mut found = Vec::new();
            let lat = measure(0, 1, |_| {
                found = dets[i].detect(frame)?;
                Ok(())
            })
            .map_err(ort_err)?;
            if let Some(l) = lat {
                samples[i].push(l.median_ms);
            }
            tops[i]
                .entry(sc.clone())
                .or_default()
                .push(found.first().map(|d| d.score));
            results[i].push(ImageResult {
                detections: found,
                truth: f
                    .objects
                    .iter()
                    .map(|o| Truth {
                        class: o.class,
                        bbox: o.bbox,
                    })
                    .collect(),
            });
        }
        if opts.progress && (fi + 1) % 20 == 0 {
            eprintln!(
                "pareto: frame {}/{n} ({:.0} s)",
                fi + 1,
                t0.elapsed().as_secs_f64()
            );
        }
    }
    let num_classes = dets.first().map_or(1, |d| d.spec().num_classes);
    let mut out = Vec::new();
    for (i, v) in variants.iter().enumerate() {
        let s = evaluate(
            &results[i],
            num_classes,
            0.5,
            opts.score_threshold,
            Interpolation::AllPoint,
        );
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
            precision: s.precision,
            recall: s.recall,
            latency,
            confidence: tops[i]
                .iter()
                .map(|(k, v)| (k.clone(), histogram(v)))
                .collect(),
            on_front: BTreeMap::new(),
            dominated_by: BTreeMap::new(),
        });
    }
    std::fs::create_dir_all(&opts.out).map_err(|e| ParetoError::io(&opts.out, e))?;
    let mut fronts = BTreeMap::new();
    let metrics: [Metric; 3] = [
        ("map", "mAP@0.5", |r| r.map),
        ("f1", "F1", |r| r.f1),
        ("iou", "mean IoU", |r| r.mean_iou),
    ];
    let lat_label = format!(
        "latency per frame, median ms (ONNX Runtime, {} thread(s))",
        opts.threads
    );
    for (key, label, get) in metrics {
        let points: Vec<Point> = out
            .iter()
            .map(|r| Point {
                accuracy: get(r),
                latency: r.latency.median_ms,
            })
            .collect();
        let mut f = front(&points);
        f.sort_by(|a, b| points[*a].latency.total_cmp(&points[*b].latency));
        let doms = dominators(&points);
        for (i, r) in out.iter_mut().enumerate() {
            r.on_front.insert(key.into(), f.contains(&i));
            r.dominated_by.insert(
                key.into(),
                doms[i]
                    .iter()
                    .map(|&j| variants[j].record.name.clone())
                    .collect(),
            );
        }
        let labelled: Vec<(String, Point)> =
            out.iter().map(|r| r.name.clone()).zip(points).collect();
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
    }
    let report = ParetoReport {
        frames: n,
        threads: opts.threads,
        variants: out,
        fronts,
    };
    write_json(&opts.out.join("pareto.json"), &report)?;
    let conf: BTreeMap<&str, &BTreeMap<String, ConfidenceHistogram>> = report
        .variants
        .iter()
        .map(|r| (r.name.as_str(), &r.confidence))
        .collect();
    write_json(&opts.out.join("confidence.json"), &conf)?;
    write_atomic(&opts.out.join("pareto.csv"), csv(&report).as_bytes())?;
    let on_map: Vec<(&VariantDir, f64)> = report.fronts["map"]
        .iter()
        .filter_map(|n| {
            let i = variants.iter().position(|v| &v.record.name == n)?;
            Some((&variants[i], report.variants[i].latency.median_ms))
        })
        .collect();
    write_variants_file(&opts.out.join("variants.json"), &on_map)?;
    if let Some(docs) = &opts.docs_png {
        let src = opts.out.join("pareto_map.png");
        std::fs::copy(&src, docs).map_err(|e| ParetoError::io(docs, e))?;
    }
    Ok(report)
}

/// The table as CSV (one row per variant).
pub fn csv(r: &ParetoReport) -> String {
    let mut s = String::from(
        "name,parent,technique,input,parameters,nonzero_parameters,file_bytes,map,f1,mean_iou,precision,recall,latency_median_ms,latency_p90_ms,front_map,front_f1,front_iou,dominated_by_map\n",
    );
    for v in &r.variants {
        let tech = v.technique.to_string().replace(',', ";").replace('"', "");
        s += &format!(
            "{},{},{},{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.3},{:.3},{},{},{},{}\n",
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
            v.precision,
            v.recall,
            v.latency.median_ms,
            v.latency.p90_ms,
            v.on_front["map"],
            v.on_front["f1"],
            v.on_front["iou"],
            v.dominated_by["map"].join(" "),
        );
    }
    s
}

/// A text table for the terminal.
pub fn table(r: &ParetoReport) -> String {
    let mut s = format!(
        "{:<14} {:<34} {:>9} {:>6} {:>6} {:>6} {:>8} {:>8} {:>5}\n",
        "variant", "technique", "params", "mAP", "F1", "IoU", "med ms", "p90 ms", "front"
    );
    for v in &r.variants {
        let mut tech = v.technique.to_string().replace('"', "");
        tech.truncate(34);
        s += &format!(
            "{:<14} {:<34} {:>9} {:>6.3} {:>6.3} {:>6.3} {:>8.2} {:>8.2} {:>5}\n",
            v.name,
            tech,
            v.parameters,
            v.map,
            v.f1,
            v.mean_iou,
            v.latency.median_ms,
            v.latency.p90_ms,
            if v.on_front["map"] { "yes" } else { "" }
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

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
