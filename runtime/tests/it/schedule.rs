//! The budget scheduler: content buckets, the state layout, the per-frame decisions on
//! a hand-made bundle, and the pilot flying it over a synthetic clip.
//!
//! About 600 lines of independent tests sharing one hand-made bundle.

use frugal_runtime::bundle::write::{
    BudgetSpec, BundleWriter, FamilySpec, ScheduleSpec, VariantSpec,
};
use frugal_runtime::bundle::{BUCKET_COUNT, Bucket, ScoreBuckets, Thresholds};
use frugal_runtime::pilot::{Carry, Pilot};
use frugal_runtime::schedule::{
    CONTENT_STATES, COUNT_BUCKETS, MOTION_BUCKETS, SIZE_BUCKETS, largest_box, state_index,
};
use frugal_runtime::synth::{ClipSpec, make_clip};
use frugal_runtime::track::{GrayImage, Pyramid};
use frugal_runtime::{
    Access, BBox, BudgetInfo, Bundle, Content, ContentEdges, Decision, Detection, FrameClock,
    ScheduleAction, ScheduleError, Scheduler, TrackState, Trigger,
};
use proptest::prelude::*;

const CNN: ScoreBuckets = ScoreBuckets {
    c_opt: 0.9,
    c_ge: 0.6,
    c_ua: 0.3,
    t_c: 0.5,
};

const fn act(variant: u16, period: u32) -> ScheduleAction {
    ScheduleAction::tracked(variant, period)
}

fn info(budget_ms: f32) -> BudgetInfo {
    BudgetInfo {
        budget_ms,
        slowdown: 1.0,
        expected_ms: budget_ms * 0.8,
        p95_ms: budget_ms,
    }
}

/// Every state of a table of `variants` variants, in state-index order.
fn states(variants: u16) -> impl Iterator<Item = (Bucket, u16, Content)> {
    Bucket::ALL.into_iter().flat_map(move |b| {
        (0..variants).flat_map(move |v| {
            (0..CONTENT_STATES).map(move |c| (b, v, Content::from_index(c).unwrap()))
        })
    })
}

/// Two CNN variants, periods 1 and 4, two budgets.
///
/// Budget 0: fast motion → (1, 1); else optimal → (0, 4); good enough → (current, 4);
/// inadequate or miss → (1, 1). Budget 1: always (0, 4). Initial: (1, 1).
fn bundle_bytes() -> Vec<u8> {
    let generous = states(2)
        .map(|(b, v, c)| match b {
            _ if c.motion == 2 => act(1, 1),
            Bucket::Optimal => act(0, 4),
            Bucket::GoodEnough => act(v, 4),
            Bucket::Inadequate | Bucket::Miss => act(1, 1),
        })
        .collect();
    let frugal = states(2).map(|_| act(0, 4)).collect();
    base()
        .schedules(ScheduleSpec {
            edges: ContentEdges::DEFAULT,
            periods: vec![1, 4],
            initial: act(1, 1),
            frame_ms: 1e3 / 30.0,
            budgets: vec![
                BudgetSpec {
                    info: info(20.0),
                    actions: generous,
                },
                BudgetSpec {
                    info: info(5.0),
                    actions: frugal,
                },
            ],
        })
        .finish()
        .unwrap()
}

fn base() -> BundleWriter {
    BundleWriter::new(Thresholds::PAPER)
        .family(FamilySpec {
            name: "cnn".into(),
            buckets: CNN,
        })
        .variant(VariantSpec::new("small", 0, 1.0, 2.0))
        .variant(VariantSpec::new("full", 0, 4.0, 8.0))
        .policy(0, vec![0, 0, 1, 1, 1, 1, 1, 1])
}

