//! Integration tests of the CNN detector on tiny configurations: overfitting a handful
//! of drawn images, checkpoints (round trip, corrupt, mismatched) and training with
//! resume on a tiny generated dataset.
use frugal_models::config::{BlockConfig, Config, ModelConfig, TrainConfig};
use frugal_models::loss::image_losses;
use frugal_models::metrics::{ImageResult, Interpolation, Truth, evaluate};
use frugal_models::optim::Optimizer;
use frugal_models::train::{TrainOptions, train};
use frugal_models::{FasterRcnn, ModelError};
use frugal_runtime::{BBox, FrameRef};
use rand::SeedableRng;
use std::path::Path;
use std::sync::{Mutex, MutexGuard};
use tch::{Device, Kind, Tensor};

/// libtorch's random generator and thread count are global to the process, and the
/// tests of this binary run on parallel threads. A test that seeds the generator and
/// then draws from it (weight init, noise augmentation) holds this lock, so a test
/// running beside it cannot draw in between and change its weights.
fn torch_globals() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// The crate docs' example, run here (doctests cannot load libtorch).
#[test]
fn crate_docs_example() {
    let _torch = torch_globals();
    tch::manual_seed(0);
    let model = FasterRcnn::new(ModelConfig::default(), Device::Cpu).unwrap();
    let pixels = vec![128u8; 96 * 64 * 3];
    let dets = model.detect(FrameRef::new(96, 64, &pixels).unwrap());
    assert!(dets.iter().all(|d| (0.0..=1.0).contains(&d.score)));
}

fn tiny_model(num_classes: usize) -> ModelConfig {
    let block = |out_channels, stride| BlockConfig {
        out_channels,
        stride,
        convs: 1,
    };
    ModelConfig {
        num_classes,
        backbone: vec![block(16, 2), block(32, 2), block(48, 2)],
        rpn_channels: 32,
        anchor_sizes: vec![12.0, 24.0],
        anchor_ratios: vec![1.0],
        roi_size: 4,
        roi_hidden: 64,
        pre_nms_train: 200,
        post_nms_train: 50,
        pre_nms_test: 200,
        post_nms_test: 20,
        ..Default::default()
    }
}

/// A 96×64 image with coloured shapes: class 0 = red square, class 1 = blue square,
/// class 2 = green cross, on a grey noisy background.
fn draw(objects: &[(u16, u32, u32, u32)], seed: u32) -> (Vec<u8>, Vec<Truth>) {
    let (w, h) = (96u32, 64u32);
    let mut px = vec![0u8; (w * h * 3) as usize];
    for y in 0..h {
        for x in 0..w {
            let n = (x.wrapping_mul(7919) ^ y.wrapping_mul(104729) ^ seed.wrapping_mul(31)) % 40;
            let i = ((y * w + x) * 3) as usize;
            px[i..i + 3].copy_from_slice(&[(100 + n) as u8; 3]);
        }
    }
    let mut truth = Vec::new();
    for &(class, x0, y0, s) in objects {
        for y in y0..y0 + s {
            for x in x0..x0 + s {
                let (dx, dy) = (x - x0, y - y0);
                let on = match class {
                    2 => (dx >= s / 3 && dx < 2 * s / 3) || (dy >= s / 3 && dy < 2 * s / 3),
                    _ => true,
                };
                if on {
                    let c = [[220u8, 30, 30], [30, 30, 220], [30, 200, 30]][class as usize];
                    let i = ((y * w + x) * 3) as usize;
                    px[i..i + 3].copy_from_slice(&c);
                }
            }
        }
        truth.push(Truth {
            class,
            bbox: BBox::new(x0 as f32, y0 as f32, (x0 + s) as f32, (y0 + s) as f32),
        });
    }
    (px, truth)
}

