//! Proof that the per-frame path allocates nothing: a counting global allocator around
//! 10,000 frames of bundle parsing, controller decisions, pyramid builds and tracking,
//! and 10,000 frames each of scheduler decisions (numbered by the tables' frame clock)
//! and of the scheduled pilot.
#![allow(unsafe_code)] // a global allocator needs `unsafe impl GlobalAlloc`

use frugal_runtime::bundle::write::{
    BudgetSpec, BundleWriter, FamilySpec, ScheduleSpec, VariantSpec,
};
use frugal_runtime::bundle::{BUCKET_COUNT, ScoreBuckets, Thresholds};
use frugal_runtime::pilot::Pilot;
use frugal_runtime::schedule::{CONTENT_STATES, largest_box};
use frugal_runtime::synth::{ClipSpec, make_clip};
use frugal_runtime::track::{GrayImage, Pyramid, Tracker, TrackerParams};
use frugal_runtime::{
    BudgetInfo, Bundle, ContentEdges, Controller, Decision, Detection, FrameClock, Observation,
    ScheduleAction, Scheduler, TrackState, TrackStatus,
};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);
thread_local! {
    // Per thread, so that the test harness's own threads (progress messages) do not count.
    static COUNTING: Cell<bool> = const { Cell::new(false) };
}

fn counting() -> bool {
    COUNTING.with(Cell::get)
}