#[test]
fn content_buckets_follow_the_edges() {
    let e = ContentEdges::DEFAULT;
    assert_eq!(e.size_px, [24.0, 64.0]);
    assert_eq!(e.motion_px, [1.0, 4.0]);
    assert_eq!(ContentEdges::default(), e);
    let size = |h| e.content(h, None, 0).size;
    assert_eq!(size(None), 0);
    assert_eq!(size(Some(0.0)), 0);
    assert_eq!(size(Some(23.99)), 0);
    assert_eq!(size(Some(24.0)), 1, "an edge belongs to the bucket above");
    assert_eq!(size(Some(63.9)), 1);
    assert_eq!(size(Some(64.0)), 2);
    assert_eq!(size(Some(f32::INFINITY)), 2);
    assert_eq!(size(Some(f32::NAN)), 0);
    assert_eq!(size(Some(-5.0)), 0);
    let motion = |m| e.content(None, m, 0).motion;
    assert_eq!(motion(None), 0);
    assert_eq!(motion(Some(0.99)), 0);
    assert_eq!(motion(Some(1.0)), 1);
    assert_eq!(motion(Some(3.99)), 1);
    assert_eq!(motion(Some(4.0)), 2);
    assert_eq!(motion(Some(f32::NAN)), 0);
    let count = |n| e.content(None, None, n).count;
    assert_eq!(
        [count(0), count(1), count(2), count(3), count(usize::MAX)],
        [0, 1, 2, 2, 2]
    );
    // equal edges: nothing in the middle bucket
    let flat = ContentEdges {
        size_px: [10.0, 10.0],
        motion_px: [0.0, 0.0],
    };
    assert!(flat.is_valid());
    assert_eq!(
        flat.content(Some(9.0), Some(0.0), 1),
        Content {
            size: 0,
            motion: 2,
            count: 1
        }
    );
    assert_eq!(flat.content(Some(10.0), None, 1).size, 2);
    for bad in [
        ContentEdges {
            size_px: [5.0, 4.0],
            ..e
        },
        ContentEdges {
            size_px: [-1.0, 4.0],
            ..e
        },
        ContentEdges {
            motion_px: [0.0, f32::NAN],
            ..e
        },
        ContentEdges {
            motion_px: [0.0, f32::INFINITY],
            ..e
        },
    ] {
        assert!(!bad.is_valid(), "{bad:?}");
    }
}

#[test]
fn content_and_state_indices_are_laid_out_as_specified() {
    assert_eq!(
        (SIZE_BUCKETS, MOTION_BUCKETS, COUNT_BUCKETS, CONTENT_STATES),
        (3, 3, 3, 27)
    );
    assert_eq!(BUCKET_COUNT * CONTENT_STATES, 108);
    for i in 0..CONTENT_STATES {
        let c = Content::from_index(i).unwrap();
        assert_eq!(c.index(), i);
        assert_eq!(
            i,
            (usize::from(c.size) * 3 + usize::from(c.motion)) * 3 + usize::from(c.count)
        );
    }
    assert_eq!(Content::from_index(CONTENT_STATES), None);
    assert_eq!(Content::default().index(), 0);
    // out-of-range buckets count as the last one
    let big = Content {
        size: 9,
        motion: 200,
        count: 3,
    };
    assert_eq!(big.index(), CONTENT_STATES - 1);
    // states run bucket-major, then variant, then content
    for (i, (b, v, c)) in states(5).enumerate() {
        assert_eq!(state_index(b, v, c, 5), i);
    }
    let c = Content {
        size: 1,
        motion: 2,
        count: 0,
    };
    assert_eq!(
        state_index(Bucket::Inadequate, 3, c, 5),
        (2 * 5 + 3) * 27 + 15
    );
    assert_eq!(
        state_index(Bucket::Miss, 4, Content::from_index(26).unwrap(), 5),
        4 * 5 * 27 - 1
    );
    // a variant outside the bundle is outside every table
    assert_eq!(state_index(Bucket::Optimal, 5, c, 5), usize::MAX);
    assert_eq!(
        state_index(Bucket::Miss, u16::MAX, c, usize::MAX),
        usize::MAX
    );
}

#[test]
fn the_largest_box_is_the_tallest_and_the_first_of_equals() {
    assert_eq!(largest_box([]), None);
    let a = BBox::new(0.0, 0.0, 100.0, 10.0);
    let b = BBox::new(0.0, 0.0, 5.0, 20.0);
    let c = BBox::new(50.0, 50.0, 55.0, 70.0);
    assert_eq!(largest_box([a, b, c]), Some(b));
    assert_eq!(largest_box([c, b, a]), Some(c));
    let nan = BBox::new(0.0, f32::NAN, 1.0, 1.0);
    assert_eq!(largest_box([nan, a]), Some(a));
}

