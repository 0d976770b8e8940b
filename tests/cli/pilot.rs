//! `frugal-pilot` on the simulator's own footage (`frugal fly --record`, every frame):
//! on the flight's odometry it issues exactly the simulator's commands on exactly the
//! same frames, first with the flight's perception replayed (ground truth, which turns
//! and lands), then through a real bundle whose detector was trained here, where every
//! frame's decision and boxes must equal what the simulator's perception returned.
use super::{frugal, maze, p};
use clap::Parser;
use frugal_nav::{FlightLog, NavCommand};
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// Fly the easy maze once at 160×90 on the host profile (ground truth at 25 fps unless
/// `perception` says otherwise), recording every frame into `rec`.
fn record(tmp: &Path, rec: &Path, perception: &[&str]) {
    let (easy, out) = (maze("easy.maze"), tmp.join("fly"));
    let mut args = super::fly::small_flight(&[
        "--maze",
        p(&easy),
        "--seeds",
        "1",
        "--record",
        p(rec),
        "--record-every",
        "1",
        "--out",
        p(&out),
    ]);
    args.extend_from_slice(perception);
    frugal(&args).expect("fly --record");
}

/// Run the pilot over the recording's frames, every frame, on its flight log, with a
/// 160×90 camera and `perception` arguments; its JSON lines go to `json`.
fn pilot(tmp: &Path, rec: &Path, json: &Path, perception: &[&str]) -> frugal_pilot::Summary {
    try_pilot(tmp, rec, p(json), perception).expect("pilot")
}

/// [`pilot`], JSON lines to `json` (a path or `none`), its error kept.
fn try_pilot(
    tmp: &Path,
    rec: &Path,
    json: &str,
    perception: &[&str],
) -> Result<frugal_pilot::Summary, frugal_pilot::PilotError> {
    let config = tmp.join("pilot.toml");
    std::fs::write(&config, "[camera]\nwidth = 160\nheight = 90\n").expect("config");
    let (frames, log) = (rec.join("frames/v0000"), rec.join("logs/flight_0.csv"));
    let mut args = vec![
        "frugal-pilot",
        "--input",
        p(&frames),
        "--every-frame",
        "--odometry",
        p(&log),
        "--config",
        p(&config),
        "--json",
        json,
    ];
    args.extend_from_slice(perception);
    let args = frugal_pilot::Args::parse_from(args);
    frugal_pilot::run(&args, &AtomicBool::new(false), |l| eprintln!("{l}"))
}

/// The simulator's commands, from the recording's flight log.
fn flown(rec: &Path) -> Vec<(u64, NavCommand)> {
    FlightLog::read(&rec.join("logs/flight_0.csv"))
        .expect("flight log")
        .commands()
}

fn lines(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .expect("json lines")
        .lines()
        .map(|l| serde_json::from_str(l).expect("json"))
        .filter(|v: &serde_json::Value| v.get("summary").is_none())
        .collect()
}

#[test]
fn on_a_recorded_flight_the_pilot_issues_the_simulators_commands_on_the_same_frames() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let rec = tmp.path().join("rec");
    record(tmp.path(), &rec, &[]);
    let flown = flown(&rec);
    // the flight turned left at the TURN LEFT sign and landed at STOP
    let names: Vec<&str> = flown.iter().map(|c| c.1.name()).collect();
    assert_eq!(names, ["turn_left", "land"], "{flown:?}");
    let percepts = rec.join("logs/percepts_0.jsonl");
    let summary = pilot(
        tmp.path(),
        &rec,
        &tmp.path().join("out.jsonl"),
        &["--detections", p(&percepts)],
    );
    assert_eq!(summary.commands, flown);
    // it stopped on the landing frame, the recording's last
    assert_eq!(Some(summary.frames - 1), flown.last().map(|c| c.0));
}

/// A detector that sees the maze's signs at 160×90 after about a minute of training:
/// wider than the tiny profile's, more frames, ten epochs at twice the default learning
/// rate (validation mAP@0.5 0.77, against 0.72 after twenty epochs at the default rate).
const SIGHTED: &str = r#"profile = "tiny"
[data]
videos_per_combo = 16
frames_per_video = 8
[detector.model]
backbone = [
  { out_channels = 16, stride = 2, convs = 1 },
  { out_channels = 32, stride = 2, convs = 1 },
  { out_channels = 32, stride = 1, convs = 1 },
]
rpn_channels = 16
roi_hidden = 64
[detector.train]
epochs = 10
lr = 0.002
train_frames = 0
val_frames = 12
batch_size = 4
threads = 2
"#;

