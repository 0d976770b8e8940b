//! The figures, each written as PNG and SVG (through a temporary name, then renamed):
//! the α sweep, grouped bars per scenario (time and F1) and per sign class (precision
//! and time), per-variant reward / IoU /
//! time on one clip, and the MDP's state over a clip with detect/track marks.

use crate::error::{PolicyError, Result};
use crate::eval::{ClassScore, FrameTrace, Score};
use crate::sweep::SweepPoint;
use crate::train::Reward;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

type DrawResult = std::result::Result<(), String>;
type PngDraw<'a> = &'a dyn for<'b> Fn(&DrawingArea<BitMapBackend<'b>, Shift>) -> DrawResult;
type SvgDraw<'a> = &'a dyn for<'b> Fn(&DrawingArea<SVGBackend<'b>, Shift>) -> DrawResult;

/// Write `stem.png` and `stem.svg` with the same drawing code.
fn both(stem: &Path, size: (u32, u32), png: PngDraw<'_>, svg: SvgDraw<'_>) -> Result<()> {
    if let Some(dir) = stem.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| PolicyError::io(dir, e))?;
    }
    for ext in ["png", "svg"] {
        let path = stem.with_extension(ext);
        let tmp = stem.with_extension(format!("partial.{ext}"));
        let err = |m: String| PolicyError::Plot {
            path: path.clone(),
            message: m,
        };
        if ext == "png" {
            let root = BitMapBackend::new(&tmp, size).into_drawing_area();
            png(&root).map_err(err)?;
            root.present().map_err(|e| err(e.to_string()))?;
        } else {
            let root = SVGBackend::new(&tmp, size).into_drawing_area();
            svg(&root).map_err(err)?;
            root.present().map_err(|e| err(e.to_string()))?;
        }
        std::fs::rename(&tmp, &path).map_err(|e| PolicyError::io(&path, e))?;
    }
    Ok(())
}

fn s<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

fn range(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        return (0.0, 1.0);
    }
    let span = (hi - lo).max(1e-6);
    (lo - pad * span, hi + pad * span)
}

fn sweep_draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    pts: &[SweepPoint],
) -> std::result::Result<(), String> {
    root.fill(&WHITE).map_err(s)?;
    let (x0, x1) = range(pts.iter().map(|p| p.ms_per_frame), 0.1);
    let (y0, y1) = range(pts.iter().map(|p| p.f1), 0.1);
    let mut chart = ChartBuilder::on(root)
        .caption(
            "MDP policies: speed vs accuracy (α sweep, no tracker)",
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(s)?;
    chart
        .configure_mesh()
        .x_desc("detector time per frame, ms")
        .y_desc("F1 @ IoU 0.5")
        .draw()
        .map_err(s)?;
    // one line per reward (and, for the confidence reward, per w_ge scale)
    let mut series: Vec<(Reward, f64)> = pts.iter().map(|p| (p.reward, p.ge_scale)).collect();
    series.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    series.dedup();
    for (i, &(reward, sc)) in series.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        let of = |p: &&SweepPoint| p.reward == reward && p.ge_scale == sc;
        let mut line: Vec<(f64, f64)> = pts
            .iter()
            .filter(of)
            .map(|p| (p.ms_per_frame, p.f1))
            .collect();
        line.sort_by(|a, b| a.0.total_cmp(&b.0));
        let label = match reward {
            Reward::Confidence => format!("confidence reward, w_ge × {sc}"),
            Reward::Outcome => "outcome reward".to_string(),
        };
        chart
            .draw_series(LineSeries::new(line, color.stroke_width(2)))
            .map_err(s)?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color));
        for p in pts.iter().filter(of) {
            chart
                .draw_series(std::iter::once(Circle::new(
                    (p.ms_per_frame, p.f1),
                    4,
                    color.filled(),
                )))
                .map_err(s)?;
            chart
                .draw_series(std::iter::once(Text::new(
                    format!("α={}", p.alpha),
                    (p.ms_per_frame, p.f1),
                    ("sans-serif", 12),
                )))
                .map_err(s)?;
        }
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .draw()
        .map_err(s)?;
    Ok(())
}

/// The α sweep: time per frame against F1, one line per reward and `w_ge` scale.
pub fn plot_sweep(stem: &Path, pts: &[SweepPoint]) -> Result<()> {
    both(stem, (900, 600), &|r| sweep_draw(r, pts), &|r| {
        sweep_draw(r, pts)
    })
}