#[test]
fn the_scheduler_follows_its_tables() {
    let bytes = bundle_bytes();
    let bundle = Bundle::parse(&bytes).unwrap();
    let mut s = Scheduler::new(bundle, 0).unwrap();
    assert_eq!(
        (s.budget(), s.current_variant(), s.current_period()),
        (0, 1, 1)
    );
    let sign = |x: f32| Some(BBox::new(x, 10.0, x + 30.0, 40.0)); // 30 px high: size 1

    // frame 0: the table at (miss, the initial variant 1, nothing shown): (1, 1)
    assert_eq!(
        s.step(0, TrackState::Idle),
        Decision::Detect {
            variant: 1,
            reason: Trigger::Start
        }
    );
    assert_eq!(s.current_period(), 1);
    s.detected(Some(0.95));
    s.shown(0, 1, sign(10.0));
    assert_eq!(
        s.content(),
        Content {
            size: 1,
            motion: 0,
            count: 1
        }
    );
    let expected = state_index(Bucket::Optimal, 1, s.content(), 2);
    assert_eq!(s.state(), expected);
    assert_eq!(s.bucket(), Bucket::Optimal);

    // frame 1: the period (1) has passed; optimal → (0, 4)
    assert_eq!(
        s.step(1, TrackState::Held),
        Decision::Detect {
            variant: 0,
            reason: Trigger::Periodic
        }
    );
    assert_eq!((s.current_variant(), s.current_period()), (0, 4));
    s.detected(Some(0.95));
    s.shown(1, 1, sign(11.0)); // 1 px per frame: motion bucket 1
    assert_eq!(
        s.content(),
        Content {
            size: 1,
            motion: 1,
            count: 1
        }
    );

    // frames 2..=4 are tracked, frame 5 = 1 + 4 is detected
    for f in 2..5 {
        assert_eq!(s.step(f, TrackState::Held), Decision::Track, "frame {f}");
        s.shown(f, 2, sign(10.0 + f as f32));
    }
    assert_eq!(s.content().count, 2);
    assert_eq!(
        s.step(5, TrackState::Held),
        Decision::Detect {
            variant: 0,
            reason: Trigger::Periodic
        }
    );
    s.detected(Some(0.7)); // good enough: keep the variant, period 4
    s.shown(5, 1, sign(15.0));

    // frame 6: the tracker lost everything, before the period is up
    assert_eq!(
        s.step(6, TrackState::Lost),
        Decision::Detect {
            variant: 0,
            reason: Trigger::TrackerLost
        }
    );
    assert_eq!(s.current_period(), 4);
    // it found nothing: the next query goes to the full variant, every frame
    s.detected(None);
    s.shown(6, 0, None);
    assert_eq!(
        s.content(),
        Content {
            size: 0,
            motion: 0,
            count: 0
        }
    );
    assert_eq!(s.bucket(), Bucket::Miss);
    // nothing carried: only the period brings the detector back
    for f in 7..10 {
        assert_eq!(s.step(f, TrackState::Idle), Decision::Track, "frame {f}");
        s.shown(f, 0, None);
    }
    assert_eq!(
        s.step(10, TrackState::Idle),
        Decision::Detect {
            variant: 1,
            reason: Trigger::Periodic
        }
    );
    assert_eq!(s.current_period(), 1);
    s.detected(Some(0.95));
    // 40 px from the last box shown (frame 5) in 5 frames: 8 px per frame, fast
    s.shown(10, 1, sign(55.0));
    assert_eq!(
        s.content(),
        Content {
            size: 1,
            motion: 2,
            count: 1
        }
    );

    // a budget switch waits for the next query
    assert_eq!(s.set_budget(2), Err(ScheduleError::NoSuchBudget));
    assert_eq!(s.budget(), 0);
    assert_eq!(s.set_budget(1), Ok(()));
    assert_eq!(
        (s.budget(), s.current_variant(), s.current_period()),
        (1, 1, 1)
    );
    // fast motion would keep (1, 1) on budget 0; budget 1 says (0, 4)
    assert_eq!(
        s.step(11, TrackState::Held),
        Decision::Detect {
            variant: 0,
            reason: Trigger::Periodic
        }
    );
    assert_eq!(s.current_period(), 4);
    s.set_budget(0).unwrap();
    s.detected(Some(0.95));
    s.shown(11, 1, sign(56.0));
    assert_eq!(s.step(12, TrackState::Held), Decision::Track);

    let stats = s.stats();
    // every detection read the table, the first too (format 5)
    assert_eq!((stats.frames, stats.detections, stats.queries), (13, 6, 6));
    s.reset();
    assert_eq!(
        (s.current_variant(), s.current_period(), s.stats().frames),
        (1, 1, 0)
    );
    assert!(matches!(
        s.step(100, TrackState::Held),
        Decision::Detect {
            reason: Trigger::Start,
            ..
        }
    ));
}

/// A version-4 bundle is read as written: its first frame runs the schedules' initial
/// action under every budget, and later detections read the table; the same bytes as
/// version 5 read the table from the first frame on.
#[test]
fn a_version_4_bundle_runs_its_initial_action_first() {
    let v4 = super::bundle::with_version(&bundle_bytes(), 4);
    let old = Bundle::parse(&v4).unwrap();
    assert_eq!(old.version(), 4);
    assert!(!old.schedules().unwrap().first_from_table());
    let bytes = bundle_bytes();
    let new = Bundle::parse(&bytes).unwrap();
    assert!(new.schedules().unwrap().first_from_table());
    // budget 1's table says (0, 4) everywhere; the initial action is (1, 1)
    // the first frame's decision: a start detection with this variant
    let starts_with = |s: &mut Scheduler, variant: u16| {
        matches!(
            s.step(0, TrackState::Idle),
            Decision::Detect { variant: v, reason: Trigger::Start } if v == variant
        )
    };
    let mut s = Scheduler::new(old, 1).unwrap();
    assert!(starts_with(&mut s, 1));
    assert_eq!((s.current_period(), s.stats().queries), (1, 0));
    s.detected(Some(0.95));
    assert!(matches!(
        s.step(1, TrackState::Held),
        Decision::Detect { variant: 0, .. }
    ));
    assert_eq!((s.current_period(), s.stats().queries), (4, 1));
    let mut s = Scheduler::new(new, 1).unwrap();
    assert!(starts_with(&mut s, 0));
    assert_eq!((s.current_period(), s.stats().queries), (4, 1));
}

