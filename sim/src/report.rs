//! Results people look at: the paper's table (mean ± spread over seeds), JSON and CSV
//! files, the top view of the maze with every flight's trajectory (PNG and SVG), and
//! camera frames (PNG, animated GIF) with the detections drawn on them.
//!
//! Every output of the flights in one place: the table, JSON/CSV, the top view and the
//! frame pictures share the drawing and the summary types.
use crate::flight::{FlightResult, FrameView, Outcome};
use crate::maze::{Dir, Maze, Mount, cell_center};
use crate::render::Board;
use frugal_data::{NavAction, Sign};
use image::RgbImage;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why a report file could not be written.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ReportError {
    /// Filesystem error.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Encoding or drawing failed.
    #[error("{}: {message}", path.display())]
    Encode {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

/// Mean and spread of one quantity over runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Stat {
    /// Number of values.
    pub n: usize,
    /// Mean (0 when `n = 0`).
    pub mean: f64,
    /// Sample standard deviation (0 when `n < 2`).
    pub std: f64,
}

impl Stat {
    /// Statistics of `values`.
    pub fn of(values: &[f64]) -> Stat {
        let n = values.len();
        if n == 0 {
            return Stat::default();
        }
        let mean = values.iter().sum::<f64>() / n as f64;
        let std = if n > 1 {
            (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
        } else {
            0.0
        };
        Stat { n, mean, std }
    }

    /// Spread as a percentage of the mean (the paper's `± x %`).
    pub fn rel_percent(&self) -> f64 {
        if self.mean.abs() > 0.0 {
            100.0 * self.std / self.mean.abs()
        } else {
            0.0
        }
    }

    /// `mean ± rel %` with `digits` decimals, or `—` without values.
    pub fn show(&self, digits: usize) -> String {
        if self.n == 0 {
            "—".into()
        } else {
            format!("{:.digits$} ± {:.1}%", self.mean, self.rel_percent())
        }
    }
}

/// The summary of one maze's flights (one column of the paper's table).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Summary {
    /// Maze name.
    pub maze: String,
    /// Perception label.
    pub perception: String,
    /// Device profile name.
    pub device: String,
    /// Flights.
    pub runs: usize,
    /// Flights that landed in the goal.
    pub successes: usize,
    /// Flights that hit a wall.
    pub collisions: usize,
    /// Flights stopped by the time limit.
    pub timeouts: usize,
    /// Processed frames per simulated second (all flights).
    pub fps: Stat,
    /// Time to completion, s (successful flights).
    pub time_to_goal_s: Stat,
    /// Average velocity, cm/s (successful flights).
    pub velocity_cm_s: Stat,
    /// Time spent hovering at WAIT zones, s (successful flights).
    pub wait_s: Stat,
    /// Wall-clock render time per frame on this machine, ms (all flights).
    pub render_ms: Stat,
    /// In-loop detection recall: frames with a visible sign that were detected.
    pub recall: f64,
    /// Confirmations by the most accurate detector per flight (all flights).
    #[serde(default)]
    pub confirmations: Stat,
    /// Of all confirmations, the fraction that dropped a sighting
    /// ([`crate::FlightResult::rejections`]).
    #[serde(default)]
    pub rejected: f64,
}

/// Summarise the flights of one maze (all with the same perception and device).
pub fn summarize(results: &[FlightResult]) -> Summary {
    let ok: Vec<&FlightResult> = results.iter().filter(|r| r.outcome.is_success()).collect();
    let col = |f: &dyn Fn(&FlightResult) -> f64, rs: &[&FlightResult]| {
        Stat::of(&rs.iter().map(|r| f(r)).collect::<Vec<_>>())
    };
    let all: Vec<&FlightResult> = results.iter().collect();
    let (frames, hits) = results.iter().fold((0u64, 0u64), |(f, h), r| {
        (f + r.sign_frames, h + r.sign_hits)
    });
    Summary {
        maze: results.first().map_or_else(String::new, |r| r.maze.clone()),
        perception: results
            .first()
            .map_or_else(String::new, |r| r.perception.clone()),
        device: results
            .first()
            .map_or_else(String::new, |r| r.device.name.clone()),
        runs: results.len(),
        successes: ok.len(),
        collisions: results
            .iter()
            .filter(|r| matches!(r.outcome, Outcome::Collision { .. }))
            .count(),
        timeouts: results
            .iter()
            .filter(|r| matches!(r.outcome, Outcome::TimeLimit { .. }))
            .count(),
        fps: col(&|r| r.fps, &all),
        time_to_goal_s: col(&|r| r.time_s, &ok),
        velocity_cm_s: col(&|r| r.avg_velocity * 100.0, &ok),
        wait_s: col(&|r| r.wait_s, &ok),
        render_ms: col(&|r| r.render_ms_mean, &all),
        recall: if frames > 0 {
            hits as f64 / frames as f64
        } else {
            0.0
        },
        confirmations: col(&|r| r.confirmations as f64, &all),
        rejected: {
            let (c, r) = results.iter().fold((0u64, 0u64), |(c, r), f| {
                (c + f.confirmations, r + f.rejections)
            });
            if c > 0 { r as f64 / c as f64 } else { 0.0 }
        },
    }
}

/// The paper's table: one column per maze.
pub fn table(summaries: &[Summary]) -> String {
    let mut rows: Vec<(String, Vec<String>)> = vec![
        (
            "".into(),
            summaries.iter().map(|s| s.maze.clone()).collect(),
        ),
        (
            "Perception".into(),
            summaries
                .iter()
                .map(|s| format!("{} @ {}", s.perception, s.device))
                .collect(),
        ),
        (
            "Average frame-rate [fps]".into(),
            summaries.iter().map(|s| s.fps.show(1)).collect(),
        ),
        (
            "Time to completion [s]".into(),
            summaries.iter().map(|s| s.time_to_goal_s.show(1)).collect(),
        ),
        (
            "Average velocity [cm/s]".into(),
            summaries.iter().map(|s| s.velocity_cm_s.show(1)).collect(),
        ),
        (
            "Success".into(),
            summaries
                .iter()
                .map(|s| format!("{}/{}", s.successes, s.runs))
                .collect(),
        ),
        (
            "Collisions".into(),
            summaries.iter().map(|s| s.collisions.to_string()).collect(),
        ),
        (
            "Time limit reached".into(),
            summaries.iter().map(|s| s.timeouts.to_string()).collect(),
        ),
        (
            "Hover at WAIT [s]".into(),
            summaries.iter().map(|s| s.wait_s.show(1)).collect(),
        ),
        (
            "In-loop sign recall".into(),
            summaries
                .iter()
                .map(|s| format!("{:.3}", s.recall))
                .collect(),
        ),
        (
            "Confirmations per flight".into(),
            summaries
                .iter()
                .map(|s| {
                    format!(
                        "{} ({:.0}% rejected)",
                        s.confirmations.show(1),
                        s.rejected * 100.0
                    )
                })
                .collect(),
        ),
        (
            "Render time [ms/frame]".into(),
            summaries.iter().map(|s| s.render_ms.show(2)).collect(),
        ),
    ];
    let w0 = rows.iter().map(|r| r.0.chars().count()).max().unwrap_or(0);
    let wc = rows
        .iter()
        .flat_map(|r| r.1.iter().map(|c| c.chars().count()))
        .max()
        .unwrap_or(0);
    let mut out = String::new();
    for (i, (label, cells)) in rows.iter_mut().enumerate() {
        out.push_str(&format!("{label:<w0$}"));
        for c in cells.iter() {
            out.push_str(&format!("  {c:>wc$}"));
        }
        out.push('\n');
        if i == 0 {
            out.push_str(&"-".repeat(w0 + (wc + 2) * cells.len()));
            out.push('\n');
        }
    }
    out
}

/// Write `bytes` to `path` through a temporary file in the same folder.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    let io = |source| ReportError::Io {
        path: path.to_owned(),
        source,
    };
    if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(io)?;
    }
    let tmp = partial(path);
    std::fs::write(&tmp, bytes).map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

