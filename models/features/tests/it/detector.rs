//! The detector end to end on drawn scenes: two sign classes (a red disc, a blue
//! square with a white bar) on a textured grey background.

use frugal_features::{Error, FeatureModel, HogParams, LabeledFrame, TrainConfig, train};
use frugal_runtime::{BBox, Detection, Detector, FrameRef};

const W: usize = 160;
const H: usize = 120;

struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn range(&mut self, lo: usize, hi: usize) -> usize {
        lo + (self.next() % (hi - lo) as u64) as usize
    }
}

/// A frame with one sign of `class` at a random place and size.
fn scene(seed: u64, class: u16) -> LabeledFrame {
    let mut rng = Rng(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
    let mut rgb = vec![0u8; W * H * 3];
    for y in 0..H {
        for x in 0..W {
            let v = (110 + (x / 16 + y / 16) % 2 * 20) as u8 + (rng.next() % 12) as u8;
            rgb[(y * W + x) * 3..(y * W + x) * 3 + 3].copy_from_slice(&[v, v, v]);
        }
    }
    let s = rng.range(26, 44);
    let (x0, y0) = (rng.range(4, W - s - 4), rng.range(4, H - s - 4));
    for y in y0..y0 + s {
        for x in x0..x0 + s {
            let (dx, dy) = (
                x as f32 + 0.5 - (x0 as f32 + s as f32 / 2.0),
                y as f32 + 0.5 - (y0 as f32 + s as f32 / 2.0),
            );
            let r = s as f32 / 2.0;
            let px = if class == 0 {
                (dx * dx + dy * dy <= r * r).then_some([210, 30, 30])
            } else if dy.abs() < r * 0.15 && dx.abs() < r * 0.6 {
                Some([240, 240, 240])
            } else {
                Some([30, 60, 200])
            };
            if let Some(c) = px {
                rgb[(y * W + x) * 3..(y * W + x) * 3 + 3].copy_from_slice(&c);
            }
        }
    }
    LabeledFrame {
        width: W,
        height: H,
        rgb,
        objects: vec![(
            class,
            BBox::new(x0 as f32, y0 as f32, (x0 + s) as f32, (y0 + s) as f32),
        )],
    }
}

fn variants() -> Vec<HogParams> {
    vec![
        HogParams {
            proposals: 300,
            block: 2,
            cell: 8,
            bins: 9,
        },
        HogParams {
            proposals: 100,
            block: 1,
            cell: 12,
            bins: 6,
        },
    ]
}

/// The model trained once for all tests of this module.
fn model() -> &'static FeatureModel {
    static MODEL: std::sync::OnceLock<FeatureModel> = std::sync::OnceLock::new();
    MODEL.get_or_init(tiny_model)
}

fn tiny_model() -> FeatureModel {
    let frames: Vec<LabeledFrame> = (0..16).map(|i| scene(i, (i % 2) as u16)).collect();
    let cfg = TrainConfig {
        proposals: 300,
        ..TrainConfig::default()
    };
    let classes = vec!["red_disc".to_string(), "blue_square".to_string()];
    train(&frames, &classes, &variants(), &cfg, &|_| {}).expect("training")
}

#[test]
fn trained_detector_finds_held_out_signs() {
    let model = model();
    assert_eq!(model.hogs.len(), 2);
    assert_eq!(model.variants(&[300]).len(), 2);
    // The richer variant must be right in 3/4 of the frames, the cheap one (fewer
    // proposals, coarse cells, one-cell blocks) in half.
    for (v, need) in variants().into_iter().zip([0.75, 0.5]) {
        let mut det = model.detector(v).expect("variant");
        let mut hits = 0;
        let held_out = 1000..1016u64;
        for seed in held_out.clone() {
            let f = scene(seed, (seed % 2) as u16);
            let frame = FrameRef::new(W as u32, H as u32, &f.rgb).expect("frame");
            let mut out = [Detection::default(); 8];
            let n = det.detect(frame, &mut out).expect("detect");
            assert!(
                out[..n].windows(2).all(|p| p[0].score >= p[1].score),
                "sorted by score"
            );
            let (class, truth) = f.objects[0];
            if n > 0
                && out[0].class == class
                && out[0].bbox.iou(&truth) >= 0.5
                && out[0].score >= 0.0
            {
                hits += 1;
            }
        }
        let total = held_out.count();
        println!("{v}: top detection right in {hits}/{total} held-out frames");
        assert!(
            hits as f64 >= need * total as f64,
            "{v}: only {hits}/{total} right"
        );
    }
}

#[test]
fn detection_is_deterministic() {
    let model = model();
    let f = scene(77, 1);
    let det = model.detector(variants()[0]).unwrap();
    let a = det.detect_all(&f.view().unwrap()).unwrap();
    let b = det.detect_all(&f.view().unwrap()).unwrap();
    assert_eq!(a, b);
    assert_eq!(&tiny_model(), model, "training is deterministic");
}

