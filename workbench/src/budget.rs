//! `frugal policy budget`: learn the budget + content policy and stream every budget
//! strategy on a simulated clock (crate `frugal-policies`, modules `budget`,
//! `budget_eval`, `stream`).

use anyhow::Context;
use frugal_data::{Dataset, Split};
use frugal_policies::budget::{BudgetConfig, train_budget};
use frugal_policies::budget_eval::{
    RESAMPLES, TuneSet, add_intervals, budget_csv, budget_margins, budget_scores, budget_table,
    plot_budget, search_tables, stream_all, stream_steps,
};
use frugal_policies::eval::{EvalConfig, Strategy, run_all};
use frugal_policies::replay::{DatasetFrames, VideoLog};
use frugal_policies::{ReplayLog, TrainedPolicy};
use std::path::{Path, PathBuf};

/// `log` with the policy's (calibrated) buckets, so that a log recorded elsewhere
/// reports and buckets scores exactly as the policy was trained to.
fn with_policy_buckets(log: &ReplayLog, policy: &TrainedPolicy) -> ReplayLog {
    let mut log = log.clone();
    log.families = policy.families.clone();
    for (v, p) in log.variants.iter_mut().zip(&policy.variants) {
        v.family = p.family;
    }
    log
}

/// Score `log`'s test videos (frames from `frames`, the dataset at `data`) and write
/// `budget.json|csv|md`, `margins.json` (with each margin's interval over the videos)
/// and the plots into `out`; the table, as `budget.md` holds it.
fn score_log(
    log: &ReplayLog,
    data: &Path,
    frames: &DatasetFrames,
    policy: &TrainedPolicy,
    cost: frugal_policies::eval::TrackerCost,
    eval: &EvalConfig,
    out: &Path,
) -> anyhow::Result<String> {
    let pol = policy
        .budget
        .as_ref()
        .context("the policy has no budget tables")?;
    if log.variants.iter().map(|v| &v.name).ne(pol.variants.iter()) {
        anyhow::bail!(
            "{}: its variants are not the budget policy's ({})",
            data.display(),
            pol.variants.join(", ")
        );
    }
    let mut log = with_policy_buckets(log, policy);
    pol.config.put_on_device(&mut log);
    let log = &log;
    let videos: Vec<&VideoLog> = log.split(Split::Test).collect();
    if videos.is_empty() {
        anyhow::bail!("{}: the log has no test videos", data.display());
    }
    let bundle = frugal_policies::bundle::policy_bundle(policy, eval.thresholds())?;
    let n = videos.len() * stream_steps(pol);
    let pb = crate::features::bar(false, n, "streaming");
    let runs = stream_all(log, &videos, frames, cost, pol, &bundle, 0.5, &|| pb.inc(1))?;
    pb.finish_and_clear();
    let scores = budget_scores(log, &videos, pol, &runs, 0.5);
    let mut margins = budget_margins(&scores);
    add_intervals(&mut margins, log, &videos, pol, &runs, RESAMPLES);
    let table = budget_table(&scores, &margins);
    std::fs::create_dir_all(out)?;
    frugal_data::dataset::write_json_atomic(&out.join("budget.json"), &scores)?;
    frugal_data::dataset::write_atomic(&out.join("budget.csv"), budget_csv(&scores).as_bytes())?;
    frugal_data::dataset::write_atomic(&out.join("budget.md"), table.as_bytes())?;
    frugal_data::dataset::write_json_atomic(&out.join("margins.json"), &margins)?;
    plot_budget(&out.join("budget"), &scores)?;
    Ok(table)
}

/// The files `frugal policy budget` reads and writes.
pub struct Files<'a> {
    /// The replay log (training videos teach, test videos score).
    pub log: &'a Path,
    /// The paper policy to attach the budget tables to.
    pub policy: &'a Path,
    /// Output folder.
    pub out: &'a Path,
    /// The log's dataset folder, when not the one it records.
    pub data: Option<&'a Path>,
    /// Budget settings.
    pub config: Option<&'a Path>,
    /// Held-out replay logs, scored.
    pub heldout: &'a [PathBuf],
    /// Tuning replay logs, the tables chosen on them.
    pub tune: &'a [PathBuf],
    /// Score the budget tables `policy` already holds as they are: no learning, no
    /// search, the tracker's cost model the tables were made with.
    pub keep_tables: bool,
    /// Learn the tables with the tracker's cost model the budget tables of this
    /// policy were made with, on the device as they charged it, rather than timing the
    /// tracker again.
    pub tracker_from: Option<&'a Path>,
}

