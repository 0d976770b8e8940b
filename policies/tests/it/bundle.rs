//! Bundle folders: write → verify → the runtime parses it and decides as the replay did;
//! corrupted bundles and wrong hashes give errors naming the file.

use super::fixture::log2;
use frugal_data::Split;
use frugal_policies::PolicyConfig;
use frugal_policies::bundle::{BUNDLE_FILE, inspect, read_bundle, verify, write_bundle};
use frugal_policies::eval::{EvalConfig, Strategy, run_with_bundle, strategy_bundle};
use frugal_policies::replay::VideoLog;
use frugal_policies::train::{TrainedPolicy, train};
use frugal_policies::variants::{Precision, VariantSource};
use frugal_runtime::Bundle;
use frugal_runtime::bundle::Bucket;
use frugal_runtime::pilot::Carry;

/// The trained fixture policy whose expensive variant points at a folder of two fake
/// ONNX graphs (the writer copies and hashes files; it does not load them).
fn policy_with_files(
    dir: &std::path::Path,
) -> (
    frugal_policies::ReplayLog,
    frugal_policies::replay::MemoryFrames,
    TrainedPolicy,
) {
    let (log, frames) = log2();
    let mut p = train(&log, &PolicyConfig::default()).unwrap();
    let onnx = dir.join("export");
    std::fs::create_dir_all(&onnx).unwrap();
    std::fs::write(onnx.join("backbone_rpn.onnx"), b"fake backbone graph").unwrap();
    std::fs::write(onnx.join("roi_head.onnx"), b"fake head graph").unwrap();
    p.variants[1].source = VariantSource::Onnx { dir: onnx };
    let hog = dir.join("features-model.json");
    std::fs::write(&hog, b"{\"fake\": \"feature model\"}").unwrap();
    p.variants[0].source = VariantSource::Hog {
        model: hog,
        params: "200,2,8,9".into(),
    };
    (log, frames, p)
}

#[test]
fn written_bundle_verifies_and_the_runtime_decides_as_the_replay() {
    let dir = tempfile::tempdir().unwrap();
    let (log, frames, mut policy) = policy_with_files(dir.path());
    policy.variants[1].precision = Precision::Int8;
    let cfg = EvalConfig::default();
    let out = dir.path().join("bundle");
    let file = write_bundle(&policy, cfg.thresholds(), &out).unwrap();
    assert_eq!(file, out.join(BUNDLE_FILE));
    let checked = verify(&out).unwrap();
    assert_eq!(checked.len(), 3, "{checked:?}");
    assert!(out.join("hog/features-model.json").is_file());
    assert!(out.join("onnx/expensive/roi_head.onnx").is_file());

    let bytes = read_bundle(&out).unwrap();
    let b = Bundle::parse(&bytes).unwrap();
    assert_eq!(b.variant_count(), 2);
    assert_eq!(b.policy().initial(), policy.initial);
    // the reference variant, which the drone confirms signs with, is the replay's
    // static one (the most accurate on the training videos), passed through as trained
    assert_eq!(policy.reference, Some(1));
    assert_eq!(b.policy().reference(), 1);
    let mut other = policy.clone();
    other.reference = Some(0);
    let bytes0 = frugal_policies::bundle::policy_bundle(&other, cfg.thresholds()).unwrap();
    assert_eq!(Bundle::parse(&bytes0).unwrap().policy().reference(), 0);
    for bucket in Bucket::ALL {
        for v in 0..2u16 {
            assert_eq!(
                b.policy().action(bucket, v),
                Some(policy.action(bucket, usize::from(v)))
            );
        }
    }
    assert_eq!(
        b.metadata_get("hog:cheap"),
        Some("hog/features-model.json 200,2,8,9")
    );
    // the int8 variant is marked, so a simulated device can charge it by its int8 speed
    assert_eq!(b.metadata_get("precision:expensive"), Some("int8"));
    assert_eq!(b.metadata_get("precision:cheap"), Some("fp32"));
    assert_eq!(
        frugal_nav::bundle::int8_variants(&b),
        Some(vec![false, true])
    );
    // a bundle written before precisions were marked cannot tell its int8 variants
    let bytes = frugal_policies::bundle::bundle_bytes(
        &policy.families,
        &policy.variants,
        &[],
        cfg.thresholds(),
        policy.initial,
        policy.reference,
        &policy.actions,
        None,
        &[],
    )
    .unwrap();
    let unmarked = Bundle::parse(&bytes).unwrap();
    assert_eq!(frugal_nav::bundle::int8_variants(&unmarked), None);
    // so a device with an int8 speed of its own refuses it, saying why
    let e = frugal_nav::bundle::int8_variants_or_refuse(&unmarked).unwrap_err();
    assert_eq!(e.to_string(), frugal_nav::bundle::NO_PRECISION);
    assert_eq!(
        frugal_nav::bundle::int8_variants_or_refuse(&b).unwrap(),
        vec![false, true]
    );
    assert_eq!(
        b.variant(1).unwrap().onnx_file,
        "onnx/expensive/backbone_rpn.onnx"
    );

    // Same decisions, frame by frame, from the file as from the replay's own bundle.
    let videos: Vec<&VideoLog> = log.split(Split::Test).collect();
    let mine = strategy_bundle(&log, &policy, Strategy::MdpTracker, 1, &cfg)
        .unwrap()
        .unwrap();
    let a = run_with_bundle(
        &log,
        &videos,
        Strategy::MdpTracker,
        &mine,
        Some(&frames),
        &cfg,
    )
    .unwrap();
    let b = run_with_bundle(
        &log,
        &videos,
        Strategy::MdpTracker,
        &bytes,
        Some(&frames),
        &cfg,
    )
    .unwrap();
    let key = |r: &[frugal_policies::eval::VideoRun]| -> Vec<_> {
        r.iter()
            .flat_map(|v| {
                v.frames
                    .iter()
                    .map(|t| (t.frame, t.detect, t.reason.clone(), t.state))
            })
            .collect()
    };
    assert_eq!(key(&a), key(&b));
    assert!(
        key(&a).iter().any(|k| k.1.is_none()),
        "some frames are tracked"
    );

    let text = inspect(&out).unwrap();
    assert!(
        text.contains("expensive") && text.contains("good enough") && text.contains("mdp.alpha"),
        "{text}"
    );
}