#[test]
fn frame_numbers_wrap() {
    let bytes = bundle_bytes();
    let mut s = Scheduler::new(Bundle::parse(&bytes).unwrap(), 1).unwrap();
    let start = u32::MAX - 1;
    // budget 1 says (0, 4) from the first frame on
    assert!(matches!(
        s.step(start, TrackState::Idle),
        Decision::Detect { variant: 0, .. }
    ));
    assert_eq!(s.current_period(), 4);
    s.detected(Some(0.95));
    s.shown(start, 1, Some(BBox::new(0.0, 0.0, 10.0, 10.0)));
    for f in 1..4u32 {
        assert!(!s.due(start.wrapping_add(f)));
        assert_eq!(
            s.step(start.wrapping_add(f), TrackState::Held),
            Decision::Track
        );
        s.shown(
            start.wrapping_add(f),
            1,
            Some(BBox::new(f as f32, 0.0, 10.0 + f as f32, 10.0)),
        );
    }
    // across the wrap: one pixel per frame, and the period has passed at start + 4
    assert_eq!(s.content().motion, 1);
    assert!(s.due(start.wrapping_add(4)));
    assert!(matches!(
        s.step(start.wrapping_add(4), TrackState::Held),
        Decision::Detect { .. }
    ));
}

#[test]
fn a_bundle_without_schedules_has_no_scheduler() {
    let bytes = base().finish().unwrap();
    let bundle = Bundle::parse(&bytes).unwrap();
    assert!(bundle.schedules().is_none());
    assert_eq!(
        Scheduler::new(bundle, 0).unwrap_err(),
        ScheduleError::NoSchedules
    );
    assert!(matches!(
        Pilot::<'_, 2, 8>::scheduled(bundle, 0),
        Err(ScheduleError::NoSchedules)
    ));
    let mut pilot: Pilot<'_, 2, 8> = Pilot::new(bundle);
    assert_eq!(pilot.set_budget(0), Err(ScheduleError::NoSchedules));
    assert!(pilot.controller().is_some() && pilot.scheduler().is_none());
    let bytes = bundle_bytes();
    let bundle = Bundle::parse(&bytes).unwrap();
    assert_eq!(
        Scheduler::new(bundle, 2).unwrap_err(),
        ScheduleError::NoSuchBudget
    );
    let e: Box<dyn std::error::Error> = Box::new(ScheduleError::NoSchedules);
    assert!(e.to_string().contains("no schedules"));
}

/// A 160×120 clip of `frames` frames whose 40 px sign moves `speed` px per frame to
/// the right, without shake.
fn steady_clip(frames: usize, speed: f32) -> ClipSpec {
    ClipSpec {
        width: 160,
        height: 120,
        sign_size: 40.0,
        growth: 1.0,
        velocity: (speed, 0.0),
        shake: 0.0,
        ..ClipSpec::standard(3, frames)
    }
}

