//! Criterion benchmarks of the simulator's per-frame cost.
//!
//! - `render/<maze>_480x270`: one camera frame (walls, floor, ceiling, sign boards,
//!   photometric pass) plus its ground truth, from the start pose of a shipped maze;
//! - `render/medium_pedestrian_480x270`: the same in front of a WAIT zone with its
//!   pedestrian crossing;
//! - `render/easy_low_light_480x270`: the easy maze with `light low`;
//! - `perceive/ground_truth`: the ground-truth perception of one frame.
//!
//! `cargo bench -p frugal-sim --bench main`
use criterion::{Criterion, criterion_group, criterion_main};
use frugal_runtime::FrameRef;
use frugal_sim::perception::FrameInput;
use frugal_sim::render::Walker;
use frugal_sim::{CameraSpec, GroundTruthPerception, Maze, Perception, Pose, Renderer};
use std::hint::black_box;
use std::path::Path;

fn load(name: &str) -> Maze {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("mazes")
        .join(name);
    Maze::load(&path).expect("shipped maze")
}

fn render(c: &mut Criterion) {
    let cam = CameraSpec::default();
    let mut group = c.benchmark_group("render");
    for name in ["easy", "medium", "hard"] {
        let maze = load(&format!("{name}.maze"));
        let pose = frugal_sim::flight::start_pose(&maze, 1);
        let mut r = Renderer::new(&maze, cam, 1);
        let mut rgb = Vec::new();
        let mut frame = 0;
        group.bench_function(format!("{name}_480x270"), |b| {
            b.iter(|| {
                frame += 1;
                black_box(r.render(black_box(pose), &[], frame, &mut rgb))
            })
        });
    }
    let maze = load("medium.maze");
    let mut r = Renderer::new(&maze, cam, 1);
    let mut rgb = Vec::new();
    let pose = Pose {
        x: 7.5,
        y: 7.5,
        yaw: 0.0,
    };
    let walker = Walker {
        zone: 0,
        pos: (13.5, 7.0),
        phase: 0.0,
    };
    group.bench_function("medium_pedestrian_480x270", |b| {
        b.iter(|| black_box(r.render(black_box(pose), &[walker], 0, &mut rgb)))
    });
    let text =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("mazes/easy.maze"))
            .expect("easy maze")
            .replace("light normal", "light low");
    let dark = Maze::parse(&text, Path::new("easy-low.maze")).expect("parses");
    let mut r = Renderer::new(&dark, cam, 1);
    let pose = frugal_sim::flight::start_pose(&dark, 1);
    group.bench_function("easy_low_light_480x270", |b| {
        b.iter(|| black_box(r.render(black_box(pose), &[], 0, &mut rgb)))
    });
    group.finish();

    let truth = Renderer::new(&maze, cam, 1).render(
        Pose {
            x: 7.5,
            y: 7.5,
            yaw: 0.0,
        },
        &[walker],
        0,
        &mut rgb,
    );
    let mut gt = GroundTruthPerception::default();
    c.bench_function("perceive/ground_truth", |b| {
        b.iter(|| {
            let input = FrameInput {
                image: FrameRef {
                    width: cam.width,
                    height: cam.height,
                    rgb: &rgb,
                },
                time_s: 0.0,
                index: 0,
                truth: &truth,
            };
            black_box(gt.perceive(&input).map(|p| p.detections.len()).unwrap_or(0))
        })
    });
}

criterion_group!(benches, render);
criterion_main!(benches);
