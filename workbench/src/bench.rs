//! `frugal export` and `frugal bench`: the deployment format and its latency.
use anyhow::{Context, Result};
use clap::Args;
use frugal_data::{Dataset, Split};
use frugal_models::FasterRcnn;
use frugal_models::onnx::{OrtDetector, StageTimes, export_detector, parity};
use frugal_pareto::{Latency, measure};
use frugal_runtime::FrameRef;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Export a trained detector to ONNX (two graphs: backbone + RPN, RoI head).
#[derive(Args, Debug)]
pub struct ExportArgs {
    /// Model folder written by `frugal train` (config.json + best.safetensors).
    #[arg(long)]
    pub model: PathBuf,
    /// Folder to write backbone_rpn.onnx and roi_head.onnx into.
    #[arg(long)]
    pub out: PathBuf,
    /// Input frame width the graphs are fixed to.
    #[arg(long, default_value_t = 480)]
    pub width: usize,
    /// Input frame height the graphs are fixed to.
    #[arg(long, default_value_t = 270)]
    pub height: usize,
    /// Check the export against the tch model on this dataset's test frames: raw
    /// outputs within 1e-4 and the same detections (same class, IoU ≥ 0.99).
    #[arg(long)]
    pub check: Option<PathBuf>,
    /// How many test frames the check uses.
    #[arg(long, default_value_t = 50)]
    pub check_frames: usize,
}

/// Time one detector per frame through ONNX Runtime and libtorch, side by side.
///
/// Both engines run the whole detector (pre-processing, both networks, proposals,
/// NMS) on the same frames of the dataset's test split, with fixed intra-op thread
/// counts; warm-up runs are not timed. Prints a table and writes JSON.
#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Model folder written by `frugal train`.
    #[arg(long)]
    pub model: PathBuf,
    /// Exported ONNX folder (exported into `<model>/onnx` when absent).
    #[arg(long)]
    pub onnx: Option<PathBuf>,
    /// Dataset whose test frames are used.
    #[arg(long)]
    pub data: PathBuf,
    /// Timed runs per configuration.
    #[arg(long, default_value_t = 30)]
    pub runs: usize,
    /// Untimed warm-up runs per configuration.
    #[arg(long, default_value_t = 5)]
    pub warmup: usize,
    /// Intra-op thread counts to measure.
    #[arg(long, value_delimiter = ',', default_value = "1,2")]
    pub threads: Vec<usize>,
    /// Where to write the JSON results (default: `<model>/latency.json`).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// One row of the latency table.
#[derive(Debug, Serialize)]
pub struct BenchRow {
    /// `onnxruntime` or `libtorch`.
    pub engine: &'static str,
    /// Intra-op threads.
    pub threads: usize,
    /// The timings.
    pub latency: Latency,
    /// Where the time goes (ONNX Runtime rows only).
    pub stages: Option<StageMedians>,
}

/// Median time of each stage of the ONNX Runtime executor, ms.
#[derive(Debug, Serialize)]
pub struct StageMedians {
    /// Normalisation (and resizing) in Rust.
    pub preprocess_ms: f64,
    /// The backbone + RPN graph.
    pub backbone_ms: f64,
    /// Proposal decoding and NMS in Rust.
    pub proposals_ms: f64,
    /// The RoI-head graph.
    pub head_ms: f64,
    /// Detection decoding and per-class NMS in Rust.
    pub detections_ms: f64,
}

impl StageMedians {
    fn of(times: &[StageTimes]) -> Self {
        let med = |f: fn(&StageTimes) -> f64| {
            let v: Vec<f64> = times.iter().map(f).collect();
            Latency::from_samples(&v).map_or(0.0, |l| l.median_ms)
        };
        Self {
            preprocess_ms: med(|t| t.preprocess_ms),
            backbone_ms: med(|t| t.backbone_ms),
            proposals_ms: med(|t| t.proposals_ms),
            head_ms: med(|t| t.head_ms),
            detections_ms: med(|t| t.detections_ms),
        }
    }

    /// Time in the Rust glue between and around the graphs.
    pub fn glue_ms(&self) -> f64 {
        self.preprocess_ms + self.proposals_ms + self.detections_ms
    }
}

