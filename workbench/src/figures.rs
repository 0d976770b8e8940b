//! The run's figures as one flat, named list (`<run>/figures.json`), and the check that
//! keeps a document's quoted figures equal to them.
//!
//! A document quotes a figure as a Markdown link whose target names the figures file
//! and the key: `[0.978](docs/results/figures.json#detector.map)`. The link text must
//! be the file's value for that key, character for character. `frugal figures check`
//! fails on any difference or unknown key; `frugal figures publish` copies a run's
//! figures (and report) into the repository and rewrites every quoted figure from
//! them, so a figure is generated, never typed.
use anyhow::Context;
use clap::{Args, Subcommand};
use frugal_pareto::stats::Latency;
use serde::Deserialize;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Figures by key.
pub type Figures = BTreeMap<String, String>;

fn read_json(path: &Path) -> Option<Value> {
    serde_json::from_slice(&std::fs::read(path).ok()?).ok()
}

fn f(v: &Value, digits: usize) -> Option<String> {
    v.as_f64().map(|x| format!("{x:.digits$}"))
}

/// The cost of a `pareto.json` latency record, as the Pareto stage charges it
/// ([`Latency::cost_ms`]); `None` when the record does not read.
fn cost_ms(latency: &Value) -> Option<f64> {
    Latency::deserialize(latency).ok().map(|l| l.cost_ms())
}

/// The cheapest and the dearest cost over a `pareto.json`'s variants; `None` without
/// any.
pub(crate) fn cost_range(variants: &[Value]) -> Option<(f64, f64)> {
    let costs: Vec<f64> = variants
        .iter()
        .filter_map(|v| cost_ms(&v["latency"]))
        .collect();
    (!costs.is_empty()).then(|| {
        costs
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(l, h), &x| (l.min(x), h.max(x)))
    })
}

fn signed(x: f64) -> String {
    format!("{x:+.1}")
}