#[test]
fn through_a_real_bundle_the_pilot_perceives_and_acts_as_the_simulator_frame_by_frame() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let run = tmp.path().join("run");
    let cfg = tmp.path().join("sighted.toml");
    std::fs::write(&cfg, SIGHTED).expect("config");
    frugal(&[
        "run",
        p(&cfg),
        "--until",
        "bundle",
        "--quiet",
        "--out",
        p(&run),
    ])
    .expect("run");
    let bundle = run.join("bundle");
    let rec = tmp.path().join("rec");
    record(
        tmp.path(),
        &rec,
        &[
            "--perception",
            "adaptive",
            "--bundle",
            p(&bundle),
            "--threads",
            "1",
            "--time-limit",
            "60",
        ],
    );
    let out = tmp.path().join("out.jsonl");
    let summary = pilot(tmp.path(), &rec, &out, &["--bundle", p(&bundle)]);
    let sim = lines(&rec.join("logs/percepts_0.jsonl"));
    let got = lines(&out);
    assert_eq!(got.len(), sim.len(), "one line per recorded frame");
    let (mut boxes, mut reads) = (0, 0);
    for (s, g) in sim.iter().zip(&got) {
        assert_eq!(g["frame"], s["frame"]);
        assert_eq!(g["decision"], s["decision"], "frame {}", s["frame"]);
        let shown: Vec<serde_json::Value> = g["boxes"]
            .as_array()
            .expect("boxes")
            .iter()
            .map(|b| serde_json::json!({"class": b["class"], "score": b["score"], "box": b["box"]}))
            .collect();
        assert_eq!(
            &serde_json::Value::from(shown),
            &s["boxes"],
            "frame {}",
            s["frame"]
        );
        // the reference variant confirmed on exactly the frames the simulator's did
        let confirmed = g["confirmed_by"].as_array().is_some_and(|c| !c.is_empty());
        assert_eq!(
            confirmed,
            s.get("confirm").is_some(),
            "frame {}",
            s["frame"]
        );
        boxes += s["boxes"].as_array().map_or(0, Vec::len);
        reads += usize::from(confirmed);
    }
    // not vacuous: the detector reported boxes and the navigator asked it to confirm
    assert!(
        boxes > 20 && reads > 0,
        "{boxes} boxes, {reads} confirmation reads"
    );
    assert_eq!(summary.commands, flown(&rec));
    eprintln!(
        "{} frames, {boxes} boxes, {reads} confirmation reads, commands {:?}",
        got.len(),
        summary.commands
    );
    let tables = flies_the_budget_tables(tmp.path(), &rec, &bundle);
    flies_the_budget_tables_in_the_maze(tmp.path(), &bundle, &tables);
    a_fallback_clock_never_overrides_the_bundles(&bundle, tables[0].0);
}

/// `BundlePerception::with_fallback_clock` (the camera's clock, for a bundle that does
/// not record its tables'): a bundle that records its clock keeps it, the paper's
/// controller keeps the caller's numbering, and an interval that is not positive is
/// refused.
fn a_fallback_clock_never_overrides_the_bundles(bundle: &Path, budget: f32) {
    let bytes = std::fs::read(bundle.join(frugal_nav::BUNDLE_FILE)).expect("bundle file");
    let parsed = frugal_runtime::Bundle::parse(&bytes).expect("bundle parses");
    let recorded = parsed
        .schedules()
        .and_then(|s| s.frame_ms())
        .expect("the bundle records its tables' frame interval");
    let open = || frugal_nav::BundlePerception::open(bundle, 1).expect("bundle opens");
    let mut flown = open()
        .with_budget(budget, 0)
        .expect("budget table")
        .with_fallback_clock(1e3 / 60.0)
        .expect("a fallback clock");
    assert_eq!(flown.table_frame_ms(), Some(f64::from(recorded)));
    // on the bundle's clock, not the fallback's: the frame at 1 s is frame 30 at 30 fps
    assert_eq!(flown.frame_number(0.0, 99), Some(0));
    let at_1s = (1e3 / f64::from(recorded)).round() as u64;
    assert_eq!(flown.frame_number(1.0, 99), Some(at_1s));
    let mut controller = open()
        .with_fallback_clock(1e3 / 60.0)
        .expect("a fallback clock");
    assert!(controller.table_clock().is_none());
    assert_eq!(controller.frame_number(1.0, 7), Some(7));
    for bad in [0.0, -1.0, f64::NAN] {
        let err = open()
            .with_budget(budget, 0)
            .expect("budget table")
            .with_fallback_clock(bad)
            .err()
            .expect("refused");
        assert!(err.to_string().contains("frame interval"), "{err}");
    }
}

