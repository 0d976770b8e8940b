//! `frugal features`: the feature-based detector family (EdgeBoxes proposals, HoG,
//! one-vs-rest linear SVMs) — train SVM sets for parameter tuples, score variants
//! per class, measure proposal recall.
use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use frugal_data::{Dataset, Split};
use frugal_features::data::{class_names, load_frames};
use frugal_features::eval::{EvalReport, evaluate, proposal_recall};
use frugal_features::{FeatureModel, HogParams, Progress, TrainConfig, train};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `frugal features`.
#[derive(Args, Debug)]
pub struct FeaturesArgs {
    #[command(subcommand)]
    command: FeaturesCommand,
}

#[derive(Subcommand, Debug)]
enum FeaturesCommand {
    /// Train SVM sets for the HoG configurations of the given tuples; writes
    /// OUT/model.json.
    Train(TrainArgs),
    /// Per-class precision / recall and time per frame of variants on a split.
    Eval(EvalArgs),
    /// EdgeBoxes proposal recall for several proposal counts on a split.
    Proposals(ProposalArgs),
}

/// Frame selection shared by the subcommands.
#[derive(Args, Debug)]
struct FrameArgs {
    /// Dataset folder.
    #[arg(long)]
    data: PathBuf,
    /// Use every n-th frame (consecutive frames are near duplicates).
    #[arg(long)]
    stride: Option<usize>,
    /// At most this many frames.
    #[arg(long)]
    limit: Option<usize>,
}

#[derive(Args, Debug)]
struct TrainArgs {
    #[command(flatten)]
    frames: FrameArgs,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
    /// Parameter tuples `proposals,block,cell,bins` (repeatable; default: the
    /// paper's baseline 1000,2,8,9).
    #[arg(long = "params", value_name = "P,B,C,N")]
    params: Vec<String>,
    /// Train the default grid (proposals {200,500,1000,2000} × block {1,2} ×
    /// cell {6,8,12} × bins {6,9}) instead.
    #[arg(long, conflicts_with = "params")]
    grid: bool,
    /// Hard-negative mining rounds.
    #[arg(long, default_value_t = 1)]
    mining_rounds: usize,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

#[derive(Args, Debug)]
struct EvalArgs {
    #[command(flatten)]
    frames: FrameArgs,
    /// Model file written by `frugal features train` (or its folder).
    #[arg(long)]
    model: PathBuf,
    /// Split to score: train, val or test.
    #[arg(long, default_value = "test")]
    split: String,
    /// Variants to score (repeatable; default: the baseline if trained, else every
    /// trained HoG configuration with 1000 proposals).
    #[arg(long = "params", value_name = "P,B,C,N")]
    params: Vec<String>,
    /// Detections at or above this margin count (default: the model's c_ge).
    #[arg(long)]
    threshold: Option<f32>,
    /// Write the reports as JSON to this file.
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct ProposalArgs {
    #[command(flatten)]
    frames: FrameArgs,
    /// Split: train, val or test.
    #[arg(long, default_value = "test")]
    split: String,
    /// Proposal counts.
    #[arg(long, value_delimiter = ',', default_value = "200,500,1000,2000")]
    counts: Vec<usize>,
    /// IoU a proposal needs with a sign.
    #[arg(long, default_value_t = 0.5)]
    iou: f32,
}

fn parse_split(s: &str) -> anyhow::Result<Split> {
    Ok(match s {
        "train" => Split::Train,
        "val" => Split::Val,
        "test" => Split::Test,
        other => bail!("unknown split `{other}` (train, val or test)"),
    })
}

fn parse_params(list: &[String]) -> anyhow::Result<Vec<HogParams>> {
    list.iter()
        .map(|s| s.parse::<HogParams>().map_err(anyhow::Error::from))
        .collect()
}

fn load(
    args: &FrameArgs,
    split: Split,
    stride: usize,
) -> anyhow::Result<(Dataset, Vec<frugal_features::LabeledFrame>)> {
    let ds = Dataset::load(&args.data)
        .with_context(|| format!("loading dataset {}", args.data.display()))?;
    let frames = load_frames(
        &ds,
        split,
        args.stride.unwrap_or(stride),
        args.limit.unwrap_or(usize::MAX),
    )?;
    if frames.is_empty() {
        bail!("{}: the {split} split has no frames", args.data.display());
    }
    Ok((ds, frames))
}

fn model_path(p: &Path) -> PathBuf {
    if p.is_dir() {
        p.join("model.json")
    } else {
        p.to_owned()
    }
}

/// Run `frugal features …`.
pub fn run(args: FeaturesArgs) -> anyhow::Result<()> {
    match args.command {
        FeaturesCommand::Train(a) => train_cmd(a),
        FeaturesCommand::Eval(a) => eval_cmd(a),
        FeaturesCommand::Proposals(a) => proposals_cmd(a),
    }
}

fn train_cmd(a: TrainArgs) -> anyhow::Result<()> {
    let params = if a.grid {
        HogParams::default_grid()
    } else if a.params.is_empty() {
        vec![HogParams::BASELINE]
    } else {
        parse_params(&a.params)?
    };
    let (ds, frames) = load(&a.frames, Split::Train, 6)?;
    let cfg = TrainConfig {
        mining_rounds: a.mining_rounds,
        ..TrainConfig::default()
    };
    let bar = if a.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(frames.len() as u64)
    };
    if let Ok(style) = ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len}, eta {eta}") {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message("proposals");
    let t = Instant::now();
    let progress = |p: Progress| match p {
        Progress::Proposals { done, .. } => bar.set_position(done as u64),
        Progress::Hog { done, total } => {
            if done == 1 {
                bar.set_message("SVM sets");
                bar.set_length(total as u64);
            }
            bar.set_position(done as u64);
        }
        _ => {}
    };
    let model = train(&frames, &class_names(&ds), &params, &cfg, &progress)?;
    bar.finish_and_clear();
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let path = a.out.join("model.json");
    model.save(&path)?;
    println!(
        "trained {} HoG configuration(s) × {} classes on {} frames in {:.1} s: {}",
        model.hogs.len(),
        model.classes.len(),
        frames.len(),
        t.elapsed().as_secs_f64(),
        path.display()
    );
    Ok(())
}

