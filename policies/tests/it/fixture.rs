//! A tiny hand-made world: textured sign clips from the runtime's synthetic clip
//! generator (so the KLT tracker has something real to track), and ground-truth-derived
//! detectors of controlled cost and miss rate: a cheap one that misses in low light
//! and reports "good enough" scores, and an expensive one that always finds the sign
//! with "optimal" scores.

use frugal_data::{Clutter, Light, Split};
use frugal_policies::ReplayLog;
use frugal_policies::replay::{Det, FrameLog, MemoryFrames, RgbFrame, VideoLog, record};
use frugal_policies::variants::{
    CNN_BUCKETS, FamilyInfo, FrameDetector, SyntheticDetector, SyntheticSpec, VariantInfo,
    VariantSet, VariantSource,
};
use frugal_runtime::synth::{ClipSpec, make_clip};

pub const W: usize = 160;
pub const H: usize = 120;
pub const FRAMES: usize = 24;

/// (id, clutter, light, split) of the fixture's videos.
pub fn plan() -> Vec<(u32, Clutter, Light, Split)> {
    use Clutter as C;
    use Light as L;
    use Split as S;
    vec![
        (0, C::Low, L::Normal, S::Train),
        (1, C::Medium, L::Normal, S::Train),
        (2, C::Low, L::Low, S::Train),
        (3, C::High, L::Low, S::Train),
        (4, C::Medium, L::Normal, S::Val),
        (5, C::Low, L::Low, S::Val),
        (10, C::Low, L::Normal, S::Test),
        (11, C::High, L::Normal, S::Test),
        (12, C::Low, L::Low, S::Test),
        (13, C::Medium, L::Normal, S::Test),
    ]
}

/// Frames and empty logs (truth only).
pub fn clips() -> (MemoryFrames, Vec<VideoLog>) {
    let mut frames = MemoryFrames::default();
    let mut videos = Vec::new();
    for (id, clutter, light, split) in plan() {
        let spec = ClipSpec {
            width: W,
            height: H,
            frames: FRAMES,
            seed: 100 + u64::from(id),
            sign_size: 30.0,
            growth: 1.01,
            velocity: (1.2, 0.4),
            shake: 0.5,
            noise: 1,
        };
        let clip = make_clip(&spec);
        let mut logs = Vec::new();
        for (i, (gray, b)) in clip.frames.iter().zip(&clip.boxes).enumerate() {
            let rgb: Vec<u8> = gray.iter().flat_map(|&g| [g, g, g]).collect();
            frames.frames.insert(
                (id, i as u32),
                RgbFrame {
                    width: W as u32,
                    height: H as u32,
                    rgb,
                },
            );
            logs.push(FrameLog {
                index: i as u32,
                truth: vec![Det {
                    class: 0,
                    score: 1.0,
                    bbox: [b.x1, b.y1, b.x2, b.y2],
                }],
                detections: Vec::new(),
                ignore: Vec::new(),
                time_s: None,
            });
        }
        videos.push(VideoLog {
            id,
            clutter,
            light,
            split,
            width: W as u32,
            height: H as u32,
            frames: logs,
        });
    }
    (frames, videos)
}

/// The cheap variant: 2 ms, "good enough" scores, blind in low light.
pub fn cheap() -> SyntheticSpec {
    SyntheticSpec {
        seed: 1,
        miss: 0.0,
        miss_low_light: 0.95,
        miss_high_clutter: 0.1,
        jitter: 0.03,
        score: [0.6, 0.85],
        ..SyntheticSpec::default()
    }
}

/// The mid variant: 5 ms, optimal scores, misses half the time in low light.
pub fn mid() -> SyntheticSpec {
    SyntheticSpec {
        seed: 2,
        miss: 0.0,
        miss_low_light: 0.5,
        miss_high_clutter: 0.0,
        jitter: 0.02,
        score: [0.9, 0.97],
        ..SyntheticSpec::default()
    }
}

/// The expensive variant: 10 ms, always finds the sign with optimal scores.
pub fn expensive() -> SyntheticSpec {
    SyntheticSpec {
        seed: 3,
        miss: 0.0,
        miss_low_light: 0.0,
        miss_high_clutter: 0.0,
        jitter: 0.01,
        score: [0.92, 1.0],
        ..SyntheticSpec::default()
    }
}

/// A variant set of synthetic detectors, given (name, latency, spec), in any order.
pub fn set(specs: &[(&str, f64, SyntheticSpec)]) -> VariantSet {
    let families = vec![FamilyInfo {
        name: "cnn".into(),
        buckets: CNN_BUCKETS,
    }];
    let variants = specs
        .iter()
        .map(|(n, l, s)| VariantInfo {
            name: (*n).into(),
            family: 0,
            latency_ms: *l,
            relative_cost: 1.0,
            precision: Default::default(),
            source: VariantSource::Synthetic(s.clone()),
        })
        .collect();
    let detectors = specs
        .iter()
        .map(|(_, _, s)| Box::new(SyntheticDetector(s.clone())) as Box<dyn FrameDetector>)
        .collect();
    VariantSet::new(families, variants, detectors)
}

/// The replay log of the fixture with the two-variant set (expensive listed first, to
/// check that the set sorts cheapest first).
pub fn log2() -> (ReplayLog, MemoryFrames) {
    let (frames, videos) = clips();
    let mut s = set(&[("expensive", 10.0, expensive()), ("cheap", 2.0, cheap())]);
    let log = record(&mut s, &frames, videos, "".into(), 1, 8, false).unwrap();
    (log, frames)
}

/// The replay log with three variants.
pub fn log3() -> (ReplayLog, MemoryFrames) {
    let (frames, videos) = clips();
    let mut s = set(&[
        ("cheap", 2.0, cheap()),
        ("mid", 5.0, mid()),
        ("expensive", 10.0, expensive()),
    ]);
    let log = record(&mut s, &frames, videos, "".into(), 1, 8, false).unwrap();
    (log, frames)
}

/// Runs `tools/<script>` with the test venv's Python (`FRUGAL_PYTHON`, set by `cargo
/// xtask setup`), `input` as JSON on its stdin, and parses its stdout as JSON.
pub fn python_peer(script: &str, input: &serde_json::Value) -> serde_json::Value {
    use std::io::Write;
    use std::process::{Command, Stdio};
    let python =
        std::env::var_os("FRUGAL_PYTHON").expect("FRUGAL_PYTHON (set by cargo xtask setup)");
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tools")
        .join(script);
    let mut child = Command::new(python)
        .arg(&path)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("start the Python peer {}: {e}", path.display()));
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.to_string().as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "the Python peer {script} failed");
    serde_json::from_slice(&out.stdout).unwrap()
}
