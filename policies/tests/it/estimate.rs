//! Transition estimation, smoothing, training and the α sweep.

use super::fixture::{log2, log3};
use frugal_data::{Clutter, Light, Split};
use frugal_policies::eval::EvalConfig;
use frugal_policies::replay::{Det, FrameLog, LOG_FORMAT, LOG_VERSION, VideoLog};
use frugal_policies::sweep::sweep;
use frugal_policies::train::{Transitions, state, train};
use frugal_policies::variants::{
    CNN_BUCKETS, FamilyInfo, SyntheticSpec, VariantInfo, VariantSource,
};
use frugal_policies::{PolicyConfig, ReplayLog, Reward};
use frugal_runtime::bundle::Bucket;

fn det(score: f32) -> Det {
    Det {
        class: 0,
        score,
        bbox: [0.0, 0.0, 10.0, 10.0],
    }
}

/// Two variants, three frames:
/// frame 0: v0 0.7 (good enough), v1 0.95 (optimal);
/// frame 1: v0 nothing (miss),    v1 0.95 (optimal);
/// frame 2: v0 0.7 (good enough), v1 0.4 (inadequate).
fn hand_log() -> ReplayLog {
    let frames = vec![
        (vec![det(0.7)], vec![det(0.95)]),
        (vec![], vec![det(0.95)]),
        (vec![det(0.7)], vec![det(0.4)]),
    ];
    let variant = |name: &str, latency: f64| VariantInfo {
        name: name.into(),
        family: 0,
        latency_ms: latency,
        relative_cost: latency,
        precision: Default::default(),
        source: VariantSource::Synthetic(SyntheticSpec::default()),
    };
    ReplayLog {
        format: LOG_FORMAT.into(),
        version: LOG_VERSION,
        dataset: "".into(),
        classes: 1,
        families: vec![FamilyInfo {
            name: "cnn".into(),
            buckets: CNN_BUCKETS,
        }],
        variants: vec![variant("a", 1.0), variant("b", 4.0)],
        max_detections: 8,
        reference_ms: None,
        reference_int8_ms: None,
        videos: vec![VideoLog {
            id: 0,
            clutter: Clutter::Low,
            light: Light::Normal,
            split: Split::Train,
            width: 64,
            height: 64,
            frames: frames
                .into_iter()
                .enumerate()
                .map(|(i, (a, b))| FrameLog {
                    index: i as u32,
                    truth: vec![],
                    detections: vec![a, b],
                    ignore: Vec::new(),
                    time_s: None,
                })
                .collect(),
        }],
    }
}

#[test]
fn transition_counts_of_a_hand_made_log() {
    use Bucket::*;
    let log = hand_log();
    let t = Transitions::count(&log, 0.5, |_| true);
    let s_n = 8;
    let count = |s: usize, a: usize, b: Bucket| t.counts[(a * s_n + s) * 4 + b.index()];
    // (f0 → f1): from (ge, a) and (opt, b); (f1 → f2): from (miss, a) and (opt, b).
    let (ge_a, opt_b, miss_a) = (
        state(GoodEnough, 0, 2),
        state(Optimal, 1, 2),
        state(Miss, 0, 2),
    );
    assert_eq!(count(ge_a, 0, Miss), 1);
    assert_eq!(count(ge_a, 1, Optimal), 1);
    assert_eq!(count(miss_a, 0, GoodEnough), 1);
    assert_eq!(count(miss_a, 1, Inadequate), 1);
    assert_eq!(count(opt_b, 0, Miss), 1);
    assert_eq!(count(opt_b, 0, GoodEnough), 1);
    assert_eq!(count(opt_b, 1, Optimal), 1);
    assert_eq!(count(opt_b, 1, Inadequate), 1);
    assert_eq!(
        t.counts.iter().sum::<u64>(),
        8,
        "2 pairs × 2 current variants × 2 actions"
    );
    assert_eq!(t.samples(opt_b, 1), 2);
    assert_eq!(t.samples(ge_a, 0), 1);
    assert_eq!(t.samples(state(Optimal, 0, 2), 0), 0);
}

