//! What the KLT tracker's parameters cost and buy on a dataset's validation videos: for
//! each parameter set, the thread CPU time of a pyramid, of a tracker start and of one
//! tracked frame per sign, and how many signs a track still covers at IoU ≥ 0.5 after
//! `steps` tracked frames `gap` frames apart (a gap of 2 or 3 is what a detection that
//! outlasts a frame interval leaves the tracker).
//!
//! ```sh
//! cargo run --release -p frugal-policies --example tracker_params -- \
//!     runs/default/data/dataset [steps 4] [videos 12] [gap 1]
//! ```
//!
//! Every sign of every `steps · gap`-th frame starts a track on its true box; the IoU is
//! taken against the best-matching true box of the same class on the last frame.

use frugal_data::Dataset;
use frugal_data::dataset::Split;
use frugal_runtime::geom::FrameRef;
use frugal_runtime::track::{LkParams, Pyramid, Tracker, TrackerParams};
use std::path::Path;

/// The calling thread's time on a CPU, in nanoseconds (Linux
/// `/proc/thread-self/schedstat`; 0 where there is none).
fn cpu_ns() -> u64 {
    let stat = std::fs::read_to_string("/proc/thread-self/schedstat").unwrap_or_default();
    stat.split_whitespace()
        .next()
        .and_then(|t| t.parse().ok())
        .unwrap_or(0)
}

fn with_lk(win_radius: usize, levels: usize, max_iters: u32, epsilon: f32) -> TrackerParams {
    TrackerParams {
        lk: LkParams {
            win_radius,
            levels,
            max_iters,
            epsilon,
            ..TrackerParams::DEFAULT.lk
        },
        ..TrackerParams::DEFAULT
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let root = args
        .get(1)
        .ok_or("usage: tracker_params DATASET [steps] [videos] [gap]")?;
    let arg = |i: usize, default: usize| -> Result<usize, Box<dyn std::error::Error>> {
        Ok(args.get(i).map_or(Ok(default), |s| s.parse())?)
    };
    let (steps, videos, gap) = (arg(2, 4)?, arg(3, 12)?, arg(4, 1)?.max(1));
    let ds = Dataset::load(Path::new(root))?;
    let mut wider = TrackerParams::DEFAULT;
    wider.corners.min_distance = 6.0;
    let sets = [
        (
            "15x15, 3 levels, 20 steps, eps 0.01",
            with_lk(7, 3, 20, 0.01),
        ),
        (
            "11x11, 3 levels, 10 steps, eps 0.03",
            with_lk(5, 3, 10, 0.03),
        ),
        (
            "11x11, 3 levels, 20 steps, eps 0.01",
            with_lk(5, 3, 20, 0.01),
        ),
        (
            "15x15, 3 levels, 10 steps, eps 0.03",
            with_lk(7, 3, 10, 0.03),
        ),
        (
            "15x15, 2 levels, 20 steps, eps 0.01",
            with_lk(7, 2, 20, 0.01),
        ),
        ("default, corners 6 px apart", wider),
    ];
    let ids: Vec<u32> = ds
        .videos
        .iter()
        .filter(|v| v.split == Split::Val)
        .map(|v| v.id)
        .take(videos)
        .collect();
    println!(
        "{} validation videos, tracks of {steps} frames {gap} apart; thread CPU ms",
        ids.len()
    );
    println!(
        "{:<38} {:>8} {:>9} {:>9} {:>8} {:>7} {:>9} {:>8}",
        "parameters", "pyramid", "start", "per sign", "points", "lost", "IoU p50", ">= 0.5"
    );
    for (name, prm) in sets {
        let levels = prm.lk.levels;
        let (mut pyr, mut start, mut track) = ((0u64, 0u64), (0u64, 0u64), (0u64, 0u64));
        let (mut points, mut lost, mut kept, mut tracks) = (0usize, 0usize, 0usize, 0usize);
        let mut ious = Vec::new();
        for &id in &ids {
            let frames: Vec<_> = ds.frames.iter().filter(|f| f.video == id).collect();
            let Some(first) = frames.first() else {
                continue;
            };
            let (w, h) = (first.width as usize, first.height as usize);
            let need = Pyramid::required_len(w, h, levels).ok_or("bad frame size")?;
            let mut pyramids = Vec::with_capacity(frames.len());
            for f in &frames {
                let img = ds.load_rgb(f)?;
                let frame = FrameRef::new(img.width(), img.height(), img.as_raw())
                    .ok_or("bad pixel buffer")?;
                let mut buf = vec![0u8; need];
                let t = cpu_ns();
                Pyramid::new(&mut buf, w, h, levels)?.build_rgb(&frame)?;
                pyr = (pyr.0 + cpu_ns() - t, pyr.1 + 1);
                pyramids.push(buf);
            }
            let span = steps * gap;
            for s in (0..frames.len().saturating_sub(span)).step_by(span.max(1)) {
                for o in &frames[s].objects {
                    tracks += 1;
                    let mut tracker = Tracker::<48>::new(prm);
                    let mut b0 = pyramids[s].clone();
                    let p0 = Pyramid::new(&mut b0, w, h, levels)?;
                    let t = cpu_ns();
                    let started = tracker.init(&p0, o.bbox);
                    start = (start.0 + cpu_ns() - t, start.1 + 1);
                    let Ok(n) = started else { continue };
                    points += n;
                    for k in 1..=steps {
                        let (mut bp, mut bc) = (
                            pyramids[s + (k - 1) * gap].clone(),
                            pyramids[s + k * gap].clone(),
                        );
                        let prev = Pyramid::new(&mut bp, w, h, levels)?;
                        let cur = Pyramid::new(&mut bc, w, h, levels)?;
                        let t = cpu_ns();
                        let r = tracker.track(&prev, &cur);
                        track = (track.0 + cpu_ns() - t, track.1 + 1);
                        if r.is_err() {
                            lost += 1;
                            break;
                        }
                        if k == steps {
                            let iou = frames[s + k * gap]
                                .objects
                                .iter()
                                .filter(|g| g.class == o.class)
                                .map(|g| g.bbox.iou(&tracker.bbox()))
                                .fold(0f32, f32::max);
                            kept += usize::from(iou >= 0.5);
                            ious.push(iou);
                        }
                    }
                }
            }
        }
        ious.sort_by(f32::total_cmp);
        let ms = |(ns, n): (u64, u64)| ns as f64 / n.max(1) as f64 / 1e6;
        println!(
            "{name:<38} {:>8.3} {:>9.3} {:>9.3} {:>8.1} {:>7} {:>9.3} {:>8.3}",
            ms(pyr),
            ms(start),
            ms(track),
            points as f64 / start.1.max(1) as f64,
            lost,
            ious.get(ious.len() / 2).copied().unwrap_or(0.0),
            kept as f64 / tracks.max(1) as f64
        );
    }
    Ok(())
}