/// The temporary name `path` is written under before it is renamed into place.
fn partial(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".partial");
    path.with_file_name(name)
}

/// Write a value as pretty JSON (atomically).
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<(), ReportError> {
    let bytes = serde_json::to_vec_pretty(value).map_err(|e| ReportError::Encode {
        path: path.to_owned(),
        message: e.to_string(),
    })?;
    write_atomic(path, &bytes)
}

/// Write one CSV row per flight (atomically).
pub fn write_flights_csv(path: &Path, results: &[FlightResult]) -> Result<(), ReportError> {
    let enc = |e: csv::Error| ReportError::Encode {
        path: path.to_owned(),
        message: e.to_string(),
    };
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record([
        "maze",
        "perception",
        "device",
        "seed",
        "outcome",
        "time_s",
        "frames",
        "fps",
        "path_m",
        "avg_velocity_cm_s",
        "wait_s",
        "compute_ms_mean",
        "int8_ms_mean",
        "tracker_ms_mean",
        "render_ms_mean",
        "sign_frames",
        "sign_hits",
        "false_detections",
        "confirmations",
        "rejections",
    ])
    .map_err(enc)?;
    for r in results {
        let outcome = match &r.outcome {
            Outcome::Success => "success",
            Outcome::LandedOutsideGoal { .. } => "landed_outside_goal",
            Outcome::Collision { .. } => "collision",
            Outcome::TimeLimit { .. } => "time_limit",
        };
        w.write_record([
            r.maze.clone(),
            r.perception.clone(),
            r.device.name.clone(),
            r.seed.to_string(),
            outcome.to_owned(),
            format!("{:.3}", r.time_s),
            r.frames.to_string(),
            format!("{:.3}", r.fps),
            format!("{:.3}", r.path_m),
            format!("{:.2}", r.avg_velocity * 100.0),
            format!("{:.3}", r.wait_s),
            format!("{:.3}", r.compute_ms_mean),
            format!("{:.3}", r.int8_ms_mean),
            format!("{:.3}", r.tracker_ms_mean),
            format!("{:.3}", r.render_ms_mean),
            r.sign_frames.to_string(),
            r.sign_hits.to_string(),
            r.false_detections.to_string(),
            r.confirmations.to_string(),
            r.rejections.to_string(),
        ])
        .map_err(enc)?;
    }
    let bytes = w.into_inner().map_err(|e| ReportError::Encode {
        path: path.to_owned(),
        message: e.to_string(),
    })?;
    write_atomic(path, &bytes)
}

