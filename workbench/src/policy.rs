//! `frugal policy record|train|eval`: the MDP stage (crate `frugal-policies`).
//!
//! ```text
//! frugal policy record --data D --variants variants.json --out run/replay.json
//! frugal policy train  --log run/replay.json --out run/policy [--config policy.toml]
//! frugal policy eval   --log run/replay.json --policy run/policy/policy.json --out run/eval
//! ```

use anyhow::Context;
use clap::{Args, Subcommand};
use frugal_data::{Dataset, Split};
use frugal_policies::eval::EvalConfig;
use frugal_policies::replay::{DEFAULT_MAX_DETECTIONS, DatasetFrames, record, time_detectors};
use frugal_policies::report::{
    evaluate_and_write, kul_tables, policy_table, score_table, train_and_write, write_per_class,
};
use frugal_policies::variants::{FrameDetector, RuntimeDetector, VariantSource, VariantsFile};
use frugal_policies::{PolicyConfig, ReplayLog, Reward, TrainedPolicy, VariantSet};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Arguments of `frugal policy`.
#[derive(Args, Debug)]
pub struct PolicyArgs {
    #[command(subcommand)]
    command: PolicyCommand,
}

#[derive(Subcommand, Debug)]
enum PolicyCommand {
    /// Run every detector variant once on every frame of the chosen splits and save
    /// the replay log (top detections per frame and variant, and the ground truth).
    ///
    /// The variants file (JSON or TOML) lists `variants = [{ name, family, latency_ms,
    /// source = { kind = "onnx", dir = "…" } }]` (or `{ kind = "hog", model = "…",
    /// params = "1000,2,8,9" }`, or `kind = "synthetic"` for ground-truth-derived test
    /// detectors) and optionally `families = [{ name,
    /// buckets = { c_opt, c_ge, c_ua, t_c } }]` to override the default buckets.
    Record(RecordArgs),
    /// Give every variant of a log its own confidence buckets, of equal precision on
    /// the log's training videos (for families whose scores are not comparable across
    /// variants, like the CNN's); writes the calibrated log and calibration.json.
    Calibrate(CalibrateArgs),
    /// Estimate the MDP from the log's training videos, solve it (value iteration,
    /// cross-checked by policy iteration), sweep α, write policy.json and the sweep plot.
    Train(TrainArgs),
    /// Replay the paper's five strategies and the oracle on the log's test videos
    /// (the KLT tracker runs on the real frames), write eval.json/csv and the plots,
    /// and per sign class per_class.json/csv and the paper's KUL table (kul.md).
    Eval(EvalArgs),
    /// Learn the budget + content policy (one table per latency budget) on the log's
    /// training videos, attach it to the policy (so `frugal bundle write` ships it), and
    /// stream every budget strategy on the test videos (and on held-out logs) on a
    /// simulated clock: sAP, deadline misses, latency; budget.json/csv/md and plots.
    Budget(BudgetArgs),
}

/// Options of `frugal policy budget`.
#[derive(Args, Debug)]
struct BudgetArgs {
    /// The replay log (its training videos teach the policy, its test videos score it).
    #[arg(long)]
    log: PathBuf,
    /// The trained paper policy (policy.json) to attach the budget tables to.
    #[arg(long)]
    policy: PathBuf,
    /// Output folder (policy.json with the budget tables, budget.json|csv|md, plots).
    #[arg(long)]
    out: PathBuf,
    /// The dataset folder (default: the one recorded in the log).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Budget settings (TOML or JSON: budgets_ms, slowdown, periods, switch_cost, …).
    #[arg(long)]
    config: Option<PathBuf>,
    /// More replay logs of the same variants to score on (their test videos), e.g.
    /// videos of a seed the policy never saw; each gets `heldout-<i>/` in the output.
    #[arg(long = "heldout")]
    heldout: Vec<PathBuf>,
    /// More replay logs of the same variants whose videos (every split) the budget
    /// tables are chosen on, with the log's training videos: a tuning set of its own
    /// seed, never scored on.
    #[arg(long = "tune")]
    tune: Vec<PathBuf>,
    /// The paper MDP's evaluation settings (as `frugal policy eval --config`): its
    /// thresholds and accesses per image in the streamed `mdp+tracker` strategy.
    #[arg(long)]
    eval_config: Option<PathBuf>,
    /// Score the budget tables `--policy` already holds (a policy.json this command
    /// wrote) as they are, on this log's test videos and every `--heldout` log: no
    /// learning, no search, the tracker cost the tables were made with. For a table
    /// made elsewhere, on new videos or under other latencies.
    #[arg(long)]
    keep_tables: bool,
    /// Learn the tables with the tracker cost the budget tables of this policy.json
    /// (one this command wrote) were made with, instead of timing the tracker again:
    /// two passes that differ in a setting or in their tuning videos then differ in
    /// that alone (the tracker's timing otherwise moves a table from pass to pass).
    #[arg(long, value_name = "POLICY")]
    tracker_from: Option<PathBuf>,
}

