//! Training curves: `curves.csv` and a two-panel plot (losses, validation mAP per
//! epoch) as `curves.png` and `curves.svg`.
use crate::ModelError;
use plotters::coord::Shift;
use plotters::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One line of the training curves.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpochRecord {
    /// Epoch number, from 1.
    pub epoch: usize,
    /// Optimizer steps done at its end.
    pub step: u64,
    /// Mean total loss over the epoch.
    pub loss: f64,
    /// Mean RPN objectness loss.
    pub rpn_objectness: f64,
    /// Mean RPN box loss.
    pub rpn_box: f64,
    /// Mean RoI classification loss.
    pub roi_class: f64,
    /// Mean RoI box loss.
    pub roi_box: f64,
    /// Validation mAP@0.5 (all-point) at its end (`None`: not validated, see
    /// `train.val_every`).
    pub val_map: Option<f64>,
    /// Learning rate at its last step.
    pub lr: f64,
    /// Wall-clock seconds it took (training + validation).
    pub seconds: f64,
    /// Of those: reading, decoding and augmenting the training frames.
    #[serde(default)]
    pub data_s: f64,
    /// The forward passes and losses.
    #[serde(default)]
    pub forward_s: f64,
    /// The backward passes and optimizer steps.
    #[serde(default)]
    pub backward_s: f64,
    /// Scoring the validation frames.
    #[serde(default)]
    pub validation_s: f64,
}

fn plot_err(path: &Path, e: impl std::fmt::Display) -> ModelError {
    ModelError::Io {
        file: path.display().to_string(),
        source: std::io::Error::other(e.to_string()),
    }
}

/// A named loss curve: label, accessor, colour.
type Series = (&'static str, fn(&EpochRecord) -> f64, RGBColor);

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, h: &[EpochRecord]) -> Result<(), String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let (left, right) = root.split_horizontally(560);
    let n = h.len().max(2) as f64;
    let ymax = h.iter().map(|r| r.loss).fold(0.1f64, f64::max) * 1.1;
    let mut c = ChartBuilder::on(&left)
        .caption("training losses", ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(1f64..n, 0f64..ymax)
        .map_err(|e| e.to_string())?;
    c.configure_mesh()
        .x_desc("epoch")
        .y_desc("loss")
        .draw()
        .map_err(|e| e.to_string())?;
    let series: [Series; 5] = [
        ("total", |r| r.loss, BLACK),
        ("rpn objectness", |r| r.rpn_objectness, BLUE),
        ("rpn box", |r| r.rpn_box, CYAN),
        ("roi class", |r| r.roi_class, RED),
        ("roi box", |r| r.roi_box, MAGENTA),
    ];
    for (name, f, color) in series {
        c.draw_series(LineSeries::new(
            h.iter().map(|r| (r.epoch as f64, f(r))),
            color.stroke_width(2),
        ))
        .map_err(|e| e.to_string())?
        .label(name)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
    }
    c.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| e.to_string())?;
    let mut m = ChartBuilder::on(&right)
        .caption("validation mAP@0.5", ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(1f64..n, 0f64..1f64)
        .map_err(|e| e.to_string())?;
    m.configure_mesh()
        .x_desc("epoch")
        .y_desc("mAP")
        .draw()
        .map_err(|e| e.to_string())?;
    m.draw_series(LineSeries::new(
        h.iter()
            .filter_map(|r| r.val_map.map(|m| (r.epoch as f64, m))),
        GREEN.stroke_width(2),
    ))
    .map_err(|e| e.to_string())?;
    m.draw_series(
        h.iter()
            .filter_map(|r| r.val_map.map(|m| (r.epoch as f64, m)))
            .map(|p| Circle::new(p, 4, GREEN.filled())),
    )
    .map_err(|e| e.to_string())?;
    root.present().map_err(|e| e.to_string())
}

/// Write `curves.csv`, `curves.png` and `curves.svg` into `dir` (temp file + rename).
pub fn write(dir: &Path, history: &[EpochRecord]) -> Result<(), ModelError> {
    let mut csv = String::from(
        "epoch,step,loss,rpn_objectness,rpn_box,roi_class,roi_box,val_map,lr,seconds,data_s,forward_s,backward_s,validation_s\n",
    );
    for r in history {
        csv.push_str(&format!(
            "{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{},{:.3e},{:.1},{:.1},{:.1},{:.1},{:.1}\n",
            r.epoch,
            r.step,
            r.loss,
            r.rpn_objectness,
            r.rpn_box,
            r.roi_class,
            r.roi_box,
            r.val_map.map_or(String::new(), |m| format!("{m:.6}")),
            r.lr,
            r.seconds,
            r.data_s,
            r.forward_s,
            r.backward_s,
            r.validation_s
        ));
    }
    let p = dir.join("curves.csv");
    let tmp = dir.join(".tmp-curves.csv");
    std::fs::write(&tmp, csv).map_err(|e| ModelError::io(&tmp, e))?;
    std::fs::rename(&tmp, &p).map_err(|e| ModelError::io(&p, e))?;
    let size = (1100, 420);
    let png = dir.join("curves.png");
    let tmp = dir.join(".tmp-curves.png");
    draw(BitMapBackend::new(&tmp, size).into_drawing_area(), history)
        .map_err(|e| plot_err(&png, e))?;
    std::fs::rename(&tmp, &png).map_err(|e| ModelError::io(&png, e))?;
    let svg = dir.join("curves.svg");
    let tmp = dir.join(".tmp-curves.svg");
    draw(SVGBackend::new(&tmp, size).into_drawing_area(), history)
        .map_err(|e| plot_err(&svg, e))?;
    std::fs::rename(&tmp, &svg).map_err(|e| ModelError::io(&svg, e))
}
