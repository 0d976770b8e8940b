//! `frugal-pilot`: the program that runs on the drone's companion computer, next to
//! the flight controller. It reads the camera (a V4L2 device, an RTP/UDP stream, a
//! video file or an image folder, [`source`]), runs the policy bundle on every frame
//! it can (the controller choosing an ONNX variant or the KLT tracker,
//! [`frugal_nav::BundlePerception`]), turns confirmed signs into commands with the
//! navigator the maze simulator flies ([`frugal_nav::Navigator`]), and writes one JSON
//! line per processed frame and MAVLink 2 to the autopilot ([`link`]).
//!
//! The distance flown, which the navigator places signs by, comes from the autopilot
//! over MAVLink (`--mavlink-odometry`: `LOCAL_POSITION_NED` and `ATTITUDE`), from a
//! flight log (`--odometry FILE`, as `frugal fly --record` writes next to its footage),
//! or from dead reckoning of the commanded speed (the navigator's cruise speed) and
//! yaw rate.
//! A pedestrian detector is not part of the bundle: without a flight log the
//! navigator is told no pedestrian is close.
#![deny(missing_docs)]

pub mod config;
pub mod link;
pub mod odometry;
pub mod replay;
pub mod source;

use config::PilotConfig;
use frugal_nav::heading::{reached, turn_target, wrap};
use frugal_nav::{BundlePerception, FlightLog, Mode, NavCommand, NavInput, Navigator, Optics};
use frugal_runtime::FrameRef;
use serde_json::json;
use source::{Input, InputStats, Mailbox, Reader};
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// The command line.
#[derive(clap::Parser, Clone, Debug)]
#[command(
    name = "frugal-pilot",
    about = "Camera in, the policy bundle's decisions, MAVLink commands out"
)]
pub struct Args {
    /// The bundle folder (`policy.frpb` and `onnx/<variant>/`, from `frugal bundle write`).
    #[arg(long, required_unless_present = "detections")]
    pub bundle: Option<PathBuf>,
    /// Replay: per-frame detections from this file (JSON lines, as `--json` writes
    /// them) instead of the bundle's detectors; see [`replay`].
    #[arg(long, conflicts_with = "bundle")]
    pub detections: Option<PathBuf>,
    /// Video file, image folder, V4L2 device (`/dev/video0`), stream URL (`udp://…`,
    /// `rtp://…`) or SDP file.
    #[arg(long)]
    pub input: String,
    /// Configuration file (TOML; see the guide). Defaults: the simulator's camera and
    /// signs.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Frame rate of an image folder.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Files and folders: hand every frame to perception (no drops) instead of pacing
    /// them at their timestamps as a camera would (the default).
    #[arg(long)]
    pub every_frame: bool,
    /// Flight log (CSV from `frugal fly --record`): the distance flown, heading and
    /// pedestrian proximity per frame, instead of dead reckoning.
    #[arg(long)]
    pub odometry: Option<PathBuf>,
    /// Take the distance flown and the heading from the autopilot's
    /// `LOCAL_POSITION_NED` and `ATTITUDE` on the `--mavlink` link (dead reckoning until
    /// both have arrived); see [`odometry`].
    #[arg(long, requires = "mavlink", conflicts_with = "odometry")]
    pub mavlink_odometry: bool,
    /// Where the JSON lines go: `-` for stdout, a file, or `none`.
    #[arg(long, default_value = "-")]
    pub json: String,
    /// MAVLink address: `udpout:HOST:PORT`, `udpin:ADDR:PORT`, `serial:DEVICE:BAUD`.
    #[arg(long)]
    pub mavlink: Option<String>,
    /// ONNX Runtime intra-op threads per variant.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Fly the bundle's budget table for this budget (device ms per frame, one of the
    /// budgets the bundle holds) with the budget scheduler, instead of the paper's
    /// controller. With a format-6 bundle the frames are numbered by their times on
    /// the tables' own clock, and those of a faster input that fall between its frames
    /// are skipped.
    #[arg(long, requires = "bundle")]
    pub budget_ms: Option<f32>,
    /// With `--budget-ms`: the budget keeper's window, in frames of budget (0: no
    /// keeper, every period as the table says). The keeper is debited each frame's
    /// measured compute on this machine.
    #[arg(long, default_value_t = 30)]
    pub keep_window: u32,
}

