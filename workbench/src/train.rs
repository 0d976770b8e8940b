//! `frugal train`: train the CNN detector on a dataset folder.
use anyhow::Context;
use clap::Args;
use frugal_models::config::Config;
use frugal_models::train::{TrainOptions, parse_device, train as train_model};
use std::path::PathBuf;

/// Arguments of `frugal train`.
#[derive(Args, Debug)]
pub struct TrainArgs {
    /// Dataset folder (as written by `frugal data generate`).
    #[arg(long)]
    pub data: PathBuf,
    /// Config file (TOML or JSON, any subset of fields; defaults built in).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Output folder: config.json, checkpoint/, best.safetensors, curves.{csv,png,svg}.
    #[arg(long)]
    pub out: PathBuf,
    /// Continue from the last checkpoint in --out (after a crash or kill).
    #[arg(long)]
    pub resume: bool,
    /// Stop after this many completed epochs (the run can be resumed later).
    #[arg(long)]
    pub stop_after: Option<usize>,
    /// Override `train.epochs` (with --resume: extend a finished run to this many).
    #[arg(long)]
    pub epochs: Option<usize>,
    /// Where to train: `cpu` (default, the tested path), `cuda` or `cuda:N` (needs a
    /// CUDA libtorch: `cargo xtask setup --cuda`).
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Run `frugal train`.
pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    let device = parse_device(&args.device)?;
    let config = match (&args.config, args.resume) {
        (Some(p), _) => Config::load(p)?,
        // resuming without --config: take the run's own config
        (None, true) => Config::load(&args.out.join("config.json"))
            .with_context(|| format!("resuming {}", args.out.display()))?,
        (None, false) => Config::default(),
    };
    let mut config = config;
    if let Some(e) = args.epochs {
        config.train.epochs = e;
    }
    let report = train_model(&TrainOptions {
        data: args.data.clone(),
        out: args.out.clone(),
        config,
        resume: args.resume,
        stop_after: args.stop_after,
        progress: !args.quiet,
        device,
    })
    .with_context(|| format!("training on {}", args.data.display()))?;
    let s = &report.state;
    println!(
        "trained {} epochs ({} steps) in {:.1} s; best validation mAP@0.5 {:.4} (epoch {}); model in {}",
        s.epochs_done,
        s.step,
        report.seconds,
        s.best_map.max(0.0),
        s.best_epoch,
        args.out.display()
    );
    Ok(())
}