fn sign_colour(sign: Sign) -> RGBColor {
    match sign.action() {
        Some(NavAction::Stop) => RGBColor(200, 20, 30),
        Some(NavAction::Wait) => RGBColor(30, 140, 230),
        Some(_) => RGBColor(10, 70, 170),
        None => RGBColor(120, 120, 120),
    }
}

fn sign_label(sign: Sign) -> &'static str {
    match sign.action() {
        Some(NavAction::TurnLeft) => "L",
        Some(NavAction::TurnRight) => "R",
        Some(NavAction::Stop) => "STOP",
        Some(NavAction::Wait) => "WAIT",
        None => sign.code(),
    }
}

const RUN_COLOURS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

fn draw_top<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    maze: &Maze,
    boards: &[Board],
    results: &[FlightResult],
) -> Result<(), String> {
    let s = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(s)?;
    let (wm, hm) = (
        maze.width as f64 * maze.cell,
        maze.height as f64 * maze.cell,
    );
    let perception = results.first().map_or("", |r| r.perception.as_str());
    // flights of several perceptions on one view (static vs adaptive) say whose they are
    let mixed = results.iter().any(|r| r.perception != perception);
    let mut names: Vec<&str> = Vec::new();
    for r in results {
        if !names.contains(&r.perception.as_str()) {
            names.push(&r.perception);
        }
    }
    let perceptions = names.join(" vs ");
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "{} maze — top view, {} flight(s), {perceptions}",
                maze.name,
                results.len()
            ),
            ("sans-serif", 20),
        )
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(40)
        .build_cartesian_2d(0f64..wm, hm..0f64)
        .map_err(s)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("east [m]")
        .y_desc("south [m]")
        .draw()
        .map_err(s)?;
    let c = maze.cell;
    for row in 0..maze.height {
        for col in 0..maze.width {
            if maze.walls[row * maze.width + col] {
                let (x0, y0) = (col as f64 * c, row as f64 * c);
                chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [(x0, y0), (x0 + c, y0 + c)],
                        RGBColor(90, 90, 95).filled(),
                    )))
                    .map_err(s)?;
            }
        }
    }
    for z in &maze.zones {
        let (x0, y0) = (z.cell.0 as f64 * c, z.cell.1 as f64 * c);
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(x0, y0), (x0 + c, y0 + c)],
                RGBColor(255, 165, 0).mix(0.35).filled(),
            )))
            .map_err(s)?;
        let (cx, cy) = cell_center(z.cell, c);
        let (a, b) = match z.axis {
            Dir::North | Dir::South => ((cx, cy - 1.5 * c), (cx, cy + 1.5 * c)),
            Dir::East | Dir::West => ((cx - 1.5 * c, cy), (cx + 1.5 * c, cy)),
        };
        // the pedestrian's walk: dashed grey, so that it is not read as a trajectory
        chart
            .draw_series(DashedLineSeries::new(
                [a, b],
                6,
                4,
                RGBColor(90, 90, 90).stroke_width(1),
            ))
            .map_err(s)?;
        chart
            .draw_series(std::iter::once(Text::new(
                format!("WAIT zone {:.0}s/{:.0}%", z.period, z.duty * 100.0),
                (x0 + 0.1, y0 + 0.3),
                ("sans-serif", 12).into_font().color(&BLACK),
            )))
            .map_err(s)?;
    }
    for (b, spec) in boards.iter().zip(&maze.signs) {
        let colour = sign_colour(spec.sign);
        chart
            .draw_series(LineSeries::new([b.a, b.b], colour.stroke_width(5)))
            .map_err(s)?;
        let (cx, cy) = b.center();
        // Labels go into the cell, clear of the board (text hangs below its anchor).
        let off = if spec.mount == Mount::Flat { 0.9 } else { 0.2 };
        let pos = (cx + b.normal.0 * off - 0.3, cy + b.normal.1 * off - 0.2);
        chart
            .draw_series(std::iter::once(Text::new(
                sign_label(spec.sign),
                pos,
                ("sans-serif", 13).into_font().color(&colour),
            )))
            .map_err(s)?;
    }
    let (sx, sy) = cell_center(maze.start, c);
    chart
        .draw_series(std::iter::once(TriangleMarker::new(
            (sx, sy),
            9,
            RGBColor(0, 150, 0).filled(),
        )))
        .map_err(s)?
        .label("start")
        .legend(|(x, y)| TriangleMarker::new((x, y), 6, RGBColor(0, 150, 0).filled()));
    let (gx, gy) = cell_center(maze.goal, c);
    chart
        .draw_series(std::iter::once(Circle::new(
            (gx, gy),
            9,
            RED.stroke_width(3),
        )))
        .map_err(s)?
        .label("goal")
        .legend(|(x, y)| Circle::new((x, y), 5, RED.stroke_width(2)));
    for (i, r) in results.iter().enumerate() {
        let colour = RUN_COLOURS[i % RUN_COLOURS.len()];
        let who = if mixed {
            format!("{} ", r.perception)
        } else {
            String::new()
        };
        let label = match &r.outcome {
            Outcome::Success => format!("{who}seed {}: {:.1} s", r.seed, r.time_s),
            other => format!("{who}seed {}: {}", r.seed, other.describe()),
        };
        chart
            .draw_series(LineSeries::new(
                r.track.iter().map(|p| (p.x, p.y)),
                colour.stroke_width(2),
            ))
            .map_err(s)?
            .label(label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 15, y)], colour.stroke_width(2)));
        if let Outcome::Collision { x, y } = r.outcome {
            chart
                .draw_series(std::iter::once(Cross::new(
                    (x, y),
                    8,
                    BLACK.stroke_width(3),
                )))
                .map_err(s)?;
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::LowerRight)
        .draw()
        .map_err(s)?;
    root.present().map_err(s)
}