#[test]
fn an_extra_logs_training_videos_add_to_the_transitions_under_the_main_logs_buckets() {
    use Bucket::*;
    let mut main = hand_log();
    let before = Transitions::count(&main, 0.5, |v| v.split == Split::Train);
    // the same variants, replayed elsewhere, with their own (ignored) buckets; one of
    // its videos is held out and must not be taken
    let mut extra = hand_log();
    extra.families[0].buckets.c_opt = 0.99;
    let mut held_out = extra.videos[0].clone();
    held_out.split = Split::Test;
    extra.videos.push(held_out);
    let path = std::path::Path::new("extra.json");
    assert_eq!(main.absorb_training(extra.clone(), path).unwrap(), 1);
    assert_eq!(
        main.videos.iter().map(|v| v.id).collect::<Vec<_>>(),
        [0, 1],
        "fresh ids"
    );
    assert_eq!(
        main.families[0].buckets, CNN_BUCKETS,
        "the main log's buckets stay"
    );
    let after = Transitions::count(&main, 0.5, |v| v.split == Split::Train);
    let (ge_a, opt_b) = (state(GoodEnough, 0, 2), state(Optimal, 1, 2));
    for (s, a) in [(ge_a, 0), (ge_a, 1), (opt_b, 0), (opt_b, 1)] {
        assert_eq!(after.samples(s, a), 2 * before.samples(s, a), "({s}, {a})");
    }
    // another variant set, or no training videos, is refused naming the file
    let mut other = extra.clone();
    other.variants[1].name = "c".into();
    let e = main.absorb_training(other, path).unwrap_err().to_string();
    assert!(e.contains("extra.json") && e.contains("variants"), "{e}");
    let mut none = extra;
    none.videos.retain(|v| v.split == Split::Test);
    let e = main.absorb_training(none, path).unwrap_err().to_string();
    assert!(
        e.contains("extra.json") && e.contains("no training videos"),
        "{e}"
    );
}