/// One bar: the group on the x axis, the series (its colour), the value.
type Bar<'a> = (&'a str, &'a str, f64);

fn bars_draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    bars: &[Bar<'_>],
    caption: &str,
    metric: &str,
) -> std::result::Result<(), String> {
    root.fill(&WHITE).map_err(s)?;
    let mut groups: Vec<&str> = Vec::new();
    let mut series: Vec<&str> = Vec::new();
    for &(g, sr, _) in bars {
        if !groups.contains(&g) {
            groups.push(g);
        }
        if !series.contains(&sr) {
            series.push(sr);
        }
    }
    let ymax = bars
        .iter()
        .map(|b| b.2)
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max)
        * 1.35
        + 1e-9;
    let n = series.len().max(1) as f64;
    let mut chart = ChartBuilder::on(root)
        .caption(caption, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..groups.len() as f64, 0.0..ymax)
        .map_err(s)?;
    let names = groups.clone();
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(groups.len() * 2 + 1)
        .x_label_formatter(&|x| {
            let i = x.floor() as usize;
            if (x - i as f64 - 0.5).abs() < 0.01 {
                names.get(i).map_or(String::new(), |n| (*n).to_owned())
            } else {
                String::new()
            }
        })
        .y_desc(metric)
        .draw()
        .map_err(s)?;
    for (k, sr) in series.iter().enumerate() {
        let color = Palette99::pick(k).to_rgba();
        let rects: Vec<Rectangle<(f64, f64)>> = groups
            .iter()
            .enumerate()
            .filter_map(|(i, g)| {
                bars.iter().find(|b| b.0 == *g && b.1 == *sr).map(|b| {
                    let x0 = i as f64 + 0.1 + 0.8 * k as f64 / n;
                    let v = if b.2.is_finite() { b.2 } else { 0.0 };
                    Rectangle::new([(x0, 0.0), (x0 + 0.8 / n, v)], color.filled())
                })
            })
            .collect();
        chart
            .draw_series(rects)
            .map_err(s)?
            .label(*sr)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], color.filled()));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .border_style(BLACK)
        .background_style(WHITE.mix(0.85))
        .draw()
        .map_err(s)?;
    Ok(())
}

/// Write `stem.png|svg` with grouped bars.
fn bars(
    stem: &Path,
    size: (u32, u32),
    bars: &[Bar<'_>],
    caption: &str,
    metric: &str,
) -> Result<()> {
    both(stem, size, &|r| bars_draw(r, bars, caption, metric), &|r| {
        bars_draw(r, bars, caption, metric)
    })
}

/// `<stem>-<suffix>` next to `stem`.
fn suffixed(stem: &Path, suffix: &str) -> std::path::PathBuf {
    let name = stem
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    stem.with_file_name(format!("{name}-{suffix}"))
}

/// Grouped bars per scenario: compute time per frame (`<stem>-time`) and F1 (`<stem>-f1`).
pub fn plot_bars(stem: &Path, scores: &[Score]) -> Result<()> {
    let of = |value: fn(&Score) -> f64| -> Vec<Bar<'_>> {
        scores
            .iter()
            .map(|x| (x.scenario.as_str(), x.strategy.as_str(), value(x)))
            .collect()
    };
    let metric = "compute ms per frame";
    bars(
        &suffixed(stem, "time"),
        (1000, 560),
        &of(|x| x.ms_per_frame),
        &format!("{metric} per scenario and strategy"),
        metric,
    )?;
    let metric = "F1 @ IoU 0.5";
    bars(
        &suffixed(stem, "f1"),
        (1000, 560),
        &of(|x| x.f1),
        &format!("{metric} per scenario and strategy"),
        metric,
    )
}

/// Grouped bars per sign class (the KUL table as figures) for the given strategies:
/// precision (`<stem>-precision`) and compute time per frame showing the class
/// (`<stem>-time`).
pub fn plot_class_bars(stem: &Path, rows: &[ClassScore], strategies: &[&str]) -> Result<()> {
    let of = |value: fn(&ClassScore) -> f64| -> Vec<Bar<'_>> {
        rows.iter()
            .filter(|r| strategies.contains(&r.strategy.as_str()))
            .map(|r| (r.name.as_str(), r.strategy.as_str(), value(r)))
            .collect()
    };
    let metric = "precision @ IoU 0.5";
    bars(
        &suffixed(stem, "precision"),
        (1300, 560),
        &of(|r| r.precision.unwrap_or(f64::NAN)),
        &format!("{metric} per sign class"),
        metric,
    )?;
    bars(
        &suffixed(stem, "time"),
        (1300, 560),
        &of(|r| r.ms_per_frame),
        "compute time of the frames showing each sign class",
        "compute ms per frame",
    )
}