/// Flies a scheduled pilot over a textured clip whose sign the "detector" always
/// finds, moving `speed` px per frame; `cut` frames have no previous pyramid. Returns
/// each frame's decision and the scheduler's content state after it.
fn fly_scheduled(
    frames: usize,
    budget: usize,
    cut: &[usize],
    speed: f32,
) -> (Vec<Decision>, Vec<Content>) {
    let spec = steady_clip(frames, speed);
    let clip = make_clip(&spec);
    let (w, h) = (clip.width, clip.height);
    let need = Pyramid::required_len(w, h, 3).unwrap();
    let (mut a, mut b) = (vec![0u8; need], vec![0u8; need]);
    let bytes = bundle_bytes();
    let mut pilot: Pilot<'_, 4, 48> = Pilot::scheduled(Bundle::parse(&bytes).unwrap(), 0).unwrap();
    assert_eq!(pilot.carry(), Carry::Reported);
    assert!(pilot.controller().is_none());
    pilot.set_budget(budget).unwrap();
    let mut prev = Pyramid::new(&mut a, w, h, 3).unwrap();
    let mut cur = Pyramid::new(&mut b, w, h, 3).unwrap();
    let (mut decisions, mut contents) = (Vec::new(), Vec::new());
    for i in 0..frames {
        cur.build(&GrayImage::new(&clip.frames[i], w, h, w).unwrap())
            .unwrap();
        let have_prev = i > 0 && !cut.contains(&i);
        let decision = pilot.decide(i as u32, have_prev.then_some(&prev), &cur);
        match decision {
            Decision::Detect { variant, .. } => {
                assert_eq!(variant, pilot.current_variant());
                let found = [
                    Detection {
                        bbox: clip.boxes[i],
                        score: 0.95,
                        class: 2,
                    },
                    // below T_c: neither reported nor counted
                    Detection {
                        bbox: BBox::new(0.0, 0.0, 150.0, 110.0),
                        score: 0.1,
                        class: 9,
                    },
                ];
                assert_eq!(pilot.detected(&cur, &found), Access::Done);
                assert_eq!(pilot.tracking(), 1);
            }
            Decision::Track => assert_eq!(pilot.tracked().count(), 1),
        }
        decisions.push(decision);
        contents.push(pilot.scheduler().unwrap().content());
        std::mem::swap(&mut prev, &mut cur);
    }
    (decisions, contents)
}

/// `due` says, before any tracking, whether the next `step` detects whatever the
/// trackers report: the first frame, then every period; a lost track is not due.
#[test]
fn a_detection_is_due_on_the_first_frame_and_when_the_period_has_passed() {
    let bytes = bundle_bytes();
    let mut s = Scheduler::new(Bundle::parse(&bytes).unwrap(), 1).unwrap();
    assert!(s.due(0) && s.due(7), "nothing detected yet");
    // budget 1: every state (0, every 4), the first detection too
    assert!(matches!(
        s.step(1, TrackState::Idle),
        Decision::Detect { .. }
    ));
    s.detected(Some(0.95));
    assert_eq!(s.current_period(), 4);
    for f in 2..4 {
        assert!(!s.due(f), "frame {f}");
        assert_eq!(s.step(f, TrackState::Held), Decision::Track);
    }
    assert!(!s.due(4) && s.due(5));
    // not due, but a lost track brings the detection forward all the same
    assert!(matches!(
        s.step(4, TrackState::Lost),
        Decision::Detect {
            reason: Trigger::TrackerLost,
            ..
        }
    ));
    assert!(!s.due(5) && s.due(8));
}

/// Budget 1 of [`bundle_bytes`] (5 ms, `(0, every 4)` everywhere) on a device where a
/// detection costs `detect_ms` and a tracked frame `track_ms`, a still sign in view,
/// for `frames` frames: (device ms per frame, detections, the longest gap between two
/// detections, what the keeper postponed).
fn keep(window: u32, detect_ms: f32, track_ms: f32, frames: u32) -> (f32, u32, u32, u32) {
    let bytes = bundle_bytes();
    let mut s = Scheduler::new(Bundle::parse(&bytes).unwrap(), 1).unwrap();
    s.keep_budget(window);
    let (mut spent, mut detections, mut gap, mut last) = (0.0f32, 0u32, 0u32, 0u32);
    let sign = BBox::new(100.0, 100.0, 140.0, 140.0);
    for f in 0..frames {
        let due = s.due(f);
        let ms = match s.step(f, TrackState::Held) {
            Decision::Detect { .. } => {
                assert!(due, "frame {f}: detected, not due");
                s.detected(Some(0.95));
                detections += 1;
                gap = gap.max(f - last);
                last = f;
                detect_ms
            }
            Decision::Track => {
                assert!(!due, "frame {f}: due, not detected");
                track_ms
            }
        };
        s.shown(f, 1, Some(sign));
        s.spent(ms);
        spent += ms;
    }
    let postponed = s.keeper().map_or(0, |k| k.postponed());
    (spent / frames as f32, detections, gap, postponed)
}

#[test]
fn a_budget_keeper_holds_a_table_to_its_budget_on_a_slower_device() {
    // every 4 frames: 20 + 3 × 1 ms, 5.75 ms per frame against the table's 5
    let (free, free_det, free_gap, _) = keep(0, 20.0, 1.0, 1200);
    assert!((free - 5.75).abs() < 0.01, "{free}");
    assert_eq!((free_det, free_gap), (300, 4));
    let (kept, det, gap, postponed) = keep(30, 20.0, 1.0, 1200);
    // the budget, but for the last detection's debt
    assert!(kept <= 5.0 + 20.0 / 1200.0, "{kept} ms per frame");
    assert!(
        kept >= 5.0 * 0.95,
        "the budget is spent, not hoarded: {kept}"
    );
    assert!(
        det < free_det && postponed > 0,
        "{det} detections, {postponed} postponed"
    );
    assert!(gap <= 8, "postponed for at most one more period: {gap}");
    // where the table keeps its budget, the keeper changes nothing
    assert_eq!(
        keep(30, 12.0, 1.0, 1200),
        (keep(0, 12.0, 1.0, 1200).0, 300, 4, 0)
    );
    // where tracking alone costs more than the budget, detections still come every
    // two periods
    // two periods
    let (_, det, gap, _) = keep(30, 20.0, 6.0, 1200);
    assert_eq!((det, gap), (150, 8));
}

