//! The pilot carries only what it can trust: a detection in its variant's optimal
//! bucket is tracked; a good-enough one, or one whose tracker cannot start, is
//! reported on its frame and the next frame is detected again. Carrying from the
//! good-enough bucket (`Carry::GoodEnough`) moves that line down to `c_ge`, and the
//! paper's rule (`Carry::Reported`) to `T_c`: everything reported is carried.

use frugal_runtime::bundle::write::{BundleWriter, FamilySpec, VariantSpec};
use frugal_runtime::bundle::{ScoreBuckets, Thresholds};
use frugal_runtime::pilot::{Carry, Pilot, TrackStats};
use frugal_runtime::synth::{ClipSpec, make_clip};
use frugal_runtime::track::{GrayImage, Pyramid};
use frugal_runtime::{Access, BBox, Bundle, Decision, Detection, Trigger};

const CNN: ScoreBuckets = ScoreBuckets {
    c_opt: 0.9,
    c_ge: 0.6,
    c_ua: 0.3,
    t_c: 0.5,
};

/// One variant, which the policy keeps in every state.
fn bundle_bytes() -> Vec<u8> {
    BundleWriter::new(Thresholds::PAPER)
        .family(FamilySpec {
            name: "cnn".into(),
            buckets: CNN,
        })
        .variant(VariantSpec::new("only", 0, 1.0, 2.0))
        .policy(0, vec![0; 4])
        .finish()
        .unwrap()
}

/// Runs the pilot over `frames` frames of a textured clip whose `blank` rectangle
/// (x0, y0, x1, y1) is painted flat grey, the "detector" answering `found(frame
/// index)`; returns each frame's decision and the boxes it reports (the detection's on
/// a detection frame, the tracked ones else).
fn fly(
    frames: usize,
    carry: Carry,
    found: impl Fn(usize) -> Vec<Detection>,
    blank: Option<(usize, usize, usize, usize)>,
) -> Vec<(Decision, Vec<Detection>)> {
    fly_counted(frames, carry, found, blank).0
}

/// [`fly`], and the pilot's count of what became of the boxes it was handed.
fn fly_counted(
    frames: usize,
    carry: Carry,
    found: impl Fn(usize) -> Vec<Detection>,
    blank: Option<(usize, usize, usize, usize)>,
) -> (Vec<(Decision, Vec<Detection>)>, TrackStats) {
    let spec = ClipSpec {
        width: 160,
        height: 120,
        sign_size: 40.0,
        growth: 1.0,
        velocity: (0.5, 0.0),
        ..ClipSpec::standard(3, frames)
    };
    let clip = make_clip(&spec);
    let (w, h) = (clip.width, clip.height);
    let need = Pyramid::required_len(w, h, 3).unwrap();
    let (mut a, mut b) = (vec![0u8; need], vec![0u8; need]);
    let bytes = bundle_bytes();
    let mut pilot: Pilot<'_, 4, 48> = Pilot::new(Bundle::parse(&bytes).unwrap()).with_carry(carry);
    let mut prev = Pyramid::new(&mut a, w, h, 3).unwrap();
    let mut cur = Pyramid::new(&mut b, w, h, 3).unwrap();
    let mut out = Vec::new();
    for i in 0..frames {
        let mut img = clip.frames[i].clone();
        if let Some((x0, y0, x1, y1)) = blank {
            for row in img.chunks_mut(w).take(y1).skip(y0) {
                row[x0..x1].fill(128);
            }
        }
        cur.build(&GrayImage::new(&img, w, h, w).unwrap()).unwrap();
        let decision = pilot.decide(i as u32, (i > 0).then_some(&prev), &cur);
        let shown = match decision {
            Decision::Detect { .. } => {
                let dets = found(i);
                assert_eq!(pilot.detected(&cur, &dets), Access::Done);
                let t_c = pilot.report_score();
                dets.into_iter().filter(|d| d.score >= t_c).collect()
            }
            Decision::Track => pilot.tracked().collect(),
        };
        out.push((decision, shown));
        std::mem::swap(&mut prev, &mut cur);
    }
    (out, pilot.track_stats())
}

fn sign(score: f32) -> Detection {
    Detection {
        bbox: BBox::new(60.0, 40.0, 100.0, 80.0),
        score,
        class: 2,
    }
}

fn detections(run: &[(Decision, Vec<Detection>)]) -> usize {
    run.iter()
        .filter(|(d, _)| matches!(d, Decision::Detect { .. }))
        .count()
}

#[test]
fn an_optimal_detection_is_carried_by_the_tracker() {
    let run = fly(10, Carry::Optimal, |_| vec![sign(0.95)], None);
    // detected at the start, tracked until the re-initialisation at M = 10
    assert_eq!(detections(&run), 1, "{run:?}");
    for (decision, shown) in &run[1..] {
        assert_eq!(*decision, Decision::Track);
        assert_eq!(shown.len(), 1);
        assert_eq!(shown[0].class, 2);
    }
}

