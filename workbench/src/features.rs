//! `frugal features`: the feature-based detector family (EdgeBoxes proposals, HoG,
//! one-vs-rest linear SVMs) — train SVM sets for parameter tuples, score variants
//! per class, measure proposal recall, and map a parameter grid's accuracy against
//! its time per frame with the Pareto front.
use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use frugal_data::{Dataset, Split};
use frugal_features::data::{class_names, load_frames};
use frugal_features::eval::{EvalReport, evaluate, evaluate_many, proposal_recall};
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
    /// Train SVM sets for a grid of tuples on the train split, score every tuple on a
    /// held-out split (precision, recall, F1 at the margin threshold; time per frame)
    /// and write OUT/grid.json, grid.csv and the Pareto plot grid.png|svg.
    Grid(GridArgs),
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

#[derive(Args, Debug)]
struct GridArgs {
    /// Dataset folder, and which held-out frames to score (`--stride`, `--limit`).
    #[command(flatten)]
    frames: FrameArgs,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
    /// Held-out split to score: val or test.
    #[arg(long, default_value = "val")]
    split: String,
    /// Proposal counts of the grid.
    #[arg(long, value_delimiter = ',', default_value = "200,500,1000,2000")]
    proposals: Vec<u32>,
    /// Block sizes (cells) of the grid.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3")]
    blocks: Vec<u8>,
    /// Cell sizes (pixels) of the grid.
    #[arg(long, value_delimiter = ',', default_value = "6,8")]
    cells: Vec<u8>,
    /// Orientation bins of the grid.
    #[arg(long, value_delimiter = ',', default_value = "6,9,12")]
    bins: Vec<u8>,
    /// Use every n-th training frame.
    #[arg(long, default_value_t = 6)]
    train_stride: usize,
    /// At most this many training frames.
    #[arg(long)]
    train_limit: Option<usize>,
    /// Reuse this trained model (file or folder) instead of training; it must hold
    /// every HoG configuration of the grid.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Hard-negative mining rounds.
    #[arg(long, default_value_t = 1)]
    mining_rounds: usize,
    /// Detections at or above this margin count (default: the model's c_ge).
    #[arg(long)]
    threshold: Option<f32>,
    /// No progress bars.
    #[arg(long)]
    quiet: bool,
}

/// One tuple of the grid, as written to grid.json / grid.csv.
#[derive(Debug, serde::Serialize)]
struct GridPoint {
    params: String,
    proposals: u32,
    block: u8,
    cell: u8,
    bins: u8,
    tp: usize,
    fp: usize,
    missed: usize,
    precision: f64,
    recall: f64,
    f1: f64,
    ms_per_frame: f64,
    on_front: bool,
}

/// What `frugal features grid` writes to grid.json.
#[derive(Debug, serde::Serialize)]
struct GridReport {
    /// The model scored (trained by this command when `train_frames > 0`).
    model: PathBuf,
    split: String,
    frames: usize,
    train_frames: usize,
    train_seconds: f64,
    eval_seconds: f64,
    score_threshold: f32,
    iou: f32,
    rayon_threads: String,
    points: Vec<GridPoint>,
    /// Indices of `points` on the Pareto front (F1 up, time down), fastest first.
    front: Vec<usize>,
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
        FeaturesCommand::Grid(a) => grid_cmd(a),
    }
}

pub(crate) fn bar(quiet: bool, len: usize, msg: &'static str) -> ProgressBar {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(len as u64)
    };
    if let Ok(style) = ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len}, eta {eta}") {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(msg);
    bar
}

/// A counter of work whose total is not known in advance, hidden when `quiet`.
pub(crate) fn counter(quiet: bool, msg: &'static str) -> ProgressBar {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new_spinner()
    };
    if let Ok(style) = ProgressStyle::with_template("{spinner} {msg}: {pos}, {elapsed}") {
        bar.set_style(style);
    }
    bar.set_message(msg);
    bar
}