#[test]
fn a_budget_keeper_never_postpones_the_first_detection_or_one_after_a_loss() {
    let bytes = bundle_bytes();
    let mut s = Scheduler::new(Bundle::parse(&bytes).unwrap(), 1).unwrap();
    s.keep_budget(30);
    assert!(matches!(
        s.step(0, TrackState::Idle),
        Decision::Detect {
            reason: Trigger::Start,
            ..
        }
    ));
    s.detected(Some(0.95));
    s.spent(1000.0); // deep in debt
    for f in 1..6 {
        assert_eq!(s.step(f, TrackState::Held), Decision::Track, "frame {f}");
        s.spent(1.0);
    }
    assert!(s.keeper().unwrap().credit_ms() < 0.0);
    assert!(matches!(
        s.step(6, TrackState::Lost),
        Decision::Detect {
            reason: Trigger::TrackerLost,
            ..
        }
    ));
    // the debt is bounded: window frames of budget
    s.spent(f32::MAX);
    assert_eq!(s.keeper().unwrap().credit_ms(), -150.0);
    s.spent(f32::NAN);
    s.spent(-3.0);
    assert_eq!(s.keeper().unwrap().credit_ms(), -150.0);
    // switching budgets credits the new table's budget per frame
    s.set_budget(0).unwrap();
    let _ = s.step(7, TrackState::Held);
    assert_eq!(s.keeper().unwrap().credit_ms(), -130.0);
    // a reset empties the keeper and keeps it
    s.reset();
    assert_eq!(s.keeper().unwrap().credit_ms(), 0.0);
    assert_eq!(s.keeper().unwrap().postponed(), 0);
}

#[test]
fn a_scheduled_pilot_detects_every_period_and_reports_what_it_shows() {
    // budget 1: (0, 4) everywhere, from the first frame on
    let (run, contents) = fly_scheduled(12, 1, &[], 0.5);
    let detected: Vec<usize> = (0..run.len())
        .filter(|&i| matches!(run[i], Decision::Detect { .. }))
        .collect();
    assert_eq!(detected, [0, 4, 8], "{run:?}");
    assert!(matches!(
        run[0],
        Decision::Detect {
            variant: 0,
            reason: Trigger::Start
        }
    ));
    assert!(matches!(
        run[8],
        Decision::Detect {
            variant: 0,
            reason: Trigger::Periodic
        }
    ));
    // a 40 px sign moving half a pixel per frame: medium size, still, one box
    for (i, c) in contents.iter().enumerate() {
        assert_eq!(
            *c,
            Content {
                size: 1,
                motion: 0,
                count: 1
            },
            "frame {i}"
        );
    }
}

#[test]
fn a_scheduled_pilot_measures_motion_on_tracked_frames() {
    // 5 px per frame is fast (edge 4): from the second frame on, detected or tracked
    let (run, contents) = fly_scheduled(9, 1, &[], 5.0);
    assert_eq!(run[2], Decision::Track, "{run:?}");
    assert_eq!(contents[0].motion, 0, "no earlier box");
    for (i, c) in contents.iter().enumerate().skip(1) {
        assert_eq!(
            *c,
            Content {
                size: 1,
                motion: 2,
                count: 1
            },
            "frame {i}"
        );
    }
}

#[test]
fn a_scheduled_pilot_detects_again_when_its_tracks_are_lost() {
    // no previous pyramid on frame 3: the held track cannot follow
    let (run, _) = fly_scheduled(8, 1, &[3], 0.5);
    assert!(
        matches!(
            run[3],
            Decision::Detect {
                variant: 0,
                reason: Trigger::TrackerLost
            }
        ),
        "{run:?}"
    );
    assert_eq!(run[4], Decision::Track);
    assert!(
        matches!(
            run[7],
            Decision::Detect {
                reason: Trigger::Periodic,
                ..
            }
        ),
        "{run:?}"
    );
}