/// Every figure the run's artifacts hold that a document may quote.
pub fn collect(run: &Path) -> Figures {
    let mut out = Figures::new();
    let mut put = |k: String, v: Option<String>| {
        if let Some(v) = v {
            out.insert(k, v);
        }
    };
    if let Some(r) = read_json(&run.join("detector/eval-test/report.json")) {
        put("detector.map".into(), f(&r["overall"]["map"], 3));
        put("detector.f1".into(), f(&r["overall"]["f1"], 3));
        put(
            "detector.hardest_map".into(),
            f(&r["scenarios"]["high-clutter/low-light"]["map"], 3),
        );
    }
    if let Some(p) = read_json(&run.join("pareto/pareto.json")) {
        let vs = p["variants"].as_array().cloned().unwrap_or_default();
        put("variants.count".into(), Some(vs.len().to_string()));
        if let Some((lo, hi)) = cost_range(&vs) {
            put("variants.fastest_ms".into(), Some(format!("{lo:.2}")));
            put("variants.slowest_ms".into(), Some(format!("{hi:.2}")));
        }
        put(
            "device.reference_ms".into(),
            cost_ms(&p["reference"]).map(|ms| format!("{ms:.2}")),
        );
        put(
            "device.reference_int8_ms".into(),
            cost_ms(&p["reference_int8"]).map(|ms| format!("{ms:.2}")),
        );
        if let Some(front) = p["fronts"]["map"].as_array() {
            let names: Vec<&str> = front.iter().filter_map(Value::as_str).collect();
            put("front.map".into(), Some(names.join(" → ")));
            for name in names {
                if let Some(v) = vs.iter().find(|v| v["name"] == name) {
                    put(
                        format!("front.{name}.ms"),
                        cost_ms(&v["latency"]).map(|ms| format!("{ms:.2}")),
                    );
                    put(format!("front.{name}.map"), f(&v["map"], 3));
                    put(format!("front.{name}.map_se"), f(&v["map_se"], 3));
                }
            }
        }
    }
    if let Some(e) = read_json(&run.join("evaluation/eval.json")) {
        put(
            "replay.static".into(),
            e["static_variant"].as_str().map(String::from),
        );
        for s in e["scores"].as_array().into_iter().flatten() {
            if s["scenario"] != "all" {
                continue;
            }
            let Some(name) = s["strategy"].as_str() else {
                continue;
            };
            put(
                format!("replay.{name}.speedup"),
                f(&s["speedup_vs_static"], 2),
            );
            put(format!("replay.{name}.f1"), f(&s["f1"], 3));
            put(
                format!("replay.{name}.f1_points"),
                s["f1_loss_vs_static"].as_f64().map(|l| signed(-100.0 * l)),
            );
        }
    }
    if let Some(p) = read_json(&run.join("budget/policy.json")) {
        let c = &p["budget"]["config"];
        put("device.slowdown".into(), f(&c["slowdown"], 2));
        put(
            "device.device_reference_ms".into(),
            f(&c["device_reference_ms"], 1),
        );
        put("device.slowdown_int8".into(), f(&c["slowdown_int8"], 2));
        put(
            "device.device_reference_int8_ms".into(),
            f(&c["device_reference_int8_ms"], 1),
        );
    }
    for (set, dir) in [("test", "budget"), ("heldout", "budget/heldout-1")] {
        if let Some(scores) = read_json(&run.join(dir).join("budget.json")) {
            for s in scores.as_array().into_iter().flatten() {
                if s["scenario"] != "all" {
                    continue;
                }
                let (Some(b), Some(name)) = (s["budget_ms"].as_f64(), s["strategy"].as_str())
                else {
                    continue;
                };
                let k = format!("budget.{set}.{b}.{name}");
                put(
                    format!("{k}.sap50"),
                    s["sap50"].as_f64().map(|x| format!("{:.1}", 100.0 * x)),
                );
                put(format!("{k}.f1"), f(&s["f1"], 3));
                put(format!("{k}.sf1"), f(&s["sf1"], 3));
                put(format!("{k}.speedup"), f(&s["speedup_vs_static"], 2));
                put(format!("{k}.ms"), f(&s["timing"]["device_ms_per_frame"], 1));
            }
        }
        if let Some(ms) = read_json(&run.join(dir).join("margins.json")) {
            for m in ms.as_array().into_iter().flatten() {
                let Some(b) = m["budget_ms"].as_f64() else {
                    continue;
                };
                let k = format!("budget.{set}.{b}");
                put(
                    format!("{k}.best_baseline"),
                    m["best_baseline"].as_str().map(String::from),
                );
                if let (Some(o), Some(bb)) = (
                    m["budget_sap50"].as_f64(),
                    m["best_baseline_sap50"].as_f64(),
                ) {
                    put(format!("{k}.margin"), Some(signed(100.0 * (o - bb))));
                }
                // the margin's interval over the videos (paired bootstrap)
                let bounds = m["interval"]["best_baseline"].as_array();
                for (end, x) in ["lo", "hi"].iter().zip(bounds.into_iter().flatten()) {
                    put(
                        format!("{k}.margin_{end}"),
                        x.as_f64().map(|x| signed(100.0 * x)),
                    );
                }
                let versus = |want: &str| {
                    m["versus"]
                        .as_array()
                        .into_iter()
                        .flatten()
                        .find(|p| p[0].as_str() == Some(want))
                        .and_then(|p| p[1].as_f64())
                };
                for pair in m["versus"].as_array().into_iter().flatten() {
                    if let (Some(name), Some(d)) = (pair[0].as_str(), pair[1].as_f64()) {
                        put(format!("{k}.vs.{name}"), Some(signed(100.0 * d)));
                    }
                }
                // how far the hindsight bound leads the better of static and static +
                // tracker (the fixed schedules it chooses among): the room a scheduler
                // choosing per video has on these videos
                if let (Some(st), Some(s), Some(h)) = (
                    versus("static+tracker"),
                    versus("static"),
                    versus("hindsight"),
                ) {
                    put(
                        format!("{k}.hindsight_room"),
                        Some(signed(100.0 * (st.min(s) - h))),
                    );
                }
            }
        }
    }
    if let Some(rows) = read_json(&run.join("flights/comparison.json")) {
        for r in rows.as_array().into_iter().flatten() {
            let Some(maze) = r["maze"].as_str() else {
                continue;
            };
            for who in ["static", "adaptive"] {
                let s = &r[who];
                if let (Some(ok), Some(n)) = (s["successes"].as_u64(), s["runs"].as_u64()) {
                    put(
                        format!("flights.{maze}.{who}.landed"),
                        Some(format!("{ok}/{n}")),
                    );
                }
                put(format!("flights.{maze}.{who}.fps"), f(&s["fps"]["mean"], 1));
            }
            put(format!("flights.{maze}.fps_ratio"), f(&r["fps_ratio"], 1));
            put(format!("flights.{maze}.time_ratio"), f(&r["time_ratio"], 1));
        }
    }
    let mut total = 0.0;
    for st in crate::run::stage_names() {
        if let Some(s) = read_json(&run.join(st).join(".stamp.json"))
            && let Some(sec) = s["seconds"].as_f64()
        {
            total += sec;
            put(format!("time.{st}.min"), Some(format!("{:.1}", sec / 60.0)));
        }
    }
    if total > 0.0 {
        put(
            "time.total.min".into(),
            Some(format!("{:.1}", total / 60.0)),
        );
    }
    out
}