/// Run `frugal policy budget`.
pub fn run(files: &Files<'_>, eval: &EvalConfig) -> anyhow::Result<()> {
    let Files {
        log: log_path,
        policy: policy_path,
        out,
        data,
        config,
        heldout,
        tune,
        keep_tables,
        tracker_from,
    } = *files;
    let log = ReplayLog::load(log_path)?;
    let mut policy = TrainedPolicy::load(policy_path)?;
    let root = data
        .map(Path::to_path_buf)
        .unwrap_or_else(|| log.dataset.clone());
    if keep_tables {
        if config.is_some() || !tune.is_empty() || tracker_from.is_some() {
            anyhow::bail!(
                "--keep-tables scores the tables {} holds as they are: --config, --tune and --tracker-from do not apply",
                policy_path.display()
            );
        }
        let stored = policy
            .budget
            .as_ref()
            .with_context(|| {
                format!(
                    "{}: holds no budget tables (`frugal policy budget` without --keep-tables writes them)",
                    policy_path.display()
                )
            })?
            .tracker_cost;
        let ds = Dataset::load(&root)?;
        let frames = DatasetFrames::new(&ds);
        let cost = match stored {
            Some(c) => {
                println!(
                    "tracker cost the tables were made with (device ms over the slowdown): pyramid {:.3} ms, track {:.3} ms/object, init {:.3} ms/object",
                    c.pyramid_ms, c.track_ms, c.init_ms
                );
                c
            }
            None => {
                let train: Vec<&VideoLog> = log.split(Split::Train).collect();
                if train.is_empty() {
                    anyhow::bail!(
                        "{}: keeps no tracker cost, and {} has no training videos to measure it on",
                        policy_path.display(),
                        log_path.display()
                    );
                }
                tracker_cost(&log, &policy, &train, &frames, eval)?
            }
        };
        return score_all(&log, &root, &frames, &policy, cost, eval, out, heldout);
    }
    let mut cfg: BudgetConfig = match config {
        Some(p) => frugal_policies::error::read_toml_or_json(p)?,
        None => BudgetConfig::default(),
    };
    cfg.check(config.unwrap_or(Path::new("<defaults>")))?;
    // the device's latencies: the measured ones scaled by the device's speed over this
    // machine's, as the reference detector timed with the variants tells
    let slowdown = cfg.device_slowdown(log.reference_ms);
    match (cfg.device_reference_ms, log.reference_ms) {
        (Some(d), Some(h)) => println!(
            "device {}: the reference detector takes {d:.1} ms there and took {h:.2} ms on the machine that timed the variants: slowdown {slowdown:.3}",
            cfg.device
        ),
        _ => println!(
            "device {}: slowdown {slowdown} as configured ({} records no reference timing)",
            cfg.device,
            log_path.display()
        ),
    }
    cfg.slowdown = slowdown;
    cfg.slowdown_int8 = cfg.device_slowdown_int8(log.reference_int8_ms);
    if cfg.device_reference_ms != Some(frugal_policies::budget::TX2_LIKE_REFERENCE_MS) {
        for (field, value, tx2, what) in [
            (
                "device_reference_int8_ms",
                cfg.device_reference_int8_ms,
                frugal_policies::budget::TX2_LIKE_REFERENCE_INT8_MS,
                "int8",
            ),
            (
                "device_tracker_reference_ms",
                cfg.device_tracker_reference_ms,
                frugal_policies::budget::TX2_LIKE_TRACKER_REFERENCE_MS,
                "tracker",
            ),
        ] {
            if value == Some(tx2) {
                eprintln!(
                    "warning: {}: device_reference_ms is not the tx2-like profile's but {field} is ({tx2} ms); state the device's {what} speed too",
                    config.unwrap_or(Path::new("<defaults>")).display(),
                );
            }
        }
    }
    print_anchor(
        &cfg.device,
        [
            cfg.slowdown_int8,
            cfg.device_reference_int8_ms,
            log.reference_int8_ms,
        ],
        [
            "int8 reference detector",
            "on the machine that timed the variants",
            "int8 variants",
            "int8",
        ],
        &format!("{} records no int8 reference timing", log_path.display()),
    );
    // the log with every variant's latency on the device's anchor (the one scored
    // below is put there by `score_log`)
    let mut on_device = log.clone();
    cfg.put_on_device(&mut on_device);
    let ds = Dataset::load(&root)?;
    let frames = DatasetFrames::new(&ds);
    let train: Vec<&VideoLog> = on_device.split(Split::Train).collect();
    if train.is_empty() {
        anyhow::bail!("{}: the log has no training videos", log_path.display());
    }
    let cost = match tracker_from {
        Some(from) => {
            let (cost, slowdown_tracker) = stored_tracker_cost(from, cfg.slowdown)?;
            cfg.slowdown_tracker = slowdown_tracker;
            println!(
                "tracker cost from {} (its tables' own, not timed again)",
                from.display()
            );
            cost
        }
        None => {
            let timed = tracker_cost(&on_device, &policy, &train, &frames, eval)?;
            cfg.slowdown_tracker = cfg.device_slowdown_tracker(timed.reference_ms);
            print_anchor(
                &cfg.device,
                [
                    cfg.slowdown_tracker,
                    cfg.device_tracker_reference_ms,
                    timed.reference_ms,
                ],
                [
                    "reference tracker",
                    "between the tracker's calls",
                    "the tracker",
                    "tracker",
                ],
                "no reference tracker timing",
            );
            cfg.tracker_on_device(timed)
        }
    };
    println!(
        "tracker on the device: pyramid {:.2} ms, track {:.2} ms/object, init {:.2} ms/object",
        cost.pyramid_ms * cfg.slowdown,
        cost.track_ms * cfg.slowdown,
        cost.init_ms * cfg.slowdown
    );
    let pol = train_budget(&on_device, &frames, cost, &cfg, 0.5)?;
    for p in &pol.policies {
        println!(
            "budget {} ms ({} ×{:.3}): λ {:.3}, expected {:.2} ms/frame (P95 over videos {:.2}), training F1/frame {:.3}",
            p.budget_ms, cfg.device, cfg.slowdown, p.lambda, p.expected_ms, p.p95_ms, p.train_f1
        );
    }
    policy.budget = Some(pol);
    // the tables are chosen on the training videos and every tuning log's videos
    let tune_logs: Vec<(ReplayLog, Dataset)> = tune
        .iter()
        .map(|p| {
            let mut l = with_policy_buckets(&ReplayLog::load(p)?, &policy);
            cfg.put_on_device(&mut l);
            let ds = Dataset::load(&l.dataset)
                .with_context(|| format!("{}: its dataset", p.display()))?;
            Ok((l, ds))
        })
        .collect::<anyhow::Result<_>>()?;
    let tune_frames: Vec<DatasetFrames> = tune_logs
        .iter()
        .map(|(_, ds)| DatasetFrames::new(ds))
        .collect();
    let mut sets = vec![TuneSet {
        log: &on_device,
        frames: &frames,
        videos: train.clone(),
    }];
    for ((l, _), f) in tune_logs.iter().zip(&tune_frames) {
        sets.push(TuneSet {
            log: l,
            frames: f,
            videos: l.videos.iter().collect(),
        });
    }
    let pb = crate::features::counter(false, "tables streamed on the tuning videos");
    let traces = search_tables(&sets, cost, &mut policy, eval.thresholds(), 0.5, &|| {
        pb.inc(1)
    })?;
    pb.finish_and_clear();
    let tuning_videos: usize = sets.iter().map(|s| s.videos.len()).sum();
    if tuning_videos < frugal_policies::budget_eval::MIN_TUNING_VIDEOS {
        eprintln!(
            "note: {tuning_videos} tuning video(s), fewer than the {} a move needs, so the \
             search keeps each table's start and makes no move (a move must hold on both \
             halves of the tuning videos); more training videos let it refine the tables",
            frugal_policies::budget_eval::MIN_TUNING_VIDEOS
        );
    }
    for (b, t) in cfg.budgets_ms.iter().zip(&traces) {
        println!(
            "budget {b} ms on the tuning clock ({} videos): learnt table sAP@0.5 {:.1}, best fixed schedule {:.1}, best untracked schedule (static) {:.1}, hindsight bound {:.1}; started from {}, {} move(s) made over {} tables in {} sweep(s) (at most {}){}: {:.1} (halves {:.1} / {:.1}), {:.2} device ms/frame",
            tuning_videos,
            100.0 * t.learnt_sap50,
            100.0 * t.best_fixed_sap50,
            100.0 * t.best_static_sap50,
            100.0 * t.hindsight_sap50,
            t.start,
            t.changes,
            t.tables,
            t.sweeps,
            cfg.search_rounds,
            t.gain_low.map_or(String::new(), |low| {
                let guard_kept = !t.kept_start || t.crossfit.is_some();
                let (verdict, then) = if guard_kept {
                    ("kept", "")
                } else {
                    ("not kept", ", so the start stays")
                };
                let across = t.crossfit.as_ref().map_or(String::new(), |c| {
                    let (verdict, then) = if c.holds() {
                        ("hold", "")
                    } else {
                        ("do not hold", ", so the start stays")
                    };
                    format!(
                        "; across halves they {verdict}: searched on one half, {:+.1} / {:+.1} points on the other{then}",
                        100.0 * c.gains[0],
                        100.0 * c.gains[1]
                    )
                });
                format!(
                    ", {verdict}: their gain's low end over resampled tuning videos is {:+.1} points{then}{across}",
                    100.0 * low
                )
            }),
            100.0 * t.sap50,
            100.0 * t.halves_sap50[0],
            100.0 * t.halves_sap50[1],
            t.device_ms_per_frame
        );
    }
    std::fs::create_dir_all(out)?;
    policy.save(&out.join("policy.json"))?;
    score_all(&log, &root, &frames, &policy, cost, eval, out, heldout)
}

