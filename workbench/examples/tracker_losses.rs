//! Why the tracker strategies lose F1 against static: on every tracked frame of the
//! test videos, each sign the static variant finds and the strategy misses, by cause.
//!
//! ```sh
//! cargo run --release -p frugal --example tracker_losses -- \
//!     runs/final/replay/replay.json runs/final/policy/policy.json [EVAL_CONFIG]
//! ```
//!
//! Causes, for a sign of class `c` missed on a tracked frame:
//! - `drift`: a tracked box of class `c` overlaps it (IoU ≥ 0.1) but below 0.5;
//! - `class`: a tracked box of another class covers it (IoU ≥ 0.5);
//! - `grew into view`: no sign of class `c` was in the ground truth at the last
//!   detection (it entered the view, or grew into the ground truth's size range);
//! - `track not started or lost`: the last detection found it, yet nothing tracks it;
//! - `missed at detection`: it was there at the last detection, which missed it.
use anyhow::Context;
use frugal_data::{Dataset, Split};
use frugal_models::metrics::{ImageResult, Truth};
use frugal_policies::eval::{EvalConfig, Strategy, VideoRun, run_all};
use frugal_policies::replay::{DatasetFrames, ReplayLog};
use frugal_policies::train::TrainedPolicy;
use frugal_runtime::Detection;
use std::collections::BTreeMap;
use std::path::Path;

fn found(t: &Truth, dets: &[Detection]) -> bool {
    dets.iter()
        .any(|d| d.class == t.class && d.bbox.iou(&t.bbox) >= 0.5)
}

fn cause(run: &VideoRun, f: usize, t: &Truth) -> &'static str {
    let dets = &run.images[f].detections;
    let best = |same: bool| {
        dets.iter()
            .filter(|d| (d.class == t.class) == same)
            .map(|d| d.bbox.iou(&t.bbox))
            .fold(0.0f32, f32::max)
    };
    if best(true) >= 0.1 {
        return "drift";
    }
    if best(false) >= 0.5 {
        return "class";
    }
    let Some(g) = (0..f).rev().find(|&g| run.frames[g].detect.is_some()) else {
        return "grew into view";
    };
    let then = &run.images[g];
    let present: Vec<&Truth> = then.truth.iter().filter(|p| p.class == t.class).collect();
    if present.is_empty() {
        "grew into view"
    } else if present.iter().any(|p| found(p, &then.detections)) {
        "track not started or lost"
    } else {
        "missed at detection"
    }
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(log), Some(policy)) = (args.get(1), args.get(2)) else {
        anyhow::bail!("usage: tracker_losses REPLAY_LOG POLICY_JSON [EVAL_CONFIG]");
    };
    let log = ReplayLog::load(Path::new(log))?;
    let policy = TrainedPolicy::load(Path::new(policy))?;
    let cfg = match args.get(3) {
        Some(p) => frugal_policies::error::read_toml_or_json(Path::new(p))?,
        None => EvalConfig::default(),
    };
    let ds = Dataset::load(&log.dataset)
        .with_context(|| format!("dataset of the log: {}", log.dataset.display()))?;
    let frames = DatasetFrames::new(&ds);
    let videos: Vec<_> = log.split(Split::Test).collect();
    let strategies = [
        Strategy::Static,
        Strategy::StaticTracker,
        Strategy::MdpTracker,
    ];
    let runs = run_all(&log, &policy, &videos, Some(&frames), &cfg, &strategies)?;
    let of = |s: Strategy| runs.runs.iter().find(|(k, _)| *k == s).map(|(_, r)| r);
    let statics = of(Strategy::Static).context("no static runs")?;
    for s in [Strategy::StaticTracker, Strategy::MdpTracker] {
        let mut causes: BTreeMap<&str, usize> = BTreeMap::new();
        for (run, stat) in of(s).context("no tracker runs")?.iter().zip(statics) {
            for (f, (trace, im)) in run.frames.iter().zip(&run.images).enumerate() {
                if trace.detect.is_some() {
                    continue;
                }
                let reference: &ImageResult = &stat.images[f];
                for t in &im.truth {
                    if found(t, &reference.detections) && !found(t, &im.detections) {
                        *causes.entry(cause(run, f, t)).or_default() += 1;
                    }
                }
            }
        }
        let total: usize = causes.values().sum();
        println!(
            "{}: {total} signs static finds and it misses on tracked frames",
            s.name()
        );
        for (c, n) in &causes {
            println!("  {c:<28} {n}");
        }
    }
    Ok(())
}