/// Options of `frugal policy record`.
#[derive(Args, Debug)]
struct RecordArgs {
    /// The dataset folder.
    #[arg(long)]
    data: PathBuf,
    /// The variants file.
    #[arg(long)]
    variants: PathBuf,
    /// Output log (JSON).
    #[arg(long)]
    out: PathBuf,
    /// Splits to replay, comma separated.
    #[arg(long, default_value = "train,val,test", value_delimiter = ',', value_parser = crate::data::parse_split)]
    splits: Vec<Split>,
    /// Detections kept per frame and variant.
    #[arg(long, default_value_t = DEFAULT_MAX_DETECTIONS)]
    max_detections: usize,
    /// ONNX Runtime intra-op threads per variant.
    #[arg(long, default_value_t = 1)]
    threads: usize,
    /// Keep at most this many videos per (split, clutter, light) combination.
    #[arg(long)]
    per_combo: Option<usize>,
    /// The dataset split whose videos the policy learns from (they are the log's
    /// `train` videos): `val` keeps the MDP's statistics off the videos the detector
    /// itself was trained on, where every variant looks better than it is.
    #[arg(long, default_value = "train", value_parser = crate::data::parse_split)]
    train_split: Split,
    /// Frames to time a variant on when the variants file gives no latency.
    #[arg(long, default_value_t = 15)]
    time_frames: usize,
    /// Hide the progress bar.
    #[arg(long)]
    quiet: bool,
}

/// Options of `frugal policy calibrate`.
#[derive(Args, Debug)]
struct CalibrateArgs {
    /// The replay log.
    #[arg(long)]
    log: PathBuf,
    /// The calibrated log (may be the same file).
    #[arg(long)]
    out: PathBuf,
    /// Training frames that must back a bucket edge.
    #[arg(long, default_value_t = 20)]
    min_samples: usize,
}

/// Options of `frugal policy train`.
#[derive(Args, Debug)]
struct TrainArgs {
    /// The replay log.
    #[arg(long)]
    log: PathBuf,
    /// Another replay log whose training videos the policy also learns from, e.g.
    /// replayed on recorded flight footage (`frugal fly --record`); same variants in
    /// the same order. The main log's buckets apply to its scores. Repeatable.
    #[arg(long = "extra-log")]
    extra_logs: Vec<PathBuf>,
    /// Output folder (policy.json, sweep.json/csv/png/svg).
    #[arg(long)]
    out: PathBuf,
    /// Policy config (TOML or JSON; unknown keys rejected; defaults built in).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Override the reward: `outcome` (next frame's F1 against the truth, the default)
    /// or `confidence` (the paper's bucket weights).
    #[arg(long, value_parser = parse_reward)]
    reward: Option<Reward>,
    /// Override α.
    #[arg(long)]
    alpha: Option<f64>,
    /// Override γ.
    #[arg(long)]
    gamma: Option<f64>,
}

/// Options of `frugal policy eval`.
#[derive(Args, Debug)]
struct EvalArgs {
    /// The replay log.
    #[arg(long)]
    log: PathBuf,
    /// The trained policy (policy.json).
    #[arg(long)]
    policy: PathBuf,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
    /// The dataset folder (default: the one recorded in the log).
    #[arg(long)]
    data: Option<PathBuf>,
    /// The test video of the per-clip figures (default: the first).
    #[arg(long)]
    clip: Option<u32>,
    /// Evaluation settings (TOML or JSON; thresholds, IoU, seed).
    #[arg(long)]
    config: Option<PathBuf>,
}

/// One HoG variant of a shared feature model (a `HogDetector` borrows its model, so
/// the detector is made per frame; that costs a table lookup).
struct HogVariant {
    model: Arc<frugal_features::FeatureModel>,
    params: frugal_features::HogParams,
}