#[test]
fn a_good_enough_detection_is_reported_but_detected_again_not_carried() {
    // 0.7: at least T_c (reported, and the controller is content with the score) but
    // below c_opt
    let run = fly(10, Carry::Optimal, |_| vec![sign(0.7)], None);
    assert_eq!(detections(&run), 10, "{run:?}");
    for (decision, shown) in &run[1..] {
        assert!(
            matches!(
                decision,
                Decision::Detect {
                    reason: Trigger::TrackerLost,
                    ..
                }
            ),
            "{decision:?}"
        );
        assert_eq!(shown.len(), 1, "reported on its own frame");
    }
    // an optimal box beside it is carried, but the frames are still detected again
    let run = fly(
        10,
        Carry::Optimal,
        |_| {
            let mut far = sign(0.7);
            far.bbox = BBox::new(10.0, 10.0, 40.0, 40.0);
            vec![sign(0.95), far]
        },
        None,
    );
    assert_eq!(detections(&run), 10, "{run:?}");
}

#[test]
fn a_detection_whose_tracker_cannot_start_is_detected_again() {
    // the second sign stands on a flat patch, with no corners to track: both are
    // reported on the detection frame, and the next frame is detected again instead
    // of showing the first sign alone until the re-initialisation
    let far = Detection {
        bbox: BBox::new(115.0, 15.0, 145.0, 45.0),
        score: 0.95,
        class: 4,
    };
    let run = fly(
        5,
        Carry::Optimal,
        |_| vec![sign(0.95), far],
        Some((105, 5, 155, 55)),
    );
    assert_eq!(detections(&run), 5, "{run:?}");
    assert!(run.iter().all(|(_, shown)| shown.len() == 2), "{run:?}");
}

#[test]
fn carrying_from_good_enough_tracks_a_good_enough_detection_but_not_a_weaker_one() {
    // 0.7 is in the good-enough bucket [c_ge 0.6, c_opt 0.9): carried under GoodEnough
    let run = fly(10, Carry::GoodEnough, |_| vec![sign(0.7)], None);
    assert_eq!(detections(&run), 1, "{run:?}");
    assert!(run.iter().all(|(_, shown)| shown.len() == 1), "{run:?}");
    // 0.55 is reported (T_c 0.5) but below c_ge: detected again on every frame
    let run = fly(10, Carry::GoodEnough, |_| vec![sign(0.55)], None);
    assert_eq!(detections(&run), 10, "{run:?}");
    assert!(run.iter().all(|(_, shown)| shown.len() == 1), "{run:?}");
}

#[test]
fn carrying_every_reported_detection_tracks_a_weak_one_but_not_an_unreported_one() {
    // 0.55 is reported (T_c 0.5) though below c_ge: the paper's rule carries it
    let (run, stats) = fly_counted(10, Carry::Reported, |_| vec![sign(0.55)], None);
    assert_eq!(detections(&run), 1, "{run:?}");
    assert!(run.iter().all(|(_, shown)| shown.len() == 1), "{run:?}");
    let started = TrackStats {
        started: 1,
        ..TrackStats::default()
    };
    assert_eq!(stats, started);
    // 0.45 is below T_c: never reported nor carried, and the controller detects again
    let (run, stats) = fly_counted(10, Carry::Reported, |_| vec![sign(0.45)], None);
    assert_eq!(detections(&run), 10, "{run:?}");
    assert!(run.iter().all(|(_, shown)| shown.is_empty()), "{run:?}");
    assert_eq!(stats, TrackStats::default());
}

#[test]
fn the_pilot_counts_why_a_reported_box_was_not_carried() {
    // below c_ge under GoodEnough: reported and detected again on each of 10 frames
    let (_, stats) = fly_counted(10, Carry::GoodEnough, |_| vec![sign(0.55)], None);
    let not_carried = TrackStats {
        not_carried: 10,
        ..TrackStats::default()
    };
    assert_eq!(stats, not_carried);
    // a sign on a flat patch has no corners: its tracker fails to start on each of 5
    // detection frames, while the textured one beside it starts every time
    let flat = Detection {
        bbox: BBox::new(115.0, 15.0, 145.0, 45.0),
        score: 0.95,
        class: 4,
    };
    let (run, stats) = fly_counted(
        5,
        Carry::Optimal,
        |_| vec![sign(0.95), flat],
        Some((105, 5, 155, 55)),
    );
    assert_eq!(detections(&run), 5, "{run:?}");
    let failed = TrackStats {
        started: 5,
        failed_to_start: 5,
        ..TrackStats::default()
    };
    assert_eq!(stats, failed);
}
