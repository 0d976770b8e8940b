//! The run's report: `report.md` and the same as a self-contained `report.html`
//! (images linked relative to the run folder, so it opens offline).
use super::flights::FlightRow;
use super::stage::{Ctx, Outcome};
use frugal_data::dataset::write_atomic;
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

fn read_json(path: &Path) -> Option<Value> {
    serde_json::from_slice(&std::fs::read(path).ok()?).ok()
}

fn read_text(path: &Path) -> Option<String> {
    std::fs::read_to_string(path).ok()
}

/// A figure, if its file exists, linked relative to the run folder.
fn figure(md: &mut String, run: &Path, rel: &str, alt: &str) {
    if run.join(rel).exists() {
        let _ = writeln!(md, "![{alt}]({rel})\n");
    }
}

fn code(md: &mut String, text: &str) {
    let _ = writeln!(md, "```text\n{}\n```\n", text.trim_end());
}

/// "Made by" lines: the commands and config of a stage.
fn provenance(md: &mut String, o: Option<&Outcome>) {
    let Some(o) = o else {
        md.push_str("*Not run yet.*\n\n");
        return;
    };
    md.push_str("Made by:\n\n```sh\n");
    for c in &o.stamp.commands {
        let _ = writeln!(md, "{c}");
    }
    md.push_str("```\n\n");
    let cfg = o
        .stamp
        .config_file
        .as_deref()
        .map_or("flags above, from `config/run.json`".to_string(), |c| {
            format!("[`{c}`]({c})")
        });
    let _ = writeln!(
        md,
        "Config: {cfg}. Inputs hash `{}`; {} in {:.1} s.\n",
        &o.stamp.inputs_hash[..12],
        if o.ran {
            "ran in this invocation"
        } else {
            "made by an earlier invocation"
        },
        o.stamp.seconds
    );
}

/// A CSV file as a markdown table of the chosen columns.
fn csv_table(path: &Path, columns: &[&str]) -> Option<String> {
    let mut r = csv::Reader::from_path(path).ok()?;
    let header = r.headers().ok()?.clone();
    let idx: Vec<usize> = columns
        .iter()
        .filter_map(|c| header.iter().position(|h| h == *c))
        .collect();
    let mut md = String::new();
    let names: Vec<&str> = idx.iter().map(|&i| &header[i]).collect();
    let _ = writeln!(md, "| {} |", names.join(" | "));
    let _ = writeln!(md, "|{}", "---|".repeat(idx.len()));
    for rec in r.records().flatten() {
        let cells: Vec<&str> = idx.iter().map(|&i| rec.get(i).unwrap_or("")).collect();
        let _ = writeln!(md, "| {} |", cells.join(" | "));
    }
    Some(md)
}

fn score<'a>(scores: &'a [Value], scenario: &str, strategy: &str) -> Option<&'a Value> {
    scores
        .iter()
        .find(|s| s["scenario"] == scenario && s["strategy"] == strategy)
}

