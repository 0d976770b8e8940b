//! Criterion benchmarks of the per-frame path.
//!
//! - `controller/step`: one decision of [`Controller::step`] (budget ≤ 100 ns median);
//! - `schedule/step+shown`: one decision of [`Scheduler::step`] with its features: the
//!   score hand-over on a detection frame and [`Scheduler::shown`] (budget ≤ 50 ns);
//! - `pyramid/build_480x270_3`: building a 3-level pyramid of a 480×270 frame;
//! - `tracker/frame_480x270_64pts`: one tracked frame — next pyramid build + LK
//!   forward and backward for ≤ 64 points + median-flow box update (budget ≤ 1 ms);
//! - `tracker/init_corners`: Shi-Tomasi corner selection in the sign's box.
//!
//! Each is measured twice: in wall-clock time (criterion's default) and in the
//! thread's CPU time (`…/cpu`), which a machine shared with other jobs inflates far
//! less: the figure to compare with the budgets when the load average is high.
//!
//! `cargo bench -p frugal-runtime --bench main`
#![allow(unsafe_code)] // one libc call: clock_gettime(CLOCK_THREAD_CPUTIME_ID)

use criterion::measurement::{Measurement, ValueFormatter, WallTime};
use criterion::{Criterion, criterion_group, criterion_main};
use frugal_runtime::bundle::write::{
    BudgetSpec, BundleWriter, FamilySpec, ScheduleSpec, VariantSpec,
};
use frugal_runtime::bundle::{BUCKET_COUNT, ScoreBuckets, Thresholds};
use frugal_runtime::schedule::CONTENT_STATES;
use frugal_runtime::synth::{ClipSpec, make_clip};
use frugal_runtime::track::{GrayImage, Pyramid, Tracker, TrackerParams};
use frugal_runtime::{
    BBox, BudgetInfo, Bundle, ContentEdges, Controller, Decision, FrameClock, Observation,
    ScheduleAction, Scheduler, TrackState, TrackStatus,
};
use std::hint::black_box;

/// The calling thread's CPU time, in nanoseconds.
struct ThreadCpuTime;

fn thread_cpu_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; the clock id is a constant.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    assert_eq!(rc, 0, "clock_gettime(CLOCK_THREAD_CPUTIME_ID) failed");
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

impl Measurement for ThreadCpuTime {
    type Intermediate = u64;
    type Value = u64;

    fn start(&self) -> u64 {
        thread_cpu_ns()
    }
    fn end(&self, start: u64) -> u64 {
        thread_cpu_ns().saturating_sub(start)
    }
    fn add(&self, a: &u64, b: &u64) -> u64 {
        a + b
    }
    fn zero(&self) -> u64 {
        0
    }
    fn to_f64(&self, v: &u64) -> f64 {
        *v as f64
    }
    fn formatter(&self) -> &dyn ValueFormatter {
        // Nanoseconds, like wall time: reuse its formatter.
        WallTime.formatter()
    }
}

fn bundle_bytes() -> Vec<u8> {
    bundle_writer().finish().expect("valid bundle")
}

/// [`bundle_bytes`] with four budget schedules over periods 1, 2, 5 and 10.
fn scheduled_bundle_bytes() -> Vec<u8> {
    let periods = [1, 2, 5, 10];
    let states = BUCKET_COUNT * 8 * CONTENT_STATES;
    let budgets = (0..4)
        .map(|k| BudgetSpec {
            info: BudgetInfo {
                budget_ms: 10.0 * (k + 1) as f32,
                slowdown: 1.0,
                expected_ms: 5.0,
                p95_ms: 9.0,
            },
            actions: (0..states)
                .map(|i| ScheduleAction {
                    variant: ((i * 5 + k) % 8) as u16,
                    period: periods[(i / 3 + k) % 4],
                    track: true,
                })
                .collect(),
        })
        .collect();
    bundle_writer()
        .schedules(ScheduleSpec {
            edges: ContentEdges::DEFAULT,
            periods: periods.to_vec(),
            initial: ScheduleAction {
                variant: 0,
                period: 1,
                track: true,
            },
            frame_ms: 1e3 / 30.0,
            budgets,
        })
        .finish()
        .expect("valid bundle")
}

