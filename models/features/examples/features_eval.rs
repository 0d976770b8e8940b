//! Proposal recall, training and per-class accuracy of the feature-based family on a
//! `frugal-data` dataset (generated with the default config when the folder holds
//! none). Prints tables; writes the model to `<data>/../features-model.json`.
//!
//! `cargo run --release -p frugal-features --example features_eval -- DATA_DIR
//!  [TRAIN_STRIDE] [TEST_STRIDE] [PARAMS...]` (train stride 0: proposal recall only;
//!  `reuse`: evaluate the saved model, without the recall table)

use frugal_data::{GenConfig, Split};
use frugal_features::data::{class_names, load_frames};
use frugal_features::eval::{evaluate, proposal_recall};
use frugal_features::{HogParams, TrainConfig, train};
use std::path::PathBuf;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = PathBuf::from(
        args.first()
            .ok_or("usage: features_eval DATA_DIR [TRAIN_STRIDE] [TEST_STRIDE] [PARAMS...]")?,
    );
    // "reuse": evaluate the saved model only.
    let train_stride: usize = match args.get(1).map(String::as_str) {
        Some("reuse") => usize::MAX,
        other => other.map_or(Ok(6), str::parse)?,
    };
    let test_stride: usize = args.get(2).map_or(Ok(4), |s| s.parse())?;
    let mut params: Vec<HogParams> = args
        .iter()
        .skip(3)
        .map(|s| s.parse())
        .collect::<Result<_, _>>()?;
    if params.is_empty() {
        params.push(HogParams::BASELINE);
    }
    let (ds, reused) = frugal_data::generate_or_reuse(&GenConfig::default(), &dir, true)?;
    println!(
        "dataset {} ({}), {} frames",
        dir.display(),
        if reused { "reused" } else { "generated" },
        ds.frames.len()
    );
    // FEATURES_EVAL_SPLIT=val scores the validation split (for choosing settings);
    // FEATURES_EVAL_INTERP=1 turns on HoG orientation interpolation.
    let split = if std::env::var("FEATURES_EVAL_SPLIT").is_ok_and(|s| s == "val") {
        Split::Val
    } else {
        Split::Test
    };
    let test = load_frames(&ds, split, test_stride, usize::MAX)?;
    let cfg = TrainConfig {
        orientation_interpolation: std::env::var("FEATURES_EVAL_INTERP").is_ok_and(|s| s == "1"),
        ..TrainConfig::default()
    };
    let out = dir.with_file_name("features-model.json");
    if train_stride == usize::MAX {
        // Reuse the saved model, skip proposal recall: a per-variant cost run.
        let model = frugal_features::FeatureModel::load(&out)?;
        for p in &params {
            let r = evaluate(&model, *p, &test, model.thresholds.ge, 0.5)?;
            let tot = r.total();
            println!(
                "{p}: {:.1} ms/frame wall, P {:.3} R {:.3}",
                r.mean_ms,
                tot.precision().unwrap_or(0.0),
                tot.recall().unwrap_or(0.0)
            );
        }
        return Ok(());
    }
    let counts = [200, 500, 1000, 2000];
    let (recall, ms) = proposal_recall(&cfg.edgeboxes, &test, &counts, 0.5)?;
    let signs: usize = test.iter().map(|f| f.objects.len()).sum();
    println!(
        "\nEdgeBoxes proposal recall at IoU 0.5, {} test frames, {signs} signs, {ms:.1} ms/frame",
        test.len()
    );
    println!("| proposals | recall |\n|---|---|");
    for (n, r) in &recall {
        println!("| {n} | {r:.3} |");
    }
    if train_stride == 0 {
        return Ok(()); // proposals only
    }
    let trainf = load_frames(&ds, Split::Train, train_stride, usize::MAX)?;
    let t = Instant::now();
    let model = train(&trainf, &class_names(&ds), &params, &cfg, &|_| {})?;
    println!(
        "\ntrained {} HoG configuration(s) on {} frames in {:.1} s",
        model.hogs.len(),
        trainf.len(),
        t.elapsed().as_secs_f64()
    );
    model.save(&out)?;
    for p in &params {
        let r = evaluate(&model, *p, &test, model.thresholds.ge, 0.5)?;
        let tot = r.total();
        println!(
            "\nvariant {p}: {:.1} ms/frame, precision {:.3}, recall {:.3} (score >= {}, IoU 0.5)",
            r.mean_ms,
            tot.precision().unwrap_or(0.0),
            tot.recall().unwrap_or(0.0),
            r.score_threshold
        );
        println!("| class | TP | FP | missed | precision | recall |\n|---|---|---|---|---|---|");
        for (name, c) in model.classes.iter().zip(&r.per_class) {
            let f = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
            println!(
                "| {name} | {} | {} | {} | {} | {} |",
                c.tp,
                c.fp,
                c.missed,
                f(c.precision()),
                f(c.recall())
            );
        }
    }
    Ok(())
}
