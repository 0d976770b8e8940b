//! Streaming AP against an independent peer, on timestamped outputs of a simulated
//! perception loop.

use super::fixture::python_peer;
use frugal_models::metrics::{IgnoreRegion, ImageResult, Truth};
use frugal_policies::stream::{FrameRule, arrivals, sap, simulate, streaming_images};
use frugal_runtime::{BBox, Detection};
use rand::{Rng, SeedableRng};

fn xywh(b: &BBox) -> [f64; 4] {
    let (x1, y1, x2, y2) = (
        f64::from(b.x1),
        f64::from(b.y1),
        f64::from(b.x2),
        f64::from(b.y2),
    );
    [x1, y1, x2 - x1, y2 - y1]
}

/// Moving objects of 3 classes over 3 videos, each with a crowd (ignore region) of one
/// class; a noisy detector whose compute time varies from 5 to 90 ms and that also
/// fires inside the crowd, streamed at 30 fps with the latest-frame rule: sAP@0.5,
/// sAP@[.5:.95] and streaming F1 equal pycocotools' on the same pairs.
#[test]
fn stream_sap_matches_pycocotools() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(23);
    let classes = 3;
    let mut all_images: Vec<ImageResult> = Vec::new();
    let mut videos_json = Vec::new();
    for _video in 0..3 {
        let n = 45;
        // 1-3 objects, each with a start box and a velocity
        let objects: Vec<(u16, [f32; 4], [f32; 2])> = (0..rng.random_range(1..=3))
            .map(|_| {
                let (x, y) = (
                    rng.random_range(0.0..300.0f32),
                    rng.random_range(0.0..200.0f32),
                );
                let (w, h) = (
                    rng.random_range(12.0..80.0f32),
                    rng.random_range(12.0..80.0f32),
                );
                let v = [
                    rng.random_range(-6.0..6.0f32),
                    rng.random_range(-3.0..3.0f32),
                ];
                (rng.random_range(0..classes) as u16, [x, y, w, h], v)
            })
            .collect();
        // a still crowd region of one class, far from the start of the moving objects
        let crowd = IgnoreRegion {
            class: Some(rng.random_range(0..classes) as u16),
            bbox: BBox::new(420.0, 260.0, 500.0, 330.0),
        };
        let truth: Vec<ImageResult> = (0..n)
            .map(|f| ImageResult {
                truth: objects
                    .iter()
                    .filter(|_| f % 17 != 5) // some frames without truth
                    .map(|&(class, [x, y, w, h], [vx, vy])| {
                        let (x, y) = (x + vx * f as f32, y + vy * f as f32);
                        Truth {
                            class,
                            bbox: BBox {
                                x1: x,
                                y1: y,
                                x2: x + w,
                                y2: y + h,
                            },
                        }
                    })
                    .collect(),
                ignore: vec![crowd],
                ..ImageResult::default()
            })
            .collect();
        let arr = arrivals(n, 30.0);
        let mut det_rng = rand_chacha::ChaCha8Rng::seed_from_u64(rng.random());
        let run = simulate(&arr, FrameRule::Latest, 1.0, |f| {
            let mut shown: Vec<Detection> = Vec::new();
            for t in &truth[f].truth {
                if det_rng.random_bool(0.15) {
                    continue; // a miss
                }
                let j = |r: &mut rand_chacha::ChaCha8Rng| r.random_range(-4.0..4.0f32);
                let class = if det_rng.random_bool(0.1) {
                    (t.class + 1) % classes as u16
                } else {
                    t.class
                };
                shown.push(Detection {
                    bbox: BBox {
                        x1: t.bbox.x1 + j(&mut det_rng),
                        y1: t.bbox.y1 + j(&mut det_rng),
                        x2: t.bbox.x2 + j(&mut det_rng),
                        y2: t.bbox.y2 + j(&mut det_rng),
                    },
                    score: det_rng.random_range(0.3..1.0),
                    class,
                });
            }
            // inside the crowd: of its class (excused when ≥ 50 % … 95 % of the box is
            // in it) or of another class (a false alarm)
            if det_rng.random_bool(0.5) {
                let (x, y) = (
                    det_rng.random_range(400.0..470.0f32),
                    det_rng.random_range(250.0..300.0f32),
                );
                let class = if det_rng.random_bool(0.7) {
                    crowd.class.unwrap_or(0)
                } else {
                    (crowd.class.unwrap_or(0) + 1) % classes as u16
                };
                shown.push(Detection {
                    bbox: BBox::new(x, y, x + 30.0, y + 25.0),
                    score: det_rng.random_range(0.3..1.0),
                    class,
                });
            }
            if det_rng.random_bool(0.3) {
                let (x, y) = (
                    det_rng.random_range(0.0..400.0f32),
                    det_rng.random_range(0.0..250.0f32),
                );
                shown.push(Detection {
                    bbox: BBox {
                        x1: x,
                        y1: y,
                        x2: x + 30.0,
                        y2: y + 25.0,
                    },
                    score: det_rng.random_range(0.3..0.9),
                    class: det_rng.random_range(0..classes) as u16,
                });
            }
            Ok(Some((shown, det_rng.random_range(5.0..90.0))))
        })
        .unwrap();
        assert!(
            run.skipped > 0,
            "the case should exercise the latest-frame rule"
        );
        all_images.extend(streaming_images(&arr, &truth, &run));
        videos_json.push(serde_json::json!({
            "frames": arr.iter().zip(&truth).map(|(t, tr)| serde_json::json!({
                "time_ms": t,
                "truth": tr.truth.iter().map(|g| serde_json::json!({"category_id": g.class, "bbox": xywh(&g.bbox)})).collect::<Vec<_>>(),
                "ignore": tr.ignore.iter().map(|g| serde_json::json!({"category_id": g.class, "bbox": xywh(&g.bbox)})).collect::<Vec<_>>(),
            })).collect::<Vec<_>>(),
            "outputs": run.outputs.iter().map(|o| serde_json::json!({
                "finish_ms": o.finish_ms,
                "detections": o.shown.iter().map(|d| serde_json::json!({
                    "category_id": d.class, "bbox": xywh(&d.bbox), "score": f64::from(d.score),
                })).collect::<Vec<_>>(),
            })).collect::<Vec<_>>(),
        }));
    }
    let (ours50, ours) = sap(&all_images, classes);
    assert!(
        ours50 > 0.05 && ours50 < 0.95,
        "a case far from 0 and 1: {ours50}"
    );
    // the crowds matter: without them, the detections inside are false alarms
    let no_crowd: Vec<ImageResult> = all_images
        .iter()
        .map(|im| ImageResult {
            ignore: Vec::new(),
            ..im.clone()
        })
        .collect();
    let (plain50, _) = sap(&no_crowd, classes);
    assert!(
        plain50 < ours50 - 0.01,
        "crowds should excuse detections: {plain50} without, {ours50} with"
    );

    let case =
        serde_json::json!({"categories": (0..classes).collect::<Vec<_>>(), "videos": videos_json});
    let theirs = python_peer("sap_peer.py", &case);
    let (t50, t) = (
        theirs["sap50"].as_f64().unwrap(),
        theirs["sap"].as_f64().unwrap(),
    );
    assert!(
        (ours50 - t50).abs() < 1e-9,
        "sAP@0.5: frugal {ours50}, pycocotools {t50}"
    );
    assert!(
        (ours - t).abs() < 1e-9,
        "sAP@[.5:.95]: frugal {ours}, pycocotools {t}"
    );
    // streaming F1 (the budget scores' `sf1`): the same pairs, F1 at IoU 0.5
    let ours_f1 = frugal_models::metrics::evaluate(
        &all_images,
        classes,
        0.5,
        f32::NEG_INFINITY,
        frugal_models::metrics::Interpolation::AllPoint,
    )
    .f1;
    let theirs_f1 = theirs["sf1"].as_f64().unwrap();
    assert!(
        ours_f1 > 0.05 && ours_f1 < 0.95,
        "a case far from 0 and 1: {ours_f1}"
    );
    assert!(
        (ours_f1 - theirs_f1).abs() < 1e-9,
        "streaming F1: frugal {ours_f1}, pycocotools {theirs_f1}"
    );
}