/// Draw the top view (walls, WAIT zones, signs, start, goal, every trajectory) to
/// `<stem>.png` and `<stem>.svg`, each through a temporary file.
pub fn plot_top_view(
    stem: &Path,
    maze: &Maze,
    results: &[FlightResult],
) -> Result<(), ReportError> {
    let boards = crate::render::boards(maze);
    let aspect = maze.height as f64 / maze.width as f64;
    let w = 900u32;
    let h = ((f64::from(w - 50) * aspect) as u32 + 90).clamp(300, 1400);
    if let Some(dir) = stem.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|source| ReportError::Io {
            path: dir.to_owned(),
            source,
        })?;
    }
    for ext in ["png", "svg"] {
        let path = stem.with_extension(ext);
        let tmp = stem.with_extension(format!("partial.{ext}"));
        let drawn = if ext == "png" {
            draw_top(
                BitMapBackend::new(&tmp, (w, h)).into_drawing_area(),
                maze,
                &boards,
                results,
            )
        } else {
            draw_top(
                SVGBackend::new(&tmp, (w, h)).into_drawing_area(),
                maze,
                &boards,
                results,
            )
        };
        if let Err(message) = drawn {
            let _ = std::fs::remove_file(&tmp);
            return Err(ReportError::Encode { path, message });
        }
        std::fs::rename(&tmp, &path).map_err(|source| ReportError::Io { path, source })?;
    }
    Ok(())
}

/// The frame as an image with detections drawn on it (green boxes) and, thinner, the
/// ground-truth boxes of visible signs (white).
pub fn annotated(view: &FrameView<'_>) -> RgbImage {
    let mut img = RgbImage::from_raw(view.image.width, view.image.height, view.image.rgb.to_vec())
        .unwrap_or_else(|| RgbImage::new(view.image.width, view.image.height));
    for t in &view.truth.signs {
        rect(&mut img, t.bbox, [255, 255, 255], 1);
    }
    for d in view.detections {
        rect(&mut img, d.bbox, [40, 230, 60], 2);
    }
    img
}

