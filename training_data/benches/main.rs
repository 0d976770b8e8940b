//! Benchmarks of the synthetic data generator: what one video and one frame cost at the
//! default 480×270 size (world drawing, frame compositing with signs, blur, lighting and
//! noise, PNG encoding), and one 64-px sign sprite.
use criterion::{Criterion, criterion_group, criterion_main};
use frugal_data::video::{RenderOptions, Video};
use frugal_data::{Clutter, GenConfig, Light, Sign, SignStyle, Split, VideoPlan, render_sign};
use std::hint::black_box;

fn plan() -> VideoPlan {
    VideoPlan {
        id: 3,
        clutter: Clutter::High,
        light: Light::Low,
        split: Split::Train,
        frames: GenConfig::default().frames_per_video,
        first_frame: 0,
    }
}

fn generator(c: &mut Criterion) {
    let config = GenConfig::default();
    c.bench_function("sign sprite 64px (stop)", |b| {
        b.iter(|| render_sign(black_box(Sign::Stop), 64, &SignStyle::default()))
    });
    c.bench_function("video setup 480x270 (world, high clutter)", |b| {
        b.iter(|| Video::new(&config, &plan(), black_box(7)))
    });
    let video = Video::new(&config, &plan(), 7);
    c.bench_function("frame render 480x270", |b| {
        b.iter(|| video.frame(black_box(30), &RenderOptions::default()))
    });
    let frame = video.frame(30, &RenderOptions::default());
    c.bench_function("frame png encode 480x270", |b| {
        b.iter(|| frugal_data::generate::encode_png(black_box(&frame.rgb), "bench.png".as_ref()))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = generator
}
criterion_main!(benches);
