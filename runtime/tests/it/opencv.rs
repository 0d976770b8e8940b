//! The Rust KLT against OpenCV's (`cv2.calcOpticalFlowPyrLK`, `cv2.goodFeaturesToTrack`)
//! on the same synthetic clip.
//!
//! Tolerance: both trackers refine each point at level 0 on the same 8-bit images with
//! the same 15×15 window and stopping rule (`parity::PARITY`, tighter than the deployed
//! defaults) (at most 20 Gauss-Newton steps, stop when a
//! step is shorter than ε = 0.01 px), so they solve the same least-squares problem and
//! differ only where one stops a step earlier than the other (≤ ε per frame), in the
//! pyramid filter (3-tap here, 5-tap in OpenCV: it moves only the coarse-level starting
//! guesses) and in interpolation precision (f32 here, 14-bit fixed point there, ~0.01
//! gray levels). Over a 10-frame chain that is at most ~10 ε = 0.1 px for a typical
//! point: the median difference must stay below 0.05 px in every frame and the 90th
//! percentile below 0.1 px. (A wrong gradient scale or gradient matrix only slows the
//! convergence yet already gave 0.2 px medians at +10 frames; a wrong sign or pyramid
//! geometry gives errors of pixels.)

use crate::parity::{MAX_POINTS, compare, python, run_opencv, run_rust, write_inputs};
use frugal_runtime::synth::{ClipSpec, make_clip};

#[test]
fn rust_klt_agrees_with_opencv() {
    let Some(py) = python() else {
        eprintln!(
            "SKIPPED rust_klt_agrees_with_opencv: FRUGAL_PYTHON is unset (run through cargo with the workspace .cargo/config.toml, after `cargo xtask setup`)"
        );
        return;
    };
    let length = 10;
    let clip = make_clip(&ClipSpec::standard(11, 31));
    let starts = [0, 10, 20];
    let rust = run_rust(&clip, &starts, length, 1);
    let dir = tempfile::tempdir().expect("temp dir");
    write_inputs(dir.path(), &clip, &rust).expect("write clip");
    let (_, cv) = run_opencv(&py, dir.path(), length, 1).expect("OpenCV peer");
    assert_eq!(cv.len(), rust.len());
    let cmp = compare(&clip, &rust, &cv, length);
    for (k, diffs) in cmp.point_diffs.iter().enumerate() {
        let mut d = diffs.clone();
        assert!(
            d.len() >= MAX_POINTS / 2,
            "frame +{}: only {} points kept by both",
            k + 1,
            d.len()
        );
        d.sort_by(f32::total_cmp);
        let med = d[d.len() / 2];
        let p90 = d[d.len() * 9 / 10];
        assert!(
            med < 0.05,
            "frame +{}: median point difference {med} px",
            k + 1
        );
        assert!(
            p90 < 0.1,
            "frame +{}: 90th percentile point difference {p90} px",
            k + 1
        );
    }
    // Same corner detector definition (min eigenvalue, 3x3 block, quality, distance).
    assert!(
        cmp.corner_match >= 0.7,
        "only {:.2} of Rust corners near an OpenCV corner",
        cmp.corner_match
    );
    for (k, (r, c)) in cmp.iou_rust.iter().zip(&cmp.iou_cv).enumerate() {
        assert!(*r >= 0.8, "frame +{}: Rust IoU {r}", k + 1);
        assert!(
            (r - c).abs() < 0.05,
            "frame +{}: Rust IoU {r} vs OpenCV {c}",
            k + 1
        );
    }
}