fn rect(img: &mut RgbImage, b: frugal_runtime::BBox, c: [u8; 3], thick: i64) {
    let (w, h) = (i64::from(img.width()), i64::from(img.height()));
    let (x1, y1, x2, y2) = (b.x1 as i64, b.y1 as i64, b.x2 as i64 - 1, b.y2 as i64 - 1);
    let mut put = |x: i64, y: i64| {
        if (0..w).contains(&x) && (0..h).contains(&y) {
            img.put_pixel(x as u32, y as u32, image::Rgb(c));
        }
    };
    for k in 0..thick {
        for x in x1..=x2 {
            put(x, y1 + k);
            put(x, y2 - k);
        }
        for y in y1..=y2 {
            put(x1 + k, y);
            put(x2 - k, y);
        }
    }
}

/// Save an annotated frame as PNG (atomically).
pub fn save_frame_png(path: &Path, view: &FrameView<'_>) -> Result<(), ReportError> {
    let img = annotated(view);
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .map_err(|e| ReportError::Encode {
        path: path.to_owned(),
        message: e.to_string(),
    })?;
    write_atomic(path, &bytes)
}

/// An animated GIF written frame by frame at half resolution; the file appears under
/// its name only when [`GifRecorder::finish`] succeeds.
pub struct GifRecorder {
    path: PathBuf,
    encoder: Option<image::codecs::gif::GifEncoder<std::io::BufWriter<std::fs::File>>>,
    delay_ms: u32,
}

impl GifRecorder {
    /// Start a GIF at `path` showing one frame every `delay_ms` milliseconds.
    pub fn create(path: &Path, delay_ms: u32) -> Result<GifRecorder, ReportError> {
        let io = |source| ReportError::Io {
            path: path.to_owned(),
            source,
        };
        if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let file = std::fs::File::create(partial(path)).map_err(io)?;
        let mut encoder =
            image::codecs::gif::GifEncoder::new_with_speed(std::io::BufWriter::new(file), 20);
        encoder
            .set_repeat(image::codecs::gif::Repeat::Infinite)
            .map_err(|e| ReportError::Encode {
                path: path.to_owned(),
                message: e.to_string(),
            })?;
        Ok(GifRecorder {
            path: path.to_owned(),
            encoder: Some(encoder),
            delay_ms,
        })
    }

    /// Append a frame (annotated, halved).
    pub fn push(&mut self, view: &FrameView<'_>) -> Result<(), ReportError> {
        let img = annotated(view);
        let small = image::imageops::resize(
            &img,
            (img.width() / 2).max(1),
            (img.height() / 2).max(1),
            image::imageops::FilterType::Triangle,
        );
        let rgba = image::DynamicImage::ImageRgb8(small).to_rgba8();
        let frame = image::Frame::from_parts(
            rgba,
            0,
            0,
            image::Delay::from_numer_denom_ms(self.delay_ms, 1),
        );
        if let Some(enc) = self.encoder.as_mut() {
            enc.encode_frame(frame).map_err(|e| ReportError::Encode {
                path: self.path.clone(),
                message: e.to_string(),
            })?;
        }
        Ok(())
    }

    /// Finish the file and move it into place.
    pub fn finish(mut self) -> Result<(), ReportError> {
        let io = |source| ReportError::Io {
            path: self.path.clone(),
            source,
        };
        // The encoder writes the GIF trailer and flushes its buffer when dropped.
        drop(self.encoder.take());
        let tmp = partial(&self.path);
        let len = std::fs::metadata(&tmp).map_err(io)?.len();
        if len == 0 {
            return Err(ReportError::Encode {
                path: self.path.clone(),
                message: "no GIF data was written".into(),
            });
        }
        std::fs::rename(partial(&self.path), &self.path).map_err(io)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stat_mean_and_relative_spread() {
        let s = Stat::of(&[1.0, 2.0, 3.0]);
        assert_eq!((s.n, s.mean), (3, 2.0));
        assert!((s.std - 1.0).abs() < 1e-12);
        assert!((s.rel_percent() - 50.0).abs() < 1e-9);
        assert_eq!(Stat::of(&[]).show(1), "—");
        assert_eq!(Stat::of(&[4.0]).show(1), "4.0 ± 0.0%");
    }
}