/// Per-variant series on one clip: `series[v][t] = (reward, iou, time_ms)`.
pub struct ClipSeries<'a> {
    /// Video id.
    pub video: u32,
    /// Variant names.
    pub names: &'a [String],
    /// Frame indices.
    pub frames: &'a [u32],
    /// `series[v][t]`.
    pub series: &'a [Vec<(f64, f64, f64)>],
}

fn clip_draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: &ClipSeries<'_>,
) -> std::result::Result<(), String> {
    root.fill(&WHITE).map_err(s)?;
    let panels = root.split_evenly((3, 1));
    let titles = ["reward R(s', w)", "IoU with the truth", "time, ms"];
    let x1 = c.frames.last().map_or(1.0, |f| f64::from(*f) + 1.0);
    for (p, (area, title)) in panels.iter().zip(titles).enumerate() {
        let get = |t: &(f64, f64, f64)| match p {
            0 => t.0,
            1 => t.1,
            _ => t.2,
        };
        let (y0, y1) = range(c.series.iter().flatten().map(get), 0.08);
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!("video {}: {title} per variant", c.video),
                ("sans-serif", 16),
            )
            .margin(8)
            .x_label_area_size(28)
            .y_label_area_size(50)
            .build_cartesian_2d(0.0..x1, y0.min(0.0)..y1)
            .map_err(s)?;
        chart.configure_mesh().x_desc("frame").draw().map_err(s)?;
        for (v, ser) in c.series.iter().enumerate() {
            let color = Palette99::pick(v).to_rgba();
            let pts: Vec<(f64, f64)> = c
                .frames
                .iter()
                .zip(ser)
                .map(|(f, t)| (f64::from(*f), get(t)))
                .collect();
            let s2 = chart
                .draw_series(LineSeries::new(pts, color.stroke_width(2)))
                .map_err(s)?;
            if p == 0 {
                s2.label(c.names[v].clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color));
            }
        }
        if p == 0 {
            chart
                .configure_series_labels()
                .border_style(BLACK)
                .background_style(WHITE.mix(0.85))
                .draw()
                .map_err(s)?;
        }
    }
    Ok(())
}

/// Reward, IoU and time against frame number for each variant on one clip.
pub fn plot_clip(stem: &Path, c: &ClipSeries<'_>) -> Result<()> {
    both(stem, (1000, 900), &|r| clip_draw(r, c), &|r| {
        clip_draw(r, c)
    })
}

fn states_draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    video: u32,
    labels: &[String],
    trace: &[FrameTrace],
) -> std::result::Result<(), String> {
    root.fill(&WHITE).map_err(s)?;
    let x1 = trace.last().map_or(1.0, |t| f64::from(t.frame) + 1.0);
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!("MDP + tracker on video {video}: state per frame"),
            ("sans-serif", 20),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(190)
        .build_cartesian_2d(0.0..x1, -0.5..labels.len() as f64 - 0.5)
        .map_err(s)?;
    let l = labels.to_vec();
    chart
        .configure_mesh()
        .y_labels(labels.len())
        .y_label_formatter(&|y| {
            let i = y.round();
            if (y - i).abs() < 0.01 && i >= 0.0 {
                l.get(i as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        })
        .x_desc("frame")
        .draw()
        .map_err(s)?;
    let line: Vec<(f64, f64)> = trace
        .iter()
        .map(|t| (f64::from(t.frame), t.state as f64))
        .collect();
    chart
        .draw_series(LineSeries::new(line, BLACK.mix(0.4)))
        .map_err(s)?;
    chart
        .draw_series(
            trace
                .iter()
                .filter(|t| t.detect.is_some())
                .map(|t| Circle::new((f64::from(t.frame), t.state as f64), 5, RED.filled())),
        )
        .map_err(s)?
        .label("detect")
        .legend(|(x, y)| Circle::new((x + 6, y), 5, RED.filled()));
    chart
        .draw_series(
            trace
                .iter()
                .filter(|t| t.detect.is_none())
                .map(|t| Cross::new((f64::from(t.frame), t.state as f64), 4, BLUE)),
        )
        .map_err(s)?
        .label("track")
        .legend(|(x, y)| Cross::new((x + 6, y), 4, BLUE));
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.85))
        .draw()
        .map_err(s)?;
    Ok(())
}

