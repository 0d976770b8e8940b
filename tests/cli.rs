//! End-to-end tests of the `frugal` CLI on tiny configurations, run in process through
//! [`frugal::run`]. One module per pipeline stage, in `tests/cli/`.
use std::path::Path;

/// Run the CLI in process; the error comes back as its one-line `{:#}` message.
pub(crate) fn frugal(args: &[&str]) -> Result<(), String> {
    frugal::run(std::iter::once("frugal").chain(args.iter().copied())).map_err(|e| format!("{e:#}"))
}

/// Generate the tiny dataset profile into `dir`.
pub(crate) fn tiny_dataset(dir: &Path) {
    frugal(&[
        "data",
        "generate",
        "--profile",
        "tiny",
        "--out",
        p(dir),
        "--quiet",
    ])
    .unwrap_or_else(|e| panic!("generating the tiny dataset: {e}"));
}

/// Train the detector of `cfg` on `data` into `out`, quietly, with `extra` arguments.
pub(crate) fn train_tiny(data: &Path, cfg: &Path, out: &Path, extra: &[&str]) {
    let mut args = vec![
        "train",
        "--data",
        p(data),
        "--config",
        p(cfg),
        "--out",
        p(out),
        "--quiet",
    ];
    args.extend_from_slice(extra);
    frugal(&args).unwrap_or_else(|e| panic!("training into {}: {e}", out.display()));
}

/// A maze file the simulator ships (`sim/mazes/<name>`).
pub(crate) fn maze(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../sim/mazes")
        .join(name)
}

/// A temporary path as an argument.
pub(crate) fn p(path: &Path) -> &str {
    path.to_str().expect("temp paths are UTF-8")
}

/// A JSON file the CLI wrote.
pub(crate) fn json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(
        &std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}
#[path = "cli/data.rs"]
mod data;
#[path = "cli/docs.rs"]
mod docs;
#[path = "cli/features.rs"]
mod features;
#[path = "cli/fly.rs"]
mod fly;
#[path = "cli/pareto.rs"]
mod pareto;
#[path = "cli/pilot.rs"]
mod pilot;
#[path = "cli/policy.rs"]
mod policy;
#[path = "cli/real.rs"]
mod real;
#[path = "cli/run.rs"]
mod run;
#[path = "cli/train.rs"]
mod train;
