//! `frugal`: the workbench CLI. One subcommand per pipeline stage.
use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// frugal: fast-enough sign detection for small drones.
///
/// The pipeline runs data → train → compress → pareto → policy → bundle → fly; each
/// stage has its own subcommand, and `frugal run` runs them all in one run folder.
#[derive(Parser)]
#[command(name = "frugal", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result: anyhow::Result<()> = match cli.command {};
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