#[test]
fn scheduled_pilot_stats_count_decisions() {
    let bytes = bundle_bytes();
    let bundle = Bundle::parse(&bytes).unwrap();
    let pilot: Pilot<'_, 2, 8> = Pilot::scheduled(bundle, 1).unwrap();
    assert_eq!(pilot.scheduler().unwrap().budget(), 1);
    assert_eq!(pilot.stats().frames, 0);
    assert_eq!(pilot.current_variant(), 1);
    assert_eq!(pilot.bundle().variant_count(), 2);
    assert!(matches!(
        Pilot::<'_, 2, 8>::scheduled(bundle, 3),
        Err(ScheduleError::NoSuchBudget)
    ));
    // the same bundle still flies its policy through the controller
    let pilot: Pilot<'_, 2, 8> = Pilot::new(bundle);
    assert_eq!(pilot.current_variant(), 0);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Any sequence of calls, with or without a budget keeper: never a panic, and every
    /// decision names a variant of the bundle with one of its periods.
    #[test]
    fn any_call_sequence_stays_in_the_tables(
        window in 0u32..40,
        calls in proptest::collection::vec((0u8..5, any::<u32>(), any::<f32>(), 0usize..5), 1..200)
    ) {
        let bytes = bundle_bytes();
        let mut s = Scheduler::new(Bundle::parse(&bytes).unwrap(), 0).unwrap();
        s.keep_budget(window);
        let mut frame = 0u32;
        for (op, x, f, n) in calls {
            frame = frame.wrapping_add(x % 3);
            match op {
                4 => s.spent(f),
                0 => {
                    let track = [TrackState::Idle, TrackState::Held, TrackState::Lost][n % 3];
                    if let Decision::Detect { variant, .. } = s.step(frame, track) {
                        prop_assert!(variant < 2);
                    }
                }
                1 => s.detected((n > 0).then_some(f)),
                2 => s.shown(frame, n, (n > 0).then(|| BBox::new(f, f * 0.5, f + x as f32, f + n as f32 * 9.0))),
                _ => {
                    let ok = s.set_budget(n).is_ok();
                    prop_assert_eq!(ok, n < 2);
                }
            }
            prop_assert!([1, 4].contains(&s.current_period()));
            prop_assert!(s.state() < 2 * 108);
            if let Some(k) = s.keeper() {
                prop_assert!(k.credit_ms().is_finite());
            }
        }
    }
}

/// The frames a camera of `fps` takes from `start_ms` on, numbered on a 30 fps clock.
fn numbered(fps: f64, start_ms: f64, frames: u32) -> Vec<Option<u32>> {
    let mut c = FrameClock::new(1e3 / 30.0).unwrap();
    (0..frames)
        .map(|i| c.frame(start_ms + f64::from(i) * 1e3 / fps))
        .collect()
}

#[test]
fn the_frame_clock_numbers_a_camera_on_the_tables_clock() {
    // at the tables' rate, every frame, in order, from any origin
    let at_30: Vec<Option<u32>> = (0..300).map(Some).collect();
    assert_eq!(numbered(30.0, 0.0, 300), at_30);
    assert_eq!(numbered(30.0, 1.0e7, 300), at_30);
    // twice as fast: every other frame, numbered as the tables count it
    let at_60 = numbered(60.0, 250.0, 600);
    for (i, n) in at_60.iter().enumerate() {
        let want = (i % 2 == 0).then_some(i as u32 / 2);
        assert_eq!(*n, want, "camera frame {i}");
    }
    // 25 fps: every frame taken, about every sixth counts two table frames on
    let at_25: Vec<u32> = numbered(25.0, 0.0, 250)
        .into_iter()
        .map(Option::unwrap)
        .collect();
    let gaps: Vec<u32> = at_25.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(gaps.iter().all(|&g| g == 1 || g == 2), "{gaps:?}");
    assert_eq!(at_25[249], 299);
    // frames taken while perception was busy count: a frame 5.4 intervals on is 5 on
    let mut c = FrameClock::new(1e3 / 30.0).unwrap();
    assert_eq!(c.frame(0.0), Some(0));
    assert_eq!(c.frame(5.4 * 1e3 / 30.0), Some(5));
    assert_eq!(c.last(), 5);
    // a quarter interval early is on time; a frame already counted, or captured
    // before the last one, or at no finite time, is not numbered and changes nothing
    assert_eq!(c.peek(5.8 * 1e3 / 30.0), Some(6));
    assert_eq!(c.frame(5.7 * 1e3 / 30.0), None);
    assert_eq!(c.frame(1.0), None);
    assert_eq!(c.frame(f64::NAN), None);
    assert_eq!(c.frame(f64::INFINITY), None);
    assert_eq!(c.frame(-f64::INFINITY), None);
    assert_eq!(c.frame(6.0 * 1e3 / 30.0), Some(6));
    // past u32 frames: the last number, then nothing
    assert_eq!(c.frame(1e3 / 30.0 * 1e10), Some(u32::MAX));
    assert_eq!(c.frame(1e3 / 30.0 * 2e10), None);
    // only a finite, positive interval makes a clock
    for bad in [0.0, -33.3, f32::NAN, f32::INFINITY] {
        assert_eq!(FrameClock::new(bad), None, "{bad}");
    }
    // the first frame must have a finite time
    let mut c = FrameClock::new(40.0).unwrap();
    assert_eq!(c.frame(f64::NAN), None);
    assert_eq!(c.frame(-80.0), Some(0));
    assert_eq!(c.frame(0.0), Some(2));
}

