//! The navigation and MAVLink chain of `frugal-pilot` on replayed detections
//! (`--detections`) and a flight log (`--odometry`): the commands equal those of the
//! navigator flown in a closed loop over the same detections (as the simulator flies
//! it, with the same detections for its confirmations), and a MAVLink ground station (pymavlink, `mavlink_peer.py`) receives
//! HEARTBEATs and exactly those commands, in order.
use frugal_data::Sign;
use frugal_nav::heading::{reached, turn_target};
use frugal_nav::{FlightLog, LogRow, Mode, NavCommand, NavInput, Navigator, Optics};
use frugal_pilot::config::PilotConfig;
use frugal_runtime::{BBox, Detection};
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, ChildStdout, Command, Stdio};
use std::time::{Duration, Instant};

const FPS: f64 = 30.0;
/// Distance flown per frame while cruising, metres.
const STEP_M: f64 = 0.05;
/// A sign stands this far ahead when the leg begins, metres.
const SIGN_AHEAD_M: f64 = 3.0;
/// The pilot's configuration: a small camera (quick to read), fast heartbeats.
const CONFIG: &str = "[camera]\nwidth = 96\nheight = 54\n\n[mavlink]\nheartbeat_hz = 20.0\n";

fn config() -> PilotConfig {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("pilot.toml");
    std::fs::write(&path, CONFIG).unwrap();
    PilotConfig::read(&path).unwrap()
}

/// A centred sign `dist` metres ahead, as a detector would box it.
fn sign_box(sign: Sign, dist: f64, optics: &Optics) -> Detection {
    let h = (optics.focal_px * optics.sign_size / dist) as f32;
    let (cx, cy) = (optics.width as f32 / 2.0, optics.width as f32 * 9.0 / 32.0);
    Detection {
        bbox: BBox {
            x1: cx - h / 2.0,
            y1: cy - h / 2.0,
            x2: cx + h / 2.0,
            y2: cy + h / 2.0,
        },
        score: 0.9,
        class: sign.id(),
    }
}

/// A short flight flown by the navigator in a closed loop: a TURN LEFT sign ahead on
/// the first leg, a STOP sign ahead on the leg after the turn. Returns the flight log
/// (odometer, heading, the command of each frame) and the detections of each frame.
fn flight() -> (FlightLog, Vec<Vec<Detection>>) {
    let config = config();
    let optics = Optics {
        width: config.camera.width,
        focal_px: config.camera.focal(),
        sign_size: config.signs.size_m,
    };
    let mut nav = Navigator::new(&config.nav, config.signs.cell_m, optics);
    let yaw_step = config.nav.yaw_rate_deg.to_radians() / FPS;
    let (mut odo, mut yaw, mut target) = (0.0, 0.0, 0.0);
    let mut sign = (Sign::TurnLeft, SIGN_AHEAD_M);
    let mut rows = Vec::new();
    let mut frames = Vec::new();
    for frame in 0..1000u64 {
        let t = frame as f64 / FPS;
        let turn_done = nav.mode() == Mode::Turning && reached(target, yaw);
        if turn_done {
            sign = (Sign::Stop, odo + SIGN_AHEAD_M);
        }
        let dist = sign.1 - odo;
        let detections = if nav.mode() != Mode::Turning && dist > 0.3 {
            vec![sign_box(sign.0, dist, &optics)]
        } else {
            Vec::new()
        };
        let input = NavInput {
            t,
            odometer: odo,
            turn_done,
            pedestrian_close: false,
            detections: &detections,
            tracked: false,
        };
        let step = nav
            .step(
                &input,
                || Ok::<_, std::convert::Infallible>(Some(detections.clone())),
                &|_| None,
            )
            .unwrap();
        rows.push(LogRow {
            frame,
            capture_s: t,
            decision_s: t,
            odometer_m: odo,
            yaw_rad: yaw,
            pedestrian_close: false,
            command: step.command,
        });
        frames.push(detections);
        if let Some(c @ (NavCommand::TurnLeft | NavCommand::TurnRight)) = step.command {
            target = turn_target(yaw, c == NavCommand::TurnLeft);
        }
        match nav.mode() {
            Mode::Cruise => odo += STEP_M,
            Mode::Turning => {
                let diff = frugal_nav::heading::wrap(target - yaw);
                yaw = frugal_nav::heading::wrap(yaw + diff.signum() * diff.abs().min(yaw_step));
            }
            Mode::Done => break,
            _ => {}
        }
    }
    (FlightLog { rows }, frames)
}

