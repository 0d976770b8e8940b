//! `frugal eval`: score a trained CNN detector on a dataset split.
use anyhow::{Context, bail};
use clap::Args;
use frugal_data::{Dataset, Split};
use frugal_models::FasterRcnn;
use frugal_models::eval::{evaluate_split, table, write_report};
use std::path::PathBuf;

/// Arguments of `frugal eval`.
#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Model folder written by `frugal train` (config.json + best.safetensors).
    #[arg(long)]
    pub model: PathBuf,
    /// Dataset folder.
    #[arg(long)]
    pub data: PathBuf,
    /// Split to score: train, val or test.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Score threshold for precision / recall / F1 and the confusion matrix.
    #[arg(long, default_value_t = 0.5)]
    pub threshold: f32,
    /// Output folder (default: <model>/eval-<split>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Score at most this many frames, spread evenly (0 = all).
    #[arg(long, default_value_t = 0)]
    pub limit: usize,
    /// How many worst frames to draw.
    #[arg(long, default_value_t = 12)]
    pub worst: usize,
    /// libtorch threads (0 = default).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Run `frugal eval`.
pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    let split = match args.split.as_str() {
        "train" => Split::Train,
        "val" => Split::Val,
        "test" => Split::Test,
        other => bail!("unknown split `{other}` (train, val or test)"),
    };
    if args.threads > 0 {
        tch::set_num_threads(args.threads as i32);
    }
    let model = FasterRcnn::load_dir(&args.model, tch::Device::Cpu)?;
    let ds = Dataset::load(&args.data)
        .with_context(|| format!("loading dataset {}", args.data.display()))?;
    let (report, results) =
        evaluate_split(&model, &ds, split, args.threshold, args.limit, !args.quiet)?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| args.model.join(format!("eval-{}", split.name())));
    write_report(&out, &ds, &report, &results, args.worst)?;
    print!("{}", table(&report));
    println!("report: {}", out.join("report.json").display());
    Ok(())
}
