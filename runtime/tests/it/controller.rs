use frugal_runtime::bundle::write::{BundleWriter, FamilySpec, VariantSpec};
use frugal_runtime::bundle::{Bucket, ScoreBuckets, Thresholds};
use frugal_runtime::synth::{ClipSpec, make_clip};
use frugal_runtime::track::{GrayImage, Pyramid, Tracker, TrackerParams};
use frugal_runtime::{
    Access, BBox, Bundle, Controller, Decision, Observation, TrackStatus, Trigger,
};

const CNN: ScoreBuckets = ScoreBuckets {
    c_opt: 0.9,
    c_ge: 0.6,
    c_ua: 0.3,
    t_c: 0.5,
};

/// Variants 0 (cheap CNN), 1 (full CNN), 2 (HoG, SVM margin scale).
/// Policy: optimal → cheapest of the family, good enough → stay, inadequate → the
/// full CNN, miss → HoG from the CNNs and the full CNN from HoG.
fn bundle_bytes(th: Thresholds) -> Vec<u8> {
    BundleWriter::new(th)
        .family(FamilySpec {
            name: "cnn".into(),
            buckets: CNN,
        })
        .family(FamilySpec {
            name: "hog".into(),
            buckets: ScoreBuckets::PAPER_SVM,
        })
        .variant(VariantSpec::new("cnn-small", 0, 1.0, 2.0))
        .variant(VariantSpec::new("cnn-full", 0, 5.0, 10.0))
        .variant(VariantSpec::new("hog", 1, 8.0, 16.0))
        .policy(0, vec![0, 0, 2, 0, 1, 2, 1, 1, 1, 2, 2, 1])
        .finish()
        .unwrap()
}

fn good(iou: f32) -> Option<TrackStatus> {
    Some(TrackStatus {
        bbox: BBox::new(10.0, 10.0, 40.0, 40.0),
        iou,
        quality: 0.9,
    })
}

fn obs(frame: u32, score: Option<f32>, track: Option<TrackStatus>) -> Observation {
    Observation {
        frame,
        score,
        track,
    }
}

fn detect(variant: u16, reason: Trigger) -> Decision {
    Decision::Detect { variant, reason }
}

#[test]
fn lookup_buckets_on_the_current_variants_family_scale() {
    let bytes = bundle_bytes(Thresholds::PAPER);
    let ctl = Controller::new(Bundle::parse(&bytes).unwrap());
    // 0.7 is "good enough" for the CNN (c_ge 0.6) → stay.
    assert_eq!(ctl.lookup(Some(0.7), 0), 0);
    assert_eq!(ctl.lookup(Some(0.95), 1), 0);
    assert_eq!(ctl.lookup(Some(0.4), 0), 1);
    assert_eq!(ctl.lookup(None, 0), 2);
    // On HoG's SVM scale 0.7 is "good enough" too, -0.2 inadequate, -0.7 a miss.
    assert_eq!(ctl.lookup(Some(0.7), 2), 2);
    assert_eq!(ctl.lookup(Some(0.95), 2), 2);
    assert_eq!(ctl.lookup(Some(-0.2), 2), 1);
    assert_eq!(ctl.lookup(Some(-0.7), 2), 1);
    // Unknown variant: no panic, stays.
    assert_eq!(ctl.lookup(Some(0.5), 9), 9);
    assert_eq!(ctl.bucket(), Bucket::Miss);
}