/// An action that does not track starts no tracker: the detection's boxes stand, as
/// found, until the next detection, those frames are left alone (the scheduler's
/// content is not updated) and no pyramid is read; the next action that tracks starts
/// the trackers again, and the boxes follow the sign.
#[test]
fn an_untracked_action_leaves_the_frames_between_alone_and_reads_no_pyramid() {
    let untracked = |variant, period| ScheduleAction {
        track: false,
        ..act(variant, period)
    };
    // optimal: track every 4; anything else (the first frame's miss too): every 4,
    // untracked
    let table = states(2)
        .map(|(b, _, _)| match b {
            Bucket::Optimal => act(0, 4),
            _ => untracked(0, 4),
        })
        .collect();
    let bytes = base()
        .schedules(ScheduleSpec {
            edges: ContentEdges::DEFAULT,
            periods: vec![1, 4],
            initial: act(0, 4),
            frame_ms: 1e3 / 30.0,
            budgets: vec![BudgetSpec {
                info: info(20.0),
                actions: table,
            }],
        })
        .finish()
        .unwrap();
    let spec = steady_clip(12, 2.0);
    let clip = make_clip(&spec);
    let (w, h) = (clip.width, clip.height);
    let need = Pyramid::required_len(w, h, 3).unwrap();
    let (mut a, mut b) = (vec![0u8; need], vec![0u8; need]);
    let mut pilot: Pilot<'_, 4, 48> = Pilot::scheduled(Bundle::parse(&bytes).unwrap(), 0).unwrap();
    let mut prev = Pyramid::new(&mut a, w, h, 3).unwrap();
    let mut cur = Pyramid::new(&mut b, w, h, 3).unwrap();
    let mut built_prev = false;
    let blank = vec![0u8; w * h];
    // frame 0 scores optimal (the next detection tracks), frame 4 good enough (the
    // next does not)
    let scores = [0.95, 0.7, 0.95];
    let mut last_found = None;
    for i in 0..12 {
        let build = |p: &mut Pyramid<'_>| {
            p.build(&GrayImage::new(&clip.frames[i], w, h, w).unwrap())
                .unwrap();
        };
        // a pyramid only where the pilot reads one: a blank one otherwise
        cur.build(&GrayImage::new(&blank, w, h, w).unwrap())
            .unwrap();
        let mut built = pilot.tracks_between();
        if built {
            build(&mut cur);
        }
        let before = pilot.scheduler().unwrap().content();
        let decision = pilot.decide(i as u32, built_prev.then_some(&prev), &cur);
        match decision {
            Decision::Detect { .. } => {
                assert_eq!(i % 4, 0, "frame {i}");
                if pilot.tracks_between() && !built {
                    build(&mut cur);
                    built = true;
                }
                let found = [Detection {
                    bbox: clip.boxes[i],
                    score: scores[i / 4],
                    class: 2,
                }];
                assert_eq!(pilot.detected(&cur, &found), Access::Done);
                assert_eq!(pilot.standing(), i != 4, "frame {i}");
                assert_eq!(pilot.tracks_between(), i == 4, "frame {i}");
                last_found = Some(clip.boxes[i]);
            }
            Decision::Track => {
                let boxes: Vec<BBox> = pilot.tracked().map(|d| d.bbox).collect();
                assert_eq!(boxes.len(), 1, "frame {i}");
                if (5..8).contains(&i) {
                    // tracked: the box follows the sign, 2 px per frame
                    assert!(!pilot.standing());
                    assert!((boxes[0].x1 - clip.boxes[i].x1).abs() < 1.0, "frame {i}");
                    assert!(boxes[0] != last_found.unwrap());
                } else {
                    // left alone: the detection's box, as found; nothing shown
                    assert!(pilot.standing());
                    assert_eq!(Some(boxes[0]), last_found, "frame {i}");
                    assert_eq!(pilot.scheduler().unwrap().content(), before);
                }
            }
        }
        built_prev = built;
        std::mem::swap(&mut prev, &mut cur);
    }
    // one tracker started: on frame 4's detection, under the one action that tracks
    assert_eq!(pilot.track_stats().started, 1);
    assert_eq!(pilot.stats().detections, 3);
}
