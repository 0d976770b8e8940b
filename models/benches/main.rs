//! Benchmarks of the default detector on one 480×270 frame (libtorch, CPU):
//!
//! - `detect/threads=N`: full inference (normalise, backbone + RPN, proposals,
//!   RoIAlign + RoI head, per-class NMS) with `tch::set_num_threads(N)`, N = 1, 2;
//! - `backbone_rpn/threads=N`: the first network alone;
//! - `train_step/threads=1`: forward + backward of one image's losses (training runs
//!   on one libtorch thread by default).
//!
//! Run: `cargo bench -p frugal-models --bench main` (add `-- --quick` for a short run).
//! The weights are random: latency does not depend on them, except through the number
//! of detections, which the fixed proposal count (`post_nms_test`) bounds.
use criterion::{Criterion, criterion_group, criterion_main};
use frugal_models::FasterRcnn;
use frugal_models::config::{ModelConfig, TrainConfig};
use frugal_models::loss::image_losses;
use frugal_models::metrics::Truth;
use frugal_runtime::{BBox, FrameRef};
use rand::SeedableRng;
use std::hint::black_box;

fn frame() -> Vec<u8> {
    (0..480 * 270 * 3)
        .map(|i| ((i * 7919) % 251) as u8)
        .collect()
}

fn bench(c: &mut Criterion) {
    tch::manual_seed(0);
    let model =
        FasterRcnn::new(ModelConfig::default(), tch::Device::Cpu).expect("default config is valid");
    let px = frame();
    let f = FrameRef::new(480, 270, &px).expect("size matches");
    for threads in [1, 2] {
        tch::set_num_threads(threads);
        c.bench_function(&format!("detect/threads={threads}"), |b| {
            b.iter(|| black_box(model.detect(f)))
        });
        let x = model.frame_tensor(f);
        c.bench_function(&format!("backbone_rpn/threads={threads}"), |b| {
            b.iter(|| tch::no_grad(|| black_box(model.backbone_rpn(&x).objectness)))
        });
    }
    tch::set_num_threads(1);
    let x = model.frame_tensor(f);
    let truth = [Truth {
        class: 2,
        bbox: BBox::new(100.0, 80.0, 140.0, 120.0),
    }];
    let tc = TrainConfig::default();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    c.bench_function("train_step/threads=1", |b| {
        b.iter(|| {
            let l = image_losses(&model, &x, &truth, &tc, &mut rng).total();
            l.backward();
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench
}
criterion_main!(benches);