impl FrameDetector for HogVariant {
    fn detect(
        &mut self,
        frame: frugal_runtime::FrameRef<'_>,
        _ctx: &frugal_policies::variants::FrameContext<'_>,
        max: usize,
    ) -> Result<Vec<frugal_runtime::Detection>, String> {
        let mut det = self
            .model
            .detector(self.params)
            .map_err(|e| e.to_string())?;
        let mut out = vec![frugal_runtime::Detection::default(); max];
        let n = frugal_runtime::Detector::detect(&mut det, frame, &mut out)
            .map_err(|e| e.to_string())?;
        out.truncate(n);
        Ok(out)
    }
}

fn open_detector(
    v: &frugal_policies::variants::VariantInfo,
    threads: usize,
    models: &mut HashMap<PathBuf, Arc<frugal_features::FeatureModel>>,
) -> frugal_policies::Result<Box<dyn FrameDetector>> {
    let bad = |path: &Path, e: String| {
        frugal_policies::PolicyError::invalid(path, format!("variant {}", v.name), e)
    };
    match &v.source {
        VariantSource::Hog { model, params } => {
            let m = match models.get(model) {
                Some(m) => m.clone(),
                None => {
                    let m = Arc::new(
                        frugal_features::FeatureModel::load(model)
                            .map_err(|e| bad(model, e.to_string()))?,
                    );
                    models.insert(model.clone(), m.clone());
                    m
                }
            };
            let params: frugal_features::HogParams = params
                .parse()
                .map_err(|e: frugal_features::Error| bad(model, e.to_string()))?;
            m.detector(params).map_err(|e| bad(model, e.to_string()))?;
            Ok(Box::new(HogVariant { model: m, params }))
        }
        VariantSource::Onnx { dir } => {
            let det = frugal_models::onnx::OrtDetector::open(dir, threads).map_err(|e| {
                frugal_policies::PolicyError::invalid(
                    dir,
                    format!("variant {}", v.name),
                    e.to_string(),
                )
            })?;
            Ok(Box::new(RuntimeDetector(det)))
        }
        other => Err(frugal_policies::PolicyError::invalid(
            "<variants>",
            format!("variant {}", v.name),
            format!("no detector for source {other:?}"),
        )),
    }
}

fn parse_reward(name: &str) -> Result<Reward, String> {
    Reward::from_name(name).ok_or_else(|| format!("{name:?}: expected outcome or confidence"))
}

fn read_eval_config(path: Option<&Path>) -> anyhow::Result<EvalConfig> {
    Ok(match path {
        Some(path) => frugal_policies::error::read_toml_or_json(path)?,
        None => EvalConfig::default(),
    })
}