#[test]
fn corrupted_bundle_and_wrong_hash_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let (_, _, policy) = policy_with_files(dir.path());
    let out = dir.path().join("bundle");
    write_bundle(&policy, EvalConfig::default().thresholds(), &out).unwrap();

    let head = out.join("onnx/expensive/roi_head.onnx");
    std::fs::write(&head, b"tampered").unwrap();
    let e = verify(&out).unwrap_err().to_string();
    assert!(
        e.contains("roi_head.onnx") && e.contains("SHA-256 mismatch"),
        "{e}"
    );

    std::fs::remove_file(&head).unwrap();
    let e = verify(&out).unwrap_err().to_string();
    assert!(e.contains("roi_head.onnx") && e.contains("missing"), "{e}");

    let file = out.join(BUNDLE_FILE);
    let mut bytes = std::fs::read(&file).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x5a;
    std::fs::write(&file, &bytes).unwrap();
    let e = verify(&out).unwrap_err().to_string();
    assert!(e.contains("policy.frpb") && e.contains("checksum"), "{e}");
}

/// The drone's whole loop, `frugal_runtime::pilot::Pilot` (controller and trackers),
/// fed the replay's detections on the replay's frames, decides, tracks and reports
/// exactly what the replay evaluation does, frame by frame.
#[test]
fn the_runtime_pilot_flies_the_replay_frame_by_frame() {
    use frugal_policies::eval::TRACK_POINTS;
    use frugal_policies::replay::Frames;
    use frugal_runtime::pilot::Pilot;
    use frugal_runtime::track::{Pyramid, TrackerParams, rgb_to_gray};
    use frugal_runtime::{Decision, Detection};

    let dir = tempfile::tempdir().unwrap();
    let (log, frames, policy) = policy_with_files(dir.path());
    let out = dir.path().join("bundle");
    write_bundle(&policy, EvalConfig::default().thresholds(), &out).unwrap();
    let videos: Vec<&VideoLog> = log.split(Split::Test).collect();
    let levels = TrackerParams::DEFAULT.lk.levels;
    // (tracked frames, detection frames with a reported box left untracked) per carry
    let mut counts = Vec::new();
    for carry in [Carry::Optimal, Carry::GoodEnough, Carry::Reported] {
        let cfg = EvalConfig {
            carry,
            ..EvalConfig::default()
        };
        let (mut tracked, mut untracked_detections) = (0, 0);
        // the policy's bundle as written, and the cheap variant alone (its scores are
        // good enough, not optimal)
        let cheap = frugal_policies::eval::constant_bundle(&log, 0, cfg.thresholds()).unwrap();
        for (strategy, bytes) in [
            (Strategy::MdpTracker, read_bundle(&out).unwrap()),
            (Strategy::StaticTracker, cheap),
        ] {
            let replay =
                run_with_bundle(&log, &videos, strategy, &bytes, Some(&frames), &cfg).unwrap();
            for (video, run) in videos.iter().zip(&replay) {
                let (w, h) = (video.width as usize, video.height as usize);
                let need = Pyramid::required_len(w, h, levels).unwrap();
                let (mut a, mut b, mut gray) = (vec![0u8; need], vec![0u8; need], vec![0u8; w * h]);
                let mut pilot: Pilot<'_, 4, TRACK_POINTS> =
                    Pilot::new(Bundle::parse(&bytes).unwrap())
                        .with_max_tracks(cfg.max_tracks)
                        .with_carry(cfg.carry);
                let mut prev = Pyramid::new(&mut a, w, h, levels).unwrap();
                let mut cur = Pyramid::new(&mut b, w, h, levels).unwrap();
                for (fi, (f, trace)) in video.frames.iter().zip(&run.frames).enumerate() {
                    let img = frames.load(video.id, f.index).unwrap();
                    cur.build(&rgb_to_gray(&img.view(), &mut gray).unwrap())
                        .unwrap();
                    let decision = pilot.decide(f.index, (fi > 0).then_some(&prev), &cur);
                    let shown: Vec<Detection> = match decision {
                        Decision::Detect { variant, reason } => {
                            assert_eq!(trace.reason, Some(format!("{reason:?}")), "frame {fi}");
                            let (last, found) = pilot
                                .detect_with(&cur, variant, |v| {
                                    let mut d: Vec<Detection> = f.detections[usize::from(v)]
                                        .iter()
                                        .map(|d| d.detection())
                                        .collect();
                                    d.sort_by(|a, b| b.score.total_cmp(&a.score));
                                    Ok::<_, ()>(d)
                                })
                                .unwrap();
                            assert_eq!(trace.detect, Some(last), "frame {fi}");
                            let t_c = pilot.report_score();
                            let shown: Vec<Detection> =
                                found.into_iter().filter(|d| d.score >= t_c).collect();
                            untracked_detections += usize::from(pilot.tracking() < shown.len());
                            shown
                        }
                        Decision::Track => {
                            assert_eq!(trace.detect, None, "frame {fi}");
                            tracked += 1;
                            pilot.tracked().collect()
                        }
                    };
                    let mut mine: Vec<_> = shown.iter().map(|d| (d.class, d.bbox)).collect();
                    let mut theirs: Vec<_> = run.images[fi]
                        .detections
                        .iter()
                        .map(|d| (d.class, d.bbox))
                        .collect();
                    for v in [&mut mine, &mut theirs] {
                        v.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.x1.total_cmp(&b.1.x1)));
                    }
                    assert_eq!(mine, theirs, "video {} frame {fi}", video.id);
                    std::mem::swap(&mut prev, &mut cur);
                }
            }
        }
        counts.push((tracked, untracked_detections));
    }
    // both behaviours of the loop were exercised: boxes carried by the trackers, and
    // reported detections that were not carried (the cheap variant's good-enough ones);
    // carrying from good-enough up carries some of those, and carrying every reported
    // one (the paper's rule) at least as many
    let [(t_opt, u_opt), (t_ge, u_ge), (t_rep, u_rep)] = counts[..] else {
        unreachable!()
    };
    assert!(t_opt > 0 && u_opt > 0, "{counts:?}");
    assert!(t_ge > t_opt && u_ge < u_opt, "{counts:?}");
    assert!(t_rep >= t_ge && u_rep <= u_ge, "{counts:?}");
}
