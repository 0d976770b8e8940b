//! What `policy train` and `policy eval` write: JSON, CSV and the figures.

use crate::error::{PolicyError, Result};
use crate::eval::{
    ClassScore, EvalConfig, EvalReport, Runs, Score, Strategy, class_scores, run_all, scores,
};
use crate::plot::{ClipSeries, plot_bars, plot_class_bars, plot_clip, plot_states, plot_sweep};
use crate::replay::{Frames, ReplayLog, VideoLog};
use crate::sweep::{SweepPoint, sweep_with};
use crate::train::{PolicyConfig, TrainedPolicy, Transitions, Weights, train_with};
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
    // counted once: the policy and every point of the sweep share the transitions
    let transitions = Transitions::training(log, cfg);
    let policy = train_with(log, &transitions, cfg)?;
    policy.save(&out.join("policy.json"))?;
    let points = sweep_with(log, &transitions, cfg, eval)?;
    write_json(&out.join("sweep.json"), &points)?;
    let mut csv = String::from("reward,alpha,ge_scale,ms_per_frame,f1\n");
    for p in &points {
        let _ = writeln!(
            csv,
            "{},{},{},{:.4},{:.4}",
            p.reward.name(),
            p.alpha,
            p.ge_scale,
            p.ms_per_frame,
            p.f1
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
        "policy ({} reward, α {}, γ {}, value iteration {} sweeps, policy iteration agrees: {})",
        p.config.reward.name(),
        p.config.alpha,
        p.config.gamma,
        p.iterations,
        p.policy_iteration_agrees
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
    plot_speed_f1(&out.join("speed-f1"), &sc)?;
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

fn per_class_csv(rows: &[ClassScore]) -> String {
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.4}"));
    let mut s =
        String::from("strategy,class,name,frames,tp,fp,fn,precision,recall,ms_per_frame,ms_std\n");
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{:.4},{:.4}",
            r.strategy,
            r.class.map_or("all".to_string(), |c| c.to_string()),
            r.name,
            r.frames,
            r.tp,
            r.fp,
            r.fn_,
            opt(r.precision),
            opt(r.recall),
            r.ms_per_frame,
            r.ms_std
        );
    }
    s
}

/// The paper's KUL table as Markdown: per class, precision `P` (and, beyond the paper,
/// recall `R`) and compute time per frame `E` (mean ± standard deviation over the
/// frames showing the class) of `base`
/// ("Average") and `other` ("Good Enough"), the speed-up `E_base / E_other`, the time
/// saved `1 − E_other / E_base` and the relative precision loss
/// `(P_base − P_other) / P_base`, then the all-classes row.
pub fn kul_table(rows: &[ClassScore], base: Strategy, other: Strategy) -> String {
    let f = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.3}"));
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| class | frames | P {b} | R {b} | E {b} [ms] | P {o} | R {o} | E {o} [ms] | speed-up | time saved | precision loss |",
        b = base.name(),
        o = other.name()
    );
    s.push_str("|---|---|---|---|---|---|---|---|---|---|---|\n");
    let of = |st: Strategy| rows.iter().filter(move |r| r.strategy == st.name());
    for a in of(base) {
        let Some(b) = of(other).find(|r| r.class == a.class) else {
            continue;
        };
        let speedup = (b.ms_per_frame > 0.0).then(|| a.ms_per_frame / b.ms_per_frame);
        let saved = (a.ms_per_frame > 0.0).then(|| 100.0 * (1.0 - b.ms_per_frame / a.ms_per_frame));
        let loss = match (a.precision, b.precision) {
            (Some(pa), Some(pb)) if pa > 0.0 => format!("{:.1} %", 100.0 * (pa - pb) / pa),
            _ => "–".into(),
        };
        let name = if a.class.is_none() {
            format!("**{}**", a.name)
        } else {
            a.name.clone()
        };
        let _ = writeln!(
            s,
            "| {name} | {} | {} | {} | {:.1} ± {:.1} | {} | {} | {:.1} ± {:.1} | {} | {} | {loss} |",
            a.frames,
            f(a.precision),
            f(a.recall),
            a.ms_per_frame,
            a.ms_std,
            f(b.precision),
            f(b.recall),
            b.ms_per_frame,
            b.ms_std,
            speedup.map_or("–".into(), |v| format!("{v:.2}×")),
            saved.map_or("–".into(), |v| format!("{v:.1} %")),
        );
    }
    s
}

/// Per-class scores of every strategy in `runs`, written as `per_class.json`,
/// `per_class.csv`, `kul.md` (the KUL table of static vs MDP and of static vs
/// MDP + tracker, where those strategies were run) and the bar charts
/// `per_class-precision|time.png|svg` of those three strategies into `out`. `names`
/// are the class names in id order.
pub fn write_per_class(
    log: &ReplayLog,
    runs: &Runs,
    cfg: &EvalConfig,
    names: &[String],
    out: &Path,
) -> Result<Vec<ClassScore>> {
    let rows = class_scores(log, runs, cfg, names);
    write_json(&out.join("per_class.json"), &rows)?;
    write_text(&out.join("per_class.csv"), &per_class_csv(&rows))?;
    let static_name = log
        .variants
        .get(runs.static_variant)
        .map_or("?", |v| v.name.as_str());
    write_text(&out.join("kul.md"), &kul_tables(runs, &rows, static_name))?;
    let shown = [Strategy::Static, Strategy::Mdp, Strategy::MdpTracker].map(Strategy::name);
    plot_class_bars(&out.join("per_class"), &rows, &shown)?;
    Ok(rows)
}

/// The KUL tables of the strategies `runs` holds: static vs MDP, static vs MDP + tracker
/// (`static_name`: the static strategy's variant).
pub fn kul_tables(runs: &Runs, rows: &[ClassScore], static_name: &str) -> String {
    let has = |s: Strategy| runs.runs.iter().any(|(x, _)| *x == s);
    let mut s = String::new();
    for other in [Strategy::Mdp, Strategy::MdpTracker] {
        if has(Strategy::Static) && has(other) {
            let _ = writeln!(
                s,
                "static = {static_name} (\"Average\") vs {} (\"Good Enough\"):\n",
                other.name()
            );
            s.push_str(&kul_table(rows, Strategy::Static, other));
            s.push('\n');
        }
    }
    s
}

/// Speed-up against F1, one point per strategy over every test video: the trade-off a
/// few F1 points wide that grouped bars hide.
pub fn plot_speed_f1(stem: &std::path::Path, scores: &[Score]) -> Result<()> {
    let mut names: Vec<&str> = Vec::new();
    for s in scores {
        if !names.contains(&s.strategy.as_str()) {
            names.push(&s.strategy);
        }
    }
    let series: Vec<(String, Vec<(f64, f64)>)> = names
        .iter()
        .map(|n| {
            let pts = scores
                .iter()
                .filter(|s| s.strategy == *n && s.scenario == "all")
                .map(|s| (s.speedup_vs_static, s.f1))
                .collect();
            (n.to_string(), pts)
        })
        .collect();
    crate::plot::plot_points(
        stem,
        "speed against F1, every test video (replay, no clock)",
        ("speed-up vs static (time per frame)", "F1 @ IoU 0.5"),
        &series,
    )
}