/// Train SVM sets for `params` on `frames`, with a progress bar unless `quiet`.
fn train_model(
    ds: &Dataset,
    frames: &[frugal_features::LabeledFrame],
    params: &[HogParams],
    mining_rounds: usize,
    quiet: bool,
) -> anyhow::Result<FeatureModel> {
    let cfg = TrainConfig {
        mining_rounds,
        ..TrainConfig::default()
    };
    let bar = bar(quiet, frames.len(), "proposals");
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
    let model = train(frames, &class_names(ds), params, &cfg, &progress)?;
    bar.finish_and_clear();
    Ok(model)
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
    let t = Instant::now();
    let model = train_model(&ds, &frames, &params, a.mining_rounds, a.quiet)?;
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

fn grid_cmd(a: GridArgs) -> anyhow::Result<()> {
    let split = parse_split(&a.split)?;
    if split == Split::Train {
        bail!("score the grid on a held-out split (val or test), not on train");
    }
    let params = HogParams::grid(&a.proposals, &a.blocks, &a.cells, &a.bins);
    if params.is_empty() {
        bail!(
            "the grid is empty: give at least one value for each of --proposals, --blocks, --cells, --bins"
        );
    }
    let (ds, frames) = load(&a.frames, split, 12)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let (model, model_file, train_frames, train_seconds) = match &a.model {
        Some(m) => (FeatureModel::load(&model_path(m))?, model_path(m), 0, 0.0),
        None => {
            let train = load_frames(
                &ds,
                Split::Train,
                a.train_stride,
                a.train_limit.unwrap_or(usize::MAX),
            )?;
            if train.is_empty() {
                bail!("{}: the train split has no frames", a.frames.data.display());
            }
            let t = Instant::now();
            let model = train_model(&ds, &train, &params, a.mining_rounds, a.quiet)?;
            let secs = t.elapsed().as_secs_f64();
            let file = a.out.join("model.json");
            model.save(&file)?;
            println!(
                "trained {} HoG configuration(s) on {} frames in {secs:.1} s",
                model.hogs.len(),
                train.len()
            );
            (model, file, train.len(), secs)
        }
    };
    let threshold = a.threshold.unwrap_or(model.thresholds.ge);
    let iou = 0.5;
    let bar = bar(a.quiet, frames.len(), "scoring the grid");
    let t = Instant::now();
    let reports = evaluate_many(&model, &params, &frames, threshold, iou, &|done, _| {
        bar.set_position(done as u64)
    })?;
    let eval_seconds = t.elapsed().as_secs_f64();
    bar.finish_and_clear();
    let mut points: Vec<GridPoint> = params
        .iter()
        .zip(&reports)
        .map(|(p, r)| {
            let c = r.total();
            GridPoint {
                params: p.to_string(),
                proposals: p.proposals,
                block: p.block,
                cell: p.cell,
                bins: p.bins,
                tp: c.tp,
                fp: c.fp,
                missed: c.missed,
                precision: c.precision().unwrap_or(0.0),
                recall: c.recall().unwrap_or(0.0),
                f1: c.f1().unwrap_or(0.0),
                ms_per_frame: r.mean_ms,
                on_front: false,
            }
        })
        .collect();
    let plane: Vec<frugal_pareto::Point> = points
        .iter()
        .map(|g| frugal_pareto::Point {
            accuracy: g.f1,
            latency: g.ms_per_frame,
        })
        .collect();
    let front = frugal_pareto::front(&plane);
    for &i in &front {
        points[i].on_front = true;
    }
    let threads = std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "all cores".into());
    // Label the front and the paper's baseline; the other points stay unlabelled.
    let baseline = HogParams::BASELINE.to_string();
    let labelled: Vec<(String, frugal_pareto::Point)> = points
        .iter()
        .zip(&plane)
        .map(|(g, p)| {
            let label = match (g.on_front, g.params == baseline) {
                (_, true) => format!("{} (baseline)", g.params),
                (true, false) => g.params.clone(),
                (false, false) => String::new(),
            };
            (label, *p)
        })
        .collect();
    let title = format!(
        "HoG + SVM grid on the {} split ({} frames): F1 vs time",
        a.split,
        frames.len()
    );
    let xlabel = format!("ms per frame (EdgeBoxes + HoG + SVMs, rayon threads: {threads})");
    let ylabel = format!("F1 (margin >= {threshold}, IoU {iou})");
    frugal_pareto::plot_front(
        &a.out.join("grid"),
        &frugal_pareto::FrontPlot {
            title: &title,
            accuracy_label: &ylabel,
            latency_label: &xlabel,
            points: &labelled,
            front: &front,
        },
    )?;
    let mut csv = String::from(
        "params,proposals,block,cell,bins,tp,fp,missed,precision,recall,f1,ms_per_frame,on_front\n",
    );
    for g in &points {
        csv.push_str(&format!(
            "\"{}\",{},{},{},{},{},{},{},{:.4},{:.4},{:.4},{:.3},{}\n",
            g.params,
            g.proposals,
            g.block,
            g.cell,
            g.bins,
            g.tp,
            g.fp,
            g.missed,
            g.precision,
            g.recall,
            g.f1,
            g.ms_per_frame,
            g.on_front
        ));
    }
    frugal_data::dataset::write_atomic(&a.out.join("grid.csv"), csv.as_bytes())?;
    let report = GridReport {
        model: model_file,
        split: a.split.clone(),
        frames: frames.len(),
        train_frames,
        train_seconds,
        eval_seconds,
        score_threshold: threshold,
        iou,
        rayon_threads: threads,
        points,
        front,
    };
    frugal_data::dataset::write_json_atomic(&a.out.join("grid.json"), &report)?;
    println!(
        "{} tuples on {} {} frames, scored in {eval_seconds:.1} s; Pareto front (F1 up, ms down):",
        report.points.len(),
        report.frames,
        a.split
    );
    println!("| tuple | precision | recall | F1 | ms/frame |\n|---|---|---|---|---|");
    for &i in &report.front {
        let g = &report.points[i];
        println!(
            "| {} | {:.3} | {:.3} | {:.3} | {:.1} |",
            g.params, g.precision, g.recall, g.f1, g.ms_per_frame
        );
    }
    println!("wrote {}", a.out.join("grid.json|csv|png|svg").display());
    Ok(())
}