#[test]
fn tiny_config_overfits_a_handful_of_images() {
    let _torch = torch_globals();
    // one intra-op thread: two OpenMP threads crawl on a shared 2-core machine
    tch::set_num_threads(1);
    tch::manual_seed(11);
    let model = FasterRcnn::new(tiny_model(3), Device::Cpu).unwrap();
    let images = [
        draw(&[(0, 10, 10, 20), (1, 60, 30, 16)], 1),
        draw(&[(2, 40, 8, 24)], 2),
        draw(&[(1, 5, 35, 22), (0, 70, 5, 14)], 3),
        draw(&[(2, 20, 20, 18), (0, 60, 34, 20)], 4),
        draw(&[], 5),
    ];
    let tc = TrainConfig {
        rpn_batch: 64,
        roi_batch: 32,
        ..Default::default()
    };
    let mut opt = Optimizer::new(model.var_store(), &tc);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let tensors: Vec<Tensor> = images
        .iter()
        .map(|(px, _)| model.frame_tensor(FrameRef::new(96, 64, px).unwrap()))
        .collect();
    let mut losses = Vec::new();
    for step in 0..160 {
        opt.zero_grad();
        let mut total = Tensor::zeros([], (Kind::Float, Device::Cpu));
        for (x, (_, truth)) in tensors.iter().zip(&images) {
            total += image_losses(&model, x, truth, &tc, &mut rng).total();
        }
        losses.push(total.double_value(&[]));
        total.backward();
        opt.step(if step < 10 { 3e-4 } else { 3e-3 });
    }
    let first: f64 = losses[..5].iter().sum::<f64>() / 5.0;
    let last: f64 = losses[losses.len() - 5..].iter().sum::<f64>() / 5.0;
    assert!(
        last < 0.25 * first,
        "loss fell only from {first:.3} to {last:.3}"
    );
    let results: Vec<ImageResult> = images
        .iter()
        .map(|(px, truth)| ImageResult {
            detections: model.detect(FrameRef::new(96, 64, px).unwrap()),
            truth: truth.clone(),
            ignore: Vec::new(),
        })
        .collect();
    let s = evaluate(&results, 3, 0.5, 0.5, Interpolation::AllPoint);
    assert!(
        s.map >= 0.9,
        "mAP on the training images {:.3}: {:?}",
        s.map,
        s.ap_per_class
    );
    assert!(
        results
            .iter()
            .flat_map(|r| &r.detections)
            .all(|d| (0.0..=1.0).contains(&d.score))
    );
}

#[test]
fn checkpoint_round_trip_gives_identical_outputs() {
    let _torch = torch_globals();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.safetensors");
    tch::manual_seed(1);
    let a = FasterRcnn::new(tiny_model(3), Device::Cpu).unwrap();
    a.save(&path).unwrap();
    tch::manual_seed(2);
    let mut b = FasterRcnn::new(tiny_model(3), Device::Cpu).unwrap();
    let (px, _) = draw(&[(0, 10, 10, 20)], 9);
    let f = FrameRef::new(96, 64, &px).unwrap();
    let x = a.frame_tensor(f);
    let before = b.backbone_rpn(&x).objectness;
    assert!(
        !a.backbone_rpn(&x)
            .objectness
            .allclose(&before, 1e-6, 1e-6, false)
    );
    b.load_weights(&path).unwrap();
    let (oa, ob) = (a.backbone_rpn(&x), b.backbone_rpn(&x));
    assert!(
        oa.objectness.equal(&ob.objectness)
            && oa.deltas.equal(&ob.deltas)
            && oa.features.equal(&ob.features)
    );
    assert_eq!(a.detect(f), b.detect(f));
    assert_eq!(a.layers(), b.layers());
}

#[test]
fn corrupt_or_mismatched_checkpoints_give_clear_errors() {
    let _torch = torch_globals();
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("corrupt.safetensors");
    std::fs::write(&bad, b"definitely not safetensors").unwrap();
    let mut m = FasterRcnn::new(tiny_model(3), Device::Cpu).unwrap();
    let err = m.load_weights(&bad).unwrap_err();
    assert!(matches!(err, ModelError::Checkpoint { .. }));
    assert!(err.to_string().contains("corrupt.safetensors"), "{err}");

    let other = dir.path().join("other.safetensors");
    FasterRcnn::new(tiny_model(5), Device::Cpu)
        .unwrap()
        .save(&other)
        .unwrap();
    let err = m.load_weights(&other).unwrap_err().to_string();
    assert!(
        err.contains("other.safetensors")
            && err.contains(
                "tensor `roi_head.box_deltas.bias` has shape [20], the config needs [12]"
            ),
        "{err}"
    );

    let mut deeper = tiny_model(3);
    deeper.backbone.push(BlockConfig {
        out_channels: 48,
        stride: 1,
        convs: 1,
    });
    let deep = dir.path().join("deeper.safetensors");
    FasterRcnn::new(deeper, Device::Cpu)
        .unwrap()
        .save(&deep)
        .unwrap();
    let err = m.load_weights(&deep).unwrap_err().to_string();
    assert!(
        err.contains("deeper.safetensors") && err.contains("unexpected tensor"),
        "{err}"
    );

    let missing = dir.path().join("missing.safetensors");
    let err = m.load_weights(&missing).unwrap_err().to_string();
    assert!(err.contains("missing.safetensors"), "{err}");
}

fn tiny_dataset(root: &Path) -> frugal_data::Dataset {
    frugal_data::generate(&frugal_data::GenConfig::tiny(), root, false).unwrap()
}

