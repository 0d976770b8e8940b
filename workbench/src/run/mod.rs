//! `frugal run`: the whole pipeline in one run folder.
//!
//! data → detector → variants → pareto → replay → policy → evaluation → budget →
//! bundle → flights, then `report.md`, `report.html` and `figures.json` (every figure
//! a document may quote, see [`crate::figures`]). Each stage is the stage's own
//! subcommand, run in process with arguments the report quotes. A stage writes into
//! `<run>/<stage>.partial/` and is renamed to `<run>/<stage>/` only when complete, with
//! a stamp (`.stamp.json`) holding the hash of its inputs: its config section, the
//! content hash of every upstream stage's output, and frugal's version. A stage whose
//! stamp matches is skipped; a killed stage is redone (training resumes from its last
//! epoch checkpoint), so a killed run, started again, ends with the same artifacts.
mod config;
mod flights;
mod report;
mod stage;

pub use config::{Profile, RunConfig, TINY_DETECTOR};

use anyhow::Context;
use clap::Args;
use stage::{Ctx, STAGES};
use std::path::PathBuf;

/// Arguments of `frugal run`.
#[derive(Args, Debug)]
pub struct RunArgs {
    /// Run config (TOML or JSON): a `profile` and any values to override, section per
    /// stage (`data`, `detector`, `compress`, `pareto`, `replay`, `policy`,
    /// `evaluation`, `budget`, `heldout`, `flights`); the built-in default profile
    /// when omitted.
    pub config: Option<PathBuf>,
    /// The run folder (every artifact, the stamps and the report go here).
    #[arg(long, default_value = "runs/default")]
    pub out: PathBuf,
    /// Use the quick profile (a first look in minutes) when the config names none.
    #[arg(long)]
    pub quick: bool,
    /// Use the tiny test profile (seconds).
    #[arg(long, hide = true)]
    pub tiny: bool,
    /// Where to train the detector: `cpu` (default, the tested path), `cuda`, `cuda:N`.
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// Re-run this stage and everything after it even if its inputs are unchanged.
    #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(STAGES.map(|s| s.name)))]
    pub force: Option<String>,
    /// Stop after this stage (the report covers what exists).
    #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(STAGES.map(|s| s.name)))]
    pub until: Option<String>,
    /// Hide progress bars.
    #[arg(long)]
    pub quiet: bool,
}

/// The stages' folder names, in pipeline order.
pub fn stage_names() -> impl Iterator<Item = &'static str> {
    STAGES.iter().map(|s| s.name)
}

/// The run files `frugal figures publish` copies, and their published names.
pub fn published_files() -> &'static [(&'static str, &'static str)] {
    &[
        ("report.md", "report.md"),
        ("pareto/pareto_map.png", "pareto_map.png"),
        ("budget/budget-sap.png", "budget_sap_test.png"),
        ("budget/heldout-1/budget-sap.png", "budget_sap_heldout.png"),
        ("budget/budget-speed-f1.png", "budget_speed_f1_test.png"),
        ("evaluation/speed-f1.png", "replay_speed_f1.png"),
        ("flights/medium_top_view.png", "flights_medium_top_view.png"),
        ("data/contact_sheet.png", "contact_sheet.png"),
    ]
}

/// Run `frugal run`.
pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let t0 = std::time::Instant::now();
    let fallback = if args.tiny {
        Profile::Tiny
    } else if args.quick {
        Profile::Quick
    } else {
        Profile::Default
    };
    // everything is checked before anything is written
    let config = RunConfig::load(args.config.as_deref(), fallback)?;
    frugal_models::train::parse_device(&args.device)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the run folder {}", args.out.display()))?;
    let ctx = Ctx::new(&args, &config)?;
    let mut forced = false;
    let mut outcomes = Vec::new();
    for (i, st) in STAGES.iter().enumerate() {
        forced |= args.force.as_deref() == Some(st.name);
        let outcome = ctx
            .stage(st, forced, i + 1)
            .with_context(|| format!("stage {}", st.name))?;
        outcomes.push(outcome);
        if args.until.as_deref() == Some(st.name) {
            break;
        }
    }
    let report = report::write(&ctx, &outcomes, t0.elapsed().as_secs_f64())?;
    println!(
        "run finished in {:.1} s: {} ran, {} skipped; report {}",
        t0.elapsed().as_secs_f64(),
        outcomes.iter().filter(|o| o.ran).count(),
        outcomes.iter().filter(|o| !o.ran).count(),
        report.display()
    );
    Ok(())
}