// SAFETY: forwards every call unchanged to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if counting() {
            ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if counting() {
            ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// A bundle with two CNN-scale variants; the policy moves to the costly one on a poor score.
fn two_variant_bundle() -> Vec<u8> {
    two_variant_writer().finish().unwrap()
}

fn two_variant_writer() -> BundleWriter {
    BundleWriter::new(Thresholds::PAPER)
        .family(FamilySpec {
            name: "cnn".into(),
            buckets: ScoreBuckets {
                c_opt: 0.9,
                c_ge: 0.6,
                c_ua: 0.3,
                t_c: 0.5,
            },
        })
        .variant(VariantSpec::new("small", 0, 1.0, 2.0))
        .variant(VariantSpec::new("full", 0, 4.0, 8.0))
        .policy(0, vec![0, 0, 0, 1, 1, 1, 1, 1])
}

/// The same with three budget schedules over periods 1, 2, 5 and 10, whose actions
/// vary with the state.
fn scheduled_bundle() -> Vec<u8> {
    let periods = [1, 2, 5, 10];
    let states = BUCKET_COUNT * 2 * CONTENT_STATES;
    let budgets = (0..3)
        .map(|k| BudgetSpec {
            info: BudgetInfo {
                budget_ms: 10.0 * (k + 1) as f32,
                slowdown: 1.0,
                expected_ms: 5.0,
                p95_ms: 9.0,
            },
            actions: (0..states)
                .map(|i| ScheduleAction {
                    variant: ((i / 7 + k) % 2) as u16,
                    period: periods[(i + k) % 4],
                    // a third of the actions leave the frames between alone
                    track: (i / 3 + k) % 3 != 0,
                })
                .collect(),
        })
        .collect();
    two_variant_writer()
        .schedules(ScheduleSpec {
            edges: ContentEdges::DEFAULT,
            periods: periods.to_vec(),
            initial: ScheduleAction {
                variant: 1,
                period: 1,
                track: true,
            },
            frame_ms: 1e3 / 30.0,
            budgets,
        })
        .finish()
        .unwrap()
}

#[test]
fn ten_thousand_frames_allocate_nothing() {
    // Everything that may allocate happens before counting starts.
    let bytes = two_variant_bundle();
    // Small frames, few points and a 9×9 window keep this debug-build test quick; the
    // code path is the one of full-size frames.
    let spec = ClipSpec {
        width: 96,
        height: 72,
        sign_size: 28.0,
        growth: 1.0,
        velocity: (1.0, 0.5),
        ..ClipSpec::standard(3, 24)
    };
    let clip = make_clip(&spec);
    let (w, h) = (clip.width, clip.height);
    let need = Pyramid::required_len(w, h, 3).unwrap();
    let (mut wa, mut wb) = (vec![0u8; need], vec![0u8; need]);
    // Ping-pong through the clip so that motion stays continuous.
    let order: Vec<usize> = (0..clip.frames.len())
        .chain((1..clip.frames.len() - 1).rev())
        .collect();
    let mut params = TrackerParams::DEFAULT;
    params.lk.win_radius = 4;
    let mut tracker = Tracker::<8>::new(params);

    COUNTING.with(|c| c.set(true));
    let bundle = Bundle::parse(&bytes).unwrap();
    let mut ctl = Controller::new(bundle);
    let mut prev = Pyramid::new(&mut wa, w, h, 3).unwrap();
    let mut next = Pyramid::new(&mut wb, w, h, 3).unwrap();
    let (mut score, mut last, mut detections, mut tracked) = (None, clip.boxes[0], 0u32, 0u32);
    for frame in 0..10_000u32 {
        let i = order[frame as usize % order.len()];
        next.build(&GrayImage::new(&clip.frames[i], w, h, w).unwrap())
            .unwrap();
        let track = if tracker.is_active() {
            tracker.track(&prev, &next).ok().map(|o| TrackStatus {
                bbox: o.bbox,
                iou: o.bbox.iou(&last),
                quality: o.quality,
            })
        } else {
            None
        };
        match ctl.step(&Observation {
            frame,
            score,
            track,
        }) {
            Decision::Detect { .. } => {
                detections += 1;
                last = clip.boxes[i];
                score = Some(0.95);
                let _ = tracker.init(&next, last);
            }
            Decision::Track => tracked += 1,
        }
        std::mem::swap(&mut prev, &mut next);
    }
    COUNTING.with(|c| c.set(false));
    let allocations = ALLOCATIONS.load(Ordering::SeqCst);
    assert_eq!(allocations, 0, "{allocations} allocations in 10,000 frames");
    // The loop did real work: mostly tracking, a detection about every 10 frames.
    assert!(
        tracked > 8_000 && detections >= 1_000,
        "tracked {tracked}, detections {detections}"
    );
}

/// The pilot tests' clip (two signs drifting across 96×72 frames), the pyramid length
/// it needs and the tracker settings for it; made before counting starts.
fn two_sign_clip() -> (frugal_runtime::synth::Clip, usize, TrackerParams) {
    let spec = ClipSpec {
        width: 96,
        height: 72,
        sign_size: 24.0,
        growth: 1.0,
        velocity: (1.0, 0.5),
        ..ClipSpec::standard(5, 24)
    };
    let clip = make_clip(&spec);
    let need = Pyramid::required_len(clip.width, clip.height, 3).unwrap();
    let mut params = TrackerParams::DEFAULT;
    params.lk.win_radius = 4;
    (clip, need, params)
}

#[test]
fn the_pilot_loop_allocates_nothing_and_follows_two_signs() {
    let bytes = two_variant_bundle();
    let (clip, need, params) = two_sign_clip();
    let (w, h) = (clip.width, clip.height);
    let (mut wa, mut wb) = (vec![0u8; need], vec![0u8; need]);

    COUNTING.with(|c| c.set(true));
    let bundle = Bundle::parse(&bytes).unwrap();
    let mut pilot: Pilot<'_, 2, 8> = Pilot::with_params(bundle, params);
    let mut prev = Pyramid::new(&mut wa, w, h, 3).unwrap();
    let mut next = Pyramid::new(&mut wb, w, h, 3).unwrap();
    let (mut detections, mut tracked_frames, mut worst_iou) = (0u32, 0u32, 1.0f32);
    let (mut unreported, mut again) = (0, 0);
    for frame in 0..2_000u32 {
        // forward through the clip, then start over (a cut: the tracker must cope)
        let i = frame as usize % clip.frames.len();
        next.build(&GrayImage::new(&clip.frames[i], w, h, w).unwrap())
            .unwrap();
        let have_prev = frame > 0 && i > 0;
        match pilot.decide(frame, have_prev.then_some(&prev), &next) {
            Decision::Detect { variant, .. } => {
                // the "detector": the sign's true box, and a second, static one
                let found = [
                    Detection {
                        bbox: clip.boxes[i],
                        score: 0.95,
                        class: 3,
                    },
                    // below every family's T_c: not reported, so never tracked
                    // (listed before the next one so that it would take its slot)
                    Detection {
                        bbox: frugal_runtime::BBox::new(60.0, 40.0, 80.0, 60.0),
                        score: -100.0,
                        class: 7,
                    },
                    // in the optimal bucket (a good-enough one is not carried)
                    Detection {
                        bbox: frugal_runtime::BBox::new(4.0, 4.0, 20.0, 20.0),
                        score: 0.92,
                        class: 5,
                    },
                ];
                // every fourth run of the small variant is unsure (below T_c): the
                // policy's next choice runs on the same frame
                let unsure = [Detection {
                    bbox: clip.boxes[i],
                    score: 0.4,
                    class: 3,
                }];
                let mut runs = 0;
                let _ = pilot.detect_with(&next, variant, |variant| {
                    runs += 1;
                    detections += 1;
                    let weak = variant == 0 && detections % 4 == 0;
                    Ok::<_, ()>(if weak { &unsure[..] } else { &found[..] })
                });
                again += runs - 1;
            }
            Decision::Track => {
                tracked_frames += 1;
                unreported += pilot.tracked().filter(|d| d.class == 7).count();
                if let Some(d) = pilot.tracked().find(|d| d.class == 3) {
                    worst_iou = worst_iou.min(d.bbox.iou(&clip.boxes[i]));
                }
            }
        }
        std::mem::swap(&mut prev, &mut next);
    }
    COUNTING.with(|c| c.set(false));
    let allocations = ALLOCATIONS.load(Ordering::SeqCst);
    assert_eq!(
        allocations, 0,
        "{allocations} allocations in 2,000 pilot frames"
    );
    assert_eq!(unreported, 0, "a detection below T_c was tracked");
    assert!(again >= 10, "{again} second detections on one image");
    assert!(
        tracked_frames > 1_500 && detections >= 150,
        "tracked {tracked_frames}, detections {detections}"
    );
    assert!(
        worst_iou > 0.6,
        "the tracked sign drifted to IoU {worst_iou}"
    );
}

#[test]
fn ten_thousand_scheduler_decisions_allocate_nothing() {
    let bytes = scheduled_bundle();
    COUNTING.with(|c| c.set(true));
    let bundle = Bundle::parse(&bytes).unwrap();
    let mut s = Scheduler::new(bundle, 0).unwrap();
    s.keep_budget(30);
    // a 60 fps camera on the tables' 30 fps clock: every other frame is numbered
    let frame_ms = bundle.schedules().and_then(|x| x.frame_ms()).unwrap();
    let mut clock = FrameClock::new(frame_ms).unwrap();
    let (mut detections, mut lost) = (0u32, 0u32);
    for camera_frame in 0..20_000u32 {
        let Some(frame) = clock.frame(f64::from(camera_frame) * 1e3 / 60.0) else {
            continue;
        };
        if frame % 1_000 == 0 {
            s.set_budget((frame / 1_000) as usize % 3).unwrap();
        }
        let track = match frame % 17 {
            0 => TrackState::Lost,
            1..=3 => TrackState::Idle,
            _ => TrackState::Held,
        };
        let x = (frame % 50) as f32 * (1.0 + (frame % 3) as f32);
        let boxes = [
            frugal_runtime::BBox::new(x, 10.0, x + 20.0, 10.0 + (frame % 90) as f32),
            frugal_runtime::BBox::new(5.0, 5.0, 30.0, 40.0),
        ];
        let shown = (frame % 4) as usize % 3;
        match s.step(frame, track) {
            Decision::Detect { reason, .. } => {
                detections += 1;
                lost += u32::from(reason == frugal_runtime::Trigger::TrackerLost);
                let score = (frame % 5 != 0).then_some((frame % 100) as f32 / 100.0);
                s.detected(score);
                s.spent(30.0);
            }
            Decision::Track => s.spent(1.5),
        }
        s.shown(frame, shown, largest_box(boxes.into_iter().take(shown)));
    }
    COUNTING.with(|c| c.set(false));
    let allocations = ALLOCATIONS.load(Ordering::SeqCst);
    assert_eq!(
        allocations, 0,
        "{allocations} allocations in 10,000 scheduler frames"
    );
    assert_eq!(s.stats().frames, 10_000);
    assert!(s.keeper().is_some_and(|k| k.postponed() > 0));
    assert!(
        detections > 1_000 && detections < 9_000 && lost > 500,
        "{detections} detections, {lost} on lost tracks"
    );
}

#[test]
fn ten_thousand_scheduled_pilot_frames_allocate_nothing() {
    let bytes = scheduled_bundle();
    let (clip, need, params) = two_sign_clip();
    let (w, h) = (clip.width, clip.height);
    let (mut wa, mut wb) = (vec![0u8; need], vec![0u8; need]);

    COUNTING.with(|c| c.set(true));
    let bundle = Bundle::parse(&bytes).unwrap();
    let mut pilot: Pilot<'_, 2, 8> = Pilot::scheduled(bundle, 0)
        .unwrap()
        .with_tracker_params(params)
        .with_budget_keeper(30);
    let mut prev = Pyramid::new(&mut wa, w, h, 3).unwrap();
    let mut next = Pyramid::new(&mut wb, w, h, 3).unwrap();
    let (mut detections, mut tracked_frames) = (0u32, 0u32);
    for frame in 0..10_000u32 {
        if frame % 2_500 == 0 {
            pilot.set_budget((frame / 2_500) as usize % 3).unwrap();
        }
        // forward through the clip, then start over (a cut: the held tracks are lost)
        let i = frame as usize % clip.frames.len();
        next.build(&GrayImage::new(&clip.frames[i], w, h, w).unwrap())
            .unwrap();
        let have_prev = frame > 0 && i > 0;
        match pilot.decide(frame, have_prev.then_some(&prev), &next) {
            Decision::Detect { .. } => {
                detections += 1;
                let found = [
                    Detection {
                        bbox: clip.boxes[i],
                        score: 0.4 + (frame % 6) as f32 / 10.0,
                        class: 3,
                    },
                    Detection {
                        bbox: frugal_runtime::BBox::new(4.0, 4.0, 20.0, 20.0),
                        score: 0.7,
                        class: 5,
                    },
                ];
                let _ = pilot.detected(&next, &found[..(frame % 3) as usize]);
                pilot.spent(25.0);
            }
            Decision::Track => {
                tracked_frames += 1;
                assert!(pilot.tracked().count() <= 2);
                pilot.spent(1.0);
            }
        }
        std::mem::swap(&mut prev, &mut next);
    }
    COUNTING.with(|c| c.set(false));
    let allocations = ALLOCATIONS.load(Ordering::SeqCst);
    assert_eq!(
        allocations, 0,
        "{allocations} allocations in 10,000 scheduled pilot frames"
    );
    assert_eq!(pilot.stats().frames, 10_000);
    assert!(
        tracked_frames > 2_000 && detections > 1_000,
        "tracked {tracked_frames}, detections {detections}"
    );
}

#[test]
fn ten_thousand_forecasts_allocate_nothing() {
    use frugal_runtime::{ForecastParams, Forecaster};
    let mut f = Forecaster::new(ForecastParams::DEFAULT);
    let mut out = [Detection::default(); 4];
    let mut moved = 0usize;
    COUNTING.with(|c| c.set(true));
    for frame in 0..10_000u32 {
        let x = (frame % 200) as f32 * 3.0;
        let shown = [
            Detection {
                bbox: frugal_runtime::BBox::new(x, 10.0, x + 20.0, 30.0),
                score: 0.9,
                class: 1,
            },
            Detection {
                bbox: frugal_runtime::BBox::new(300.0, x, 330.0, x + 25.0),
                score: 0.8,
                class: 2,
            },
        ];
        // an output every other frame, used on the two frames after it
        if frame % 2 == 0 {
            f.update(frame, &shown[..(frame as usize / 2) % 3]);
        }
        let n = f.at(frame + 1, &mut out);
        moved += out[..n]
            .iter()
            .filter(|d| d.bbox.x1 != 300.0 && d.bbox.x1 > x)
            .count();
    }
    COUNTING.with(|c| c.set(false));
    let allocations = ALLOCATIONS.load(Ordering::SeqCst);
    assert_eq!(
        allocations, 0,
        "{allocations} allocations in 10,000 forecasts"
    );
    // the moving box is forecast ahead of where it was shown
    assert!(moved > 1_000, "{moved} boxes moved ahead");
}
