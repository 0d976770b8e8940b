//! The full on-drone loop, as a companion computer would run it: a policy bundle, its
//! ONNX variants through ONNX Runtime, the controller and the KLT trackers, over a
//! folder of video frames (PNG, in name order).
//!
//! ```text
//! cargo run --release -p frugal-runtime --features onnx --example drone_loop -- \
//!     runs/default/bundle frames_dir [--threads 1]
//! ```
//!
//! The bundle folder is what `frugal bundle write` makes: `policy.frpb` plus the
//! variants' ONNX graphs under `onnx/<variant>/`. Prints one line per frame (decision,
//! variant, best box) and a summary: detections per variant, mean compute per frame.
use frugal_runtime::onnx::OrtDetector;
use frugal_runtime::pilot::Pilot;
use frugal_runtime::track::Pyramid;
use frugal_runtime::{Bundle, Decision, FrameRef};
use std::path::{Path, PathBuf};
use std::time::Instant;

type Error = Box<dyn std::error::Error>;

fn main() -> Result<(), Error> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(bundle_dir), Some(frames_dir)) = (args.first(), args.get(1)) else {
        return Err("usage: drone_loop BUNDLE_DIR FRAMES_DIR [--threads N]".into());
    };
    let threads = match args.iter().position(|a| a == "--threads") {
        Some(i) => args.get(i + 1).ok_or("--threads needs a number")?.parse()?,
        None => 1,
    };
    let bundle_dir = Path::new(bundle_dir);
    let bundle_path = bundle_dir.join("policy.frpb");
    let bytes =
        std::fs::read(&bundle_path).map_err(|e| format!("{}: {e}", bundle_path.display()))?;
    let bundle = Bundle::parse(&bytes).map_err(|e| format!("{}: {e}", bundle_path.display()))?;

    // Each ONNX variant opened once, lazily, from the folder of its primary graph.
    let mut detectors: Vec<Option<OrtDetector>> =
        (0..bundle.variant_count()).map(|_| None).collect();
    let mut frames: Vec<PathBuf> = std::fs::read_dir(frames_dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .collect();
    frames.sort();
    if frames.is_empty() {
        return Err(format!("{frames_dir}: no PNG frames").into());
    }

    let mut pilot: Pilot<'_, 4, 64> = Pilot::new(bundle);
    let (mut prev_buf, mut cur_buf) = (Vec::new(), Vec::new());
    let mut size = (0usize, 0usize);
    let mut per_variant = vec![0u32; bundle.variant_count()];
    let mut tracked = 0u32;
    let mut compute_ms = 0.0;
    for (t, path) in frames.iter().enumerate() {
        let img = image::open(path)
            .map_err(|e| format!("{}: {e}", path.display()))?
            .into_rgb8();
        let (w, h) = (img.width() as usize, img.height() as usize);
        let start = Instant::now();
        if (w, h) != size {
            // first frame, or a new size: fresh buffers, no previous pyramid
            let need = Pyramid::required_len(w, h, 3).ok_or("frame too small")?;
            (prev_buf, cur_buf) = (vec![0; need], vec![0; need]);
            size = (w, h);
        }
        let frame = FrameRef::new(w as u32, h as u32, img.as_raw()).ok_or("bad frame")?;
        let mut cur = Pyramid::new(&mut cur_buf, w, h, 3)?;
        cur.build_rgb(&frame)?;
        let prev = if t > 0 {
            Some(Pyramid::new(&mut prev_buf, w, h, 3)?)
        } else {
            None
        };
        let decision = pilot.decide(t as u32, prev.as_ref(), &cur);
        let line = match decision {
            Decision::Detect { variant, reason } => {
                // the first variant, then any the policy asks for on the same frame
                let mut run = Vec::new();
                let (_, found) = pilot.detect_with(&cur, variant, |variant| {
                    let v = usize::from(variant);
                    let info = bundle
                        .variant(variant)
                        .ok_or("policy names a missing variant")?;
                    let slot = detectors.get_mut(v).ok_or("variant out of range")?;
                    if slot.is_none() {
                        let graph = bundle_dir.join(info.onnx_file);
                        let dir = graph.parent().ok_or("variant without an ONNX folder")?;
                        *slot = Some(OrtDetector::open(dir, threads)?);
                    }
                    let det = slot.as_mut().ok_or("detector not opened")?;
                    if let Some(n) = per_variant.get_mut(v) {
                        *n += 1;
                    }
                    run.push(info.name);
                    det.detect(frame)
                        .map_err(Box::<dyn std::error::Error>::from)
                })?;
                let best = found.first().map_or("nothing".to_string(), |d| {
                    format!(
                        "class {} score {:.3} box {:.0?}",
                        d.class,
                        d.score,
                        [d.bbox.x1, d.bbox.y1, d.bbox.x2, d.bbox.y2]
                    )
                });
                format!("detect  {:<20} ({reason:?}) {best}", run.join(" → "))
            }
            Decision::Track => {
                tracked += 1;
                let boxes: Vec<String> = pilot
                    .tracked()
                    .map(|d| {
                        format!(
                            "{}:{:.0?}",
                            d.class,
                            [d.bbox.x1, d.bbox.y1, d.bbox.x2, d.bbox.y2]
                        )
                    })
                    .collect();
                format!("track   {}", boxes.join(" "))
            }
        };
        let ms = start.elapsed().as_secs_f64() * 1e3;
        compute_ms += ms;
        println!("{t:>5} {ms:>7.2} ms  {line}");
        std::mem::swap(&mut prev_buf, &mut cur_buf);
    }
    let n = frames.len() as f64;
    println!(
        "\n{} frames, {:.2} ms compute per frame ({:.1} fps)",
        frames.len(),
        compute_ms / n,
        1e3 * n / compute_ms
    );
    for (v, count) in per_variant.iter().enumerate() {
        if let Some(info) = bundle.variant(v as u16) {
            println!("  {:<24} {count:>5} detections", info.name);
        }
    }
    let stats = pilot.stats();
    println!(
        "  {} frames tracked, {} policy queries",
        tracked, stats.queries
    );
    Ok(())
}
