//! `frugal pareto`: accuracy and latency of every compressed variant, the Pareto
//! front, plots, and the variants file for `frugal policy record`.
use clap::Args;
use frugal_pareto::measure::{DeviceSpeed, ParetoOptions, run as measure_all, table};
use std::path::PathBuf;

/// Arguments of `frugal pareto`.
#[derive(Args, Debug)]
pub struct ParetoArgs {
    /// Folder of variant folders written by `frugal compress`.
    #[arg(long)]
    pub variants: PathBuf,
    /// Dataset folder (its validation split is scored).
    #[arg(long)]
    pub data: PathBuf,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// ONNX Runtime intra-op threads (fixed for every variant).
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Validation frames, spread evenly (0 = all).
    #[arg(long, default_value_t = 0)]
    pub frames: usize,
    /// Of those, the frames timed, spread evenly (0 = all). One worker times them
    /// while the other cores idle; the rest are scored for accuracy on every core.
    #[arg(long, default_value_t = 0)]
    pub timed_frames: usize,
    /// Untimed warm-up detections per variant.
    #[arg(long, default_value_t = 3)]
    pub warmup: usize,
    /// Score threshold for P/R/F1 and IoU.
    #[arg(long, default_value_t = 0.5)]
    pub threshold: f32,
    /// Also copy the mAP plot (PNG) here, e.g. docs/pareto_map.png.
    #[arg(long)]
    pub docs_png: Option<PathBuf>,
    /// No progress lines.
    #[arg(long)]
    pub quiet: bool,
    /// Draw the fronts on a device where the reference detector (fp32) takes this
    /// many ms (tx2-like: 194.4), each variant scaled by its precision's slowdown;
    /// with `--device-reference-int8-ms`. Without them, on this machine's latencies.
    #[arg(long, requires = "device_reference_int8_ms")]
    pub device_reference_ms: Option<f64>,
    /// The device's int8 reference detector time, ms (tx2-like: 140.1).
    #[arg(long, requires = "device_reference_ms")]
    pub device_reference_int8_ms: Option<f64>,
}

/// Run `frugal pareto`.
pub fn run(args: ParetoArgs) -> anyhow::Result<()> {
    let report = measure_all(&ParetoOptions {
        variants: args.variants.clone(),
        data: args.data.clone(),
        out: args.out.clone(),
        threads: args.threads,
        frames: args.frames,
        timed_frames: args.timed_frames,
        // the untimed frames: as many workers of `threads` threads as the cores hold
        workers: std::thread::available_parallelism()
            .map_or(1, |c| (c.get() / args.threads.max(1)).max(1)),
        warmup: args.warmup,
        score_threshold: args.threshold,
        docs_png: args.docs_png.clone(),
        progress: !args.quiet,
        device: args
            .device_reference_ms
            .zip(args.device_reference_int8_ms)
            .map(|(reference_ms, reference_int8_ms)| DeviceSpeed {
                reference_ms,
                reference_int8_ms,
            }),
    })?;
    print!("{}", table(&report));
    for (metric, names) in &report.fronts {
        println!("front ({metric}): {}", names.join(" → "));
    }
    println!(
        "{} variants × {} validation frames ({} timed); wrote {}/pareto.json, pareto.csv, pareto_*.png|svg, confidence.json, timings.json, variants.json",
        report.variants.len(),
        report.frames,
        report.timed_frames,
        args.out.display()
    );
    Ok(())
}
