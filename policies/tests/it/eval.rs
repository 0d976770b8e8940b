//! The strategies replayed through the runtime's controller and the real KLT tracker.

use super::fixture::log2;
use frugal_data::Split;
use frugal_policies::eval::{EvalConfig, Strategy, run_all, scores};
use frugal_policies::replay::VideoLog;
use frugal_policies::report::evaluate_and_write;
use frugal_policies::train::train;
use frugal_policies::{PolicyConfig, Reward};

/// The paper's reward: in this fixture the cheap variant is confident exactly when it is
/// right. (The outcome reward learns from (optimal, expensive) that the cheap one is
/// blind in low light half the time, and stays expensive there.)
fn paper_policy(log: &frugal_policies::ReplayLog) -> frugal_policies::TrainedPolicy {
    let paper = PolicyConfig {
        reward: Reward::Confidence,
        alpha: 1.0,
        ..PolicyConfig::default()
    };
    train(log, &paper).unwrap()
}

#[test]
fn strategies_run_and_the_oracle_is_never_slower_or_worse_than_static() {
    let (log, frames) = log2();
    let policy = paper_policy(&log);
    let cfg = EvalConfig::default();
    let videos: Vec<&VideoLog> = log.split(Split::Test).collect();
    let runs = run_all(&log, &policy, &videos, Some(&frames), &cfg, &Strategy::ALL).unwrap();
    assert_eq!(
        runs.static_variant, 1,
        "the expensive variant is the most accurate"
    );
    let sc = scores(&log, &videos, &runs, &cfg);
    // 4 scenarios + all, 6 strategies each.
    assert_eq!(sc.len(), 5 * 6);
    for scen in [
        "low-clutter",
        "medium-clutter",
        "high-clutter",
        "low-light",
        "all",
    ] {
        let get = |s: Strategy| {
            sc.iter()
                .find(|x| x.scenario == scen && x.strategy == s.name())
                .unwrap()
        };
        let (st, or) = (get(Strategy::Static), get(Strategy::Oracle));
        assert!(
            or.total_ms <= st.total_ms + 1e-9,
            "{scen}: {or:?} vs {st:?}"
        );
        assert!(or.f1 >= st.f1 - 1e-12, "{scen}: {or:?} vs {st:?}");
        assert_eq!(st.detections, st.frames, "static detects every frame");
        // every frame, and a second variant on frames the first was unsure of
        assert!(get(Strategy::Mdp).detections >= st.frames);
        // The tracker carries the box: fewer detections than frames.
        let mt = get(Strategy::MdpTracker);
        assert!(mt.detections < mt.frames, "{scen}: {mt:?}");
    }
    let all = |s: Strategy| {
        sc.iter()
            .find(|x| x.scenario == "all" && x.strategy == s.name())
            .unwrap()
    };
    // In normal light the cheap variant is adequate, so the MDP is cheaper than static.
    assert!(all(Strategy::Mdp).total_ms < all(Strategy::Static).total_ms);
    // The real tracker keeps the sign: static + tracker stays accurate.
    assert!(
        all(Strategy::StaticTracker).f1 > 0.8,
        "{:?}",
        all(Strategy::StaticTracker)
    );
    let stt = all(Strategy::StaticTracker);
    assert!(stt.detections * 3 < stt.frames, "{stt:?}");
    assert!(runs.cost.samples.1 > 0 && runs.cost.track_ms > 0.0);
    // the reference tracker was timed between the tracker's calls (one tracked
    // 480×270 frame: more work than one 48-point track)
    let r = runs
        .cost
        .reference_ms
        .expect("the reference tracker's median");
    assert!(r > runs.cost.track_ms, "{:?}", runs.cost);
}