/// The tracker's cost model the budget tables of the policy at `path` were made with,
/// for a stage whose fp32 slowdown is `slowdown`: the same device time (the stored
/// costs are device ms over that policy's slowdown), and the tracker slowdown it was
/// timed with.
fn stored_tracker_cost(
    path: &Path,
    slowdown: f64,
) -> anyhow::Result<(frugal_policies::eval::TrackerCost, Option<f64>)> {
    let from = TrainedPolicy::load(path)?;
    let budget = from.budget.as_ref().with_context(|| {
        format!(
            "{}: holds no budget tables, so no tracker cost they were made with",
            path.display()
        )
    })?;
    let cost = budget.tracker_cost.with_context(|| {
        format!(
            "{}: its budget tables were made before their tracker cost was kept",
            path.display()
        )
    })?;
    Ok((
        cost.scaled(budget.config.slowdown / slowdown),
        budget.config.slowdown_tracker,
    ))
}

/// Reports one of the device's anchors: `[slowdown, device_ms, host_ms]` as the
/// budget stage drew them; `[the reference, where it was timed, what scales by it,
/// what speed the profile states]`; why there is no host time.
fn print_anchor(device: &str, [s, d, h]: [Option<f64>; 3], names: [&str; 4], untimed: &str) {
    let [reference, timed, scaled, speed] = names;
    match (s, d, h) {
        (Some(s), Some(d), Some(h)) => println!(
            "device {device}: the {reference} takes {d:.2} ms there and took {h:.3} ms {timed}: slowdown {s:.3} for {scaled}"
        ),
        (_, None, _) => println!(
            "device {device}: {scaled} on the fp32 anchor (the profile states no {speed} speed)"
        ),
        _ => println!("device {device}: {scaled} on the fp32 anchor ({untimed})"),
    }
}