/// `--budget-ms` flies each budget table the bundle ships with the budget scheduler:
/// the first frame detects; a detection frame runs one variant, one the table names; without a keeper, detections come at most the table's
/// longest period apart (a lost track brings one forward), every frame detects when
/// every action's period is 1 and some are only tracked when none is; with the keeper, a
/// periodic detection waits at most one more period. A budget the bundle does not hold
/// is refused, naming those it does. Returns each table's budget and longest period.
fn flies_the_budget_tables(tmp: &Path, rec: &Path, bundle: &Path) -> Vec<(f32, u64)> {
    let bytes = std::fs::read(bundle.join(frugal_nav::BUNDLE_FILE)).expect("bundle file");
    let parsed = frugal_runtime::Bundle::parse(&bytes).expect("bundle parses");
    let tables = parsed.schedules().expect("the bundle ships budget tables");
    assert!(tables.budget_count() > 0);
    let mut budgets = Vec::new();
    for k in 0..tables.budget_count() {
        let budget = tables.budget(k).expect("budget record").budget_ms;
        let periods: std::collections::BTreeSet<u32> = (0..tables.state_count())
            .filter_map(|s| tables.action(k, s))
            .map(|a| a.period)
            .collect();
        let longest = u64::from(*periods.last().expect("a table has actions"));
        budgets.push((budget, longest));
        for (window, most) in [("0", longest), ("30", 2 * longest)] {
            let out = tmp.join(format!("budget-{k}-{window}.jsonl"));
            let b = budget.to_string();
            let summary = pilot(
                tmp,
                rec,
                &out,
                &[
                    "--bundle",
                    p(bundle),
                    "--budget-ms",
                    &b,
                    "--keep-window",
                    window,
                ],
            );
            assert_eq!(summary.budget_ms, Some(budget));
            let got = lines(&out);
            assert!(!got.is_empty());
            // periods count frames on the tables' clock, which the bundle records
            let detected: Vec<u64> = got
                .iter()
                .filter(|l| l["decision"] == "detect")
                .map(|l| l["table_frame"].as_u64().expect("table_frame"))
                .collect();
            assert_eq!(detected.first(), got[0]["table_frame"].as_u64().as_ref());
            assert_eq!(got[0]["table_frame"], 0);
            // the clock numbers frames in order, none twice
            let numbers: Vec<u64> = got
                .iter()
                .map(|l| l["table_frame"].as_u64().expect("table_frame"))
                .collect();
            assert!(numbers.windows(2).all(|w| w[0] < w[1]), "{numbers:?}");
            // one detection per detection frame, by a variant the table names
            let named: std::collections::BTreeSet<&str> = (0..tables.state_count())
                .filter_map(|s| tables.action(k, s))
                .filter_map(|a| parsed.variant(a.variant).map(|v| v.name))
                .collect();
            for l in got.iter().filter(|l| l["decision"] == "detect") {
                let ran = l["variants"].as_array().expect("variants");
                assert_eq!(ran.len(), 1, "{budget} ms, frame {}: {ran:?}", l["frame"]);
                assert!(
                    named.contains(ran[0].as_str().expect("variant name")),
                    "{budget} ms, frame {}: {ran:?} is not in the table ({named:?})",
                    l["frame"]
                );
            }
            let last = got
                .last()
                .and_then(|l| l["table_frame"].as_u64())
                .expect("table_frame");
            for gap in detected
                .windows(2)
                .map(|d| d[1] - d[0])
                .chain([last + 1 - detected[detected.len() - 1]])
            {
                assert!(
                    gap <= most,
                    "{budget} ms, window {window}: a gap of {gap} frames, periods {periods:?}"
                );
            }
            eprintln!(
                "budget {budget} ms, keeper window {window}: periods {periods:?}, {} of {} frames detected, {} postponed",
                detected.len(),
                got.len(),
                summary.postponed
            );
            if window == "0" {
                assert_eq!(summary.postponed, 0);
                // every frame when the table says every frame; some frames only
                // tracked when no action detects every frame
                let shortest = *periods.first().expect("a table has actions");
                if longest == 1 {
                    assert_eq!(detected.len(), got.len(), "{budget} ms");
                }
                if shortest > 1 {
                    assert!(
                        detected.len() < got.len(),
                        "{budget} ms: periods {periods:?}"
                    );
                }
            }
        }
    }
    let err = try_pilot(
        tmp,
        rec,
        "none",
        &["--bundle", p(bundle), "--budget-ms", "1234.5"],
    )
    .expect_err("no such budget table")
    .to_string();
    assert!(err.contains("1234.5"), "{err}");
    for (b, _) in &budgets {
        assert!(err.contains(&format!("{b} ms")), "{err}");
    }
    budgets
}