/// Headline figures, each from the artifact that holds it.
fn headline(run: &Path, flights: &[FlightRow]) -> String {
    let mut md = String::new();
    if let Some(r) = read_json(&run.join("detector/eval-test/report.json")) {
        let hardest = &r["scenarios"]["high-clutter/low-light"]["map"];
        let _ = writeln!(
            md,
            "- **Detector** on the held-out test videos: mAP@0.5 {:.3}, hardest scenario (high clutter, low light) {}.",
            r["overall"]["map"].as_f64().unwrap_or(f64::NAN),
            hardest
                .as_f64()
                .map_or("n/a".to_string(), |v| format!("{v:.3}"))
        );
    }
    if let Some(p) = read_json(&run.join("pareto/pareto.json")) {
        let vs = p["variants"].as_array().cloned().unwrap_or_default();
        let (lo, hi) = crate::figures::cost_range(&vs).unwrap_or((f64::INFINITY, 0.0));
        let front = p["fronts"]["map"]
            .as_array()
            .map(|f| {
                f.iter()
                    .filter_map(Value::as_str)
                    .collect::<Vec<_>>()
                    .join(" → ")
            })
            .unwrap_or_default();
        let _ = writeln!(
            md,
            "- **Variants**: {} made, {lo:.2}–{hi:.2} ms per frame on ONNX Runtime (one thread); mAP front: {front}.",
            vs.len()
        );
    }
    if let Some(e) = read_json(&run.join("evaluation/eval.json")) {
        let scores = e["scores"].as_array().cloned().unwrap_or_default();
        for strat in ["mdp+tracker", "mdp"] {
            if let Some(s) = score(&scores, "all", strat) {
                let _ = writeln!(
                    md,
                    "- **{}** against static ({}) on the test videos: {:.2}× faster ({:.0} fps), F1 {:.3} ({:+.1} points).",
                    if strat == "mdp" {
                        "MDP alone"
                    } else {
                        "MDP + tracker"
                    },
                    e["static_variant"].as_str().unwrap_or("?"),
                    s["speedup_vs_static"].as_f64().unwrap_or(f64::NAN),
                    s["fps"].as_f64().unwrap_or(f64::NAN),
                    s["f1"].as_f64().unwrap_or(f64::NAN),
                    -100.0 * s["f1_loss_vs_static"].as_f64().unwrap_or(f64::NAN),
                );
            }
        }
    }
    for r in flights {
        let _ = writeln!(
            md,
            "- **{} maze**: adaptive {}/{} landed at {:.1} fps, static {}/{} at {:.1} fps ({:.1}× the frame rate){}.",
            r.maze,
            r.adaptive.successes,
            r.adaptive.runs,
            r.adaptive.fps.mean,
            r.r#static.successes,
            r.r#static.runs,
            r.r#static.fps.mean,
            r.fps_ratio,
            r.time_ratio
                .map_or(String::new(), |t| format!(", {t:.1}× sooner"))
        );
    }
    md
}

fn flights_table(rows: &[FlightRow]) -> String {
    let mut md = String::from(
        "| maze | perception | success | collisions | fps | time to goal, s | velocity, cm/s | in-loop recall |\n|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        for (who, s) in [
            (format!("static ({})", r.static_variant), &r.r#static),
            ("adaptive (bundle)".to_string(), &r.adaptive),
        ] {
            let _ = writeln!(
                md,
                "| {} | {who} | {}/{} | {} | {} | {} | {} | {:.2} |",
                r.maze,
                s.successes,
                s.runs,
                s.collisions,
                s.fps.show(1),
                s.time_to_goal_s.show(1),
                s.velocity_cm_s.show(0),
                s.recall
            );
        }
    }
    md
}