/// The line that reports the tracker's timed medians (and the reference tracker's).
pub(crate) fn tracker_medians(cost: &frugal_policies::eval::TrackerCost) -> String {
    let reference = cost
        .reference_ms
        .map(|r| format!(", reference tracker {r:.3} ms"))
        .unwrap_or_default();
    format!(
        "tracker medians: pyramid {:.3} ms, track {:.3} ms/object, init {:.3} ms/object{reference}",
        cost.pyramid_ms, cost.track_ms, cost.init_ms
    )
}

/// The tracker's medians, measured on the `train` videos as `policy eval` does.
fn tracker_cost(
    log: &ReplayLog,
    policy: &TrainedPolicy,
    train: &[&VideoLog],
    frames: &DatasetFrames,
    eval: &EvalConfig,
) -> anyhow::Result<frugal_policies::eval::TrackerCost> {
    let cost = run_all(
        log,
        policy,
        train,
        Some(frames),
        eval,
        &[Strategy::StaticTracker],
    )?
    .cost;
    println!("{}", tracker_medians(&cost));
    Ok(cost)
}

/// Scores `policy`'s budget tables on `log`'s test videos (into `out`; its dataset at
/// `root`, read through `frames`) and on every held-out log's (into
/// `out/heldout-<i>`).
#[allow(clippy::too_many_arguments)]
fn score_all(
    log: &ReplayLog,
    root: &Path,
    frames: &DatasetFrames,
    policy: &TrainedPolicy,
    cost: frugal_policies::eval::TrackerCost,
    eval: &EvalConfig,
    out: &Path,
    heldout: &[PathBuf],
) -> anyhow::Result<()> {
    print!("{}", score_log(log, root, frames, policy, cost, eval, out)?);
    for (i, h) in heldout.iter().enumerate() {
        let hl = ReplayLog::load(h)?;
        let dir = out.join(format!("heldout-{}", i + 1));
        let ds = Dataset::load(&hl.dataset)?;
        let frames = DatasetFrames::new(&ds);
        let table = score_log(&hl, &hl.dataset, &frames, policy, cost, eval, &dir)?;
        println!("\nheld out: {}", h.display());
        print!("{table}");
    }
    println!("wrote {}", out.display());
    Ok(())
}
