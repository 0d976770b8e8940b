//! The Pareto plot: every variant labelled, the front drawn, as PNG and SVG.

use crate::front::Point;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Why a plot could not be written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlotError {
    /// Drawing or encoding failed.
    #[error("cannot draw {path}: {message}")]
    Draw {
        /// The file being written.
        path: PathBuf,
        /// What the plotting backend said.
        message: String,
    },
    /// Moving the finished file into place failed.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The file being written.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// What to draw: labelled points, which of them are on the front, and the axis names.
pub struct FrontPlot<'a> {
    /// The title above the chart.
    pub title: &'a str,
    /// The accuracy axis (y) name, e.g. `"mAP@0.5"`.
    pub accuracy_label: &'a str,
    /// The latency axis (x) name, e.g. `"latency, ms (ONNX Runtime, 1 thread)"`.
    pub latency_label: &'a str,
    /// Every variant: its label and position.
    pub points: &'a [(String, Point)],
    /// Indices of `points` on the front.
    pub front: &'a [usize],
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    plot: &FrontPlot<'_>,
) -> Result<(), String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let finite = plot
        .points
        .iter()
        .map(|(_, p)| *p)
        .filter(|p| p.accuracy.is_finite() && p.latency.is_finite());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for p in finite {
        x0 = x0.min(p.latency);
        x1 = x1.max(p.latency);
        y0 = y0.min(p.accuracy);
        y1 = y1.max(p.accuracy);
    }
    if x0 > x1 {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    let xpad = ((x1 - x0) * 0.12).max(0.1);
    let ypad = ((y1 - y0) * 0.12).max(0.01);
    let mut chart = ChartBuilder::on(&root)
        .caption(plot.title, ("sans-serif", 22))
        .margin(16)
        .x_label_area_size(44)
        .y_label_area_size(56)
        .build_cartesian_2d((x0 - xpad).max(0.0)..x1 + xpad, y0 - ypad..(y1 + ypad))
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc(plot.latency_label)
        .y_desc(plot.accuracy_label)
        .draw()
        .map_err(|e| e.to_string())?;
    let front_color = RGBColor(200, 40, 40);
    let front_pts: Vec<(f64, f64)> = plot
        .front
        .iter()
        .filter_map(|&i| plot.points.get(i))
        .map(|(_, p)| (p.latency, p.accuracy))
        .collect();
    chart
        .draw_series(LineSeries::new(
            front_pts.clone(),
            front_color.stroke_width(2),
        ))
        .map_err(|e| e.to_string())?
        .label("Pareto front")
        .legend(move |(x, y)| {
            PathElement::new(vec![(x, y), (x + 18, y)], front_color.stroke_width(2))
        });
    let dominated = RGBColor(90, 90, 90);
    for (i, (label, p)) in plot.points.iter().enumerate() {
        let on = plot.front.contains(&i);
        let color = if on { front_color } else { dominated };
        chart
            .draw_series(std::iter::once(Circle::new(
                (p.latency, p.accuracy),
                5,
                color.filled(),
            )))
            .map_err(|e| e.to_string())?;
        chart
            .draw_series(std::iter::once(Text::new(
                label.clone(),
                (p.latency, p.accuracy),
                ("sans-serif", 13).into_font().color(&color).pos(
                    plotters::style::text_anchor::Pos::new(
                        plotters::style::text_anchor::HPos::Left,
                        plotters::style::text_anchor::VPos::Bottom,
                    ),
                ),
            )))
            .map_err(|e| e.to_string())?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::LowerRight)
        .draw()
        .map_err(|e| e.to_string())?;
    root.present().map_err(|e| e.to_string())
}

/// Write `<stem>.png` and `<stem>.svg` (900×600), each through a temporary file.
pub fn plot_front(stem: &Path, plot: &FrontPlot<'_>) -> Result<(), PlotError> {
    for ext in ["png", "svg"] {
        let path = stem.with_extension(ext);
        let tmp = stem.with_extension(format!("partial.{ext}"));
        let drawn = if ext == "png" {
            draw(
                BitMapBackend::new(&tmp, (900, 600)).into_drawing_area(),
                plot,
            )
        } else {
            draw(SVGBackend::new(&tmp, (900, 600)).into_drawing_area(), plot)
        };
        if let Err(message) = drawn {
            let _ = std::fs::remove_file(&tmp);
            return Err(PlotError::Draw { path, message });
        }
        std::fs::rename(&tmp, &path).map_err(|source| PlotError::Io { path, source })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_png_and_svg_with_every_label() {
        let dir = tempfile::tempdir().unwrap();
        let points = vec![
            (
                "base".to_string(),
                Point {
                    accuracy: 0.95,
                    latency: 20.0,
                },
            ),
            (
                "int8".to_string(),
                Point {
                    accuracy: 0.94,
                    latency: 8.0,
                },
            ),
            (
                "prune90".to_string(),
                Point {
                    accuracy: 0.60,
                    latency: 19.0,
                },
            ),
        ];
        let front = crate::front::front(&points.iter().map(|(_, p)| *p).collect::<Vec<_>>());
        assert_eq!(front, vec![1, 0]);
        let stem = dir.path().join("pareto_map");
        plot_front(
            &stem,
            &FrontPlot {
                title: "test",
                accuracy_label: "mAP@0.5",
                latency_label: "ms",
                points: &points,
                front: &front,
            },
        )
        .unwrap();
        let png = image::open(stem.with_extension("png")).unwrap();
        assert_eq!((png.width(), png.height()), (900, 600));
        let svg = std::fs::read_to_string(stem.with_extension("svg")).unwrap();
        for label in ["base", "int8", "prune90", "Pareto front"] {
            assert!(svg.contains(label), "{label} missing from the SVG");
        }
        assert!(!dir.path().join("pareto_map.partial.png").exists());
    }
}