/// A quoted figure that does not match.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Mismatch {
    /// 1-based line in the document.
    pub line: usize,
    /// The key.
    pub key: String,
    /// The text the document shows.
    pub shown: String,
    /// The figures file's value (`None`: no such key).
    pub expected: Option<String>,
}

/// A Markdown link `[label](target)` (or image `![label](target)`) of a document: byte
/// offsets of its `[`, its `]` and its `)`.
struct Link {
    open: usize,
    close: usize,
    end: usize,
}

impl Link {
    fn target<'a>(&self, doc: &'a str) -> &'a str {
        &doc[self.close + 2..self.end]
    }
}

/// Every link of `doc`, in order (a link does not span lines).
fn links(doc: &str) -> Vec<Link> {
    let mut out = Vec::new();
    let mut offset = 0;
    for line in doc.split_inclusive('\n') {
        let mut from = 0;
        while let Some(p) = line[from..].find("](") {
            let close = from + p;
            let Some(end) = line[close + 2..].find(')').map(|e| close + 2 + e) else {
                break;
            };
            if let Some(open) = line[..close].rfind('[') {
                out.push(Link {
                    open: offset + open,
                    close: offset + close,
                    end: offset + end,
                });
            }
            from = end;
        }
        offset += line.len();
    }
    out
}

/// Every `[text](<…>figures.json#key)` link of `doc`: (line, byte range of the text,
/// key).
fn quoted(doc: &str) -> Vec<(usize, std::ops::Range<usize>, String)> {
    const MARK: &str = "figures.json#";
    links(doc)
        .into_iter()
        .filter_map(|l| {
            let target = l.target(doc);
            let k = target.find(MARK)?;
            let line = doc[..l.open].matches('\n').count() + 1;
            Some((
                line,
                l.open + 1..l.close,
                target[k + MARK.len()..].to_string(),
            ))
        })
        .collect()
}

/// The quoted figures of `doc` that differ from `figures` (or name no figure).
pub fn check(doc: &str, figures: &Figures) -> Vec<Mismatch> {
    quoted(doc)
        .into_iter()
        .filter_map(|(line, range, key)| {
            let shown = &doc[range];
            let expected = figures.get(&key);
            (expected.map(String::as_str) != Some(shown)).then(|| Mismatch {
                line,
                key,
                shown: shown.to_string(),
                expected: expected.cloned(),
            })
        })
        .collect()
}

