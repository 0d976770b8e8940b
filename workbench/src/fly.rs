//! `frugal fly`: closed-loop flights through the warehouse mazes, the paper's
//! end-to-end table (frame rate, time to completion, velocity, plus success and
//! collisions), JSON / CSV, top views and camera frames.
use anyhow::Context;
use clap::{Args, ValueEnum};
use frugal_data::Source;
use frugal_runtime::pilot::Carry;
use frugal_sim::report::{self, GifRecorder, Summary};
use frugal_sim::{
    CameraSpec, DeviceProfile, FlightConfig, FlightResult, FootageRecorder, FrameView,
    GroundTruthPerception, Maze, Perception,
};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};

/// Arguments of `frugal fly`.
#[derive(Args, Debug, Clone)]
pub struct FlyArgs {
    /// Maze file(s) (see `sim/mazes/README.md` for the format), or the name of a
    /// shipped maze (`easy`, `medium`, `hard`); repeat for several.
    #[arg(long, required = true)]
    pub maze: Vec<PathBuf>,
    /// Flights per maze, with seeds `seed, seed+1, …`.
    #[arg(long, default_value_t = 5)]
    pub seeds: u64,
    /// First seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// What perceives the signs.
    #[arg(long, value_enum, default_value_t = PerceptionKind::GroundTruth)]
    pub perception: PerceptionKind,
    /// The ONNX variant folder of `--perception static`.
    #[arg(long)]
    pub variant: Option<PathBuf>,
    /// The bundle folder of `--perception adaptive`.
    #[arg(long)]
    pub bundle: Option<PathBuf>,
    /// Which detections the adaptive runtime carries with its trackers: from the
    /// optimal bucket up (the default, as the replay evaluation), from the
    /// good-enough bucket up, or every reported one (the paper's rule). The flight
    /// confirms a sign before acting on it and never places one from a carried box.
    /// The names are the run config's `[flights] carry` (possible values: optimal,
    /// good-enough, reported).
    #[arg(long, default_value = "optimal", value_parser = parse_carry)]
    pub carry: Carry,
    /// Fly the bundle's budget table for this many device ms per frame (one of the
    /// budgets `frugal policy budget` wrote into it) with the budget scheduler,
    /// instead of the paper's controller. Needs `--perception adaptive`.
    #[arg(long)]
    pub budget_ms: Option<f32>,
    /// With `--budget-ms`: the budget keeper's window, frames (0: no keeper). The
    /// keeper is debited each frame's compute times the device's slowdown.
    #[arg(long, default_value_t = 30)]
    pub keep_window: u32,
    /// The camera's frame rate: perception takes at most one frame per camera period
    /// (`NavConfig::camera_fps`). Flying a budget table of a format-6 bundle, the
    /// frames are numbered on the tables' own clock, and those of a faster camera that
    /// fall between its frames are dropped.
    #[arg(long, default_value_t = 60.0)]
    pub camera_fps: f64,
    /// ONNX Runtime intra-op threads for detector-based perception.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Compute time per frame of the ground-truth perception, ms (before the slowdown).
    #[arg(long, default_value_t = 5.0)]
    pub gt_compute_ms: f64,
    /// Device profile: `host` (slowdown 1) or `tx2-like` (slowdown 6).
    #[arg(long, default_value = "tx2-like")]
    pub device: String,
    /// Override the device's slowdown factor.
    #[arg(long)]
    pub slowdown: Option<f64>,
    /// The device's slowdown for int8 detectors, when its int8 speed relative to this
    /// machine is not its fp32 one (`frugal run` passes the budget stage's: the device
    /// profile's int8 reference over this machine's). The static variant is int8 when
    /// its `variant.json` says so; the bundle's variants when its `precision:` metadata
    /// does.
    #[arg(long)]
    pub slowdown_int8: Option<f64>,
    /// The device's slowdown for the compute outside the detectors (the adaptive
    /// runtime's tracker and decisions), when it differs from the fp32 one (`frugal
    /// run` passes the budget stage's: the device profile's reference tracker over this
    /// machine's, timed with the tracker's costs).
    #[arg(long)]
    pub slowdown_tracker: Option<f64>,
    /// Camera width, pixels.
    #[arg(long, default_value_t = 480)]
    pub width: u32,
    /// Camera height, pixels.
    #[arg(long, default_value_t = 270)]
    pub height: u32,
    /// Simulated time limit per flight, seconds.
    #[arg(long, default_value_t = 3600.0)]
    pub time_limit: f64,
    /// Output folder; each maze gets `<out>/<maze name>/`.
    #[arg(long, default_value = "runs/fly")]
    pub out: PathBuf,
    /// Save every N-th camera frame of the first seed's flight as PNG (0 = none).
    #[arg(long, default_value_t = 0)]
    pub frames_every: u64,
    /// Save the first seed's flight as an animated GIF (half resolution).
    #[arg(long)]
    pub gif: bool,
    /// One GIF frame every N processed frames (shown 100 ms each).
    #[arg(long, default_value_t = 60)]
    pub gif_every: u64,
    /// Record every flight's processed frames, with the renderer's sign boxes, as a
    /// frugal-data dataset in this folder (one `val` video per flight), for the policy
    /// to learn from (`frugal policy record --data DIR --splits val --train-split
    /// val`). Fly training mazes (`train-a`, `train-b`, `train-c`) for this, never the
    /// evaluation ones.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Keep one processed frame in this many when recording.
    #[arg(long, default_value_t = 3)]
    pub record_every: u64,
    /// Hide progress bars.
    #[arg(long)]
    pub quiet: bool,
}

