//! `frugal run`: the whole pipeline on the tiny profile, stage skipping, config
//! checking before any work, and restarts after the process is killed mid-stage.
use super::{frugal, json, p};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const STAGES: [&str; 10] = [
    "data",
    "detector",
    "variants",
    "pareto",
    "replay",
    "policy",
    "evaluation",
    "budget",
    "bundle",
    "flights",
];

fn run_tiny(out: &Path, config: Option<&Path>) {
    let mut args = vec!["run", "--tiny", "--quiet", "--out", p(out)];
    if let Some(c) = config {
        args.push(p(c));
    }
    frugal(&args).unwrap_or_else(|e| panic!("frugal run: {e}"));
}

fn stamp(run: &Path, stage: &str) -> serde_json::Value {
    json(&run.join(stage).join(".stamp.json"))
}

/// Every file under `dir` (relative path → bytes).
fn files(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<PathBuf, Vec<u8>>) {
        for e in std::fs::read_dir(dir).unwrap().flatten() {
            let path = e.path();
            if path.is_dir() {
                walk(root, &path, out);
            } else {
                let rel = path.strip_prefix(root).unwrap().to_owned();
                out.insert(rel, std::fs::read(&path).unwrap());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

#[test]
fn the_tiny_pipeline_runs_end_to_end_skips_when_unchanged_and_reruns_downstream() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    run_tiny(&run, None);
    for stage in STAGES {
        let s = stamp(&run, stage);
        assert_eq!(s["stage"], stage);
        assert!(
            s["commands"].as_array().is_some_and(|c| !c.is_empty()),
            "{stage}: {s}"
        );
        assert!(
            !run.join(format!("{stage}.partial")).exists(),
            "{stage} left a partial folder"
        );
    }
    for f in [
        "data/dataset/manifest.json",
        "data/contact_sheet.png",
        "detector/model/best.safetensors",
        "detector/model/curves.png",
        "detector/eval-test/report.json",
        "pareto/variants.json",
        "pareto/pareto_map.png",
        "replay/replay.json",
        "policy/policy.json",
        "evaluation/eval.json",
        "evaluation/bars-f1.png",
        "evaluation/speed-f1.png",
        "budget/heldout/replay.json",
        "budget/policy.json",
        "budget/budget.json",
        "budget/margins.json",
        "budget/budget-sap.png",
        "budget/heldout-1/budget.json",
        "bundle/policy.frpb",
        "flights/comparison.json",
        "flights/easy_top_view.png",
        "flights/static/easy/flights.json",
        "flights/adaptive/easy/flights.json",
        "config/run.json",
        "config/heldout.json",
        "report.md",
        "report.html",
        "figures.json",
    ] {
        assert!(run.join(f).is_file(), "{f} missing");
    }
    frugal(&["bundle", "verify", p(&run.join("bundle"))]).unwrap();
    let md = std::fs::read_to_string(run.join("report.md")).unwrap();
    for needle in [
        "## Headline figures",
        "frugal train --data",
        "frugal policy eval",
        "frugal policy budget",
        "## 6. Budget policies, by streaming AP",
        "budget/heldout-1/budget-sap.png",
        "frugal fly",
        "![contact sheet](data/contact_sheet.png)",
        "![Pareto front, mAP](pareto/pareto_map.png)",
        "flights/easy_top_view.png",
        "| easy | adaptive (bundle) |",
    ] {
        assert!(md.contains(needle), "report.md lacks {needle:?}");
    }
    // the bundle ships the budget tables (section 6) beside the paper's MDP table
    let inspect = frugal_policies::bundle::inspect(&run.join("bundle")).unwrap();
    assert!(inspect.contains("schedules: 3 budget tables"), "{inspect}");
    // every strategy streamed at every budget on the held-out videos, and the figures
    // a document may quote
    let held = json(&run.join("budget/heldout-1/budget.json"));
    for strategy in [
        "static",
        "static+tracker",
        "random+tracker",
        "approxdet",
        "mdp+tracker",
        "budget",
        "oracle",
        "hindsight",
    ] {
        let rows = held
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["strategy"] == strategy && r["scenario"] == "all")
            .count();
        assert_eq!(rows, 3, "{strategy}: one overall row per budget");
    }
    // the tables scored as they are, with the tracker cost they were made with: the
    // stage's own figures, strategy by strategy, on the same test and held-out videos
    let kept = tmp.path().join("kept");
    let (replay, evaluation, held_log) = (
        run.join("replay/replay.json"),
        run.join("config/evaluation.json"),
        run.join("budget/heldout/replay.json"),
    );
    let keep_args = |log: &Path, policy: &Path, extra: &[&str]| -> Result<(), String> {
        let mut args = vec![
            "policy",
            "budget",
            "--keep-tables",
            "--log",
            p(log),
            "--policy",
            p(policy),
            "--out",
            p(&kept),
            "--eval-config",
            p(&evaluation),
            "--heldout",
            p(&held_log),
        ];
        args.extend_from_slice(extra);
        frugal(&args)
    };
    keep_args(&replay, &run.join("budget/policy.json"), &[]).unwrap();
    for (stage, again) in [
        ("budget/budget.json", "budget.json"),
        ("budget/heldout-1/budget.json", "heldout-1/budget.json"),
    ] {
        let (a, b) = (json(&run.join(stage)), json(&kept.join(again)));
        let (a, b) = (a.as_array().unwrap(), b.as_array().unwrap());
        assert_eq!(a.len(), b.len(), "{stage}");
        for (x, y) in a.iter().zip(b) {
            for key in ["budget_ms", "scenario", "strategy", "detections", "timing"] {
                assert_eq!(x[key], y[key], "{stage}: {key}");
            }
            let (sx, sy) = (x["sap50"].as_f64().unwrap(), y["sap50"].as_f64().unwrap());
            assert!((sx - sy).abs() < 1e-12, "{stage}: {x} vs {y}");
        }
    }
    // settings that would change the tables, and a policy without tables, are refused
    let e = keep_args(
        &replay,
        &run.join("budget/policy.json"),
        &["--config", p(&run.join("config/budget.json"))],
    )
    .unwrap_err();
    assert!(
        e.contains("--keep-tables") && e.contains("policy.json"),
        "{e}"
    );
    // a policy made before the tracker cost was kept has it measured on the log's
    // training videos, and is refused when the log has none
    let mut old = json(&run.join("budget/policy.json"));
    old["budget"]
        .as_object_mut()
        .unwrap()
        .remove("tracker_cost")
        .unwrap();
    let old_path = tmp.path().join("old-policy.json");
    std::fs::write(&old_path, serde_json::to_vec(&old).unwrap()).unwrap();
    keep_args(&replay, &old_path, &[]).unwrap();
    let e = keep_args(&held_log, &old_path, &[]).unwrap_err();
    assert!(
        e.contains("old-policy.json") && e.contains("no training videos"),
        "{e}"
    );
    let e = keep_args(&replay, &run.join("policy/policy.json"), &[]).unwrap_err();
    assert!(
        e.contains("policy/policy.json") && e.contains("holds no budget tables"),
        "{e}"
    );
    // the tables learnt again with the tracker cost the stage's were made with, not
    // timed again: the stage's very tables, and its figures
    let again = tmp.path().join("again");
    let (base, config, tuning) = (
        run.join("policy/policy.json"),
        run.join("config/budget.json"),
        run.join("budget/tuning/replay.json"),
    );
    let relearn = |from: &Path, extra: &[&str]| -> Result<(), String> {
        let mut args = vec![
            "policy",
            "budget",
            "--log",
            p(&replay),
            "--policy",
            p(&base),
            "--out",
            p(&again),
            "--config",
            p(&config),
            "--eval-config",
            p(&evaluation),
            "--heldout",
            p(&held_log),
            "--tune",
            p(&tuning),
            "--tracker-from",
            p(from),
        ];
        args.extend_from_slice(extra);
        frugal(&args)
    };
    relearn(&run.join("budget/policy.json"), &[]).unwrap();
    assert_eq!(
        json(&again.join("policy.json"))["budget"],
        json(&run.join("budget/policy.json"))["budget"],
        "the tables learnt with the stage's tracker cost"
    );
    for file in ["margins.json", "heldout-1/margins.json", "budget.json"] {
        assert_eq!(
            json(&again.join(file)),
            json(&run.join("budget").join(file)),
            "{file}"
        );
    }
    // a policy without budget tables has no tracker cost to give; --keep-tables
    // learns nothing, so takes none
    let e = relearn(&run.join("policy/policy.json"), &[]).unwrap_err();
    assert!(
        e.contains("policy/policy.json") && e.contains("no tracker cost"),
        "{e}"
    );
    let e = keep_args(
        &replay,
        &run.join("budget/policy.json"),
        &["--tracker-from", p(&run.join("budget/policy.json"))],
    )
    .unwrap_err();
    assert!(e.contains("--tracker-from"), "{e}");
    let figures = json(&run.join("figures.json"));
    for key in [
        "detector.map",
        "front.map",
        "replay.mdp+tracker.speedup",
        "budget.heldout.33.margin",
        "budget.heldout.33.margin_lo",
        "budget.test.8.margin_hi",
        "flights.easy.fps_ratio",
        "time.total.min",
    ] {
        assert!(
            figures[key].is_string(),
            "figures.json lacks {key}: {figures}"
        );
    }
    let html = std::fs::read_to_string(run.join("report.html")).unwrap();
    assert!(html.contains("<table>") && html.contains("src=\"data/contact_sheet.png\""));
    let cmp = json(&run.join("flights/comparison.json"));
    assert_eq!(cmp[0]["maze"], "easy");
    assert_eq!(cmp[0]["static"]["runs"], 1);
    assert_eq!(cmp[0]["adaptive"]["runs"], 1);
    // the adaptive flight says what its runtime ran: frames detected by the
    // controller's trigger (the first frame by `Start`), confirmations, and runs per
    // variant, which cover every detection and confirmation
    let flight = &json(&run.join("flights/adaptive/easy/flights.json"))[0];
    // both sides fly the budget stage's device, int8 and tracker speeds included
    let device = &json(&run.join("budget/policy.json"))["budget"]["config"];
    for side in ["static", "adaptive"] {
        let f = &json(&run.join(format!("flights/{side}/easy/flights.json")))[0];
        for key in ["slowdown", "slowdown_int8", "slowdown_tracker"] {
            let (a, b) = (f["device"][key].as_f64(), device[key].as_f64());
            assert!(
                a.is_some() && a == b,
                "{side} flight's {key} {a:?}, the budget stage's {b:?}"
            );
        }
    }
    // the Pareto stage drew its fronts on the same device: the slowdowns it scaled the
    // variants by are the budget stage's, fp32 and int8
    let pareto = json(&run.join("pareto/pareto.json"));
    for (i, key) in ["slowdown", "slowdown_int8"].into_iter().enumerate() {
        let (a, b) = (pareto["slowdowns"][i].as_f64(), device[key].as_f64());
        assert!(
            matches!((a, b), (Some(a), Some(b)) if (a - b).abs() < 1e-9 * b),
            "the Pareto stage's {key} {a:?}, the budget stage's {b:?}"
        );
    }
    // the tracker is on the device by its own anchor: the reference tracker, timed
    // between its calls and put on the device with them, takes the profile's time
    let budget = &json(&run.join("budget/policy.json"))["budget"];
    let (r, s, d) = (
        budget["tracker_cost"]["reference_ms"].as_f64(),
        budget["config"]["slowdown"].as_f64(),
        budget["config"]["device_tracker_reference_ms"].as_f64(),
    );
    assert!(
        budget["config"]["slowdown_tracker"].as_f64().is_some(),
        "{budget}"
    );
    let (r, s, d) = (
        r.expect("reference_ms"),
        s.expect("slowdown"),
        d.expect("anchor"),
    );
    assert!((r * s - d).abs() < 1e-6 * d, "{r} × {s} against {d}");
    // and each reports its int8 detectors' time as such: the static variant's whole
    // compute when it is int8 (none when fp32), the adaptive side's when one ran (the
    // tiny run's variants may all be fp32; the sim test
    // `int8_compute_is_charged_by_the_devices_int8_slowdown` covers int8 time)
    let int8: Vec<String> = json(&run.join("pareto/variants.json"))["variants"]
        .as_array()
        .expect("variants")
        .iter()
        .filter(|v| v["precision"] == "int8")
        .map(|v| v["name"].as_str().unwrap().to_string())
        .collect();
    // the bundle marks every variant's precision as the Pareto stage recorded it
    let bytes = std::fs::read(run.join("bundle").join(frugal_nav::BUNDLE_FILE)).expect("bundle");
    let bundle = frugal_runtime::Bundle::parse(&bytes).expect("bundle parses");
    let marked: Vec<bool> = bundle
        .variants()
        .map(|(_, v)| int8.iter().any(|n| n == v.name))
        .collect();
    assert_eq!(frugal_nav::bundle::int8_variants(&bundle), Some(marked));
    let st = &json(&run.join("flights/static/easy/flights.json"))[0];
    let name = st["perception"]
        .as_str()
        .unwrap()
        .trim_start_matches("static-");
    let (compute, in_int8) = (st["compute_ms_mean"].as_f64(), st["int8_ms_mean"].as_f64());
    if int8.iter().any(|v| v == name) {
        assert!(compute > Some(0.0) && in_int8 == compute, "{name}: {st}");
    } else {
        assert_eq!(in_int8, Some(0.0), "{name}: {st}");
    }
    // a static detector spends nothing outside it; the adaptive runtime tracks (and
    // builds pyramids) between its detections, so part of its compute is the tracker's
    assert_eq!(st["tracker_ms_mean"].as_f64(), Some(0.0), "{st}");
    let in_tracker = flight["tracker_ms_mean"].as_f64().expect("tracker_ms_mean");
    assert!(
        in_tracker > 0.0
            && in_tracker + flight["int8_ms_mean"].as_f64().unwrap()
                <= flight["compute_ms_mean"].as_f64().unwrap() + 1e-9,
        "{flight}"
    );
    let counts: BTreeMap<String, u64> = flight["perception_counts"]
        .as_array()
        .expect("perception_counts")
        .iter()
        .map(|c| (c[0].as_str().unwrap().to_string(), c[1].as_u64().unwrap()))
        .collect();
    assert_eq!(counts["frames detected: Start"], 1, "{counts:?}");
    let int8_runs: u64 = int8
        .iter()
        .filter_map(|v| counts.get(&format!("runs of {v}")))
        .sum();
    let in_int8 = flight["int8_ms_mean"].as_f64().expect("int8_ms_mean");
    assert_eq!(int8_runs > 0, in_int8 > 0.0, "{in_int8} ms, {counts:?}");
    assert!(
        in_int8 <= flight["compute_ms_mean"].as_f64().unwrap(),
        "{flight}"
    );
    let sum = |prefix: &str| -> u64 {
        counts
            .iter()
            .filter(|(k, _)| k.starts_with(prefix))
            .map(|(_, n)| n)
            .sum()
    };
    let detected = sum("frames detected: ");
    assert!(
        detected >= 1 && detected <= flight["frames"].as_u64().unwrap(),
        "{counts:?}"
    );
    assert_eq!(
        counts["confirmations"],
        flight["confirmations"].as_u64().unwrap()
    );
    assert!(
        sum("runs of ") >= detected + counts["confirmations"],
        "{counts:?}"
    );

    // nothing changed: every stage is skipped and no artifact is touched
    let before = files(&run);
    run_tiny(&run, None);
    let after = files(&run);
    let changed: Vec<&PathBuf> = before
        .keys()
        .filter(|k| !k.starts_with("report.md") && !k.starts_with("report.html"))
        .filter(|k| before.get(*k) != after.get(*k))
        .collect();
    assert!(changed.is_empty(), "a skipped run changed {changed:?}");

    // a new α changes the policy and what depends on it, nothing upstream
    let cfg = tmp.path().join("alpha.toml");
    std::fs::write(&cfg, "profile = \"tiny\"\n[policy]\nalpha = 2.5\n").unwrap();
    let old: Vec<serde_json::Value> = STAGES.iter().map(|s| stamp(&run, s)).collect();
    run_tiny(&run, Some(&cfg));
    for (stage, old) in STAGES.iter().zip(&old) {
        let new = stamp(&run, stage);
        let same = new == *old;
        let upstream = ["data", "detector", "variants", "pareto", "replay"].contains(stage);
        assert_eq!(same, upstream, "{stage}: unchanged = {same}");
    }
    assert_eq!(
        json(&run.join("policy/policy.json"))["config"]["alpha"],
        2.5
    );

    // flight footage from a training maze: the replay records and replays it, and the
    // policy learns from its one video too
    let videos = |run: &Path| {
        json(&run.join("policy/policy.json"))["training_videos"]
            .as_array()
            .map_or(0, Vec::len)
    };
    let before = videos(&run);
    let cfg = tmp.path().join("footage.toml");
    std::fs::write(
        &cfg,
        "profile = \"tiny\"\n[policy]\nalpha = 2.5\n[replay.footage]\nmazes = [\"train-a\"]\nseeds = 1\nevery = 40\n",
    )
    .unwrap();
    run_tiny(&run, Some(&cfg));
    let log = json(&run.join("replay/footage.json"));
    assert_eq!(log["videos"].as_array().map(Vec::len), Some(1));
    assert_eq!(videos(&run), before + 1);
    let commands = stamp(&run, "policy")["commands"].to_string();
    assert!(commands.contains("--extra-log"), "{commands}");
}

#[test]
fn a_bad_config_is_refused_before_anything_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    for (text, needles) in [
        (
            "[detector.train]\nepochz = 3\n",
            &["detector.train.epochz", "epochs"][..],
        ),
        (
            "[pareto]\nthreshold = 1.5\n",
            &["pareto.threshold", "1.5"][..],
        ),
        (
            "[flights]\nmazes = [\"missing.maze\"]\n",
            &["flights.mazes", "missing.maze", "easy, medium, hard"][..],
        ),
        (
            "profile = \"huge\"\n",
            &["huge", "default, quick, tiny"][..],
        ),
    ] {
        let cfg = tmp.path().join("bad.toml");
        std::fs::write(&cfg, text).unwrap();
        let e = frugal(&["run", "--quiet", "--out", p(&run), p(&cfg)]).unwrap_err();
        assert!(e.contains("bad.toml"), "{e}");
        for n in needles {
            assert!(e.contains(n), "{text:?}: {e} lacks {n}");
        }
        assert!(!run.exists(), "{text:?}: the run folder was created");
    }
    let e = frugal(&["run", "--quiet", "--out", p(&run), "/nonexistent/run.toml"]).unwrap_err();
    assert!(e.contains("/nonexistent/run.toml"), "{e}");
    let e = frugal(&["run", "--quiet", "--out", p(&run), "--device", "tpu"]).unwrap_err();
    assert!(e.contains("tpu") && e.contains("cuda"), "{e}");
    assert!(!run.exists());
}