/// The flight's footage (blank frames), detections and log written in `dir`; the
/// pilot's arguments.
fn replay_files(dir: &Path, log: &FlightLog, frames: &[Vec<Detection>]) -> Vec<String> {
    let footage = dir.join("frames");
    std::fs::create_dir_all(&footage).unwrap();
    let blank = image::RgbImage::from_pixel(96, 54, image::Rgb([120, 120, 120]));
    for i in 0..frames.len() {
        blank.save(footage.join(format!("{i:04}.png"))).unwrap();
    }
    let lines: Vec<String> = frames
        .iter()
        .enumerate()
        .filter(|(_, d)| !d.is_empty())
        .map(|(i, d)| {
            let boxes: Vec<_> = d.iter().map(frugal_nav::DetectionRecord::from).collect();
            serde_json::json!({ "frame": i, "boxes": boxes }).to_string()
        })
        .collect();
    let detections = dir.join("detections.jsonl");
    std::fs::write(&detections, lines.join("\n") + "\n").unwrap();
    let odometry = dir.join("flight.csv");
    log.write(&odometry).unwrap();
    let config = dir.join("pilot.toml");
    std::fs::write(&config, CONFIG).unwrap();
    [
        "--detections",
        detections.to_str().unwrap(),
        "--input",
        footage.to_str().unwrap(),
        "--every-frame",
        "--odometry",
        odometry.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
        "--json",
        dir.join("pilot.jsonl").to_str().unwrap(),
    ]
    .iter()
    .map(|s| (*s).to_owned())
    .collect()
}

/// The pilot's commands by frame, from its JSON lines.
fn actions(jsonl: &Path) -> Vec<(u64, String)> {
    std::fs::read_to_string(jsonl)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter_map(|v| {
            let action = v.get("action")?.as_str()?.to_owned();
            Some((v["frame"].as_u64().unwrap(), action))
        })
        .collect()
}

fn run_pilot(args: &[String]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_frugal-pilot"))
        .args(args)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{err}");
    err
}

#[test]
fn the_flight_turns_left_at_the_sign_then_lands_at_the_stop_sign() {
    let (log, frames) = flight();
    let commands = log.commands();
    let names: Vec<NavCommand> = commands.iter().map(|(_, c)| *c).collect();
    assert_eq!(names, [NavCommand::TurnLeft, NavCommand::Land]);
    // each at the navigator's distance from its sign (half a cell), within a step
    let half_cell = config().signs.cell_m / 2.0;
    let turn = &log.rows[commands[0].0 as usize];
    assert!((SIGN_AHEAD_M - turn.odometer_m - half_cell).abs() <= STEP_M + 1e-9);
    assert!(turn.yaw_rad.abs() < 1e-9);
    let land = log.rows.last().unwrap();
    assert_eq!(land.command, Some(NavCommand::Land));
    assert!((land.yaw_rad + std::f64::consts::FRAC_PI_2).abs() < 1e-9);
    assert_eq!(frames.len(), log.rows.len());
}

#[test]
fn the_pilot_issues_the_navigators_commands_on_the_same_frames() {
    let (log, frames) = flight();
    let tmp = tempfile::tempdir().unwrap();
    let args = replay_files(tmp.path(), &log, &frames);
    let err = run_pilot(&args);
    let expected: Vec<(u64, String)> = log
        .commands()
        .into_iter()
        .map(|(f, c)| (f, c.name().to_owned()))
        .collect();
    assert_eq!(actions(&tmp.path().join("pilot.jsonl")), expected, "{err}");
    let last = err.lines().last().unwrap();
    assert!(last.contains("2 commands [turn_left, land]"), "{err}");
    // the pilot stopped at the landing: every frame of the flight, none after
    assert!(
        last.contains(&format!("{} frames processed", log.rows.len())),
        "{err}"
    );
    // and its own output replays to the same commands
    let mut again = args.clone();
    let i = again.iter().position(|a| a == "--detections").unwrap();
    again[i + 1] = tmp.path().join("pilot.jsonl").display().to_string();
    let j = again.iter().position(|a| a == "--json").unwrap();
    again[j + 1] = tmp.path().join("again.jsonl").display().to_string();
    run_pilot(&again);
    assert_eq!(actions(&tmp.path().join("again.jsonl")), expected);
}

