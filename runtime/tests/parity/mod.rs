//! Side-by-side KLT comparison with OpenCV, shared by the parity test and the
//! `klt_vs_opencv` example: the same synthetic clip, the same starting boxes, the Rust
//! tracker here and `tools/klt_opencv.py` (cv2) there.

use frugal_runtime::BBox;
use frugal_runtime::synth::Clip;
use frugal_runtime::track::{GrayImage, Point, Pyramid, Tracker, TrackerParams, track_point};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// The parameters both trackers run with: the deployed tracker's
/// ([`TrackerParams::DEFAULT`]) but for a 15×15 window and a tight stopping rule (at
/// most 20 steps, ε = 0.01 px), so that the two solve the same least-squares problem to
/// a precision the comparison can hold them to; the deployed defaults stop earlier.
pub const PARITY: TrackerParams = TrackerParams {
    lk: frugal_runtime::track::LkParams {
        win_radius: 7,
        levels: 3,
        max_iters: 20,
        epsilon: 0.01,
        min_eigen: 1e-3,
    },
    ..TrackerParams::DEFAULT
};

/// Most points per track, as in the benchmark budget.
pub const MAX_POINTS: usize = 64;

/// What the Rust side produced for one segment.
pub struct RustSegment {
    pub start: usize,
    pub corners: Vec<Point>,
    /// Per frame after `start`: each starting corner chained through LK (no filtering).
    pub given_tracks: Vec<Vec<Option<Point>>>,
    /// Per frame after `start`: the full tracker's box (`None` once lost).
    pub boxes: Vec<Option<BBox>>,
    pub ms_per_frame: f64,
    /// The same run in thread CPU time (NaN where /proc/thread-self/schedstat is absent).
    pub cpu_ms_per_frame: f64,
}

/// What OpenCV produced for one segment.
pub struct CvSegment {
    pub corners: Vec<Point>,
    pub given_tracks: Vec<Vec<Option<Point>>>,
    pub boxes: Vec<Option<BBox>>,
    pub ms_per_frame: f64,
    pub cpu_ms_per_frame: f64,
}

/// This thread's time on a CPU in nanoseconds (Linux `/proc/thread-self/schedstat`),
/// which other jobs on a shared machine inflate far less than wall-clock time.
pub fn thread_cpu_ns() -> Option<u64> {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

fn gray(clip: &Clip, f: usize) -> GrayImage<'_> {
    GrayImage::new(&clip.frames[f], clip.width, clip.height, clip.width).expect("clip frame")
}

/// Runs the Rust tracker over `[start, start + length]` for every start; the timing is
/// the best of `repeat` runs of pyramid build + track per frame.
pub fn run_rust(clip: &Clip, starts: &[usize], length: usize, repeat: usize) -> Vec<RustSegment> {
    let (w, h) = (clip.width, clip.height);
    let prm = PARITY;
    let need = Pyramid::required_len(w, h, prm.lk.levels).expect("pyramid size");
    let (mut wa, mut wb) = (vec![0u8; need], vec![0u8; need]);
    let mut out = Vec::new();
    for &start in starts {
        let end = (start + length).min(clip.frames.len() - 1);
        let mut prev = Pyramid::new(&mut wa, w, h, prm.lk.levels).expect("workspace");
        let mut next = Pyramid::new(&mut wb, w, h, prm.lk.levels).expect("workspace");
        prev.build(&gray(clip, start)).expect("build");
        let mut tracker = Tracker::<MAX_POINTS>::new(prm);
        tracker
            .init(&prev, clip.boxes[start])
            .expect("corners on the sign");
        let corners = tracker.points().to_vec();

        // LK chain from the corners, no filtering.
        let mut pts: Vec<Option<Point>> = corners.iter().copied().map(Some).collect();
        let mut given = Vec::new();
        for f in start + 1..=end {
            next.build(&gray(clip, f)).expect("build");
            for p in pts.iter_mut() {
                *p = p.and_then(|q| track_point(&prev, &next, q, q, &prm.lk));
            }
            given.push(pts.clone());
            std::mem::swap(&mut prev, &mut next);
        }

        // The full tracker, timed.
        let mut best: Option<(Vec<Option<BBox>>, f64, f64)> = None;
        for _ in 0..repeat.max(1) {
            prev.build(&gray(clip, start)).expect("build");
            tracker.init(&prev, clip.boxes[start]).expect("corners");
            let mut boxes = Vec::new();
            let (t0, c0) = (Instant::now(), thread_cpu_ns());
            for f in start + 1..=end {
                next.build(&gray(clip, f)).expect("build");
                let b = if tracker.is_active() {
                    tracker.track(&prev, &next).ok().map(|o| o.bbox)
                } else {
                    None
                };
                boxes.push(b);
                std::mem::swap(&mut prev, &mut next);
            }
            let frames = (end - start).max(1) as f64;
            let ms = t0.elapsed().as_secs_f64() * 1e3 / frames;
            let cpu = match (c0, thread_cpu_ns()) {
                (Some(a), Some(b)) => (b - a) as f64 * 1e-6 / frames,
                _ => f64::NAN,
            };
            if best.as_ref().is_none_or(|(_, b, _)| ms < *b) {
                best = Some((boxes, ms, cpu));
            }
        }
        let (boxes, ms_per_frame, cpu_ms_per_frame) = best.expect("at least one run");
        out.push(RustSegment {
            start,
            corners,
            given_tracks: given,
            boxes,
            ms_per_frame,
            cpu_ms_per_frame,
        });
    }
    out
}

