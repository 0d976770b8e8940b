//! `frugal run`: the whole pipeline in one run folder. For now: the data stage.
use clap::Args;
use frugal_data::GenConfig;
use std::path::PathBuf;

/// Arguments of `frugal run`.
#[derive(Args, Debug)]
pub struct RunArgs {
    /// The run folder; the dataset goes to `<out>/data`.
    #[arg(long, default_value = "runs/default")]
    pub out: PathBuf,
    /// Use the quick profile (small dataset) instead of the default one.
    #[arg(long)]
    pub quick: bool,
    /// Use the tiny test profile (a few dozen small frames).
    #[arg(long, hide = true)]
    pub tiny: bool,
    /// Hide progress bars.
    #[arg(long)]
    pub quiet: bool,
}

/// The data stage: generate the dataset into `<out>/data`, or reuse it when one made
/// from the identical config is already there, and print its summary.
pub fn data_stage(args: &RunArgs) -> anyhow::Result<frugal_data::Dataset> {
    let config = if args.tiny {
        GenConfig::tiny()
    } else if args.quick {
        GenConfig::quick()
    } else {
        GenConfig::default()
    };
    let dir = args.out.join("data");
    let (ds, reused) = frugal_data::generate_or_reuse(&config, &dir, !args.quiet)?;
    if reused {
        println!(
            "data: reusing {} (config {})",
            dir.display(),
            &config.hash()[..12]
        );
    } else {
        println!(
            "data: generated {} frames into {}",
            ds.frames.len(),
            dir.display()
        );
    }
    print!("{}", frugal_data::summary(&ds));
    Ok(ds)
}

/// Run `frugal run`.
pub fn run(args: RunArgs) -> anyhow::Result<()> {
    data_stage(&args)?;
    Ok(())
}
