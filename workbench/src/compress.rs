//! `frugal compress`: make the compressed variants of a trained detector (int8,
//! magnitude pruning, channel pruning, block removal, input resolution, combinations).
use anyhow::Context;
use clap::Args;
use frugal_models::compress::{CompressOptions, Grid, compress};
use std::path::PathBuf;

/// Arguments of `frugal compress`.
#[derive(Args, Debug)]
pub struct CompressArgs {
    /// Base model folder written by `frugal train` (config.json + best.safetensors).
    #[arg(long)]
    pub model: PathBuf,
    /// Dataset folder (training frames for calibration and fine-tuning).
    #[arg(long)]
    pub data: PathBuf,
    /// Output folder: one sub-folder per variant.
    #[arg(long)]
    pub out: PathBuf,
    /// Variant grid (TOML or JSON); the built-in grid when omitted.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// No progress lines.
    #[arg(long)]
    pub quiet: bool,
}

/// Run `frugal compress`.
pub fn run(args: CompressArgs) -> anyhow::Result<()> {
    let grid = match &args.config {
        Some(p) => Grid::load(p)?,
        None => Grid::default(),
    };
    let records = compress(&CompressOptions {
        model: args.model.clone(),
        data: args.data.clone(),
        out: args.out.clone(),
        grid,
        progress: !args.quiet,
    })
    .with_context(|| format!("compressing {}", args.model.display()))?;
    println!(
        "{:<14} {:<12} {:>10} {:>10} {:>9} {:>7}",
        "variant", "parent", "params", "nonzero", "input", "int8"
    );
    for r in &records {
        println!(
            "{:<14} {:<12} {:>10} {:>10} {:>9} {:>7}",
            r.name,
            r.parent.as_deref().unwrap_or("-"),
            r.parameters,
            r.nonzero_parameters,
            format!("{}x{}", r.input_width, r.input_height),
            r.int8
        );
        if let Some(d) = &r.drift {
            println!(
                "  int8 drift vs {}: features max {:.4} mean {:.5} (mean |fp32| {:.4}), objectness max {:.4} mean {:.5}",
                r.parent.as_deref().unwrap_or("?"),
                d.max_abs_diff.get("features").copied().unwrap_or(f64::NAN),
                d.mean_abs_diff.get("features").copied().unwrap_or(f64::NAN),
                d.mean_abs_fp32.get("features").copied().unwrap_or(f64::NAN),
                d.max_abs_diff
                    .get("objectness")
                    .copied()
                    .unwrap_or(f64::NAN),
                d.mean_abs_diff
                    .get("objectness")
                    .copied()
                    .unwrap_or(f64::NAN),
            );
        }
    }
    println!("{} variants in {}", records.len(), args.out.display());
    Ok(())
}
