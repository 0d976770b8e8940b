//! What `policy train` and `policy eval` write: JSON, CSV and the figures.

use crate::error::{PolicyError, Result};
use crate::eval::{EvalConfig, EvalReport, Runs, Score, Strategy, run_all, scores};
use crate::plot::{ClipSeries, plot_bars, plot_clip, plot_states, plot_sweep};
use crate::replay::{Frames, ReplayLog, VideoLog};
use crate::sweep::{SweepPoint, sweep};
use crate::train::{PolicyConfig, TrainedPolicy, Weights, train};
use frugal_data::Split;
use frugal_runtime::bundle::Bucket;
use std::fmt::Write as _;
use std::path::Path;

fn write_text(path: &Path, text: &str) -> Result<()> {
    frugal_data::dataset::write_atomic(path, text.as_bytes()).map_err(PolicyError::from)
}

fn write_json<T: serde::Serialize>(path: &Path, v: &T) -> Result<()> {
    frugal_data::dataset::write_json_atomic(path, v).map_err(PolicyError::from)
}

/// Names of the states, `bucket/variant`, in state order.
pub fn state_labels(names: &[String]) -> Vec<String> {
    let b = ["opt", "ge", "ua", "miss"];
    b.iter()
        .flat_map(|b| names.iter().map(move |n| format!("{b}/{n}")))
        .collect()
}

/// Train on `log`, sweep `α`, and write `policy.json`, `sweep.json`, `sweep.csv`,
/// `sweep.png|svg` into `out`.
pub fn train_and_write(
    log: &ReplayLog,
    cfg: &PolicyConfig,
    eval: &EvalConfig,
    out: &Path,
) -> Result<(TrainedPolicy, Vec<SweepPoint>)> {
    let policy = train(log, cfg)?;
    policy.save(&out.join("policy.json"))?;
    let points = sweep(log, cfg, eval)?;
    write_json(&out.join("sweep.json"), &points)?;
    let mut csv = String::from("alpha,ge_scale,ms_per_frame,f1\n");
    for p in &points {
        let _ = writeln!(
            csv,
            "{},{},{:.4},{:.4}",
            p.alpha, p.ge_scale, p.ms_per_frame, p.f1
        );
    }
    write_text(&out.join("sweep.csv"), &csv)?;
    plot_sweep(&out.join("sweep"), &points)?;
    Ok((policy, points))
}

/// A printable summary of a trained policy: the table and the samples per row.
pub fn policy_table(p: &TrainedPolicy) -> String {
    let v = p.variants.len();
    let mut s = String::new();
    let _ = writeln!(
        s,
        "policy (α {}, γ {}, value iteration {} sweeps, policy iteration agrees: {})",
        p.config.alpha, p.config.gamma, p.iterations, p.policy_iteration_agrees
    );
    let _ = writeln!(
        s,
        "  {:<28} {:<16} {:>10} {:>22}",
        "state", "action", "value", "samples (min..max/row)"
    );
    for b in Bucket::ALL {
        for cur in 0..v {
            let st = b.index() * v + cur;
            let a = p.actions[st] as usize;
            let rows = &p.samples[st * v..(st + 1) * v];
            let _ = writeln!(
                s,
                "  {:<28} {:<16} {:>10.3} {:>14}..{}",
                format!("{b:?}/{}", p.variants[cur].name),
                p.variants[a].name,
                p.values[st],
                rows.iter().min().unwrap_or(&0),
                rows.iter().max().unwrap_or(&0)
            );
        }
    }
    s
}

/// Per-variant reward, IoU with the truth and time per frame on one video.
pub fn clip_series(
    log: &ReplayLog,
    video: &VideoLog,
    alpha: f64,
    w: &Weights,
) -> Vec<Vec<(f64, f64, f64)>> {
    (0..log.variants.len())
        .map(|v| {
            let b = log.buckets(v);
            let var = &log.variants[v];
            video
                .frames
                .iter()
                .map(|f| {
                    let bucket = b.to_runtime().bucket(f.best_score(v));
                    let reward = w.of(bucket) / var.relative_cost.powf(alpha);
                    let iou = f.detections[v]
                        .iter()
                        .filter(|d| d.score >= b.t_c)
                        .flat_map(|d| f.truth.iter().map(move |t| d.bbox().iou(&t.bbox())))
                        .fold(0.0f32, f32::max);
                    (reward, f64::from(iou), var.latency_ms)
                })
                .collect()
        })
        .collect()
}

