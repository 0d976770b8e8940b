//! The Rust KLT tracker side by side with OpenCV's on the same synthetic clips.
//!
//! `cargo run --release -p frugal-runtime --example klt_vs_opencv [-- SEEDS FRAMES]`
//!
//! Renders deterministic 480×270 clips (a textured sign drifting, growing 2 %/frame and
//! shaking over a textured scene), tracks 10-frame segments with the Rust tracker and
//! with `tools/klt_opencv.py` (cv2.goodFeaturesToTrack + calcOpticalFlowPyrLK, one
//! thread, run by $FRUGAL_PYTHON), and prints: the corner-position difference of the
//! same starting corners chained through both LK implementations, the box IoU against
//! ground truth per frame for both full trackers, and time per frame for both.

#[path = "../tests/parity/mod.rs"]
#[allow(dead_code)]
mod parity;

use frugal_runtime::synth::{ClipSpec, make_clip};
use parity::{compare, median, python, run_opencv, run_rust, write_inputs};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let seeds: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(3);
    let frames: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(61);
    let py = python().ok_or(
        "FRUGAL_PYTHON is unset: run through cargo in the workspace after `cargo xtask setup`",
    )?;
    let length = 10;
    let starts: Vec<usize> = (0..frames.saturating_sub(length)).step_by(length).collect();
    let mut all_diffs = vec![Vec::new(); length];
    let (mut gt_r, mut gt_c) = (vec![Vec::new(); length], vec![Vec::new(); length]);
    let (mut iou_r, mut iou_c) = (vec![0.0; length], vec![0.0; length]);
    let (mut ms_r, mut ms_c, mut match_frac, mut n_r, mut n_c) = (0.0, 0.0, 0.0, 0, 0);
    let (mut cpu_r, mut cpu_c) = (0.0, 0.0);
    let mut version = String::new();
    for seed in 0..seeds {
        let clip = make_clip(&ClipSpec::standard(1000 + seed, frames));
        let rust = run_rust(&clip, &starts, length, 5);
        let dir = tempfile::tempdir()?;
        write_inputs(dir.path(), &clip, &rust)?;
        let (v, cv) = run_opencv(&py, dir.path(), length, 5)?;
        version = v;
        let c = compare(&clip, &rust, &cv, length);
        for k in 0..length {
            all_diffs[k].extend_from_slice(&c.point_diffs[k]);
            gt_r[k].extend_from_slice(&c.gt_err_rust[k]);
            gt_c[k].extend_from_slice(&c.gt_err_cv[k]);
            iou_r[k] += c.iou_rust[k] / seeds as f64;
            iou_c[k] += c.iou_cv[k] / seeds as f64;
        }
        ms_r += c.ms_rust / seeds as f64;
        ms_c += c.ms_cv / seeds as f64;
        cpu_r += c.cpu_ms_rust / seeds as f64;
        cpu_c += c.cpu_ms_cv / seeds as f64;
        match_frac += c.corner_match / seeds as f64;
        n_r += c.corners_rust;
        n_c += c.corners_cv;
    }
    println!(
        "KLT, Rust vs OpenCV {version}: {seeds} clips × {} segments of {length} frames, 480×270, 15×15 window, 3 levels, ≤ 64 points",
        starts.len()
    );
    println!(
        "corners: Rust {n_r}, OpenCV {n_c}; {:.1} % of Rust corners within 1.5 px of an OpenCV corner",
        100.0 * match_frac
    );
    println!();
    println!("Δ: Rust vs OpenCV position of the same starting corner chained through each LK;");
    println!("err: median distance to the exact position (the sign moves by a known similarity).");
    println!();
    println!(
        "| frame | points both kept | mean Δ (px) | median Δ (px) | max Δ (px) | err Rust (px) | err OpenCV (px) | IoU Rust | IoU OpenCV |"
    );
    println!(
        "|------:|-----------------:|------------:|--------------:|-----------:|--------------:|----------------:|---------:|-----------:|"
    );
    for k in 0..length {
        let d = &mut all_diffs[k];
        let mean = d.iter().map(|&x| f64::from(x)).sum::<f64>() / d.len().max(1) as f64;
        let max = d.iter().copied().fold(0.0f32, f32::max);
        let n = d.len();
        println!(
            "| +{:<4} | {n:>16} | {mean:>11.4} | {:>13.4} | {max:>10.3} | {:>13.4} | {:>15.4} | {:>8.3} | {:>10.3} |",
            k + 1,
            median(d),
            median(&mut gt_r[k]),
            median(&mut gt_c[k]),
            iou_r[k],
            iou_c[k]
        );
    }
    println!();
    println!(
        "| time per frame | Rust (pyramid + LK fwd/bwd + median flow) | OpenCV (LK fwd/bwd incl. its pyramids + median flow) | OpenCV / Rust |"
    );
    println!("|---|---:|---:|---:|");
    println!(
        "| wall clock, mean of best-of-5 | {ms_r:.3} ms | {ms_c:.3} ms | {:.2}× |",
        ms_c / ms_r
    );
    println!(
        "| thread CPU time, same runs | {cpu_r:.3} ms | {cpu_c:.3} ms | {:.2}× |",
        cpu_c / cpu_r
    );
    Ok(())
}