/// `doc` with every quoted figure rewritten from `figures`; an unknown key is an error.
pub fn update(doc: &str, figures: &Figures) -> Result<String, Mismatch> {
    let mut out = String::with_capacity(doc.len());
    let mut last = 0;
    for (line, range, key) in quoted(doc) {
        let Some(v) = figures.get(&key) else {
            return Err(Mismatch {
                line,
                key,
                shown: doc[range].to_string(),
                expected: None,
            });
        };
        out.push_str(&doc[last..range.start]);
        out.push_str(v);
        last = range.end;
    }
    out.push_str(&doc[last..]);
    Ok(out)
}

/// `text` (a run's report) with its run-relative links pointed at the published copies
/// (`files`: run path → published name); a link to anything not published becomes
/// plain text naming the run file, so the published report has no dead link.
pub fn relink(text: &str, files: &[(&str, &str)]) -> String {
    let mut out = String::with_capacity(text.len());
    let mut last = 0;
    for l in links(text) {
        let target = l.target(text);
        if target.contains("://") || target.starts_with('#') {
            continue;
        }
        let image = l.open > 0 && text.as_bytes()[l.open - 1] == b'!';
        let start = if image { l.open - 1 } else { l.open };
        out.push_str(&text[last..start]);
        let label = &text[l.open + 1..l.close];
        match files.iter().find(|(from, _)| *from == target) {
            Some((_, name)) => {
                out.push_str(&text[start..l.close + 2]);
                out.push_str(name);
                out.push(')');
            }
            None if image => out.push_str(&format!("*{label}: `{target}` in the run folder*")),
            None => out.push_str(&format!("{label} (`{target}` in the run folder)")),
        }
        last = l.end + 1;
    }
    out.push_str(&text[last..]);
    out
}

/// Options of `frugal figures`.
#[derive(Args, Debug)]
pub struct FiguresArgs {
    #[command(subcommand)]
    command: FiguresCommand,
}

#[derive(Subcommand, Debug)]
enum FiguresCommand {
    /// Check that every figure the documents quote equals the figures file's.
    Check {
        /// The figures file (as `frugal run` writes it, or its published copy).
        #[arg(long, default_value = "docs/results/figures.json")]
        figures: PathBuf,
        /// The documents.
        #[arg(default_value = "README.md")]
        docs: Vec<PathBuf>,
    },
    /// Copy a run's figures, report and pictures into `--to`, and rewrite the figures
    /// the documents quote.
    Publish {
        /// The run folder.
        #[arg(long, default_value = "runs/default")]
        run: PathBuf,
        /// Where the published copy goes.
        #[arg(long, default_value = "docs/results")]
        to: PathBuf,
        /// The documents to rewrite.
        #[arg(default_value = "README.md")]
        docs: Vec<PathBuf>,
    },
}

/// Read a figures file.
pub fn load(path: &Path) -> anyhow::Result<Figures> {
    let bytes = std::fs::read(path).with_context(|| format!("{}", path.display()))?;
    serde_json::from_slice(&bytes).with_context(|| {
        format!(
            "{}: not a figures file (a JSON object of strings)",
            path.display()
        )
    })
}