/// Run `frugal export`.
pub fn export(args: ExportArgs) -> Result<()> {
    let model = FasterRcnn::load_dir(&args.model, tch::Device::Cpu)?;
    let files = export_detector(&model, args.height, args.width, &args.out)?;
    println!(
        "wrote {} and {} ({}×{} input)",
        files.backbone_rpn.display(),
        files.roi_head.display(),
        args.width,
        args.height
    );
    if let Some(data) = &args.check {
        let frames = test_frames(data, args.check_frames)?;
        let mut ort = OrtDetector::open(&args.out, 1)?;
        let r = parity(&model, &mut ort, &frames)?;
        println!(
            "parity on {} test frames: max raw output difference {:.2e}; detections tch {} / onnxruntime {}, \
             {} matched (same class, IoU ≥ 0.99), min IoU {:.4}",
            r.frames, r.max_raw_diff, r.tch_detections, r.ort_detections, r.matched, r.min_iou
        );
        anyhow::ensure!(
            r.agrees(1e-4),
            "the export does not agree with the tch model"
        );
    }
    Ok(())
}

fn test_frames(data: &Path, n: usize) -> Result<Vec<(u32, u32, Vec<u8>)>> {
    let ds = Dataset::load(data)?;
    let frames: Vec<_> = ds.split(Split::Test).collect();
    anyhow::ensure!(
        !frames.is_empty(),
        "{}: the test split has no frames",
        data.display()
    );
    let step = (frames.len() / n.max(1)).max(1);
    frames
        .iter()
        .step_by(step)
        .take(n)
        .map(|f| {
            let img = ds.load_rgb(f)?;
            Ok((img.width(), img.height(), img.into_raw()))
        })
        .collect()
}

/// Run `frugal bench`.
pub fn bench(args: BenchArgs) -> Result<()> {
    let model = FasterRcnn::load_dir(&args.model, tch::Device::Cpu)?;
    let frames = test_frames(&args.data, 16)?;
    let (w, h, _) = frames[0];
    let onnx_dir = match &args.onnx {
        Some(d) => d.clone(),
        None => {
            let d = args.model.join("onnx");
            export_detector(&model, h as usize, w as usize, &d)?;
            d
        }
    };
    let mut rows = Vec::new();
    for &threads in &args.threads {
        let mut ort = OrtDetector::open(&onnx_dir, threads)?;
        let mut stages = Vec::new();
        let ort_lat = measure(args.warmup, args.runs, |i| {
            let (w, h, px) = &frames[i % frames.len()];
            let frame = FrameRef::new(*w, *h, px).context("frame size")?;
            let (_, times) = ort.detect_timed(frame)?;
            if i >= args.warmup {
                stages.push(times);
            }
            Ok::<(), anyhow::Error>(())
        })?
        .context("no timed runs")?;
        rows.push(BenchRow {
            engine: "onnxruntime",
            threads,
            latency: ort_lat,
            stages: Some(StageMedians::of(&stages)),
        });
        tch::set_num_threads(threads as i32);
        let tch_lat = measure(args.warmup, args.runs, |i| {
            let (w, h, px) = &frames[i % frames.len()];
            let frame = FrameRef::new(*w, *h, px).context("frame size")?;
            model.detect(frame);
            Ok::<(), anyhow::Error>(())
        })?
        .context("no timed runs")?;
        rows.push(BenchRow {
            engine: "libtorch",
            threads,
            latency: tch_lat,
            stages: None,
        });
    }
    println!(
        "whole detector per {w}×{h} frame, {} timed runs after {} warm-up",
        args.runs, args.warmup
    );
    println!(
        "{:<12} {:>7} {:>10} {:>10} {:>8}",
        "engine", "threads", "median ms", "p90 ms", "fps"
    );
    for r in &rows {
        println!(
            "{:<12} {:>7} {:>10.2} {:>10.2} {:>8.1}",
            r.engine,
            r.threads,
            r.latency.median_ms,
            r.latency.p90_ms,
            1e3 / r.latency.median_ms
        );
    }
    for r in &rows {
        if let Some(s) = &r.stages {
            println!(
                "onnxruntime, {} thread(s), median ms per stage: normalise {:.2}, backbone+RPN graph {:.2}, \
                 proposals {:.2}, RoI-head graph {:.2}, detections {:.2} (Rust glue {:.2})",
                r.threads,
                s.preprocess_ms,
                s.backbone_ms,
                s.proposals_ms,
                s.head_ms,
                s.detections_ms,
                s.glue_ms()
            );
        }
    }
    for &threads in &args.threads {
        let get = |e: &str| {
            rows.iter()
                .find(|r| r.engine == e && r.threads == threads)
                .map(|r| r.latency.median_ms)
        };
        if let (Some(o), Some(t)) = (get("onnxruntime"), get("libtorch")) {
            println!(
                "{threads} thread(s): libtorch / onnxruntime median = {:.2}×",
                t / o
            );
        }
    }
    let out = args.out.unwrap_or_else(|| args.model.join("latency.json"));
    frugal_data::dataset::write_json_atomic(&out, &rows)?;
    println!("wrote {}", out.display());
    Ok(())
}