/// `frugal fly --budget-ms` flies each budget table in the maze with the budget
/// scheduler and its keeper (the simulator's own perception, as `frugal-pilot
/// --budget-ms` on the drone): the flight names the table, the first frame detects,
/// each detection frame runs one variant, and processed frames between detections are
/// at most twice the table's longest period (the keeper postpones a periodic detection
/// by at most one period; frames the camera took while perception was busy count
/// towards the period, so processed gaps are no longer). It reports the postponed
/// detections. A budget the bundle does not hold, or one without the adaptive runtime,
/// is refused.
fn flies_the_budget_tables_in_the_maze(tmp: &Path, bundle: &Path, tables: &[(f32, u64)]) {
    for (k, &(budget, longest)) in tables.iter().enumerate() {
        let rec = tmp.join(format!("maze-rec-{k}"));
        let b = budget.to_string();
        record(
            tmp,
            &rec,
            &[
                "--perception",
                "adaptive",
                "--bundle",
                p(bundle),
                "--threads",
                "1",
                "--time-limit",
                "30",
                "--budget-ms",
                &b,
            ],
        );
        let flights = super::json(&tmp.join("fly/easy/flights.json"));
        let flight = &flights[0];
        let name = flight["perception"].as_str().expect("perception name");
        assert!(name.ends_with(&format!("-budget-{budget}ms")), "{name}");
        let counts: Vec<(String, u64)> =
            serde_json::from_value(flight["perception_counts"].clone()).expect("counts");
        assert!(
            counts.iter().any(|(n, _)| n == "postponed detections"),
            "{counts:?}"
        );
        // the 60 fps camera is flown on the tables' 30 fps clock: the frames between
        // two of its frames are dropped, and no more frames are processed than it has
        let dropped = counts
            .iter()
            .find(|(n, _)| n == "dropped camera frames")
            .map(|c| c.1);
        assert!(dropped.is_some_and(|d| d > 0), "{counts:?}");
        let (frames, time_s) = (
            flight["frames"].as_f64().expect("frames"),
            flight["time_s"].as_f64().expect("time_s"),
        );
        assert!(
            frames <= time_s * 30.0 + 1.0,
            "{frames} frames in {time_s} s on a 30 fps clock"
        );
        let got = lines(&rec.join("logs/percepts_0.jsonl"));
        assert!(got.len() > 10, "{} frames", got.len());
        assert_eq!(got[0]["decision"], "detect");
        let detected: Vec<usize> = got
            .iter()
            .enumerate()
            .filter(|(_, l)| l["decision"] == "detect")
            .map(|(i, _)| i)
            .collect();
        for gap in detected
            .windows(2)
            .map(|d| d[1] - d[0])
            .chain([got.len() - detected[detected.len() - 1]])
        {
            assert!(
                gap as u64 <= 2 * longest,
                "{budget} ms: {gap} processed frames between detections, longest period {longest}"
            );
        }
        eprintln!(
            "maze, budget {budget} ms: {} of {} processed frames detected, counts {counts:?}",
            detected.len(),
            got.len()
        );
    }
    let (easy, out) = (maze("easy.maze"), tmp.join("fly-err"));
    let fly = |extra: &[&str]| {
        let mut args = super::fly::small_flight(&["--maze", p(&easy), "--seeds", "1"]);
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--out", p(&out)]);
        frugal(&args)
    };
    let err = fly(&[
        "--perception",
        "adaptive",
        "--bundle",
        p(bundle),
        "--budget-ms",
        "1234.5",
    ])
    .expect_err("no such budget table");
    assert!(err.contains("no budget table for 1234.5 ms"), "{err}");
    assert!(err.contains(p(bundle)), "{err}");
    let err = fly(&["--budget-ms", "33"]).expect_err("budget without the adaptive runtime");
    assert!(
        err.contains("--budget-ms") && err.contains("adaptive"),
        "{err}"
    );
}
