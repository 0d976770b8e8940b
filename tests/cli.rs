//! End-to-end tests of the `frugal` CLI on tiny configurations, run in process through
//! [`frugal::run`]. One module per pipeline stage, in `tests/cli/`.
#[path = "cli/data.rs"]
mod data;
#[path = "cli/features.rs"]
mod features;
#[path = "cli/fly.rs"]
mod fly;
#[path = "cli/pareto.rs"]
mod pareto;
#[path = "cli/policy.rs"]
mod policy;
#[path = "cli/train.rs"]
mod train;