/// The controller's state (bucket, variant) per frame, detections and tracked frames
/// marked. `labels[state]` names each state.
pub fn plot_states(stem: &Path, video: u32, labels: &[String], trace: &[FrameTrace]) -> Result<()> {
    both(
        stem,
        (1000, 560),
        &|r| states_draw(r, video, labels, trace),
        &|r| states_draw(r, video, labels, trace),
    )
}

fn lines_draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    axes: (&str, &str),
    series: &[(String, Vec<(f64, f64)>)],
    join: bool,
) -> std::result::Result<(), String> {
    root.fill(&WHITE).map_err(s)?;
    // the legend gets a column of its own, so that it hides no point
    let (w, _) = root.dim_in_pixel();
    let (plot, legend) = root.split_horizontally(w.saturating_sub(170));
    let (x0, x1) = range(series.iter().flat_map(|(_, p)| p.iter().map(|q| q.0)), 0.08);
    let (y0, y1) = range(series.iter().flat_map(|(_, p)| p.iter().map(|q| q.1)), 0.08);
    let mut chart = ChartBuilder::on(&plot)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(s)?;
    chart
        .configure_mesh()
        .x_desc(axes.0)
        .y_desc(axes.1)
        .draw()
        .map_err(s)?;
    for (i, (name, pts)) in series.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        if join {
            chart
                .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
                .map_err(s)?;
        }
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 5, color.filled())))
            .map_err(s)?;
        let y = 60 + 26 * i as i32;
        legend
            .draw(&Circle::new((16, y), 5, color.filled()))
            .map_err(s)?;
        if join {
            legend
                .draw(&PathElement::new(
                    vec![(4, y), (28, y)],
                    color.stroke_width(2),
                ))
                .map_err(s)?;
        }
        legend
            .draw(&Text::new(name.clone(), (36, y - 8), ("sans-serif", 16)))
            .map_err(s)?;
    }
    Ok(())
}

/// Points joined by a line per named series (e.g. one strategy's figure at every
/// budget), axes fitted to the points (not to zero, so that differences of a few
/// points stay visible).
pub fn plot_lines(
    stem: &Path,
    title: &str,
    axes: (&str, &str),
    series: &[(String, Vec<(f64, f64)>)],
) -> Result<()> {
    series_plot(stem, title, axes, series, true)
}

/// Points, one colour per named series, not joined (e.g. one strategy's figure per
/// scenario), axes fitted to the points.
pub fn plot_points(
    stem: &Path,
    title: &str,
    axes: (&str, &str),
    series: &[(String, Vec<(f64, f64)>)],
) -> Result<()> {
    series_plot(stem, title, axes, series, false)
}

fn series_plot(
    stem: &Path,
    title: &str,
    axes: (&str, &str),
    series: &[(String, Vec<(f64, f64)>)],
    join: bool,
) -> Result<()> {
    both(
        stem,
        (900, 600),
        &|r| lines_draw(r, title, axes, series, join),
        &|r| lines_draw(r, title, axes, series, join),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_and_point_plots_write_png_and_svg_with_every_series_named() {
        let dir = tempfile::tempdir().unwrap();
        let series: Vec<(String, Vec<(f64, f64)>)> = ["static", "budget", "oracle"]
            .iter()
            .enumerate()
            .map(|(i, n)| {
                let pts = (0..3)
                    .map(|k| (8.0 * (k + 1) as f64, 50.0 + (i * k) as f64))
                    .collect();
                (n.to_string(), pts)
            })
            .collect();
        plot_lines(&dir.path().join("l"), "lines", ("x", "y"), &series).unwrap();
        plot_points(&dir.path().join("p"), "points", ("x", "y"), &series).unwrap();
        for stem in ["l", "p"] {
            assert!(dir.path().join(format!("{stem}.png")).is_file());
            let svg = std::fs::read_to_string(dir.path().join(format!("{stem}.svg"))).unwrap();
            for (name, _) in &series {
                assert!(svg.contains(name.as_str()), "{stem}.svg lacks {name}");
            }
        }
    }
}