/// The streaming clock runs on the frames' own times when every frame has one (imported
/// video, here with a gap where the source dropped frames), else at the given rate.
#[test]
fn frames_arrive_at_their_own_times_when_they_have_them() {
    use frugal_data::{Clutter, Light, Split};
    use frugal_policies::replay::{FrameLog, VideoLog};
    let frame = |index: u32, time_s: Option<f64>| FrameLog {
        index,
        truth: Vec::new(),
        detections: Vec::new(),
        ignore: Vec::new(),
        time_s,
    };
    let mut video = VideoLog {
        id: 0,
        clutter: Clutter::Low,
        light: Light::Normal,
        split: Split::Test,
        width: 64,
        height: 48,
        frames: vec![
            frame(0, Some(10.0)),
            frame(1, Some(10.04)),
            frame(2, Some(10.2)),
        ],
    };
    let arr = video.arrivals_ms(30.0);
    assert_eq!(arr.len(), 3);
    for (a, want) in arr.iter().zip([0.0, 40.0, 200.0]) {
        assert!((a - want).abs() < 1e-9, "{arr:?}");
    }
    // one frame without a time: the whole video runs on the rate
    video.frames[1].time_s = None;
    assert_eq!(video.arrivals_ms(25.0), arrivals(3, 25.0));
}