fn bundle_writer() -> BundleWriter {
    let mut w = BundleWriter::new(Thresholds::PAPER)
        .family(FamilySpec {
            name: "cnn".into(),
            buckets: ScoreBuckets {
                c_opt: 0.9,
                c_ge: 0.6,
                c_ua: 0.3,
                t_c: 0.5,
            },
        })
        .family(FamilySpec {
            name: "hog".into(),
            buckets: ScoreBuckets::PAPER_SVM,
        });
    for v in 0..8u16 {
        w = w.variant(VariantSpec::new(
            &format!("v{v}"),
            v % 2,
            1.0 + f32::from(v),
            5.0 * f32::from(v + 1),
        ));
    }
    let actions = (0..4 * 8).map(|i| ((i * 5 + 3) % 8) as u16).collect();
    w.policy(0, actions)
}

fn controller<M: Measurement + 'static>(c: &mut Criterion<M>, suffix: &str) {
    let bytes = bundle_bytes();
    let bundle = Bundle::parse(&bytes).expect("parse");
    let mut ctl = Controller::new(bundle);
    // A repeating pattern of observations that exercises every branch.
    let obs: Vec<Observation> = (0..1000u32)
        .map(|f| Observation {
            frame: f,
            score: Some(((f * 37) % 100) as f32 / 50.0 - 0.8),
            track: (f % 13 != 0).then_some(TrackStatus {
                bbox: BBox::new(10.0, 10.0, 50.0, 50.0),
                iou: ((f * 7) % 10) as f32 / 10.0 + 0.05,
                quality: 0.9,
            }),
        })
        .collect();
    let mut i = 0usize;
    c.bench_function(&format!("controller/step{suffix}"), |b| {
        b.iter(|| {
            i = (i + 1) % obs.len();
            black_box(ctl.step(black_box(&obs[i])))
        })
    });
}

/// One frame of the scheduler's input: the trackers' state, the detection's best score
/// (used on a detection frame), and what the frame shows.
struct ScheduleInput {
    frame: u32,
    track: TrackState,
    score: Option<f32>,
    count: usize,
    largest: Option<BBox>,
}

fn schedule<M: Measurement + 'static>(c: &mut Criterion<M>, suffix: &str) {
    let bytes = scheduled_bundle_bytes();
    let bundle = Bundle::parse(&bytes).expect("parse");
    // A repeating pattern that exercises every trigger, bucket and content state.
    let inputs: Vec<ScheduleInput> = (0..1000u32)
        .map(|f| {
            let count = (f % 7) as usize % 4;
            let x = ((f * 3) % 200) as f32;
            let h = ((f * 13) % 90) as f32 + 4.0;
            ScheduleInput {
                frame: f,
                track: match f % 23 {
                    0 => TrackState::Lost,
                    1..=4 => TrackState::Idle,
                    _ => TrackState::Held,
                },
                score: (f % 9 != 0).then_some(((f * 37) % 100) as f32 / 100.0),
                count,
                largest: (count > 0).then_some(BBox::new(x, 20.0, x + h, 20.0 + h)),
            }
        })
        .collect();
    // without a budget keeper, then with one charged every frame's compute
    for window in [0u32, 30] {
        let mut s = Scheduler::new(bundle, 0).expect("schedules");
        s.keep_budget(window);
        let name = if window > 0 {
            "step+shown+spent"
        } else {
            "step+shown"
        };
        let mut i = 0usize;
        c.bench_function(&format!("schedule/{name}{suffix}"), |b| {
            b.iter(|| {
                i = (i + 1) % inputs.len();
                let input = black_box(&inputs[i]);
                let decision = s.step(input.frame, input.track);
                let ms = if let Decision::Detect { .. } = decision {
                    s.detected(input.score);
                    40.0
                } else {
                    2.0
                };
                s.shown(input.frame, input.count, input.largest);
                if window > 0 {
                    s.spent(black_box(ms));
                }
                black_box(decision)
            })
        });
    }
    // numbering a 60 fps camera's frames on the tables' 30 fps clock (every other
    // frame dropped), as the drone does before each step
    let frame_ms = bundle
        .schedules()
        .and_then(|s| s.frame_ms())
        .expect("format 6");
    let mut clock = FrameClock::new(frame_ms).expect("clock");
    let mut camera_frame = 0u64;
    c.bench_function(&format!("schedule/frame_clock{suffix}"), |b| {
        b.iter(|| {
            camera_frame += 1;
            black_box(clock.frame(black_box(camera_frame as f64 * 1e3 / 60.0)))
        })
    });
}

