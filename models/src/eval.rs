//! Evaluation behind `frugal eval`: run a trained model on a dataset split and report
//! mAP@0.5 (all-point, per class and mean), precision / recall / F1 at a score
//! threshold, mean IoU of matched detections, the confusion matrix, a breakdown per
//! scenario (clutter × light), as `report.json` + `report.txt`, and the worst frames
//! with their boxes drawn (`worst/*.png`: ground truth green, correct detections blue,
//! wrong ones red).
use crate::frames::{detect_frames, frame_truth, scenario, spread};
use crate::metrics::{ImageResult, Interpolation, Summary, evaluate, image_counts};
use crate::{FasterRcnn, ModelError};
use frugal_data::{Dataset, FrameRecord, Split};
use frugal_runtime::BBox;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// IoU threshold of every metric here.
pub const IOU: f32 = 0.5;

/// Each scored frame with its detections and ground truth.
pub type FrameResults<'d> = Vec<(&'d FrameRecord, ImageResult)>;

/// The evaluation of one model on one split.
#[derive(Clone, Debug, Serialize)]
pub struct EvalReport {
    /// Split name.
    pub split: String,
    /// Class names, by class id.
    pub classes: Vec<String>,
    /// All frames.
    pub overall: Summary,
    /// Per scenario `"<clutter>-clutter/<light>-light"`.
    pub scenarios: BTreeMap<String, Summary>,
    /// Mean seconds per frame of detection (libtorch, this machine, this load).
    pub seconds_per_frame: f64,
}