/// `mavlink_peer.py` started with `args` after its port (0: any free one); its stdout
/// after the line with the port, and the port.
fn ground_station(args: &[&str]) -> (Child, BufReader<ChildStdout>, u64) {
    let python =
        std::env::var_os("FRUGAL_PYTHON").expect("FRUGAL_PYTHON (set by cargo xtask setup)");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/mavlink_peer.py");
    let mut peer = Command::new(python)
        .arg(&script)
        .arg("0")
        .args(args)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("start {}: {e}", script.display()));
    let mut out = BufReader::new(peer.stdout.take().unwrap());
    let mut first = String::new();
    out.read_line(&mut first).unwrap();
    let port: serde_json::Value = serde_json::from_str(&first)
        .unwrap_or_else(|e| panic!("{}: {e}: {first:?}", script.display()));
    (peer, out, port["port"].as_u64().unwrap())
}

/// The rest of the ground station's output: its report.
fn station_report(mut peer: Child, mut out: BufReader<ChildStdout>) -> serde_json::Value {
    let mut report = String::new();
    std::io::Read::read_to_string(&mut out, &mut report).unwrap();
    assert!(peer.wait().unwrap().success(), "{report}");
    serde_json::from_str(&report).unwrap_or_else(|e| panic!("{e}: {report}"))
}

#[test]
fn a_mavlink_ground_station_receives_heartbeats_and_the_commands_in_order() {
    let (log, frames) = flight();
    let tmp = tempfile::tempdir().unwrap();
    let mut args = replay_files(tmp.path(), &log, &frames);
    let (peer, out, port) = ground_station(&["30"]);
    args.extend(["--mavlink".into(), format!("udpout:127.0.0.1:{port}")]);
    let started = Instant::now();
    let err = run_pilot(&args);
    let got = station_report(peer, out);
    assert!(started.elapsed() < Duration::from_secs(60));
    let report = got.to_string();
    assert_eq!(got["bad"], 0, "{report}");
    let heartbeats = got["heartbeats"].as_array().unwrap();
    assert!(!heartbeats.is_empty(), "{report}");
    // MAV_TYPE_ONBOARD_CONTROLLER 18, MAV_AUTOPILOT_INVALID 8, MAV_STATE_ACTIVE 4, from
    // system 1, component 191
    for h in heartbeats {
        assert_eq!(
            (
                &h["type"],
                &h["autopilot"],
                &h["state"],
                &h["system"],
                &h["component"]
            ),
            (&18.into(), &8.into(), &4.into(), &1.into(), &191.into()),
            "{report}"
        );
    }
    let commands = got["commands"].as_array().unwrap();
    assert_eq!(commands.len(), 2, "{report}");
    // turn left: MAV_CMD_CONDITION_YAW 90° at 90°/s, counter-clockwise, relative
    assert_eq!(commands[0]["command"], 115, "{report}");
    assert_eq!(
        commands[0]["params"],
        serde_json::json!([90.0, 90.0, -1.0, 1.0, 0.0, 0.0, 0.0])
    );
    // land here: MAV_CMD_NAV_LAND, positions NaN
    assert_eq!(commands[1]["command"], 21, "{report}");
    assert_eq!(
        commands[1]["params"],
        serde_json::json!([0.0, 0.0, 0.0, null, null, null, null])
    );
    for c in commands {
        assert_eq!(c["target"], serde_json::json!([1, 1]), "{report}");
    }
    // one DEBUG_VECT per detection the pilot saw
    let boxes: usize = frames.iter().map(Vec::len).sum();
    assert_eq!(got["debug_vect"], boxes, "{report}");
    assert_eq!(got["debug_names"], serde_json::json!(["left", "stop"]));
    let hb: u64 = err
        .lines()
        .last()
        .and_then(|l| l.split(", ").find(|p| p.contains(" heartbeats;")))
        .and_then(|p| p.split_whitespace().next()?.parse().ok())
        .unwrap();
    assert_eq!(hb, heartbeats.len() as u64, "{err}\n{report}");
}