/// The child process of the kill test: a tiny run into `FRUGAL_KILL_CHILD_DIR`.
#[test]
#[ignore = "the kill test runs this in a child process"]
fn kill_child() {
    if let Ok(dir) = std::env::var("FRUGAL_KILL_CHILD_DIR") {
        run_tiny(Path::new(&dir), None);
    }
}

/// Start the child run, wait until `ready` holds for the run folder, then SIGKILL it.
/// Returns whether the kill landed before the child finished by itself.
fn kill_when(run: &Path, ready: impl Fn(&Path) -> bool) -> bool {
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args([
            "run::kill_child",
            "--exact",
            "--ignored",
            "--test-threads=1",
        ])
        .env("FRUGAL_KILL_CHILD_DIR", run)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            assert!(status.success(), "the child run failed: {status}");
            return false;
        }
        if ready(run) {
            child.kill().unwrap();
            child.wait().unwrap();
            return true;
        }
        assert!(t0.elapsed() < Duration::from_secs(600), "child run hung");
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn a_run_killed_at_several_points_finishes_with_the_same_artifacts() {
    let tmp = tempfile::tempdir().unwrap();
    // the reference runs in a child process too: torch's random generator is global,
    // and other tests in this process train at the same time
    let reference = tmp.path().join("reference");
    assert!(!kill_when(&reference, |_| false));
    let run = tmp.path().join("killed");
    // each kill lands in a different stage: during training (after the first epoch's
    // checkpoint), while variants are written, during replay, during the flights
    type Ready = fn(&Path) -> bool;
    let points: [(&str, Ready); 4] = [
        ("training", |r| {
            r.join("detector.partial/model/checkpoint/state.json")
                .exists()
        }),
        ("compression", |r| r.join("variants.partial/base").exists()),
        ("replay", |r| r.join("replay.partial").exists()),
        ("flights", |r| r.join("flights.partial/static").exists()),
    ];
    let mut landed = Vec::new();
    let mut data_stamp = None;
    for (name, ready) in points {
        if kill_when(&run, ready) {
            landed.push(name);
        }
        // a stage completed before a kill is never redone
        if let Ok(s) = std::fs::read(run.join("data/.stamp.json")) {
            let first = data_stamp.get_or_insert_with(|| s.clone());
            assert_eq!(*first, s, "the data stage ran again after a kill");
        }
    }
    assert!(
        landed.len() >= 3,
        "only the kills during {landed:?} landed before the child finished"
    );
    assert!(
        !kill_when(&run, |_| false),
        "the last start runs to the end"
    );

    // no half-written stage is left, and every artifact of the reference exists
    let (want, got) = (files(&reference), files(&run));
    // (which variants the bundle carries depends on measured latencies)
    let names = |m: &BTreeMap<PathBuf, Vec<u8>>| {
        m.keys()
            .filter(|k| !k.starts_with("bundle/onnx"))
            .cloned()
            .collect::<std::collections::BTreeSet<_>>()
    };
    let (w, g) = (names(&want), names(&got));
    let only: Vec<_> = w.symmetric_difference(&g).collect();
    assert!(only.is_empty(), "artifact sets differ in {only:?}");
    assert!(got.keys().any(|k| k.starts_with("bundle/onnx")));
    for e in std::fs::read_dir(&run).unwrap().flatten() {
        let n = e.file_name().to_string_lossy().into_owned();
        assert!(
            !n.ends_with(".partial") && !n.ends_with(".old"),
            "{n} left behind"
        );
    }
    // the deterministic outputs (the dataset, the trained weights, the compressed
    // models) are identical bytes; logs, curves and later stages hold timings
    let deterministic = |k: &PathBuf| {
        k.starts_with("data/dataset")
            || ((k.starts_with("detector") || k.starts_with("variants"))
                && k.extension()
                    .is_some_and(|e| e == "safetensors" || e == "onnx"))
    };
    let compared: Vec<&PathBuf> = want.keys().filter(|k| deterministic(k)).collect();
    assert!(compared.len() > 20, "{compared:?}");
    for k in compared {
        assert!(want[k] == got[k], "{} differs after the kills", k.display());
    }
    frugal(&["bundle", "verify", p(&run.join("bundle"))]).unwrap();
}