fn forecast<M: Measurement + 'static>(c: &mut Criterion<M>, suffix: &str) {
    use frugal_runtime::{Detection, ForecastParams, Forecaster};
    // Outputs of four signs moving across the view, one output every other frame, each
    // read on the two frames after it: one update and two reads per output.
    let outputs: Vec<[Detection; 4]> = (0..1000u32)
        .map(|f| {
            core::array::from_fn(|k| {
                let x = ((f * (3 + k as u32)) % 400) as f32;
                Detection {
                    bbox: BBox::new(x, 30.0 * k as f32, x + 24.0, 30.0 * k as f32 + 24.0),
                    score: 0.9,
                    class: k as u16 % 2,
                }
            })
        })
        .collect();
    let mut fc = Forecaster::new(ForecastParams::DEFAULT);
    let mut out = [Detection::default(); 4];
    let mut i = 0usize;
    c.bench_function(&format!("forecast/update+2_reads_4_boxes{suffix}"), |b| {
        b.iter(|| {
            i = (i + 1) % outputs.len();
            let frame = 2 * i as u32;
            fc.update(frame, black_box(&outputs[i]));
            let n = fc.at(frame + 1, &mut out) + fc.at(frame + 2, &mut out);
            black_box(n)
        })
    });
}

fn tracker<M: Measurement + 'static>(c: &mut Criterion<M>, suffix: &str) {
    let clip = make_clip(&ClipSpec::standard(5, 30));
    let (w, h) = (clip.width, clip.height);
    let prm = TrackerParams::DEFAULT;
    let need = Pyramid::required_len(w, h, prm.lk.levels).expect("size");
    let (mut wa, mut wb) = (vec![0u8; need], vec![0u8; need]);
    let mut prev = Pyramid::new(&mut wa, w, h, prm.lk.levels).expect("ws");
    let mut next = Pyramid::new(&mut wb, w, h, prm.lk.levels).expect("ws");
    let gray = |f: usize| GrayImage::new(&clip.frames[f], w, h, w).expect("frame");
    let rgb: Vec<u8> = clip.frames[1].iter().flat_map(|&g| [g, g, g]).collect();
    let frame = frugal_runtime::FrameRef::new(w as u32, h as u32, &rgb).expect("rgb");
    let mut gray_out = vec![0u8; w * h];
    c.bench_function(&format!("gray/rgb_to_gray_480x270{suffix}"), |b| {
        b.iter(|| {
            frugal_runtime::track::rgb_to_gray(black_box(&frame), &mut gray_out)
                .expect("gray")
                .width()
        })
    });
    c.bench_function(&format!("pyramid/build_480x270_3{suffix}"), |b| {
        b.iter(|| next.build(black_box(&gray(1))).expect("build"))
    });

    // The first frame whose sign box holds the full 64 corners.
    let mut t = Tracker::<64>::new(prm);
    let f = (0..clip.frames.len() - 1)
        .find(|&f| {
            prev.build(&gray(f)).expect("build");
            t.init(&prev, clip.boxes[f]) == Ok(64)
        })
        .expect("a frame with 64 corners");
    let pts = t.points().to_vec();
    c.bench_function(&format!("tracker/init_corners{suffix}"), |b| {
        b.iter(|| t.init(&prev, black_box(clip.boxes[f])).expect("init"))
    });
    c.bench_function(&format!("tracker/frame_480x270_64pts{suffix}"), |b| {
        b.iter(|| {
            t.init_with_points(clip.boxes[f], &pts).expect("points");
            next.build(&gray(f + 1)).expect("build");
            black_box(t.track(&prev, &next))
        })
    });
}

fn wall(c: &mut Criterion) {
    controller(c, "");
    schedule(c, "");
    forecast(c, "");
    tracker(c, "");
}

fn cpu(c: &mut Criterion<ThreadCpuTime>) {
    controller(c, "/cpu");
    schedule(c, "/cpu");
    forecast(c, "/cpu");
    tracker(c, "/cpu");
}

criterion_group!(wall_time, wall);
criterion_group! {
    name = cpu_time;
    config = Criterion::default().with_measurement(ThreadCpuTime);
    targets = cpu
}
criterion_main!(wall_time, cpu_time);