fn csv(scores: &[Score]) -> String {
    let mut s = String::from(
        "scenario,strategy,videos,frames,f1,precision,recall,mean_iou,total_ms,ms_per_frame,fps,speedup_vs_static,f1_loss_vs_static,detections\n",
    );
    for x in scores {
        let _ = writeln!(
            s,
            "{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.3},{:.4},{:.2},{:.3},{:.4},{}",
            x.scenario,
            x.strategy,
            x.videos,
            x.frames,
            x.f1,
            x.precision,
            x.recall,
            x.mean_iou,
            x.total_ms,
            x.ms_per_frame,
            x.fps,
            x.speedup_vs_static,
            x.f1_loss_vs_static,
            x.detections
        );
    }
    s
}

/// A printable table of scores.
pub fn score_table(scores: &[Score]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<15} {:<15} {:>6} {:>6} {:>7} {:>9} {:>8} {:>8} {:>8} {:>6}",
        "scenario",
        "strategy",
        "F1",
        "IoU",
        "ms/fr",
        "total ms",
        "fps",
        "speedup",
        "F1 loss",
        "dets"
    );
    for x in scores {
        let _ = writeln!(
            s,
            "{:<15} {:<15} {:>6.3} {:>6.3} {:>7.3} {:>9.1} {:>8.1} {:>7.2}x {:>8.4} {:>6}",
            x.scenario,
            x.strategy,
            x.f1,
            x.mean_iou,
            x.ms_per_frame,
            x.total_ms,
            x.fps,
            x.speedup_vs_static,
            x.f1_loss_vs_static,
            x.detections
        );
    }
    s
}

/// Evaluate every strategy on the log's test videos and write `eval.json`, `eval.csv`,
/// `bars-time|bars-f1`, `clip` and `states` figures into `out`. `clip` picks the video
/// of the per-clip figures (default: the first test video).
pub fn evaluate_and_write(
    log: &ReplayLog,
    policy: &TrainedPolicy,
    frames: &dyn Frames,
    cfg: &EvalConfig,
    out: &Path,
    clip: Option<u32>,
) -> Result<(EvalReport, Runs)> {
    if policy.variants.len() != log.variants.len()
        || policy
            .variants
            .iter()
            .zip(&log.variants)
            .any(|(a, b)| a.name != b.name)
    {
        return Err(PolicyError::invalid(
            &log.dataset,
            "variants",
            "the policy was trained on other variants than the log's",
        ));
    }
    let videos: Vec<&VideoLog> = log.split(Split::Test).collect();
    if videos.is_empty() {
        return Err(PolicyError::invalid(
            &log.dataset,
            "videos",
            "the log has no test videos",
        ));
    }
    let runs = run_all(log, policy, &videos, Some(frames), cfg, &Strategy::ALL)?;
    let sc = scores(log, &videos, &runs, cfg);
    let report = EvalReport {
        config: cfg.clone(),
        static_variant: log.variants[runs.static_variant].name.clone(),
        tracker_cost: runs.cost,
        scores: sc.clone(),
        videos: videos.iter().map(|v| v.id).collect(),
    };
    write_json(&out.join("eval.json"), &report)?;
    write_text(&out.join("eval.csv"), &csv(&sc))?;
    plot_bars(&out.join("bars"), &sc)?;
    let clip_video = match clip {
        Some(id) => *videos.iter().find(|v| v.id == id).ok_or_else(|| {
            PolicyError::invalid(
                &log.dataset,
                "clip",
                format!("video {id} is not a test video of the log"),
            )
        })?,
        None => videos[0],
    };
    let names: Vec<String> = log.variants.iter().map(|v| v.name.clone()).collect();
    let series = clip_series(log, clip_video, policy.config.alpha, &policy.config.weights);
    let frames_idx: Vec<u32> = clip_video.frames.iter().map(|f| f.index).collect();
    plot_clip(
        &out.join("clip"),
        &ClipSeries {
            video: clip_video.id,
            names: &names,
            frames: &frames_idx,
            series: &series,
        },
    )?;
    if let Some((_, rs)) = runs.runs.iter().find(|(s, _)| *s == Strategy::MdpTracker)
        && let Some(r) = rs.iter().find(|r| r.video == clip_video.id)
    {
        plot_states(
            &out.join("states"),
            clip_video.id,
            &state_labels(&names),
            &r.frames,
        )?;
        write_json(&out.join("states.json"), &r.frames)?;
    }
    Ok((report, runs))
}