/// The JSON lines of a pilot run.
fn lines(jsonl: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(jsonl)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .filter(|v: &serde_json::Value| v.get("frame").is_some())
        .collect()
}

/// The recorded flight's detections fed at 30 frames/s (paced, as a camera would),
/// with two seconds of empty frames after them, and the distance flown and the
/// heading taken from a simulated autopilot over MAVLink: flying at the recorded speed
/// and turning when told, it steers the pilot through the turn to the landing; an
/// autopilot that never turns leaves the pilot waiting for the turn to end.
#[test]
fn the_autopilots_position_and_heading_carry_the_flight() {
    let (log, frames) = flight();
    let speed = (STEP_M * FPS).to_string();
    let half_cell = config().signs.cell_m / 2.0;
    for turns in [true, false] {
        let tmp = tempfile::tempdir().unwrap();
        let mut args = replay_files(tmp.path(), &log, &frames);
        let blank = image::RgbImage::from_pixel(96, 54, image::Rgb([120, 120, 120]));
        for i in frames.len()..frames.len() + 60 {
            blank
                .save(tmp.path().join("frames").join(format!("{i:04}.png")))
                .unwrap();
        }
        // paced, and no flight log: the autopilot's odometry instead
        args.retain(|a| a != "--every-frame");
        let i = args.iter().position(|a| a == "--odometry").unwrap();
        args.drain(i..i + 2);
        let mode = if turns { "turn" } else { "no-turn" };
        let (peer, out, port) = ground_station(&["12", &speed, mode]);
        args.extend([
            "--mavlink".into(),
            format!("udpout:127.0.0.1:{port}"),
            "--mavlink-odometry".into(),
        ]);
        let err = run_pilot(&args);
        let got = station_report(peer, out);
        let lines = lines(&tmp.path().join("pilot.jsonl"));
        let action = |name: &str| {
            lines
                .iter()
                .find(|l| l["action"] == name)
                .unwrap_or_else(|| panic!("no {name} ({turns}): {err}"))
        };
        // the autopilot's pose from the first frames on, none dead-reckoned after
        let first = lines
            .iter()
            .position(|l| l["odometry"] == "mavlink")
            .unwrap_or_else(|| panic!("{err}"));
        assert!(first < 10, "{first}: {err}");
        assert!(lines[first..].iter().all(|l| l["odometry"] == "mavlink"));
        // the turn at the navigator's distance from the sign, read off the autopilot's
        // path (jitter not counted)
        let turn = action("turn_left");
        let odo = turn["odometer_m"].as_f64().unwrap();
        assert!(
            (odo - (SIGN_AHEAD_M - half_cell)).abs() < 0.3,
            "turned at {odo} m: {err}"
        );
        assert!(turn["yaw_deg"].as_f64().unwrap().abs() < 1.0);
        let sent: Vec<u64> = got["commands"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["command"].as_u64().unwrap())
            .collect();
        if turns {
            // the landing after the autopilot's quarter turn counter-clockwise
            let land = action("land");
            let yaw = land["yaw_deg"].as_f64().unwrap();
            assert!((yaw + 90.0).abs() <= 3.0, "landed at heading {yaw}: {err}");
            assert_eq!(sent, [115, 21], "{got}");
            let final_yaw = got["final_yaw"].as_f64().unwrap();
            assert!((final_yaw - (2.0 - std::f64::consts::FRAC_PI_2)).abs() < 1e-6);
        } else {
            // still turning when the footage ends: no landing
            assert_eq!(sent, [115], "{got}");
            assert_eq!(lines.last().unwrap()["mode"], "turning", "{err}");
        }
        assert!(got["poses_sent"].as_u64().unwrap() > 100, "{got}");
    }
}
