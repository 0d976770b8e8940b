//! `frugal bundle write|verify|inspect`: the policy bundle the drone loads.

use clap::{Args, Subcommand};
use frugal_policies::TrainedPolicy;
use frugal_policies::bundle::{inspect, verify, write_bundle};
use frugal_policies::eval::EvalConfig;
use std::path::PathBuf;

/// Arguments of `frugal bundle`.
#[derive(Args, Debug)]
pub struct BundleArgs {
    #[command(subcommand)]
    command: BundleCommand,
}

#[derive(Subcommand, Debug)]
enum BundleCommand {
    /// Write a bundle folder from a trained policy: policy.frpb (thresholds, families
    /// and buckets, variant table with ONNX file names and SHA-256, policy table,
    /// metadata) and the ONNX graphs copied beside it.
    Write {
        /// The trained policy (policy.json).
        #[arg(long)]
        policy: PathBuf,
        /// Output folder (replaced only once complete).
        #[arg(long)]
        out: PathBuf,
        /// θ_th: re-ask the policy when the tracker's IoU with the detection falls below.
        #[arg(long, default_value_t = 0.5)]
        iou_threshold: f32,
        /// N: re-run the policy every N frames.
        #[arg(long, default_value_t = 100)]
        mdp_period: u32,
        /// M: re-initialise the tracker every M frames.
        #[arg(long, default_value_t = 10)]
        reinit_period: u32,
        /// Most MDP accesses (detections) per image: after a detection below T_c the
        /// policy's next choice runs on the same image (paper: 5; 1 turns this off).
        #[arg(long, default_value_t = 5)]
        accesses_per_image: u32,
    },
    /// Check a bundle (folder or file): the runtime parses it and every referenced file
    /// hashes to the bundle's SHA-256.
    Verify {
        /// The bundle folder or file.
        path: PathBuf,
    },
    /// Print a bundle readably.
    Inspect {
        /// The bundle folder or file.
        path: PathBuf,
    },
}

/// Run `frugal bundle …`.
pub fn run(args: BundleArgs) -> anyhow::Result<()> {
    match args.command {
        BundleCommand::Write {
            policy,
            out,
            iou_threshold,
            mdp_period,
            reinit_period,
            accesses_per_image,
        } => {
            let p = TrainedPolicy::load(&policy)?;
            let mut th = EvalConfig::default().thresholds();
            th.iou_threshold = iou_threshold;
            th.mdp_period = mdp_period;
            th.reinit_period = reinit_period;
            th.accesses_per_image = accesses_per_image;
            if !th.is_valid() {
                anyhow::bail!("thresholds out of range: {th:?}");
            }
            let file = write_bundle(&p, th, &out)?;
            let files = verify(&out)?;
            println!(
                "wrote {} ({} referenced files verified)",
                file.display(),
                files.len()
            );
            Ok(())
        }
        BundleCommand::Verify { path } => {
            let files = verify(&path)?;
            println!(
                "{}: OK ({} referenced files verified)",
                path.display(),
                files.len()
            );
            for f in files {
                println!("  {}", f.display());
            }
            Ok(())
        }
        BundleCommand::Inspect { path } => {
            print!("{}", inspect(&path)?);
            Ok(())
        }
    }
}