/// Write `report.md` and `report.html` into the run folder; returns the markdown path.
pub(crate) fn write(ctx: &Ctx, outcomes: &[Outcome], seconds: f64) -> anyhow::Result<PathBuf> {
    let run = &ctx.run;
    let of = |name: &str| outcomes.iter().find(|o| o.def.name == name);
    let flights: Vec<FlightRow> = std::fs::read(run.join("flights/comparison.json"))
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .unwrap_or_default();
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# frugal run report\n\nRun folder `{}`, profile `{:?}` (every value: [`config/run.json`](config/run.json)); frugal {}. This invocation took {seconds:.1} s.\n",
        run.display(),
        ctx.config.profile,
        env!("CARGO_PKG_VERSION"),
    );
    md.push_str("## Headline figures\n\n");
    md.push_str(&headline(run, &flights));
    md.push_str("\n## Stages\n\n| stage | what | this invocation | seconds | inputs hash |\n|---|---|---|---|---|\n");
    for o in outcomes {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {:.1} | `{}` |",
            o.def.name,
            o.def.what,
            if o.ran { "ran" } else { "skipped (unchanged)" },
            o.stamp.seconds,
            &o.stamp.inputs_hash[..12]
        );
    }

    md.push_str("\n## 1. Data\n\n");
    provenance(&mut md, of("data"));
    figure(&mut md, run, "data/contact_sheet.png", "contact sheet");

    md.push_str("## 2. Detector\n\n");
    provenance(&mut md, of("detector"));
    figure(&mut md, run, "detector/model/curves.png", "training curves");
    if let Some(t) = read_text(&run.join("detector/eval-test/report.txt")) {
        md.push_str("On the held-out test videos:\n\n");
        code(&mut md, &t);
    }

    md.push_str("## 3. Variants and the Pareto front\n\n");
    provenance(&mut md, of("variants"));
    provenance(&mut md, of("pareto"));
    figure(&mut md, run, "pareto/pareto_map.png", "Pareto front, mAP");
    if let Some(t) = csv_table(
        &run.join("pareto/pareto.csv"),
        &[
            "name",
            "technique",
            "input",
            "parameters",
            "map",
            "f1",
            "mean_iou",
            "latency_ms",
            "front_map",
        ],
    ) {
        md.push_str(&t);
        md.push('\n');
    }

    md.push_str("## 4. Policy\n\n");
    provenance(&mut md, of("replay"));
    provenance(&mut md, of("policy"));
    if let Ok(p) = frugal_policies::TrainedPolicy::load(&run.join("policy/policy.json")) {
        code(&mut md, &frugal_policies::report::policy_table(&p));
    }
    figure(&mut md, run, "policy/sweep.png", "α sweep");

    md.push_str("## 5. Replay evaluation\n\n");
    provenance(&mut md, of("evaluation"));
    if let Some(v) = read_json(&run.join("evaluation/eval.json"))
        && let Ok(r) = serde_json::from_value::<frugal_policies::eval::EvalReport>(v)
    {
        let _ = writeln!(
            md,
            "Static strategy: the most accurate variant, `{}`.\n",
            r.static_variant
        );
        code(&mut md, &frugal_policies::report::score_table(&r.scores));
    }
    for (f, alt) in [
        ("evaluation/speed-f1.png", "speed against F1 per strategy"),
        ("evaluation/bars-f1.png", "F1 per scenario"),
        ("evaluation/bars-time.png", "time per frame per scenario"),
        ("evaluation/clip.png", "reward, IoU and time over one clip"),
        ("evaluation/states.png", "the MDP's state over one clip"),
    ] {
        figure(&mut md, run, f, alt);
    }

    md.push_str("## 6. Budget policies, by streaming AP\n\n");
    provenance(&mut md, of("budget"));
    for (dir, what) in [
        ("budget", "On the test videos"),
        (
            "budget/heldout-1",
            "On the held-out videos (a seed and scenario mix no other stage saw)",
        ),
    ] {
        if let Some(t) = read_text(&run.join(dir).join("budget.md")) {
            let _ = writeln!(md, "{what}:\n\n{t}");
            figure(
                &mut md,
                run,
                &format!("{dir}/budget-sap.png"),
                "streaming AP against the budget",
            );
            figure(
                &mut md,
                run,
                &format!("{dir}/budget-speed-f1.png"),
                "speed against F1 per strategy",
            );
        }
    }

    md.push_str("## 7. Bundle\n\n");
    provenance(&mut md, of("bundle"));
    if let Ok(t) = frugal_policies::bundle::inspect(&run.join("bundle")) {
        code(&mut md, &t);
    }

    md.push_str("## 8. Maze flights\n\n");
    provenance(&mut md, of("flights"));
    if !flights.is_empty() {
        md.push_str(&flights_table(&flights));
        md.push('\n');
        for r in &flights {
            figure(
                &mut md,
                run,
                &format!("flights/{}_top_view.png", r.maze),
                &format!("{} maze, static and adaptive trajectories", r.maze),
            );
            figure(
                &mut md,
                run,
                &format!("flights/adaptive/{}/flight.gif", r.maze),
                &format!("{} maze, adaptive flight", r.maze),
            );
        }
    }

    let md_path = run.join("report.md");
    write_atomic(&md_path, md.as_bytes())?;
    frugal_data::dataset::write_json_atomic(
        &run.join("figures.json"),
        &crate::figures::collect(run),
    )?;
    let mut body = String::new();
    let parser = pulldown_cmark::Parser::new_ext(&md, pulldown_cmark::Options::ENABLE_TABLES);
    pulldown_cmark::html::push_html(&mut body, parser);
    let html = format!(
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>frugal run report</title>\n<style>\nbody {{ font-family: sans-serif; max-width: 70em; margin: 2em auto; padding: 0 1em; line-height: 1.45; }}\ntable {{ border-collapse: collapse; }} td, th {{ border: 1px solid #bbb; padding: 0.2em 0.6em; }}\npre {{ background: #f4f4f4; padding: 0.8em; overflow-x: auto; }} img {{ max-width: 100%; }}\n</style></head><body>\n{body}</body></html>\n"
    );
    write_atomic(&run.join("report.html"), html.as_bytes())?;
    Ok(md_path)
}