#[test]
fn the_paper_loop_triggers_in_order() {
    let th = Thresholds {
        iou_threshold: 0.5,
        min_track_quality: 0.3,
        mdp_period: 30,
        reinit_period: 10,
        accesses_per_image: 1,
    };
    let bytes = bundle_bytes(th);
    let mut c = Controller::new(Bundle::parse(&bytes).unwrap());
    // Start: the initial variant, no policy query.
    assert_eq!(c.step(&obs(0, None, None)), detect(0, Trigger::Start));
    // The detection scored 0.7 (>= T_c 0.5), the tracker holds a good box: track.
    assert_eq!(c.step(&obs(1, Some(0.7), good(0.9))), Decision::Track);
    // The score passed with a Track decision is ignored (no detection was asked for).
    for f in 2..10 {
        assert_eq!(
            c.step(&obs(f, Some(-5.0), good(0.9))),
            Decision::Track,
            "frame {f}"
        );
    }
    // M = 10 frames after the last detection: re-initialise with the same variant.
    assert_eq!(
        c.step(&obs(10, Some(-5.0), good(0.9))),
        detect(0, Trigger::Reinit)
    );
    // That detection scored 0.4 < T_c: ask the policy (inadequate, cnn-small) → cnn-full.
    assert_eq!(
        c.step(&obs(11, Some(0.4), good(0.9))),
        detect(1, Trigger::LowScore)
    );
    // cnn-full found it at 0.95; tracking resumes.
    assert_eq!(c.step(&obs(12, Some(0.95), good(0.9))), Decision::Track);
    // The tracker drifted away from the last detection (θ < θ_th).
    assert_eq!(c.step(&obs(13, None, good(0.3))), detect(0, Trigger::Drift));
    assert_eq!(c.step(&obs(14, Some(0.8), good(0.9))), Decision::Track);
    // Too few points left (quality < T_m), then no box at all.
    let weak = Some(TrackStatus {
        quality: 0.2,
        ..good(0.9).unwrap()
    });
    assert_eq!(
        c.step(&obs(15, None, weak)),
        detect(0, Trigger::TrackerLost)
    );
    assert_eq!(
        c.step(&obs(16, Some(0.8), None)),
        detect(0, Trigger::TrackerLost)
    );
    // A NaN IoU is not trusted.
    assert_eq!(
        c.step(&obs(17, Some(0.8), good(f32::NAN))),
        detect(0, Trigger::Drift)
    );
    assert_eq!(c.step(&obs(18, Some(0.8), good(0.9))), Decision::Track);
    // The last policy query was at frame 17: N = 30 frames later the MDP re-runs,
    // even though nothing else asks; reinit detections in between do not reset it.
    let mut reinits = 0;
    for f in 19..47 {
        match c.step(&obs(f, Some(0.8), good(0.9))) {
            Decision::Track => {}
            Decision::Detect {
                reason: Trigger::Reinit,
                variant: 0,
            } => reinits += 1,
            d => panic!("frame {f}: {d:?}"),
        }
    }
    assert_eq!(reinits, 2, "reinit detections at frames 27 and 37");
    assert_eq!(
        c.step(&obs(47, Some(0.8), good(0.9))),
        detect(0, Trigger::Periodic)
    );
    // The detector found nothing: a miss on cnn-small → HoG.
    assert_eq!(c.step(&obs(48, None, None)), detect(2, Trigger::LowScore));
    // HoG's score 0.2 is on the SVM scale: above its T_c 0 → track.
    assert_eq!(c.step(&obs(49, Some(0.2), good(0.9))), Decision::Track);
    assert_eq!(c.current_variant(), 2);
    let s = c.stats();
    assert_eq!((s.frames, s.queries), (50, 7));
    c.reset();
    assert_eq!(c.step(&obs(100, None, None)), detect(0, Trigger::Start));
}

#[test]
fn frame_counters_wrap() {
    let bytes = bundle_bytes(Thresholds::PAPER);
    let mut c = Controller::new(Bundle::parse(&bytes).unwrap());
    let start = u32::MAX - 3;
    assert!(matches!(
        c.step(&obs(start, None, None)),
        Decision::Detect { .. }
    ));
    for k in 1..9u32 {
        assert_eq!(
            c.step(&obs(start.wrapping_add(k), Some(0.8), good(0.9))),
            Decision::Track
        );
    }
    assert_eq!(
        c.step(&obs(start.wrapping_add(10), Some(0.8), good(0.9))),
        detect(0, Trigger::Reinit)
    );
}

