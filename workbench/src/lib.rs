//! `frugal`: the workbench CLI. One subcommand per pipeline stage; each stage's
//! arguments and glue live in a module of the same name. The binary (`main.rs`) only
//! calls [`main_from`]; the end-to-end tests in `tests/` call [`run`] in process.
#![deny(missing_docs)]
use clap::{Parser, Subcommand};
use std::ffi::OsString;

pub mod bench;
pub mod budget;
pub mod bundle;
pub mod compress;
pub mod data;
pub mod eval;
pub mod features;
pub mod figures;
pub mod fly;
pub mod pareto;
pub mod policy;
pub mod run;
pub mod train;

/// frugal: fast-enough sign detection for small drones.
///
/// The pipeline runs data → train → compress → pareto → policy → bundle → fly; each
/// stage has its own subcommand, and `frugal run` runs them all in one run folder.
#[derive(Parser)]
#[command(name = "frugal", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fly the warehouse mazes in closed loop and print the paper's end-to-end table.
    Fly(fly::FlyArgs),
    /// Synthetic dataset generation, import, export, summary and inspection.
    Data(data::DataArgs),
    /// Train the CNN detector (Faster-R-CNN style) on a dataset folder.
    Train(train::TrainArgs),
    /// Score a trained CNN detector on a dataset split (mAP, P/R/F1, per scenario).
    Eval(eval::EvalArgs),
    /// The feature-based family (EdgeBoxes + HoG + linear SVM): train, eval, proposal recall.
    #[command(subcommand_required = true)]
    Features(features::FeaturesArgs),
    /// Export a trained detector to ONNX (backbone + RPN graph, RoI-head graph).
    Export(bench::ExportArgs),
    /// Time a detector per frame through ONNX Runtime and libtorch, side by side.
    Bench(bench::BenchArgs),
    /// Make compressed variants of a trained detector (int8, pruning, layer removal, resolution).
    Compress(compress::CompressArgs),
    /// Accuracy and latency of every variant, the Pareto front, plots, variants file.
    Pareto(pareto::ParetoArgs),
    /// The MDP stage: replay variants on videos, train the policy, evaluate strategies.
    Policy(policy::PolicyArgs),
    /// Write, verify or inspect a policy bundle (the file the drone loads).
    Bundle(bundle::BundleArgs),
    /// Run the whole pipeline into one run folder, skipping stages whose inputs are
    /// unchanged, and write report.md / report.html.
    Run(run::RunArgs),
    /// The run's figures in documents: check that every quoted figure matches the run,
    /// or publish a run's figures and rewrite them.
    Figures(figures::FiguresArgs),
}

/// Parse `args` (the first is the program name) and run the subcommand.
///
/// `--help` and `--version` come back as a [`clap::Error`] inside the result, like
/// any other parse outcome; [`main_from`] prints them.
pub fn run<I, T>(args: I) -> anyhow::Result<()>
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let cli = Cli::try_parse_from(args)?;
    match cli.command {
        Command::Fly(args) => fly::run(args),
        Command::Data(args) => data::run(args),
        Command::Run(args) => run::run(args),
        Command::Figures(args) => figures::run(args),
        Command::Policy(args) => policy::run(args),
        Command::Bundle(args) => bundle::run(args),
        Command::Train(args) => train::run(args),
        Command::Eval(args) => eval::run(args),
        Command::Features(args) => features::run(args),
        Command::Export(args) => bench::export(args),
        Command::Bench(args) => bench::bench(args),
        Command::Compress(args) => compress::run(args),
        Command::Pareto(args) => pareto::run(args),
    }
}

/// Run the CLI and turn the outcome into a process exit code: 0 on success, 2 for a
/// usage error, 1 for any other error, printed as one line on stderr.
pub fn main_from<I, T>(args: I) -> u8
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    match run(args) {
        Ok(()) => 0,
        Err(err) => match err.downcast_ref::<clap::Error>() {
            Some(clap_err) => {
                let _ = clap_err.print();
                if clap_err.use_stderr() { 2 } else { 0 }
            }
            None => {
                eprintln!("error: {err:#}");
                1
            }
        },
    }
}