/// Evaluate `model` on `split` of `ds` (all frames, or `limit` spread evenly).
pub fn evaluate_split<'d>(
    model: &FasterRcnn,
    ds: &'d Dataset,
    split: Split,
    score_threshold: f32,
    limit: usize,
    progress: bool,
) -> Result<(EvalReport, FrameResults<'d>), ModelError> {
    let frames = spread(ds.split(split).collect(), limit);
    if frames.is_empty() {
        return Err(ModelError::Data(format!(
            "{}: the {} split is empty",
            ds.root.display(),
            split.name()
        )));
    }
    let bar = if progress {
        ProgressBar::new(frames.len() as u64)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("eval {pos}/{len} [{bar:30}] {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let t0 = std::time::Instant::now();
    let mut results = Vec::with_capacity(frames.len());
    for chunk in frames.chunks(16) {
        results.extend(detect_frames(model, ds, chunk)?);
        bar.inc(chunk.len() as u64);
    }
    bar.finish_and_clear();
    let seconds_per_frame = t0.elapsed().as_secs_f64() / frames.len() as f64;
    let k = model.config().num_classes;
    let overall = evaluate(&results, k, IOU, score_threshold, Interpolation::AllPoint);
    let mut groups: BTreeMap<String, Vec<ImageResult>> = BTreeMap::new();
    for (f, r) in frames.iter().zip(&results) {
        groups.entry(scenario(ds, f)).or_default().push(r.clone());
    }
    let scenarios = groups
        .into_iter()
        .map(|(name, rs)| {
            (
                name,
                evaluate(&rs, k, IOU, score_threshold, Interpolation::AllPoint),
            )
        })
        .collect();
    let mut classes: Vec<String> = (0..k).map(|c| format!("class {c}")).collect();
    for info in &ds.classes {
        if let Some(slot) = classes.get_mut(usize::from(info.id)) {
            slot.clone_from(&info.name);
        }
    }
    let report = EvalReport {
        split: split.name().into(),
        classes,
        overall,
        scenarios,
        seconds_per_frame,
    };
    Ok((report, frames.into_iter().zip(results).collect()))
}

fn pct(v: f64) -> String {
    format!("{:6.2}", 100.0 * v)
}

/// A readable table of a report.
pub fn table(r: &EvalReport) -> String {
    let o = &r.overall;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "split {} — {} frames, score threshold {:.2}, IoU {IOU}",
        r.split, o.images, o.score_threshold
    );
    let _ = writeln!(
        s,
        "mAP@0.5 {} %   precision {} %  recall {} %  F1 {} %  mean IoU {:.3}",
        pct(o.map),
        pct(o.precision),
        pct(o.recall),
        pct(o.f1),
        o.mean_iou
    );
    let _ = writeln!(
        s,
        "latency {:.1} ms/frame (incl. PNG decode)\n",
        r.seconds_per_frame * 1e3
    );
    let _ = writeln!(s, "{:<28} {:>8}", "class", "AP %");
    for (name, ap) in r.classes.iter().zip(&o.ap_per_class) {
        let _ = writeln!(s, "{:<28} {:>8}", name, ap.map_or("   n/a".into(), pct));
    }
    let _ = writeln!(
        s,
        "\n{:<34} {:>7} {:>8} {:>8} {:>8} {:>8}",
        "scenario", "frames", "mAP %", "prec %", "recall %", "F1 %"
    );
    for (name, m) in &r.scenarios {
        let _ = writeln!(
            s,
            "{:<34} {:>7} {:>8} {:>8} {:>8} {:>8}",
            name,
            m.images,
            pct(m.map),
            pct(m.precision),
            pct(m.recall),
            pct(m.f1)
        );
    }
    let _ = writeln!(
        s,
        "\nconfusion (rows = truth, cols = predicted, last = background)"
    );
    let k = r.classes.len();
    let _ = write!(s, "{:>4}", "");
    for c in 0..=k {
        let _ = write!(s, "{:>5}", if c == k { "bg".into() } else { c.to_string() });
    }
    let _ = writeln!(s);
    for (i, row) in o.confusion.iter().enumerate() {
        let _ = write!(s, "{:>4}", if i == k { "bg".into() } else { i.to_string() });
        for v in row {
            let _ = write!(s, "{v:>5}");
        }
        let _ = writeln!(s);
    }
    s
}

fn draw_box(img: &mut image::RgbImage, b: &BBox, color: [u8; 3]) {
    let (w, h) = (img.width() as i64, img.height() as i64);
    let (x1, y1) = (
        (b.x1.floor() as i64).clamp(0, w - 1),
        (b.y1.floor() as i64).clamp(0, h - 1),
    );
    let (x2, y2) = (
        ((b.x2.ceil() as i64) - 1).clamp(0, w - 1),
        ((b.y2.ceil() as i64) - 1).clamp(0, h - 1),
    );
    for t in 0..2 {
        for x in x1..=x2 {
            for y in [(y1 + t).min(y2), (y2 - t).max(y1)] {
                img.put_pixel(x as u32, y as u32, image::Rgb(color));
            }
        }
        for y in y1..=y2 {
            for x in [(x1 + t).min(x2), (x2 - t).max(x1)] {
                img.put_pixel(x as u32, y as u32, image::Rgb(color));
            }
        }
    }
}

/// Write `report.json`, `report.txt` and the `worst` worst frames (most errors at the
/// score threshold) with drawn boxes into `out`.
pub fn write_report(
    out: &Path,
    ds: &Dataset,
    report: &EvalReport,
    results: &[(&FrameRecord, ImageResult)],
    worst: usize,
) -> Result<(), ModelError> {
    std::fs::create_dir_all(out.join("worst")).map_err(|e| ModelError::io(out, e))?;
    let json = serde_json::to_vec_pretty(report).map_err(|e| ModelError::Data(e.to_string()))?;
    for (name, bytes) in [
        ("report.json", json),
        ("report.txt", table(report).into_bytes()),
    ] {
        let p = out.join(name);
        let tmp = out.join(format!(".tmp-{name}"));
        std::fs::write(&tmp, bytes).map_err(|e| ModelError::io(&tmp, e))?;
        std::fs::rename(&tmp, &p).map_err(|e| ModelError::io(&p, e))?;
    }
    let thr = report.overall.score_threshold;
    let mut ranked: Vec<(usize, usize)> = results
        .iter()
        .enumerate()
        .map(|(i, (_, r))| {
            let (_, fp, fnn) = image_counts(r, IOU, thr);
            (fp + fnn, i)
        })
        .filter(|(e, _)| *e > 0)
        .collect();
    ranked.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    for (rank, &(errors, i)) in ranked.iter().take(worst).enumerate() {
        let (f, r) = &results[i];
        let mut img = ds
            .load_rgb(f)
            .map_err(|e| ModelError::Data(e.to_string()))?;
        for t in frame_truth(f) {
            draw_box(&mut img, &t.bbox, [0, 220, 0]);
        }
        for d in r.detections.iter().filter(|d| d.score >= thr) {
            let ok = r
                .truth
                .iter()
                .any(|t| t.class == d.class && t.bbox.iou(&d.bbox) >= IOU);
            draw_box(
                &mut img,
                &d.bbox,
                if ok { [40, 90, 255] } else { [255, 30, 30] },
            );
        }
        let p = out
            .join("worst")
            .join(format!("{rank:02}-frame{}-{errors}err.png", f.id));
        img.save(&p).map_err(|e| ModelError::Io {
            file: p.display().to_string(),
            source: std::io::Error::other(e),
        })?;
    }
    Ok(())
}