/// The closed loop on a synthetic clip: controller + tracker + a stand-in detector that
/// returns the ground-truth box with a score. Most frames are tracked, the output box
/// stays on the sign, and the loop follows the paper's periods.
#[test]
fn closed_loop_on_a_clip_mostly_tracks() {
    let clip = make_clip(&ClipSpec {
        growth: 1.005,
        ..ClipSpec::standard(31, 60)
    });
    let (w, h) = (clip.width, clip.height);
    let bytes = bundle_bytes(Thresholds::PAPER);
    let mut ctl = Controller::new(Bundle::parse(&bytes).unwrap());
    let levels = 3;
    let need = Pyramid::required_len(w, h, levels).unwrap();
    let (mut wa, mut wb) = (vec![0u8; need], vec![0u8; need]);
    let mut prev = Pyramid::new(&mut wa, w, h, levels).unwrap();
    let mut next = Pyramid::new(&mut wb, w, h, levels).unwrap();
    let mut tracker = Tracker::<48>::new(TrackerParams::DEFAULT);
    let (mut last_det, mut score) = (BBox::default(), None);
    let (mut detections, mut min_iou) = (0, 1.0f32);
    for (f, frame) in clip.frames.iter().enumerate() {
        next.build(&GrayImage::new(frame, w, h, w).unwrap())
            .unwrap();
        let track = if f > 0 && tracker.is_active() {
            tracker.track(&prev, &next).ok().map(|o| TrackStatus {
                bbox: o.bbox,
                iou: o.bbox.iou(&last_det),
                quality: o.quality,
            })
        } else {
            None
        };
        let out = match ctl.step(&obs(f as u32, score, track)) {
            Decision::Detect { variant, .. } => {
                detections += 1;
                last_det = clip.boxes[f];
                // cnn-small is unsure on every third detection; the others are sure.
                score = Some(if variant == 0 && detections % 3 == 0 {
                    0.4
                } else {
                    0.93
                });
                tracker.init(&next, last_det).unwrap();
                last_det
            }
            Decision::Track => track.unwrap().bbox,
        };
        min_iou = min_iou.min(out.iou(&clip.boxes[f]));
        std::mem::swap(&mut prev, &mut next);
    }
    assert!(min_iou > 0.7, "output box left the sign: IoU {min_iou}");
    // Reinit every 10 frames plus the low-score re-asks: far fewer than 60 detections.
    assert!(
        (6..=15).contains(&detections),
        "{detections} detections in 60 frames"
    );
    assert_eq!(ctl.stats().detections, detections);
}

/// The paper's "access MDP per image" (5): a detection below `T_c` asks the policy
/// again at once and its choice runs on the same image; a variant already run on the
/// image ends the chain, and so does the limit.
#[test]
fn a_weak_detection_asks_the_policy_again_on_the_same_image() {
    let bytes = bundle_bytes(Thresholds::PAPER);
    let mut c = Controller::new(Bundle::parse(&bytes).unwrap());
    assert_eq!(c.step(&obs(0, None, None)), detect(0, Trigger::Start));
    // cnn-small unsure (0.4 < T_c): (inadequate, cnn-small) → cnn-full, same image.
    assert_eq!(c.detected(Some(0.4)), Access::Again(1));
    // cnn-full unsure too: (inadequate, cnn-full) → cnn-full, already run: done.
    assert_eq!(c.detected(Some(0.45)), Access::Done);
    assert_eq!(c.current_variant(), 1);
    assert_eq!(c.last_score(), Some(0.45));
    let s = c.stats();
    assert_eq!((s.frames, s.detections, s.queries), (1, 2, 2));
    // The image is done; the next frame still sees a weak score and asks again.
    assert_eq!(
        c.step(&obs(1, None, good(0.9))),
        detect(1, Trigger::LowScore)
    );
    // Found nothing: (miss, cnn-full) → HoG; HoG's -0.7 is a miss on its SVM scale:
    // (miss, HoG) → cnn-full, already run on this image: done after two.
    assert_eq!(c.detected(None), Access::Again(2));
    assert_eq!(c.detected(Some(-0.7)), Access::Done);
    assert_eq!(c.current_variant(), 2);
    // A sure detection ends the image at once; tracking resumes.
    assert_eq!(
        c.step(&obs(2, None, good(0.9))),
        detect(1, Trigger::LowScore)
    );
    assert_eq!(c.detected(Some(0.95)), Access::Done);
    assert_eq!(c.step(&obs(3, None, good(0.9))), Decision::Track);
    // Without a pending detection it only records the score.
    assert_eq!(c.detected(None), Access::Done);
}

#[test]
fn accesses_per_image_cap_the_chain() {
    for (limit, chain) in [(1, 1), (2, 2), (3, 3), (16, 3)] {
        let bytes = bundle_bytes(Thresholds {
            accesses_per_image: limit,
            ..Thresholds::PAPER
        });
        let mut c = Controller::new(Bundle::parse(&bytes).unwrap());
        assert_eq!(c.step(&obs(0, None, None)), detect(0, Trigger::Start));
        // Nothing is ever found: cnn-small → HoG → cnn-full → (HoG, run): three at most.
        let mut run = vec![0u16];
        while let Access::Again(v) = c.detected(None) {
            run.push(v);
        }
        assert_eq!(run.len(), chain, "limit {limit}: ran {run:?}");
        assert_eq!(&run[..], &[0, 2, 1][..chain]);
        assert_eq!(c.stats().detections as usize, chain);
    }
}

#[test]
fn every_trigger_is_listed_at_its_own_index() {
    for (i, t) in Trigger::ALL.iter().enumerate() {
        assert_eq!(*t as usize, i, "{t:?}");
    }
}