#[test]
fn odd_frames_give_errors_or_nothing_never_a_panic() {
    let model = model();
    let mut det = model.detector(variants()[0]).unwrap();
    let mut out = [Detection::default(); 4];
    // Slice length mismatch: an error naming the sizes.
    let bad = FrameRef {
        width: 10,
        height: 10,
        rgb: &[0u8; 299],
    };
    let err = det.detect(bad, &mut out).unwrap_err();
    assert!(
        matches!(
            err,
            Error::FrameSize {
                width: 10,
                height: 10,
                len: 299,
                expected: 300
            }
        ),
        "{err}"
    );
    let absurd = FrameRef {
        width: u32::MAX,
        height: u32::MAX,
        rgb: &[],
    };
    assert!(det.detect(absurd, &mut out).is_err());
    // Blank, tiny, empty and large frames: no detections, no panic.
    for (w, h) in [
        (0usize, 0usize),
        (1, 1),
        (0, 50),
        (3, 2),
        (64, 64),
        (2000, 1500),
    ] {
        let px = vec![128u8; w * h * 3];
        let frame = FrameRef::new(w as u32, h as u32, &px).unwrap();
        assert_eq!(det.detect(frame, &mut out).unwrap(), 0, "{w}×{h}");
    }
    // No room for detections.
    let f = scene(5, 0);
    let frame = FrameRef::new(W as u32, H as u32, &f.rgb).unwrap();
    assert_eq!(det.detect(frame, &mut []).unwrap(), 0);
    // A variant the model was not trained for.
    assert!(matches!(
        model.detector(HogParams::BASELINE.with_hog(3, 4, 12)),
        Err(Error::MissingHog {
            block: 3,
            cell: 4,
            bins: 12
        })
    ));
}

#[test]
fn model_files_round_trip_and_bad_files_are_clear_errors() {
    let model = model();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.json");
    model.save(&path).unwrap();
    assert_eq!(&FeatureModel::load(&path).unwrap(), model);
    // Overwriting keeps a complete file (written to a temp file, then renamed).
    model.save(&path).unwrap();
    assert_eq!(&FeatureModel::load(&path).unwrap(), model);

    let missing = dir.path().join("nope.json");
    let err = FeatureModel::load(&missing).unwrap_err();
    assert!(
        matches!(err, Error::Io { .. }) && err.to_string().contains("nope.json"),
        "{err}"
    );

    let text = std::fs::read_to_string(&path).unwrap();
    let truncated = dir.path().join("truncated.json");
    std::fs::write(&truncated, &text[..text.len() / 2]).unwrap();
    let err = FeatureModel::load(&truncated).unwrap_err();
    assert!(
        matches!(err, Error::Model { .. }) && err.to_string().contains("truncated.json"),
        "{err}"
    );

    let mut wrong = model.clone();
    wrong.hogs[0].svms[1].w.pop();
    let wrong_path = dir.path().join("wrong.json");
    std::fs::write(&wrong_path, serde_json::to_string(&wrong).unwrap()).unwrap();
    let err = FeatureModel::load(&wrong_path).unwrap_err();
    assert!(err.to_string().contains("weights"), "{err}");
}

#[test]
fn training_without_signs_or_with_bad_classes_is_an_error() {
    let blank = LabeledFrame {
        width: 32,
        height: 32,
        rgb: vec![0; 32 * 32 * 3],
        objects: vec![],
    };
    let classes = vec!["a".to_string()];
    let cfg = TrainConfig::default();
    assert!(matches!(
        train(
            std::slice::from_ref(&blank),
            &classes,
            &variants(),
            &cfg,
            &|_| {}
        ),
        Err(Error::Training(_))
    ));
    let mut bad = scene(1, 1);
    bad.objects[0].0 = 5;
    assert!(matches!(
        train(&[bad], &classes, &variants(), &cfg, &|_| {}),
        Err(Error::Training(_))
    ));
    assert!(matches!(
        train(&[blank], &classes, &[], &cfg, &|_| {}),
        Err(Error::Training(_))
    ));
}

#[test]
fn scoring_many_variants_on_shared_proposals_counts_like_one_at_a_time() {
    use frugal_features::eval::{evaluate, evaluate_many};
    let model = model();
    let frames: Vec<LabeledFrame> = (2000..2006u64).map(|s| scene(s, (s % 2) as u16)).collect();
    let mut vs = variants();
    vs.push(HogParams {
        proposals: 30,
        ..vs[0]
    });
    let calls = std::cell::Cell::new(0);
    let many = evaluate_many(model, &vs, &frames, 0.0, 0.5, &|done, total| {
        assert_eq!(total, frames.len());
        calls.set(done);
    })
    .unwrap();
    assert_eq!(calls.get(), frames.len());
    assert_eq!(many.len(), vs.len());
    for (v, m) in vs.iter().zip(&many) {
        let one = evaluate(model, *v, &frames, 0.0, 0.5).unwrap();
        assert_eq!(m.params, one.params);
        assert_eq!(m.per_class, one.per_class, "{v}");
        assert!(m.mean_ms > 0.0);
        let t = m.total();
        assert_eq!(t.tp + t.missed, frames.len(), "one sign per frame");
    }
    // Unknown HoG configurations are an error, not a panic.
    let bad = HogParams { bins: 7, ..vs[0] };
    assert!(evaluate_many(model, &[bad], &frames, 0.0, 0.5, &|_, _| {}).is_err());
}
