//! The flights stage's side-by-side comparison: static against adaptive, maze by maze,
//! with both perceptions' trajectories on one top view.
use super::config::RunConfig;
use anyhow::Context;
use frugal_sim::report::{Stat, Summary, plot_top_view, summarize};
use frugal_sim::{FlightResult, Maze};
use serde::Serialize;
use std::path::Path;

/// One maze of the flights comparison.
#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub(crate) struct FlightRow {
    /// Maze name.
    pub maze: String,
    /// The static variant flown.
    pub static_variant: String,
    /// Static perception.
    pub r#static: Summary,
    /// Adaptive perception (the bundle).
    pub adaptive: Summary,
    /// Adaptive frame rate over static.
    pub fps_ratio: f64,
    /// Static time to goal over adaptive (both must have landed at least once).
    pub time_ratio: Option<f64>,
}

fn read_results(path: &Path) -> anyhow::Result<Vec<FlightResult>> {
    let bytes = std::fs::read(path).with_context(|| format!("{}", path.display()))?;
    serde_json::from_slice(&bytes).with_context(|| format!("{}", path.display()))
}

/// Compare the static and adaptive flights under `out` maze by maze, and draw both
/// perceptions' trajectories on one top view per maze (`<out>/<maze>_top_view.*`).
pub(crate) fn compare_flights(
    out: &Path,
    config: &RunConfig,
    static_variant: &str,
) -> anyhow::Result<Vec<FlightRow>> {
    let mut rows = Vec::new();
    for m in &config.flights.mazes {
        let maze = Maze::resolve(Path::new(m))?;
        let st = read_results(&out.join("static").join(&maze.name).join("flights.json"))?;
        let ad = read_results(&out.join("adaptive").join(&maze.name).join("flights.json"))?;
        let both: Vec<FlightResult> = st.iter().chain(&ad).cloned().collect();
        plot_top_view(&out.join(format!("{}_top_view", maze.name)), &maze, &both)?;
        let (s, a) = (summarize(&st), summarize(&ad));
        let ratio = |num: &Stat, den: &Stat| {
            (num.n > 0 && den.n > 0 && den.mean > 0.0).then(|| num.mean / den.mean)
        };
        rows.push(FlightRow {
            maze: maze.name.clone(),
            static_variant: static_variant.into(),
            fps_ratio: if s.fps.mean > 0.0 {
                a.fps.mean / s.fps.mean
            } else {
                0.0
            },
            time_ratio: ratio(&s.time_to_goal_s, &a.time_to_goal_s),
            r#static: s,
            adaptive: a,
        });
    }
    Ok(rows)
}