/// Why the pilot could not start or had to stop.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PilotError {
    /// The configuration file.
    #[error(transparent)]
    Config(#[from] config::ConfigError),
    /// The bundle, its files, or a variant.
    #[error("bundle {path}: {message}")]
    Bundle {
        /// The bundle folder.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The detections file.
    #[error(transparent)]
    Replay(#[from] replay::ReplayError),
    /// The flight log.
    #[error(transparent)]
    Log(#[from] frugal_nav::flight_log::LogError),
    /// The MAVLink link.
    #[error(transparent)]
    Link(#[from] link::LinkError),
    /// The JSON output.
    #[error("{path}: {message}")]
    Output {
        /// The output.
        path: String,
        /// What went wrong.
        message: String,
    },
    /// Perception failed on a frame.
    #[error("perception failed on frame {frame}: {message}")]
    Perception {
        /// The frame.
        frame: u64,
        /// Why.
        message: String,
    },
    /// A bad argument.
    #[error("{0}")]
    Usage(String),
}

/// How a run went.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Summary {
    /// Frames processed.
    pub frames: u64,
    /// Frames decoded by the reader.
    pub decoded: u64,
    /// Frames overwritten before perception took them.
    pub drops: u64,
    /// Corrupt frames skipped.
    pub corrupt: u64,
    /// Reconnections of a live input.
    pub reconnects: u64,
    /// Commands issued, in order, with the frame each was decided on.
    pub commands: Vec<(u64, NavCommand)>,
    /// MAVLink heartbeats sent.
    pub heartbeats: u64,
    /// MAVLink messages read from the autopilot (`--mavlink-odometry`).
    pub mavlink_received: u64,
    /// Processed frames per second of wall-clock time.
    pub fps: f64,
    /// Median time from a frame's arrival to its decision (and command), ms.
    pub latency_p50_ms: f64,
    /// 95th percentile of the same, ms.
    pub latency_p95_ms: f64,
    /// Mean compute per processed frame (perception, confirmations included), ms.
    pub compute_ms_mean: f64,
    /// The budget table flown (`--budget-ms`), device ms per frame.
    pub budget_ms: Option<f32>,
    /// Periodic detections the budget keeper postponed.
    pub postponed: u32,
    /// Frames not processed because they fell on a frame the budget table's clock had
    /// already counted (an input faster than the rate the tables were made at).
    pub table_drops: u64,
    /// Stopped by SIGINT or SIGTERM.
    pub interrupted: bool,
    /// Why the input ended early, when it failed.
    pub input_error: Option<String>,
}

impl Summary {
    /// The last line the program prints.
    pub fn line(&self) -> String {
        let commands: Vec<&str> = self.commands.iter().map(|(_, c)| c.name()).collect();
        format!(
            "frugal-pilot: {}{} frames processed ({} decoded), {} dropped, {} corrupt, {} reconnects, {} commands [{}], {} heartbeats; {:.1} frames/s, arrival to decision P50 {:.1} ms P95 {:.1} ms",
            if self.interrupted { "stopped: " } else { "" },
            self.frames,
            self.decoded,
            self.drops,
            self.corrupt,
            self.reconnects,
            self.commands.len(),
            commands.join(", "),
            self.heartbeats,
            self.fps,
            self.latency_p50_ms,
            self.latency_p95_ms
        ) + &self
            .budget_ms
            .map(|b| {
                format!(
                    "; budget table {b} ms, {} periodic detections postponed, {} frames faster than its clock skipped",
                    self.postponed, self.table_drops
                )
            })
            .unwrap_or_default()
    }
}

/// The sign's short name for telemetry: its action, else its class id.
fn sign_name(navigator: &Navigator, class: u16) -> String {
    match navigator.action_of(class) {
        Some(frugal_data::NavAction::TurnLeft) => "left".into(),
        Some(frugal_data::NavAction::TurnRight) => "right".into(),
        Some(frugal_data::NavAction::Stop) => "stop".into(),
        Some(frugal_data::NavAction::Wait) => "wait".into(),
        None => format!("class{class}"),
    }
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

/// Where the distance flown and the heading of a frame came from (the JSON lines'
/// `odometry`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
enum PoseSource {
    /// The flight log (`--odometry`).
    Log,
    /// The autopilot (`--mavlink-odometry`).
    Mavlink,
    /// Dead reckoning.
    Reckoned,
}

/// Where detections come from: the bundle's detectors, or a replayed file.
enum Perception {
    Bundle(Box<BundlePerception>),
    Replay(replay::Replay),
}

impl Perception {
    /// The number to perceive the frame by, processed frame `index`, number `frame`
    /// of the input captured at `time_s`: flying a budget table, its number on the
    /// tables' clock, or the input's when the bundle does not say the tables' rate
    /// (periods count arriving frames, dropped ones too), or `None`: the frame falls on
    /// a frame that clock has counted, and is skipped; else `index`.
    fn number(&mut self, index: u64, frame: u64, time_s: f64) -> Option<u64> {
        match self {
            Perception::Bundle(p) if p.budget_ms().is_some() => p.frame_number(time_s, frame),
            _ => Some(index),
        }
    }

    /// Perceive the frame numbered `number` ([`Perception::number`]), number `frame`
    /// of the input.
    fn perceive(
        &mut self,
        image: FrameRef<'_>,
        number: u64,
        frame: u64,
    ) -> Result<frugal_nav::Percept, frugal_nav::PerceptionError> {
        match self {
            Perception::Bundle(p) => p.perceive(image, number),
            Perception::Replay(r) => Ok(r.percept(frame)),
        }
    }

    /// The reference variant's reading of frame number `frame`; `None` when a
    /// replay says there was none.
    fn confirm(
        &mut self,
        image: FrameRef<'_>,
        frame: u64,
    ) -> Result<Option<frugal_nav::Percept>, frugal_nav::PerceptionError> {
        match self {
            Perception::Bundle(p) => p.confirm(image).map(Some),
            Perception::Replay(r) => Ok(r.confirm(frame).map(|detections| frugal_nav::Percept {
                detections,
                ..frugal_nav::Percept::default()
            })),
        }
    }

    /// The variants run on the last frame.
    fn last_variants(&self, tracked: bool) -> Vec<&'static str> {
        match self {
            Perception::Bundle(p) => p.last_variants(),
            Perception::Replay(_) if tracked => Vec::new(),
            Perception::Replay(_) => vec![REPLAY],
        }
    }

    /// The name of the variant that confirms.
    fn reference(&self) -> Option<&'static str> {
        match self {
            Perception::Bundle(p) => {
                let b = p.bundle();
                b.variant(b.policy().reference()).map(|v| v.name)
            }
            Perception::Replay(_) => Some(REPLAY),
        }
    }
}

/// The variant name JSON lines give replayed detections.
const REPLAY: &str = "replay";

/// Dead reckoning of the distance flown and the heading from the commands.
struct Reckoner {
    odo: f64,
    yaw: f64,
    last_t: Option<f64>,
    dt_avg: Option<f64>,
}

/// Run the pilot until the input ends, the drone lands, or `stop` is raised (by
/// SIGINT / SIGTERM in the program). `report` prints one problem line (stderr in the
/// program).
pub fn run(args: &Args, stop: &AtomicBool, report: fn(&str)) -> Result<Summary, PilotError> {
    let config = match &args.config {
        Some(path) => PilotConfig::read(path)?,
        None => PilotConfig::default(),
    };
    if !(args.fps.is_finite() && args.fps > 0.0) {
        return Err(PilotError::Usage(format!(
            "--fps must be a positive number, not {}",
            args.fps
        )));
    }
    let input = Input::parse(&args.input, args.fps);
    let log = args.odometry.as_deref().map(FlightLog::read).transpose()?;
    // the bundle is checked (every graph's hash) and every variant opened before the
    // first frame
    let mut perception = match (&args.bundle, &args.detections) {
        (_, Some(path)) => Perception::Replay(replay::Replay::read(path)?),
        (Some(dir), None) => {
            let bad = |e: frugal_nav::PerceptionError| PilotError::Bundle {
                path: dir.clone(),
                message: e.to_string(),
            };
            let mut p = BundlePerception::open(dir, args.threads).map_err(bad)?;
            if let Some(b) = args.budget_ms {
                p = p.with_budget(b, args.keep_window).map_err(bad)?;
            }
            Perception::Bundle(Box::new(p))
        }
        (None, None) => {
            return Err(PilotError::Usage(
                "--bundle or --detections is required".into(),
            ));
        }
    };
    let mut link = args
        .mavlink
        .as_deref()
        .map(|a| link::Link::open(a, &config.mavlink, config.nav.yaw_rate_deg))
        .transpose()?;
    let mut out: Option<Box<dyn Write>> = match args.json.as_str() {
        "none" => None,
        "-" => Some(Box::new(std::io::stdout().lock())),
        path => Some(Box::new(std::io::BufWriter::new(
            std::fs::File::create(path).map_err(|e| PilotError::Output {
                path: path.to_owned(),
                message: e.to_string(),
            })?,
        ))),
    };
    let (w, h) = (config.camera.width, config.camera.height);
    let mut navigator = Navigator::new(
        &config.nav,
        config.signs.cell_m,
        Optics {
            width: w,
            focal_px: config.camera.focal(),
            sign_size: config.signs.size_m,
        },
    );
    // (checked when the config was read)
    if let Ok(Some(table)) = config.signs.action_table() {
        navigator = navigator.with_actions(table);
    }

    let reference = perception.reference();
    let mailbox = Arc::new(Mailbox::new(config.input.queue));
    let stats = Arc::new(InputStats::default());
    let halt = Arc::new(AtomicBool::new(false));
    let reader = Reader {
        input,
        size: (w, h),
        realtime: !args.every_frame,
        retry: config.input.clone(),
        report,
    };
    let thread = {
        let (mailbox, stats, halt) = (Arc::clone(&mailbox), Arc::clone(&stats), Arc::clone(&halt));
        std::thread::spawn(move || reader.run(&mailbox, &stats, &halt))
    };

    let started = Instant::now();
    let mut summary = Summary::default();
    let mut latencies = Vec::new();
    let mut compute_total = 0.0;
    let mut reckoner = Reckoner {
        odo: 0.0,
        yaw: 0.0,
        last_t: None,
        dt_avg: None,
    };
    let mut target_yaw = 0.0;
    let yaw_rate = config.nav.yaw_rate_deg.to_radians();
    let mut autopilot = odometry::MavOdometry::default();
    let mut waiting_reported = false;
    let mut last_read_error: Option<String> = None;
    let turn_tolerance = config.mavlink.turn_tolerance_deg.to_radians();
    let result = loop {
        if stop.load(Ordering::Relaxed) {
            summary.interrupted = true;
            break Ok(());
        }
        let Some(frame) = mailbox.take(stop) else {
            summary.interrupted = stop.load(Ordering::Relaxed);
            break Ok(());
        };
        let Some(number) = perception.number(summary.frames, frame.index, frame.time_s) else {
            summary.table_drops += 1;
            continue;
        };
        let image = FrameRef {
            width: w,
            height: h,
            rgb: frame.image.as_raw(),
        };
        let percept = match perception.perceive(image, number, frame.index) {
            Ok(p) => p,
            Err(e) => {
                break Err(PilotError::Perception {
                    frame: frame.index,
                    message: e.to_string(),
                });
            }
        };
        let variants = perception.last_variants(percept.tracked);
        let mut compute_ms = percept.compute_ms;
        // what the navigator is told besides the detections
        let mut from_autopilot = None;
        if args.mavlink_odometry
            && let Some(link) = link.as_ref()
        {
            match link.poll(&mut autopilot) {
                Ok(n) => {
                    summary.mavlink_received += n;
                    last_read_error = None;
                }
                // a failing link fails on every frame: say so once, and again when
                // the error changes or after it has cleared
                Err(e) => {
                    let message = e.to_string();
                    if last_read_error.as_deref() != Some(message.as_str()) {
                        report(&message);
                        last_read_error = Some(message);
                    }
                }
            }
            from_autopilot = autopilot.pose();
            if from_autopilot.is_none() && !waiting_reported {
                report(
                    "no LOCAL_POSITION_NED and ATTITUDE from the autopilot yet: dead reckoning until both arrive",
                );
                waiting_reported = true;
            }
        }
        let (t, odometer, yaw, pedestrian_close, source) = match (&log, from_autopilot) {
            (Some(log), _) => match log.rows.get(frame.index as usize) {
                Some(r) => (
                    r.decision_s,
                    r.odometer_m,
                    r.yaw_rad,
                    r.pedestrian_close,
                    PoseSource::Log,
                ),
                None => {
                    break Err(PilotError::Usage(format!(
                        "{}: no row for frame {}",
                        args.odometry
                            .as_deref()
                            .unwrap_or_else(|| "".as_ref())
                            .display(),
                        frame.index
                    )));
                }
            },
            (None, Some((odo, yaw))) => (
                started.elapsed().as_secs_f64(),
                odo,
                yaw,
                false,
                PoseSource::Mavlink,
            ),
            (None, None) => {
                let t = started.elapsed().as_secs_f64();
                let dt = t - reckoner.last_t.unwrap_or(t);
                if dt > 0.0 {
                    let avg = reckoner.dt_avg.map_or(dt, |a| a * 0.7 + dt * 0.3);
                    reckoner.dt_avg = Some(avg);
                    match navigator.mode() {
                        Mode::Cruise => reckoner.odo += config.nav.cruise_speed(avg) * dt,
                        Mode::Turning => {
                            let diff = wrap(target_yaw - reckoner.yaw);
                            let turn = (yaw_rate * dt).min(diff.abs());
                            reckoner.yaw = wrap(reckoner.yaw + turn * diff.signum());
                        }
                        _ => {}
                    }
                }
                reckoner.last_t = Some(t);
                (t, reckoner.odo, reckoner.yaw, false, PoseSource::Reckoned)
            }
        };
        // a real heading never lands exactly on the target: the autopilot's counts
        // within the configured tolerance
        let turn_done = navigator.mode() == Mode::Turning
            && if source == PoseSource::Mavlink {
                wrap(target_yaw - yaw).abs() <= turn_tolerance
            } else {
                reached(target_yaw, yaw)
            };
        let nav_input = NavInput {
            t,
            odometer,
            turn_done,
            pedestrian_close,
            detections: &percept.detections,
            tracked: percept.tracked,
        };
        let mut confirmed = Vec::new();
        let step = navigator.step(
            &nav_input,
            || {
                let Some(check) = perception.confirm(image, frame.index)? else {
                    return Ok(None);
                };
                compute_ms += check.compute_ms;
                confirmed.extend(reference);
                Ok::<_, frugal_nav::PerceptionError>(Some(check.detections))
            },
            &|_| None,
        );
        let step = match step {
            Ok(s) => s,
            Err(e) => {
                break Err(PilotError::Perception {
                    frame: frame.index,
                    message: e.to_string(),
                });
            }
        };
        if let Some(c @ (NavCommand::TurnLeft | NavCommand::TurnRight)) = step.command {
            target_yaw = turn_target(yaw, c == NavCommand::TurnLeft);
        }
        // out: telemetry, the command, then the JSON line
        let mut link_error = None;
        if let Some(link) = link.as_mut() {
            let usec = (frame.time_s.max(0.0) * 1e6) as u64;
            for d in percept.detections.iter().take(4) {
                let (cx, _) = d.bbox.center();
                let offset = (cx - w as f32 / 2.0) / w as f32;
                let dist = navigator.distance_of(d) as f32;
                if let Err(e) =
                    link.detection(usec, &sign_name(&navigator, d.class), offset, dist, d.score)
                {
                    link_error = Some(e);
                }
            }
            if let Some(c) = step.command
                && let Err(e) = link.command(c)
            {
                link_error = Some(e);
            }
        }
        let latency_ms = frame.arrived.elapsed().as_secs_f64() * 1e3;
        if let Some(e) = link_error {
            report(&e.to_string());
        }
        latencies.push(latency_ms);
        compute_total += compute_ms;
        summary.frames += 1;
        if let Some(c) = step.command {
            summary.commands.push((frame.index, c));
        }
        if let Some(out) = out.as_mut() {
            let boxes: Vec<_> = percept
                .detections
                .iter()
                .map(|d| {
                    let mut b = json!(frugal_nav::DetectionRecord::from(d));
                    b["sign"] = json!(sign_name(&navigator, d.class));
                    b
                })
                .collect();
            let mut line = json!({
                "frame": frame.index,
                "time_s": frame.time_s,
                "decision": if percept.tracked { "track" } else { "detect" },
                "variants": variants,
                "confirmed_by": confirmed,
                "boxes": boxes,
                "action": step.command.map(NavCommand::name),
                "mode": navigator.mode(),
                "odometry": source,
                "odometer_m": odometer,
                "yaw_deg": yaw.to_degrees(),
                "events": step.events,
                "compute_ms": compute_ms,
                "latency_ms": latency_ms,
            });
            if let Perception::Bundle(p) = &perception
                && p.budget_ms().is_some()
            {
                // the frame's number on the budget tables' clock, which periods count
                line["table_frame"] = json!(number);
            }
            if let Err(e) = writeln!(out, "{line}") {
                break Err(PilotError::Output {
                    path: args.json.clone(),
                    message: e.to_string(),
                });
            }
        }
        if navigator.mode() == Mode::Done {
            break Ok(());
        }
    };
    halt.store(true, Ordering::Relaxed);
    let _ = thread.join();
    let elapsed = started.elapsed().as_secs_f64();
    latencies.sort_by(f64::total_cmp);
    summary.decoded = stats.frames.load(Ordering::Relaxed);
    summary.drops = mailbox.drops();
    summary.corrupt = stats.corrupt.load(Ordering::Relaxed);
    summary.reconnects = stats.reconnects.load(Ordering::Relaxed);
    summary.heartbeats = link.as_ref().map_or(0, link::Link::heartbeats);
    summary.fps = if elapsed > 0.0 {
        summary.frames as f64 / elapsed
    } else {
        0.0
    };
    summary.latency_p50_ms = percentile(&latencies, 0.5);
    summary.latency_p95_ms = percentile(&latencies, 0.95);
    summary.compute_ms_mean = compute_total / summary.frames.max(1) as f64;
    summary.input_error = mailbox.error();
    if let Perception::Bundle(p) = &perception {
        summary.budget_ms = p.budget_ms();
        summary.postponed = p.postponed();
    }
    drop(link);
    if let Some(out) = out.as_mut() {
        let line = json!({ "summary": summary });
        let _ = writeln!(out, "{line}").and_then(|()| out.flush());
    }
    result.map(|()| summary)
}