/// Writes the clip and the Rust corners (`rust_points.csv`) for the Python side.
pub fn write_inputs(dir: &Path, clip: &Clip, segs: &[RustSegment]) -> std::io::Result<()> {
    clip.write_pgm_dir(dir)?;
    let mut csv = String::from("start,x,y\n");
    for s in segs {
        for p in &s.corners {
            writeln!(csv, "{},{},{}", s.start, p.x, p.y).expect("string write");
        }
    }
    std::fs::write(dir.join("rust_points.csv"), csv)
}

/// The Python interpreter with cv2, or `None` when FRUGAL_PYTHON is unset.
pub fn python() -> Option<PathBuf> {
    std::env::var_os("FRUGAL_PYTHON").map(PathBuf::from)
}

fn point(v: &serde_json::Value) -> Option<Point> {
    Some(Point {
        x: v.get(0)?.as_f64()? as f32,
        y: v.get(1)?.as_f64()? as f32,
    })
}

fn bbox(v: &serde_json::Value) -> Option<BBox> {
    let a = v.as_array()?;
    let f = |i: usize| a.get(i).and_then(|x| x.as_f64()).map(|x| x as f32);
    Some(BBox::new(f(0)?, f(1)?, f(2)?, f(3)?))
}

/// Runs `tools/klt_opencv.py` on `dir`; returns the OpenCV version and its segments.
pub fn run_opencv(
    python: &Path,
    dir: &Path,
    length: usize,
    repeat: usize,
) -> Result<(String, Vec<CvSegment>), String> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/klt_opencv.py");
    let prm = PARITY;
    let out = Command::new(python)
        .arg(&script)
        .arg(dir)
        .args(["--length", &length.to_string()])
        .args(["--win", &(2 * prm.lk.win_radius + 1).to_string()])
        .args(["--levels", &prm.lk.levels.to_string()])
        .args(["--iters", &prm.lk.max_iters.to_string()])
        .args(["--eps", &prm.lk.epsilon.to_string()])
        .args(["--max-points", &MAX_POINTS.to_string()])
        .args(["--quality", &prm.corners.quality_level.to_string()])
        .args(["--min-distance", &prm.corners.min_distance.to_string()])
        .args(["--margin", &prm.box_margin.to_string()])
        .args(["--max-fb", &prm.max_fb_error.to_string()])
        .args(["--repeat", &repeat.to_string()])
        .output()
        .map_err(|e| format!("running {}: {e}", python.display()))?;
    if !out.status.success() {
        return Err(format!(
            "{} failed: {}",
            script.display(),
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    let v: serde_json::Value = serde_json::from_slice(&out.stdout)
        .map_err(|e| format!("{}: bad JSON: {e}", script.display()))?;
    let version = v["opencv"].as_str().unwrap_or("?").to_string();
    let segs = v["segments"]
        .as_array()
        .ok_or("no segments")?
        .iter()
        .map(|s| CvSegment {
            corners: s["corners"]
                .as_array()
                .map(|a| a.iter().filter_map(point).collect())
                .unwrap_or_default(),
            given_tracks: s["given_tracks"]
                .as_array()
                .map(|fr| {
                    fr.iter()
                        .map(|f| {
                            f.as_array()
                                .map(|ps| {
                                    ps.iter()
                                        .map(|p| {
                                            if p[2].as_bool() == Some(true) {
                                                point(p)
                                            } else {
                                                None
                                            }
                                        })
                                        .collect()
                                })
                                .unwrap_or_default()
                        })
                        .collect()
                })
                .unwrap_or_default(),
            boxes: s["boxes"]
                .as_array()
                .map(|a| a.iter().map(bbox).collect())
                .unwrap_or_default(),
            ms_per_frame: s["ms_per_frame"].as_f64().unwrap_or(f64::NAN),
            cpu_ms_per_frame: s["cpu_ms_per_frame"].as_f64().unwrap_or(f64::NAN),
        })
        .collect();
    Ok((version, segs))
}

/// Per-frame-offset figures over all segments.
pub struct Comparison {
    /// Distances between Rust and OpenCV positions of the same starting corner, for
    /// points both kept, per frame offset (1..=length).
    pub point_diffs: Vec<Vec<f32>>,
    /// Distances to the exact position (the sign moves by a known similarity) of the
    /// same points, per frame offset, Rust and OpenCV.
    pub gt_err_rust: Vec<Vec<f32>>,
    pub gt_err_cv: Vec<Vec<f32>>,
    /// Mean IoU with ground truth per frame offset (lost counts as 0), Rust and OpenCV.
    pub iou_rust: Vec<f64>,
    pub iou_cv: Vec<f64>,
    /// Fraction of Rust corners within 1.5 px of an OpenCV corner.
    pub corner_match: f64,
    pub corners_rust: usize,
    pub corners_cv: usize,
    pub ms_rust: f64,
    pub ms_cv: f64,
    pub cpu_ms_rust: f64,
    pub cpu_ms_cv: f64,
}

pub fn median(v: &mut [f32]) -> f32 {
    if v.is_empty() {
        return f32::NAN;
    }
    v.sort_by(f32::total_cmp);
    v[v.len() / 2]
}

pub fn compare(clip: &Clip, rust: &[RustSegment], cv: &[CvSegment], length: usize) -> Comparison {
    let mut point_diffs = vec![Vec::new(); length];
    let (mut gt_err_rust, mut gt_err_cv) = (vec![Vec::new(); length], vec![Vec::new(); length]);
    let (mut iou_rust, mut iou_cv, mut counts) =
        (vec![0.0; length], vec![0.0; length], vec![0usize; length]);
    let (mut matched, mut corners_rust, mut corners_cv) = (0usize, 0usize, 0usize);
    let (mut ms_rust, mut ms_cv, mut cpu_ms_rust, mut cpu_ms_cv) = (0.0, 0.0, 0.0, 0.0);
    for (r, c) in rust.iter().zip(cv) {
        corners_rust += r.corners.len();
        corners_cv += c.corners.len();
        matched += r
            .corners
            .iter()
            .filter(|p| {
                c.corners
                    .iter()
                    .any(|q| (p.x - q.x).hypot(p.y - q.y) <= 1.5)
            })
            .count();
        for (k, (rf, cf)) in r.given_tracks.iter().zip(&c.given_tracks).enumerate() {
            let (b0, b1) = (clip.boxes[r.start], clip.boxes[r.start + k + 1]);
            for ((a, b), p0) in rf.iter().zip(cf).zip(&r.corners) {
                // Where the corner truly is: the renderer maps pixel centres (x + 0.5).
                let u = (p0.x + 0.5 - b0.x1) / b0.width();
                let v = (p0.y + 0.5 - b0.y1) / b0.height();
                let (tx, ty) = (b1.x1 + u * b1.width() - 0.5, b1.y1 + v * b1.height() - 0.5);
                if let (Some(a), Some(b)) = (a, b) {
                    point_diffs[k].push((a.x - b.x).hypot(a.y - b.y));
                    gt_err_rust[k].push((a.x - tx).hypot(a.y - ty));
                    gt_err_cv[k].push((b.x - tx).hypot(b.y - ty));
                }
            }
        }
        for (k, (rb, cb)) in r.boxes.iter().zip(&c.boxes).enumerate() {
            let gt = clip.boxes[r.start + k + 1];
            iou_rust[k] += rb.map_or(0.0, |b| f64::from(b.iou(&gt)));
            iou_cv[k] += cb.map_or(0.0, |b| f64::from(b.iou(&gt)));
            counts[k] += 1;
        }
        ms_rust += r.ms_per_frame;
        ms_cv += c.ms_per_frame;
        cpu_ms_rust += r.cpu_ms_per_frame;
        cpu_ms_cv += c.cpu_ms_per_frame;
    }
    for k in 0..length {
        let n = counts[k].max(1) as f64;
        iou_rust[k] /= n;
        iou_cv[k] /= n;
    }
    let segs = rust.len().max(1) as f64;
    Comparison {
        point_diffs,
        gt_err_rust,
        gt_err_cv,
        iou_rust,
        iou_cv,
        corner_match: matched as f64 / corners_rust.max(1) as f64,
        corners_rust,
        corners_cv,
        ms_rust: ms_rust / segs,
        ms_cv: ms_cv / segs,
        cpu_ms_rust: cpu_ms_rust / segs,
        cpu_ms_cv: cpu_ms_cv / segs,
    }
}