fn tiny_train_config() -> Config {
    Config {
        model: tiny_model(10),
        train: TrainConfig {
            epochs: 2,
            batch_size: 3,
            warmup_steps: 2,
            train_frames: 9,
            val_frames: 6,
            ..Default::default()
        },
    }
}

fn weights(dir: &Path) -> Vec<(String, Tensor)> {
    let mut v = Tensor::read_safetensors(dir.join("checkpoint").join("model.safetensors")).unwrap();
    v.sort_by(|a, b| a.0.cmp(&b.0));
    v
}

#[test]
fn interrupted_training_resumes_to_the_same_weights() {
    let _torch = torch_globals();
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    tiny_dataset(&data);
    let opts = |out: &str| TrainOptions {
        data: data.clone(),
        out: tmp.path().join(out),
        config: tiny_train_config(),
        resume: false,
        stop_after: None,
        progress: false,
        device: tch::Device::Cpu,
    };
    let full = train(&opts("full")).unwrap();
    assert_eq!(full.state.epochs_done, 2);
    assert_eq!(full.state.history.len(), 2);
    for f in [
        "best.safetensors",
        "config.json",
        "curves.csv",
        "curves.png",
        "curves.svg",
        "checkpoint/state.json",
    ] {
        assert!(tmp.path().join("full").join(f).exists(), "{f} missing");
    }
    let csv = std::fs::read_to_string(tmp.path().join("full/curves.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3);

    let first = train(&TrainOptions {
        stop_after: Some(1),
        ..opts("resumed")
    })
    .unwrap();
    assert_eq!(first.state.epochs_done, 1);
    let second = train(&TrainOptions {
        resume: true,
        ..opts("resumed")
    })
    .unwrap();
    assert_eq!(second.state.epochs_done, 2);
    assert_eq!(second.state.step, full.state.step);
    for ((na, a), (nb, b)) in weights(&tmp.path().join("full"))
        .iter()
        .zip(&weights(&tmp.path().join("resumed")))
    {
        assert_eq!(na, nb);
        assert!(
            a.allclose(b, 1e-5, 1e-6, false),
            "{na} differs after resume"
        );
    }
    let h =
        |s: &frugal_models::train::TrainState| s.history.iter().map(|r| r.loss).collect::<Vec<_>>();
    for (a, b) in h(&full.state).iter().zip(h(&second.state)) {
        assert!((a - b).abs() < 1e-4, "{a} vs {b}");
    }

    // resuming with a different config is refused, naming the saved config
    let mut other = tiny_train_config();
    other.train.lr *= 2.0;
    let err = train(&TrainOptions {
        resume: true,
        config: other,
        ..opts("resumed")
    })
    .unwrap_err()
    .to_string();
    assert!(err.contains("config.json"), "{err}");
    // a corrupt checkpoint is reported with its file name
    std::fs::write(
        tmp.path().join("resumed/checkpoint/optimizer.safetensors"),
        b"junk",
    )
    .unwrap();
    let err = train(&TrainOptions {
        resume: true,
        ..opts("resumed")
    })
    .unwrap_err()
    .to_string();
    assert!(err.contains("optimizer.safetensors"), "{err}");
}

/// The metric code against pycocotools (COCOeval, iouThrs = [0.5], 101-point
/// interpolation) on a fixed random case with crowd regions (ignore regions) that
/// some detections fall in: per-class AP must agree to 1e-9.
#[test]
fn coco101_ap_matches_pycocotools() {
    use frugal_models::metrics::average_precision;
    use frugal_runtime::Detection;
    let Ok(python) = std::env::var("FRUGAL_PYTHON") else {
        panic!("FRUGAL_PYTHON is not set (cargo sets it from .cargo/config.toml)");
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    use rand::Rng;
    let mut images = Vec::new();
    let mut score_id = 0u32;
    for _ in 0..30 {
        let mut im = ImageResult::default();
        for _ in 0..rng.random_range(0..4) {
            let (x, y, s) = (
                rng.random_range(0.0..300.0f32),
                rng.random_range(0.0..150.0f32),
                rng.random_range(12.0..80.0f32),
            );
            let class = rng.random_range(0..3u16);
            im.truth.push(Truth {
                class,
                bbox: BBox::from_xywh(x, y, s, s),
            });
            // a detection: good (IoU > 0.65), poor (IoU < 0.35), or wrong class; or none
            let kind = rng.random_range(0..4);
            let off = match kind {
                0 | 3 => 0.05 * s,
                _ => 0.6 * s,
            };
            let dc = if kind == 2 { (class + 1) % 3 } else { class };
            if kind < 3 {
                score_id += 1;
                let score = rng.random_range(0.0..1.0f32) * 0.5 + (score_id as f32) * 1e-4;
                im.detections.push(Detection {
                    bbox: BBox::from_xywh(x + off, y, s, s),
                    score,
                    class: dc,
                });
            }
        }
        for _ in 0..rng.random_range(0..3) {
            score_id += 1;
            let score = rng.random_range(0.0..1.0f32) * 0.5 + (score_id as f32) * 1e-4;
            let b = BBox::from_xywh(
                rng.random_range(0.0..300.0),
                rng.random_range(0.0..150.0),
                20.0,
                20.0,
            );
            if im.truth.iter().all(|t| {
                let i = t.bbox.iou(&b);
                !(0.3..0.7).contains(&i)
            }) {
                im.detections.push(Detection {
                    bbox: b,
                    score,
                    class: rng.random_range(0..3),
                });
            }
        }
        // a crowd of one class in a third of the images, with detections in and
        // around it (excused only when of its class and mostly inside)
        if rng.random_range(0..3) == 0 {
            let class = rng.random_range(0..3u16);
            let (x, y) = (
                rng.random_range(0.0..300.0f32),
                rng.random_range(0.0..150.0f32),
            );
            im.ignore.push(frugal_models::metrics::IgnoreRegion {
                class: Some(class),
                bbox: BBox::from_xywh(x, y, 60.0, 50.0),
            });
            for _ in 0..rng.random_range(1..4) {
                score_id += 1;
                let score = rng.random_range(0.0..1.0f32) * 0.5 + (score_id as f32) * 1e-4;
                im.detections.push(Detection {
                    bbox: BBox::from_xywh(
                        x + rng.random_range(-20.0..50.0),
                        y + rng.random_range(-20.0..40.0),
                        20.0,
                        20.0,
                    ),
                    score,
                    class: if rng.random_range(0..4) == 0 {
                        (class + 1) % 3
                    } else {
                        class
                    },
                });
            }
        }
        images.push(im);
    }
    assert!(images.iter().filter(|im| !im.ignore.is_empty()).count() >= 5);
    let dir = tempfile::tempdir().unwrap();
    let (mut gts, mut dts, mut imgs) = (Vec::new(), Vec::new(), Vec::new());
    for (i, im) in images.iter().enumerate() {
        imgs.push(serde_json::json!({"id": i, "width": 480, "height": 270}));
        for t in &im.truth {
            let b = t.bbox;
            gts.push(
                serde_json::json!({"id": gts.len() + 1, "image_id": i, "category_id": t.class,
                "bbox": [b.x1, b.y1, b.width(), b.height()], "area": b.area(), "iscrowd": 0}),
            );
        }
        for r in &im.ignore {
            let b = r.bbox;
            gts.push(
                serde_json::json!({"id": gts.len() + 1, "image_id": i, "category_id": r.class,
                "bbox": [b.x1, b.y1, b.width(), b.height()], "area": b.area(), "iscrowd": 1}),
            );
        }
        for d in &im.detections {
            let b = d.bbox;
            dts.push(serde_json::json!({"image_id": i, "category_id": d.class,
                "bbox": [b.x1, b.y1, b.width(), b.height()], "score": d.score}));
        }
    }
    let cats: Vec<_> = (0..3)
        .map(|c| serde_json::json!({"id": c, "name": format!("c{c}")}))
        .collect();
    let gt_path = dir.path().join("gt.json");
    let dt_path = dir.path().join("dt.json");
    std::fs::write(
        &gt_path,
        serde_json::json!({"images": imgs, "annotations": gts, "categories": cats}).to_string(),
    )
    .unwrap();
    std::fs::write(&dt_path, serde_json::Value::from(dts).to_string()).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/coco_ap.py");
    let out = std::process::Command::new(&python)
        .arg(&script)
        .arg(&gt_path)
        .arg(&dt_path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let mut nontrivial = 0;
    for c in 0..3u16 {
        let want = v["ap"][c.to_string()].as_f64().unwrap();
        let have = average_precision(&images, c, 0.5, Interpolation::Coco101).unwrap_or(-1.0);
        assert!(
            (want - have).abs() < 1e-9,
            "class {c}: pycocotools {want} vs ours {have}"
        );
        if want > 0.05 && want < 0.95 {
            nontrivial += 1;
        }
    }
    assert!(
        nontrivial >= 2,
        "the case should exercise partial precision: {v}"
    );
    // the crowds matter: without them some class's AP changes
    let plain: Vec<ImageResult> = images
        .iter()
        .map(|im| ImageResult {
            ignore: Vec::new(),
            ..im.clone()
        })
        .collect();
    assert!(
        (0..3u16).any(|c| {
            average_precision(&plain, c, 0.5, Interpolation::Coco101)
                != average_precision(&images, c, 0.5, Interpolation::Coco101)
        }),
        "no crowd changed any AP"
    );
}