fn eval_cmd(a: EvalArgs) -> anyhow::Result<()> {
    let model = FeatureModel::load(&model_path(&a.model))?;
    let params = if a.params.is_empty() {
        if model.svms(2, 8, 9).is_ok() {
            vec![HogParams::BASELINE]
        } else {
            model.variants(&[1000])
        }
    } else {
        parse_params(&a.params)?
    };
    let (_, frames) = load(&a.frames, parse_split(&a.split)?, 4)?;
    let threshold = a.threshold.unwrap_or(model.thresholds.ge);
    let mut reports: Vec<EvalReport> = Vec::new();
    for p in params {
        let r = evaluate(&model, p, &frames, threshold, 0.5)?;
        print!("{}", table(&model, &r));
        reports.push(r);
    }
    if let Some(out) = &a.out {
        let json = serde_json::to_string_pretty(&reports)?;
        let tmp = out.with_extension("json.tmp");
        std::fs::write(&tmp, json).with_context(|| format!("writing {}", tmp.display()))?;
        std::fs::rename(&tmp, out).with_context(|| format!("writing {}", out.display()))?;
        println!("report: {}", out.display());
    }
    Ok(())
}

/// A Markdown table of one variant's per-class counts.
fn table(model: &FeatureModel, r: &EvalReport) -> String {
    let f = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
    let tot = r.total();
    let mut s = format!(
        "\nvariant {}: {} frames, {:.1} ms/frame, precision {}, recall {} (margin >= {}, IoU {})\n",
        r.params,
        r.frames,
        r.mean_ms,
        f(tot.precision()),
        f(tot.recall()),
        r.score_threshold,
        r.iou
    );
    s.push_str("| class | TP | FP | missed | precision | recall |\n|---|---|---|---|---|---|\n");
    for (name, c) in model.classes.iter().zip(&r.per_class) {
        s.push_str(&format!(
            "| {name} | {} | {} | {} | {} | {} |\n",
            c.tp,
            c.fp,
            c.missed,
            f(c.precision()),
            f(c.recall())
        ));
    }
    s
}

fn proposals_cmd(a: ProposalArgs) -> anyhow::Result<()> {
    let (_, frames) = load(&a.frames, parse_split(&a.split)?, 4)?;
    let (recall, ms) =
        proposal_recall(&TrainConfig::default().edgeboxes, &frames, &a.counts, a.iou)?;
    let signs: usize = frames.iter().map(|f| f.objects.len()).sum();
    println!(
        "EdgeBoxes proposal recall at IoU {}: {} frames, {signs} signs, {ms:.1} ms/frame",
        a.iou,
        frames.len()
    );
    println!("| proposals | recall |\n|---|---|");
    for (n, r) in recall {
        println!("| {n} | {r:.3} |");
    }
    Ok(())
}