/// Run `frugal policy …`.
pub fn run(args: PolicyArgs) -> anyhow::Result<()> {
    match args.command {
        PolicyCommand::Record(a) => {
            let ds = Dataset::load(&a.data)?;
            let file = VariantsFile::read(&a.variants)?;
            let mut models = HashMap::new();
            let frames = DatasetFrames::new(&ds);
            if a.train_split != Split::Train && a.splits.contains(&Split::Train) {
                anyhow::bail!(
                    "--train-split {} takes the place of the train split: leave train out of --splits",
                    a.train_split.name()
                );
            }
            let mut videos = frames.skeleton(&a.splits);
            for v in &mut videos {
                if v.split == a.train_split {
                    v.split = Split::Train;
                }
            }
            if let Some(k) = a.per_combo {
                let mut seen: HashMap<(Split, String, String), usize> = HashMap::new();
                videos.retain(|v| {
                    let n = seen
                        .entry((v.split, v.clutter.name().into(), v.light.name().into()))
                        .or_insert(0);
                    *n += 1;
                    *n <= k
                });
            }
            if videos.is_empty() {
                anyhow::bail!("{}: no videos in splits {:?}", a.data.display(), a.splits);
            }
            let mut set = VariantSet::from_file(
                &file,
                &a.variants,
                |v| open_detector(v, a.threads, &mut models),
                |dets| {
                    let ms =
                        time_detectors(dets, &frames, &videos, a.time_frames, a.max_detections)?;
                    for ((name, _), ms) in dets.iter().zip(&ms) {
                        println!(
                            "timed {name}: {ms:.3} ms/frame, the fastest of {} frames (variants taking turns)",
                            a.time_frames
                        );
                    }
                    Ok(ms)
                },
            )?;
            let mut log = record(
                &mut set,
                &frames,
                videos,
                a.data.clone(),
                ds.classes.len(),
                a.max_detections,
                !a.quiet,
            )?;
            log.reference_ms = file.reference_ms;
            log.reference_int8_ms = file.reference_int8_ms;
            log.save(&a.out)?;
            let n: usize = log.videos.iter().map(|v| v.frames.len()).sum();
            println!(
                "replayed {} variants on {} frames of {} videos into {}",
                log.variants.len(),
                n,
                log.videos.len(),
                a.out.display()
            );
            Ok(())
        }
        PolicyCommand::Calibrate(a) => {
            let mut log = ReplayLog::load(&a.log)?;
            let cal = frugal_policies::calibrate::calibrate(&mut log, a.min_samples).with_context(
                || {
                    format!(
                        "{}: no training video with detections to calibrate on",
                        a.log.display()
                    )
                },
            )?;
            log.save(&a.out)?;
            let json_path = a.out.with_file_name("calibration.json");
            frugal_data::dataset::write_json_atomic(&json_path, &cal)?;
            println!(
                "reference {}: precision {:.3} / {:.3} / {:.3} at its c_opt / c_ge / c_ua",
                cal.reference, cal.targets[0], cal.targets[1], cal.targets[2]
            );
            let show = |x: f32| {
                if x == frugal_policies::calibrate::UNREACHABLE {
                    "never".to_string()
                } else {
                    format!("{x:.3}")
                }
            };
            println!(
                "{:<16} {:>7} {:>9} {:>8} {:>8} {:>8}",
                "variant", "frames", "precision", "c_opt", "c_ge", "c_ua"
            );
            for v in &cal.variants {
                println!(
                    "{:<16} {:>7} {:>9.3} {:>8} {:>8} {:>8}",
                    v.variant,
                    v.samples,
                    v.precision,
                    show(v.after.c_opt),
                    show(v.after.c_ge),
                    show(v.after.c_ua)
                );
            }
            println!("wrote {} and {}", a.out.display(), json_path.display());
            Ok(())
        }
        PolicyCommand::Train(a) => {
            let mut log = ReplayLog::load(&a.log)?;
            for extra in &a.extra_logs {
                let added = log.absorb_training(ReplayLog::load(extra)?, extra)?;
                println!("+ {added} training videos from {}", extra.display());
            }
            let mut cfg = match &a.config {
                Some(p) => PolicyConfig::read(p)?,
                None => PolicyConfig::default(),
            };
            if let Some(r) = a.reward {
                cfg.reward = r;
            }
            if let Some(x) = a.alpha {
                cfg.alpha = x;
            }
            if let Some(x) = a.gamma {
                cfg.gamma = x;
            }
            cfg.check(a.config.as_deref().unwrap_or(Path::new("<command line>")))?;
            let (policy, sweep) = train_and_write(&log, &cfg, &EvalConfig::default(), &a.out)?;
            print!("{}", policy_table(&policy));
            println!("α sweep (no tracker, held-out videos):");
            for p in &sweep {
                println!(
                    "  {:<10} α {:<5} w_ge×{:<5} {:>8.3} ms/frame  F1 {:.3}",
                    p.reward.name(),
                    p.alpha,
                    p.ge_scale,
                    p.ms_per_frame,
                    p.f1
                );
            }
            println!("wrote {}", a.out.join("policy.json").display());
            Ok(())
        }
        PolicyCommand::Budget(a) => crate::budget::run(
            &crate::budget::Files {
                log: &a.log,
                policy: &a.policy,
                out: &a.out,
                data: a.data.as_deref(),
                config: a.config.as_deref(),
                heldout: &a.heldout,
                tune: &a.tune,
                keep_tables: a.keep_tables,
                tracker_from: a.tracker_from.as_deref(),
            },
            &read_eval_config(a.eval_config.as_deref())?,
        ),
        PolicyCommand::Eval(a) => {
            let log = ReplayLog::load(&a.log)?;
            let policy = TrainedPolicy::load(&a.policy)?;
            let cfg = read_eval_config(a.config.as_deref())?;
            let root = a.data.clone().unwrap_or_else(|| log.dataset.clone());
            let ds = Dataset::load(&root)?;
            let frames = DatasetFrames::new(&ds);
            let (report, runs) = evaluate_and_write(&log, &policy, &frames, &cfg, &a.out, a.clip)?;
            let names: Vec<String> = ds.classes.iter().map(|c| c.name.clone()).collect();
            let per_class = write_per_class(&log, &runs, &cfg, &names, &a.out)?;
            println!(
                "static variant: {}; {}",
                report.static_variant,
                crate::budget::tracker_medians(&report.tracker_cost)
            );
            print!("{}", score_table(&report.scores));
            println!(
                "\nper class (precision at the family's T_c, ms per frame showing the class):"
            );
            print!("{}", kul_tables(&runs, &per_class, &report.static_variant));
            println!("wrote {}", a.out.display());
            Ok(())
        }
    }
}