#[test]
fn eval_writes_tables_and_figures() {
    let (log, frames) = log2();
    let policy = train(&log, &PolicyConfig::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (report, _) = evaluate_and_write(
        &log,
        &policy,
        &frames,
        &EvalConfig::default(),
        dir.path(),
        None,
    )
    .unwrap();
    assert_eq!(report.static_variant, "expensive");
    for f in [
        "eval.json",
        "eval.csv",
        "bars-time.png",
        "bars-time.svg",
        "bars-f1.png",
        "bars-f1.svg",
        "clip.png",
        "clip.svg",
        "states.png",
        "states.svg",
        "states.json",
    ] {
        let len = std::fs::metadata(dir.path().join(f))
            .map(|m| m.len())
            .unwrap_or(0);
        assert!(len > 100, "{f} missing or empty");
    }
    let csv = std::fs::read_to_string(dir.path().join("eval.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 5 * 6);
}

#[test]
fn per_class_counts_sum_to_the_overall_counts() {
    use frugal_policies::eval::{ClassScore, class_scores};
    use frugal_policies::report::write_per_class;
    let (mut log, frames) = log2();
    // Two classes: the signs of two test videos become class 1 (their detections too,
    // except on every fifth frame, where a wrong class makes a false alarm and a miss).
    log.classes = 2;
    for v in log.videos.iter_mut().filter(|v| v.id == 11 || v.id == 13) {
        for f in &mut v.frames {
            for t in &mut f.truth {
                t.class = 1;
            }
            if f.index % 5 != 0 {
                for d in f.detections.iter_mut().flatten() {
                    d.class = 1;
                }
            }
        }
    }
    let policy = train(&log, &PolicyConfig::default()).unwrap();
    let cfg = EvalConfig::default();
    let videos: Vec<&VideoLog> = log.split(Split::Test).collect();
    let runs = run_all(&log, &policy, &videos, Some(&frames), &cfg, &Strategy::ALL).unwrap();
    let sc = scores(&log, &videos, &runs, &cfg);
    let names = ["zero".to_string(), "one".to_string()];
    let rows = class_scores(&log, &runs, &cfg, &names);
    assert_eq!(rows.len(), Strategy::ALL.len() * 3);
    for s in Strategy::ALL {
        let mine: Vec<_> = rows.iter().filter(|r| r.strategy == s.name()).collect();
        let all = mine.iter().find(|r| r.class.is_none()).unwrap();
        let classes: Vec<_> = mine.iter().filter(|r| r.class.is_some()).collect();
        assert_eq!(classes.len(), 2);
        assert_eq!(classes[1].name, "one");
        // Both classes have signs and (for detecting strategies) false alarms.
        assert!(classes.iter().all(|c| c.tp + c.fn_ > 0), "{classes:?}");
        let sum = |get: fn(&ClassScore) -> usize| classes.iter().map(|c| get(c)).sum::<usize>();
        assert_eq!(sum(|c| c.tp), all.tp, "{s:?}");
        assert_eq!(sum(|c| c.fp), all.fp, "{s:?}");
        assert_eq!(sum(|c| c.fn_), all.fn_, "{s:?}");
        // The all row is the overall score of the strategy.
        let overall = sc
            .iter()
            .find(|x| x.scenario == "all" && x.strategy == s.name())
            .unwrap();
        assert!((all.precision.unwrap() - overall.precision).abs() < 1e-12);
        assert!((all.recall.unwrap() - overall.recall).abs() < 1e-12);
        assert!((all.ms_per_frame - overall.ms_per_frame).abs() < 1e-9);
        assert_eq!(all.frames, overall.frames);
        // Every test frame shows one sign: the class frames partition the frames.
        assert_eq!(classes[0].frames + classes[1].frames, all.frames);
    }
    // The mislabelled frames are false alarms of class 0 in the class-1 videos.
    let st = rows
        .iter()
        .find(|r| r.strategy == "static" && r.class == Some(0))
        .unwrap();
    assert!(st.fp > 0, "{st:?}");
    let dir = tempfile::tempdir().unwrap();
    write_per_class(&log, &runs, &cfg, &names, dir.path()).unwrap();
    let csv = std::fs::read_to_string(dir.path().join("per_class.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + rows.len());
    for f in ["per_class-precision", "per_class-time"] {
        for ext in ["png", "svg"] {
            let path = dir.path().join(format!("{f}.{ext}"));
            assert!(path.metadata().is_ok_and(|m| m.len() > 100), "{path:?}");
        }
    }
    let kul = std::fs::read_to_string(dir.path().join("kul.md")).unwrap();
    assert!(
        kul.contains("| one |") && kul.contains("| **all** |"),
        "{kul}"
    );
}

/// The paper's MDP accesses per image: where the MDP's variant scores below `T_c`, the
/// policy's next choice runs on the same frame, the frame reports that one, and both
/// detections are charged. With one access per image every frame gets one detection.
#[test]
fn an_unsure_detection_reruns_the_policys_choice_on_the_same_frame() {
    let (log, frames) = log2();
    let policy = paper_policy(&log);
    let videos: Vec<&VideoLog> = log.split(Split::Test).collect();
    let run = |accesses: u32| {
        let cfg = EvalConfig {
            accesses_per_image: accesses,
            ..EvalConfig::default()
        };
        let runs = run_all(
            &log,
            &policy,
            &videos,
            Some(&frames),
            &cfg,
            &[Strategy::Mdp],
        )
        .unwrap();
        let sc = scores(&log, &videos, &runs, &cfg);
        let all = sc
            .into_iter()
            .find(|x| x.scenario == "all" && x.strategy == Strategy::Mdp.name())
            .unwrap();
        (runs, all)
    };
    let (_, single) = run(1);
    assert_eq!(single.detections, single.frames);
    let (runs, paper_runs) = run(5);
    let mut reruns = 0;
    for (video, r) in videos.iter().zip(&runs.runs[0].1) {
        for (fi, t) in r.frames.iter().enumerate() {
            let shown = t.detect.expect("the MDP detects every frame");
            let mut latency = log.variants[usize::from(shown)].latency_ms;
            for &v in &t.tried {
                let v = usize::from(v);
                // only an unsure detection asks again, and never twice with one variant
                let best = video.frames[fi].best_score(v);
                assert!(!best.is_some_and(|s| s >= log.buckets(v).t_c), "{t:?}");
                assert_ne!(v, usize::from(shown));
                latency += log.variants[v].latency_ms;
                reruns += 1;
            }
            assert!((t.time_ms - latency).abs() < 1e-9, "{t:?}");
        }
    }
    assert!(reruns > 0, "no frame ran a second variant");
    assert_eq!(paper_runs.detections, paper_runs.frames + reruns);
    assert!(paper_runs.total_ms > single.total_ms);
    // the fixture's cheap variant is unsure when blind; asking again finds the sign
    assert!(paper_runs.f1 > single.f1, "{paper_runs:?} vs {single:?}");
}

#[test]
fn a_held_out_log_is_compared_with_the_policys_static_variant_not_its_own_best() {
    let (log, frames) = log2();
    let policy = paper_policy(&log);
    assert_eq!(
        policy.reference,
        Some(1),
        "most accurate on the training videos"
    );
    // a held-out log holds test videos only; on these, make the cheap variant the
    // most accurate by giving it the expensive one's detections
    let mut held_out = log.clone();
    held_out.videos.retain(|v| v.split == Split::Test);
    for v in &mut held_out.videos {
        for f in &mut v.frames {
            f.detections[0] = f.detections[1].clone();
        }
    }
    assert_eq!(
        frugal_policies::eval::most_accurate(&held_out, 0.5),
        0,
        "the held-out videos alone would pick the cheap variant"
    );
    let videos: Vec<&VideoLog> = held_out.videos.iter().collect();
    let cfg = EvalConfig::default();
    let runs = run_all(
        &held_out,
        &policy,
        &videos,
        Some(&frames),
        &cfg,
        &[Strategy::Static],
    )
    .unwrap();
    assert_eq!(runs.static_variant, 1, "the policy's reference");
    let mut unset = policy.clone();
    unset.reference = None;
    let runs = run_all(
        &held_out,
        &unset,
        &videos,
        Some(&frames),
        &cfg,
        &[Strategy::Static],
    )
    .unwrap();
    assert_eq!(runs.static_variant, 0, "no reference: the log's own best");
}