fn report(doc: &Path, bad: &[Mismatch]) -> String {
    bad.iter()
        .map(|m| match &m.expected {
            Some(e) => format!(
                "{}:{}: `{}` shows {} but the run says {e}",
                doc.display(),
                m.line,
                m.key,
                m.shown
            ),
            None => format!(
                "{}:{}: `{}` is not a figure of the run",
                doc.display(),
                m.line,
                m.key
            ),
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// Run `frugal figures …`.
pub fn run(args: FiguresArgs) -> anyhow::Result<()> {
    match args.command {
        FiguresCommand::Check { figures, docs } => {
            let figs = load(&figures)?;
            let mut problems = Vec::new();
            let mut n = 0;
            for d in &docs {
                let text =
                    std::fs::read_to_string(d).with_context(|| format!("{}", d.display()))?;
                n += quoted(&text).len();
                let bad = check(&text, &figs);
                if !bad.is_empty() {
                    problems.push(report(d, &bad));
                }
            }
            if !problems.is_empty() {
                anyhow::bail!(
                    "{}\n(rewrite them with `frugal figures publish`)",
                    problems.join("\n")
                );
            }
            println!("{n} quoted figures match {}", figures.display());
            Ok(())
        }
        FiguresCommand::Publish { run, to, docs } => {
            let figs = collect(&run);
            if figs.is_empty() {
                anyhow::bail!("{}: no figures (has `frugal run` made it?)", run.display());
            }
            std::fs::create_dir_all(&to).with_context(|| format!("{}", to.display()))?;
            frugal_data::dataset::write_json_atomic(&to.join("figures.json"), &figs)?;
            let files = crate::run::published_files();
            for (from, name) in files {
                let src = run.join(from);
                if !src.exists() {
                    continue;
                }
                let mut bytes =
                    std::fs::read(&src).with_context(|| format!("{}", src.display()))?;
                if name.ends_with(".md") {
                    let text = String::from_utf8_lossy(&bytes);
                    bytes = relink(&text, files).into_bytes();
                }
                frugal_data::dataset::write_atomic(&to.join(name), &bytes)?;
            }
            for d in &docs {
                let text =
                    std::fs::read_to_string(d).with_context(|| format!("{}", d.display()))?;
                let new =
                    update(&text, &figs).map_err(|m| anyhow::anyhow!("{}", report(d, &[m])))?;
                frugal_data::dataset::write_atomic(d, new.as_bytes())?;
            }
            println!(
                "{} figures of {} published to {}",
                figs.len(),
                run.display(),
                to.display()
            );
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn figs() -> Figures {
        [("detector.map", "0.978"), ("front.map", "a → b")]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    #[test]
    fn a_matching_document_passes_and_a_drifted_one_fails() {
        let ok = "mAP [0.978](docs/results/figures.json#detector.map), front [a → b](figures.json#front.map), [a link](x.md#y)\n";
        assert!(check(ok, &figs()).is_empty());
        let drifted = "line one\nmAP [0.975](docs/results/figures.json#detector.map)\n";
        assert_eq!(
            check(drifted, &figs()),
            vec![Mismatch {
                line: 2,
                key: "detector.map".into(),
                shown: "0.975".into(),
                expected: Some("0.978".into()),
            }]
        );
        let unknown = "[1](figures.json#nope)";
        assert_eq!(check(unknown, &figs())[0].expected, None);
    }

    #[test]
    fn a_published_report_links_only_what_was_published() {
        let files = [("pareto/pareto_map.png", "pareto_map.png")];
        let md = "![front](pareto/pareto_map.png) and ![sheet](data/sheet.png), [cfg](config/run.json), [w](https://x.org/a)\n";
        assert_eq!(
            relink(md, &files),
            "![front](pareto_map.png) and *sheet: `data/sheet.png` in the run folder*, cfg (`config/run.json` in the run folder), [w](https://x.org/a)\n"
        );
    }

    #[test]
    fn update_rewrites_every_quoted_figure_and_nothing_else() {
        let doc = "a [0.9](figures.json#detector.map) b [x](figures.json#front.map) [k](l)\n";
        let new = update(doc, &figs()).unwrap();
        assert_eq!(
            new,
            "a [0.978](figures.json#detector.map) b [a → b](figures.json#front.map) [k](l)\n"
        );
        assert!(check(&new, &figs()).is_empty());
        assert!(update("[1](figures.json#nope)", &figs()).is_err());
    }
}