#[test]
fn signs_below_outcome_min_px_are_dont_care_in_the_outcome() {
    use frugal_policies::eval::frame_f1;
    let mut log = hand_log();
    let (near, far) = ([100.0, 100.0, 140.0, 140.0], [300.0, 50.0, 310.0, 60.0]);
    let at = |bbox: [f32; 4]| Det {
        class: 0,
        score: 0.95,
        bbox,
    };
    let frame = &mut log.videos[0].frames[1];
    // a 40 px sign near and a 10 px one far; variant a finds both plus a false alarm
    // (10 px) where there is nothing, variant b finds the near one only
    frame.truth = vec![
        Det {
            score: 1.0,
            ..at(near)
        },
        Det {
            score: 1.0,
            ..at(far)
        },
    ];
    frame.detections = vec![
        vec![at(near), at(far), at([0.0, 0.0, 10.0, 10.0])],
        vec![at(near)],
    ];
    let video = &log.videos[0];
    let f1 = |v, min_px| frame_f1(&log, video, 1, v, 0.5, min_px);
    // every sign counts: a has 2 tp + 1 fp, b has 1 tp + 1 miss
    assert!((f1(0, 0.0) - 0.8).abs() < 1e-9, "{}", f1(0, 0.0));
    assert!((f1(1, 0.0) - 2.0 / 3.0).abs() < 1e-9);
    // below 24 px is don't-care: b misses nothing, a's far find is no false alarm,
    // and its detection of nothing still is one
    assert!((f1(1, 24.0) - 1.0).abs() < 1e-9);
    assert!((f1(0, 24.0) - 2.0 / 3.0).abs() < 1e-9, "{}", f1(0, 24.0));
    // and the policy config carries it into the transitions' outcome
    let cfg = PolicyConfig {
        outcome_min_px: 24.0,
        ..PolicyConfig::default()
    };
    let t = Transitions::training(&log, &cfg);
    let t0 = Transitions::training(&log, &PolicyConfig::default());
    assert_eq!(t.counts, t0.counts, "the buckets do not depend on it");
    assert!(t.f1 != t0.f1, "the outcome does");
    let bad = PolicyConfig {
        outcome_min_px: -1.0,
        ..PolicyConfig::default()
    };
    let e = bad
        .check(std::path::Path::new("p.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("outcome_min_px"), "{e}");
}

#[test]
fn smoothing_spreads_mass_over_the_actions_buckets() {
    let log = hand_log();
    let t = Transitions::count(&log, 0.5, |_| true);
    let opt_b = state(Bucket::Optimal, 1, 2);
    // counts (opt 1, ge 0, ua 1, miss 0) under λ = 1: (1+1)/(2+4) and (0+1)/(2+4).
    assert!((t.prob(opt_b, 1, 0, 1.0) - 2.0 / 6.0).abs() < 1e-12);
    assert!((t.prob(opt_b, 1, 1, 1.0) - 1.0 / 6.0).abs() < 1e-12);
    assert!((t.prob(opt_b, 1, 0, 0.0) - 0.5).abs() < 1e-12);
    assert_eq!(t.prob(opt_b, 1, 1, 0.0), 0.0);
    // A row without samples and without smoothing is uniform, not NaN.
    assert_eq!(t.prob(state(Bucket::Optimal, 0, 2), 0, 3, 0.0), 0.25);
    // The MDP's next state is always the action's variant, rows sum to one, and the
    // reward is the expectation of w / r^α.
    let cfg = PolicyConfig {
        reward: Reward::Confidence,
        alpha: 1.0,
        ..PolicyConfig::default()
    };
    let mdp = t.mdp(&[1.0, 4.0], &cfg).unwrap();
    for s in 0..8 {
        for a in 0..2 {
            let row: f64 = (0..8).map(|s2| mdp.prob(a, s, s2)).sum();
            assert!((row - 1.0).abs() < 1e-12);
            for s2 in 0..8 {
                if s2 % 2 != a {
                    assert_eq!(mdp.prob(a, s, s2), 0.0);
                }
            }
        }
    }
    let w = cfg.weights;
    let want = (2.0 * w.opt + 1.0 * w.ge + 2.0 * w.ua + 1.0 * w.miss) / 6.0 / 4.0;
    assert!((mdp.r[opt_b * 2 + 1] - want).abs() < 1e-12);
}

#[test]
fn learned_policy_runs_cheap_when_adequate_and_expensive_when_cheap_misses() {
    let (log, _) = log2();
    assert_eq!(log.variants[0].name, "cheap", "sorted cheapest first");
    assert_eq!(log.variants[1].relative_cost, 5.0);
    let p = train(&log, &PolicyConfig::default()).unwrap();
    assert!(p.policy_iteration_agrees);
    assert_eq!(p.action(Bucket::GoodEnough, 0), 0, "{:?}", p.actions);
    assert_eq!(p.action(Bucket::Miss, 0), 1, "{:?}", p.actions);
    assert_eq!(p.training_videos, vec![0, 1, 2, 3]);
    // Every row is backed by the training pairs that reached its state.
    let pairs: u64 = log
        .split(Split::Train)
        .map(|v| v.frames.len() as u64 - 1)
        .sum();
    let total: u64 = p.samples.iter().sum();
    assert_eq!(total, pairs * 2 * 2);
}

#[test]
fn alpha_sweep_trades_accuracy_for_cost_monotonically() {
    let (log, _) = log3();
    let cfg = PolicyConfig {
        sweep_alpha: vec![0.0, 0.5, 1.0, 2.0, 4.0, 8.0],
        sweep_ge_scale: vec![1.0],
        // w_opt slightly above w_ge: at α = 0 an optimal score on a costly variant beats
        // a good-enough one on the cheap variant; as α grows, cost wins.
        weights: frugal_policies::Weights {
            opt: 12.0,
            ge: 10.0,
            ua: 0.0,
            miss: 0.0,
        },
        ..PolicyConfig::default()
    };
    let all = sweep(&log, &cfg, &EvalConfig::default()).unwrap();
    assert_eq!(all.len(), 12, "6 α for each reward");
    for reward in [Reward::Confidence, Reward::Outcome] {
        let pts: Vec<_> = all.iter().filter(|p| p.reward == reward).collect();
        assert_eq!(pts.len(), 6);
        for w in pts.windows(2) {
            assert!(
                w[1].ms_per_frame <= w[0].ms_per_frame + 1e-9,
                "{reward:?}: cost rose from α {} to α {}: {pts:#?}",
                w[0].alpha,
                w[1].alpha
            );
        }
        let (first, last) = (pts[0], pts[pts.len() - 1]);
        assert!(last.ms_per_frame < first.ms_per_frame, "{pts:#?}");
        assert!(last.f1 <= first.f1 + 1e-9, "{pts:#?}");
    }
}

/// Four frames with one sign (class 0) each: the cheap variant is *confidently wrong*
/// (class 1 at 0.95, the optimal bucket), the expensive one right at 0.7 (good enough).
fn confidently_wrong_log() -> ReplayLog {
    let mut log = hand_log();
    let sign = Det {
        class: 0,
        score: 1.0,
        bbox: [0.0, 0.0, 10.0, 10.0],
    };
    let wrong = Det {
        class: 1,
        ..det(0.95)
    };
    log.classes = 2;
    log.videos[0].frames = (0..4)
        .map(|i| FrameLog {
            index: i,
            truth: vec![sign],
            detections: vec![vec![wrong], vec![det(0.7)]],
            ignore: Vec::new(),
            time_s: None,
        })
        .collect();
    log
}

#[test]
fn outcome_reward_is_the_next_frames_f1_and_prefers_being_right_to_being_confident() {
    let log = confidently_wrong_log();
    let t = Transitions::count(&log, 0.5, |_| true);
    // every pair starts from (opt, cheap) and (ge, expensive): 3 pairs each
    let (opt_a, ge_b) = (
        state(Bucket::Optimal, 0, 2),
        state(Bucket::GoodEnough, 1, 2),
    );
    for s in [opt_a, ge_b] {
        assert_eq!(t.samples(s, 0), 3);
        // cheap: F1 0 on every next frame; smoothed towards the prior 0.5 by λ = 1
        assert!((t.mean_f1(s, 0, 1.0) - 0.5 / 4.0).abs() < 1e-12);
        assert!((t.mean_f1(s, 1, 1.0) - 3.5 / 4.0).abs() < 1e-12);
        assert_eq!(t.mean_f1(s, 1, 0.0), 1.0);
    }
    // α = 1: the expensive variant is 4× dearer; the paper's reward takes the confident
    // cheap variant, the outcome reward the right one.
    let base = PolicyConfig {
        alpha: 1.0,
        ..PolicyConfig::default()
    };
    let confidence = train(
        &log,
        &PolicyConfig {
            reward: Reward::Confidence,
            ..base.clone()
        },
    )
    .unwrap();
    let outcome = train(&log, &base).unwrap();
    assert_eq!(base.reward, Reward::Outcome, "the default");
    assert_eq!(confidence.action(Bucket::Optimal, 0), 0);
    assert_eq!(outcome.action(Bucket::Optimal, 0), 1);
    assert_eq!(outcome.action(Bucket::GoodEnough, 1), 1);
    let r = &outcome.mdp.r;
    assert!(
        (r[opt_a * 2 + 1] - (3.5 / 4.0) / 4.0).abs() < 1e-12,
        "{r:?}"
    );
}

#[test]
fn config_rejects_unknown_keys_and_bad_ranges() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("policy.toml");
    std::fs::write(&p, "alpha = 2.0\nbogus = 1\n").unwrap();
    let e = PolicyConfig::read(&p).unwrap_err().to_string();
    assert!(e.contains("policy.toml") && e.contains("bogus"), "{e}");
    std::fs::write(&p, "gamma = 1.5\n").unwrap();
    let e = PolicyConfig::read(&p).unwrap_err().to_string();
    assert!(e.contains("gamma"), "{e}");
    std::fs::write(&p, "alpha = 2.0\n[weights]\nge = 20.0\n").unwrap();
    let c = PolicyConfig::read(&p).unwrap();
    assert_eq!((c.alpha, c.weights.ge, c.weights.opt), (2.0, 20.0, 2.0));
}

#[test]
fn replay_log_round_trips_and_rejects_a_wrong_version() {
    let (log, _) = log2();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("replay.json");
    log.save(&p).unwrap();
    assert_eq!(ReplayLog::load(&p).unwrap(), log);
    let text = std::fs::read_to_string(&p)
        .unwrap()
        .replace("\"version\": 1", "\"version\": 9");
    std::fs::write(&p, text).unwrap();
    let e = ReplayLog::load(&p).unwrap_err().to_string();
    assert!(e.contains("replay.json") && e.contains("version 9"), "{e}");
}

/// A dataset inside the log's folder moves with it: a run stage writes into
/// `<stage>.partial/` and renames the folder when it is done.
#[test]
fn a_dataset_beside_the_log_is_found_after_the_folder_moves() {
    let (mut log, _) = log2();
    let dir = tempfile::tempdir().unwrap();
    let partial = dir.path().join("budget.partial");
    log.dataset = partial.join("heldout").join("data");
    let p = partial.join("heldout").join("replay.json");
    std::fs::create_dir_all(&log.dataset).unwrap();
    log.save(&p).unwrap();
    let text = std::fs::read_to_string(&p).unwrap();
    assert!(text.contains("\"dataset\": \"./data\""), "{text}");
    let done = dir.path().join("budget");
    std::fs::rename(&partial, &done).unwrap();
    let moved = ReplayLog::load(&done.join("heldout").join("replay.json")).unwrap();
    assert_eq!(moved.dataset, done.join("heldout").join("data"));
    // a dataset elsewhere stays as given, a leading `./` dropped (it means the same)
    log.dataset = "./elsewhere/data".into();
    let q = done.join("other.json");
    log.save(&q).unwrap();
    assert_eq!(
        ReplayLog::load(&q).unwrap().dataset,
        std::path::Path::new("elsewhere/data")
    );
}

#[test]
fn estimated_mdp_solves_the_same_in_pymdptoolbox() {
    let (log, _) = log3();
    for reward in [Reward::Confidence, Reward::Outcome] {
        let cfg = PolicyConfig {
            reward,
            ..PolicyConfig::default()
        };
        same_in_pymdptoolbox(&train(&log, &cfg).unwrap(), &cfg);
    }
}

fn same_in_pymdptoolbox(p: &frugal_policies::TrainedPolicy, cfg: &PolicyConfig) {
    let m = &p.mdp;
    let input = serde_json::json!([{"states": m.states, "actions": m.actions, "p": m.p, "r": m.r, "gamma": cfg.gamma}]);
    let theirs: Vec<serde_json::Value> =
        serde_json::from_value(super::fixture::python_peer("mdptoolbox_check.py", &input)).unwrap();
    let pi_policy: Vec<u16> = serde_json::from_value(theirs[0]["pi_policy"].clone()).unwrap();
    let vi_policy: Vec<u16> = serde_json::from_value(theirs[0]["vi_policy"].clone()).unwrap();
    let values: Vec<f64> = serde_json::from_value(theirs[0]["pi_values"].clone()).unwrap();
    assert_eq!(p.actions, pi_policy);
    assert_eq!(p.actions, vi_policy);
    for (a, b) in p.values.iter().zip(&values) {
        assert!((a - b).abs() < 1e-6, "frugal {a} vs pymdptoolbox {b}");
    }
}