/// `--carry NAME`: the run config's name of a carry (`[flights] carry`), so that the
/// flights stage passes it through as it is.
fn parse_carry(name: &str) -> Result<Carry, String> {
    serde_json::from_value(serde_json::Value::String(name.into())).map_err(|e| e.to_string())
}

/// Perception choices.
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum PerceptionKind {
    /// Exact boxes from the renderer's projection, fixed compute time.
    GroundTruth,
    /// One exported ONNX variant (`--variant DIR`) on every frame, through ONNX
    /// Runtime: the paper's static baseline.
    Static,
    /// The adaptive runtime of a policy bundle (`--bundle DIR`): controller, KLT
    /// trackers and the bundle's ONNX variants, exactly as on the drone.
    Adaptive,
}

fn perception(args: &FlyArgs, config: &FlightConfig) -> anyhow::Result<Box<dyn Perception>> {
    Ok(match args.perception {
        PerceptionKind::GroundTruth => Box::new(GroundTruthPerception {
            compute_ms: args.gt_compute_ms,
            ..GroundTruthPerception::default()
        }),
        PerceptionKind::Static => {
            let dir = args
                .variant
                .as_ref()
                .context("--perception static needs --variant DIR (an ONNX export)")?;
            let mut p =
                frugal_sim::static_onnx(dir, args.threads).map_err(|e| anyhow::anyhow!("{e}"))?;
            if config.device.slowdown_int8.is_some() {
                let record = dir.join(frugal_models::compress::VARIANT_FILE);
                p.int8 = frugal_models::compress::read_record(&record)
                    .with_context(|| {
                        format!(
                            "--slowdown-int8 needs the static variant's precision: {}",
                            record.display()
                        )
                    })?
                    .int8;
            }
            Box::new(p)
        }
        PerceptionKind::Adaptive => {
            let dir = args
                .bundle
                .as_ref()
                .context("--perception adaptive needs --bundle DIR (from `frugal bundle write`)")?;
            let mut p = frugal_sim::AdaptivePerception::open(dir, args.threads)
                .map_err(|e| anyhow::anyhow!("{e}"))?
                .with_carry(args.carry);
            p.check_device(&config.device)
                .map_err(|e| anyhow::anyhow!("{}: {e}", dir.display()))?;
            if let Some(b) = args.budget_ms {
                p = p
                    .with_budget(b, args.keep_window, &config.device, config.nav.camera_fps)
                    .map_err(|e| anyhow::anyhow!("{}: {e}", dir.display()))?;
            }
            Box::new(p)
        }
    })
}

