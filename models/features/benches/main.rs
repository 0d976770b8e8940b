//! Per-frame cost of the feature-based family on rendered 480×270 frames: the edge map,
//! EdgeBoxes proposals, HoG of one 48×48 window per configuration, and whole-frame
//! detection with SVMs trained on a few frames, per variant. Cost must grow with the
//! proposal count and shrink with bigger cells: that is what the MDP trades.
//!
//! `cargo bench -p frugal-features`

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use frugal_data::{GenConfig, Split};
use frugal_features::data::{class_names, load_frames};
use frugal_features::edgeboxes::{EdgeBoxesConfig, proposals};
use frugal_features::edges::edge_map;
use frugal_features::hog::{HogScratch, hog_into};
use frugal_features::{HogParams, LabeledFrame, TrainConfig, train};
use frugal_runtime::{Detection, Detector, FrameRef};
use std::hint::black_box;

fn frames() -> (Vec<LabeledFrame>, Vec<LabeledFrame>, Vec<String>) {
    let dir = tempfile::tempdir().expect("temp dir");
    let cfg = GenConfig {
        videos_per_combo: 3,
        val_per_combo: 1,
        test_per_combo: 1,
        frames_per_video: 6,
        ..GenConfig::default()
    };
    let ds = frugal_data::generate(&cfg, dir.path(), false).expect("generate frames");
    let train = load_frames(&ds, Split::Train, 1, usize::MAX).expect("load train");
    let test = load_frames(&ds, Split::Test, 1, usize::MAX).expect("load test");
    (train, test, class_names(&ds))
}

fn bench(c: &mut Criterion) {
    let (train_frames, test, classes) = frames();
    let frame = test
        .iter()
        .find(|f| !f.objects.is_empty())
        .unwrap_or(&test[0]);
    let img = frame.view().expect("frame");
    let eb = EdgeBoxesConfig::default();
    c.bench_function("edge_map 480x270", |b| {
        b.iter(|| edge_map(black_box(&img), &eb.edges))
    });
    c.bench_function("edgeboxes 480x270 top-2000", |b| {
        b.iter(|| proposals(black_box(&img), &eb, 2000).expect("proposals"))
    });

    let mut window = Vec::new();
    img.window(
        &frugal_runtime::BBox::new(100.0, 60.0, 160.0, 120.0),
        48,
        &mut window,
    );
    let mut g = c.benchmark_group("hog 48x48 window");
    for p in [(2, 8, 9), (2, 6, 9), (1, 12, 6), (2, 12, 9)] {
        let cfg = HogParams {
            proposals: 1,
            block: p.0,
            cell: p.1,
            bins: p.2,
        }
        .hog(false);
        let (mut scratch, mut out) = (HogScratch::default(), Vec::new());
        g.bench_function(BenchmarkId::from_parameter(format!("{p:?}")), |b| {
            b.iter(|| hog_into(black_box(&window), 48, 48, 3, &cfg, &mut scratch, &mut out))
        });
    }
    g.finish();

    let variants = HogParams::grid(&[200, 1000, 2000], &[2], &[6, 8, 12], &[9]);
    let tcfg = TrainConfig {
        mining_rounds: 0,
        ..TrainConfig::default()
    };
    let model = train(
        &train_frames[..6.min(train_frames.len())],
        &classes,
        &variants,
        &tcfg,
        &|_| {},
    )
    .expect("train");
    let mut g = c.benchmark_group("detect 480x270");
    g.sample_size(10);
    for v in variants {
        let mut det = model.detector(v).expect("variant");
        let fr = FrameRef::new(frame.width as u32, frame.height as u32, &frame.rgb).expect("frame");
        let mut out = [Detection::default(); 16];
        g.bench_function(BenchmarkId::from_parameter(v), |b| {
            b.iter(|| det.detect(black_box(fr), &mut out).expect("detect"))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