/// Run `frugal fly`.
pub fn run(args: FlyArgs) -> anyhow::Result<()> {
    let mut device = DeviceProfile::by_name(&args.device).with_context(|| {
        format!(
            "unknown device profile `{}` (use host or tx2-like)",
            args.device
        )
    })?;
    // each stated slowdown replaces the profile's, and the tables and files name the
    // device by its label: say what it now is
    let positive = |flag: &str, s: f64| -> anyhow::Result<f64> {
        anyhow::ensure!(s > 0.0 && s.is_finite(), "{flag} must be positive, got {s}");
        Ok(s)
    };
    if let Some(s) = args.slowdown {
        device.slowdown = positive("--slowdown", s)?;
        device.name = format!("{} at slowdown {s}", device.name);
    }
    if let Some(s) = args.slowdown_int8 {
        device.slowdown_int8 = Some(positive("--slowdown-int8", s)?);
        device.name = format!("{} (int8 {s})", device.name);
    }
    if let Some(s) = args.slowdown_tracker {
        device.slowdown_tracker = Some(positive("--slowdown-tracker", s)?);
        device.name = format!("{} (tracker {s})", device.name);
    }
    anyhow::ensure!(args.seeds >= 1, "--seeds must be at least 1");
    anyhow::ensure!(
        args.carry == Carry::Optimal || args.perception == PerceptionKind::Adaptive,
        "--carry other than optimal applies to the adaptive runtime's trackers (--perception adaptive)"
    );
    anyhow::ensure!(
        args.budget_ms.is_none() || args.perception == PerceptionKind::Adaptive,
        "--budget-ms flies a bundle's budget table (--perception adaptive --bundle DIR)"
    );
    anyhow::ensure!(
        args.budget_ms.is_none() || args.carry == Carry::Optimal,
        "--budget-ms flies the budget scheduler, whose trackers carry what it reports: --carry does not apply"
    );
    anyhow::ensure!(
        args.gt_compute_ms >= 0.0,
        "--gt-compute-ms must not be negative"
    );
    let mut config = FlightConfig {
        camera: CameraSpec {
            width: args.width,
            height: args.height,
            ..CameraSpec::default()
        },
        device,
        ..FlightConfig::default()
    };
    config.nav.time_limit_s = args.time_limit;
    anyhow::ensure!(
        args.camera_fps > 0.0 && args.camera_fps.is_finite(),
        "--camera-fps must be positive, got {}",
        args.camera_fps
    );
    config.nav.camera_fps = args.camera_fps;
    let mazes = args
        .maze
        .iter()
        .map(|p| Maze::resolve(p))
        .collect::<Result<Vec<_>, _>>()?;
    anyhow::ensure!(args.record_every >= 1, "--record-every must be at least 1");
    let mut recorder = match &args.record {
        Some(dir) => Some(
            FootageRecorder::create(dir, args.record_every)
                .with_context(|| format!("cannot record into {}", dir.display()))?,
        ),
        None => None,
    };
    let mut summaries: Vec<Summary> = Vec::new();
    for maze in &mazes {
        let dir = args.out.join(&maze.name);
        let results = fly_maze(maze, &config, &args, &dir, recorder.as_mut())?;
        let summary = report::summarize(&results);
        report::write_json(&dir.join("flights.json"), &results)?;
        report::write_flights_csv(&dir.join("flights.csv"), &results)?;
        report::write_json(&dir.join("summary.json"), &summary)?;
        report::plot_top_view(&dir.join("top_view"), maze, &results)?;
        for r in &results {
            if !r.outcome.is_success() {
                println!("{} seed {}: {}", maze.name, r.seed, r.outcome.describe());
            }
        }
        summaries.push(summary);
    }
    report::write_json(&args.out.join("summary.json"), &summaries)?;
    print!("{}", report::table(&summaries));
    if let (Some(rec), Some(dir)) = (recorder, &args.record) {
        let frames = rec.frames();
        let perception = summaries
            .first()
            .map_or_else(String::new, |s| s.perception.clone());
        rec.finish(Source::Flight {
            mazes: args.maze.iter().map(|m| m.display().to_string()).collect(),
            seeds: (args.seed..args.seed + args.seeds).collect(),
            every: args.record_every,
            perception,
        })?;
        println!("recorded {frames} frames into {}", dir.display());
    }
    println!("results in {}", args.out.display());
    Ok(())
}

fn fly_maze(
    maze: &Maze,
    config: &FlightConfig,
    args: &FlyArgs,
    dir: &Path,
    mut recorder: Option<&mut FootageRecorder>,
) -> anyhow::Result<Vec<FlightResult>> {
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(args.seeds)
    };
    bar.set_style(
        ProgressStyle::with_template("{prefix:>8} [{bar:30}] {pos}/{len} flights {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_prefix(maze.name.clone());
    let mut results = Vec::new();
    for seed in args.seed..args.seed + args.seeds {
        let mut p = perception(args, config)?;
        let first = seed == args.seed;
        let mut gif = if first && args.gif {
            Some(GifRecorder::create(&dir.join("flight.gif"), 100)?)
        } else {
            None
        };
        let mut failure: Option<anyhow::Error> = None;
        let frames_dir = dir.join("frames");
        if let Some(rec) = recorder.as_deref_mut() {
            rec.begin_flight(maze, seed);
        }
        let mut observe = |v: &FrameView<'_>| {
            if v.index.is_multiple_of(100) {
                bar.set_message(format!("seed {seed}: t = {:.0} s", v.time_s));
            }
            if failure.is_some() {
                return;
            }
            if let Some(rec) = recorder.as_deref_mut()
                && let Err(e) = rec.observe(v)
            {
                failure = Some(e.into());
                return;
            }
            if !first {
                return;
            }
            if args.frames_every > 0 && v.index.is_multiple_of(args.frames_every) {
                let path = frames_dir.join(format!("frame_{:06}.png", v.index));
                if let Err(e) = report::save_frame_png(&path, v) {
                    failure = Some(e.into());
                }
            }
            if let Some(g) = gif.as_mut()
                && v.index.is_multiple_of(args.gif_every.max(1))
                && let Err(e) = g.push(v)
            {
                failure = Some(e.into());
            }
        };
        let r = frugal_sim::fly(maze, config, p.as_mut(), seed, Some(&mut observe))?;
        if let Some(e) = failure {
            return Err(e);
        }
        if let Some(g) = gif {
            g.finish()?;
        }
        results.push(r);
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(results)
}

#[cfg(test)]
mod tests {
    use frugal_runtime::pilot::Carry;

    /// The run's flights stage passes `[flights] carry` to `frugal fly --carry` by its
    /// config name: every name must be a value the CLI takes, meaning the same carry.
    #[test]
    fn every_run_config_carry_is_a_fly_carry_value() {
        for carry in [Carry::Optimal, Carry::GoodEnough, Carry::Reported] {
            let name = serde_json::to_value(carry).unwrap();
            let name = name.as_str().unwrap();
            assert_eq!(super::parse_carry(name), Ok(carry), "{name}");
        }
    }
}
