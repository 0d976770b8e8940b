//! Proposal recall of frugal-features' EdgeBoxes box search against OpenCV contrib's
//! (`cv2.ximgproc.createEdgeBoxes`, through `FRUGAL_PYTHON`) on the SAME edge maps
//! (ours: gradient edges thinned by NMS; OpenCV gets the edge strength and the edge
//! normal orientation, its structured-edge convention). Prints a table.
//!
//! `cargo run --release -p frugal-features --example edgeboxes_vs_opencv -- DATA_DIR [STRIDE]`

use frugal_data::Split;
use frugal_features::data::load_frames;
use frugal_features::edgeboxes::{EdgeBoxesConfig, proposals_from_edges, recall_at};
use frugal_features::edges::edge_map;
use frugal_runtime::BBox;
use std::process::Command;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let data = args
        .first()
        .ok_or("usage: edgeboxes_vs_opencv DATA_DIR [STRIDE]")?;
    let stride: usize = args.get(1).map_or(Ok(8), |s| s.parse())?;
    let ds = frugal_data::Dataset::load(data.as_ref())?;
    let frames = load_frames(&ds, Split::Test, stride, usize::MAX)?;
    let python = std::env::var("FRUGAL_PYTHON")
        .map_err(|_| "FRUGAL_PYTHON is not set (run through cargo)")?;
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/peers/edgeboxes_peer.py");
    let dir = tempfile::tempdir()?;
    let counts = [200, 500, 1000, 2000];
    let reference = EdgeBoxesConfig {
        alpha: 0.65,
        max_aspect_ratio: 3.0,
        refine_limit: usize::MAX,
        ..EdgeBoxesConfig::default()
    };
    let settings = [
        ("ours (defaults)", EdgeBoxesConfig::default()),
        ("reference settings", reference),
    ];
    let (w, h) = (frames[0].width, frames[0].height);
    let mut edges = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        let e = edge_map(&f.view()?, &EdgeBoxesConfig::default().edges);
        let le = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        let normal: Vec<f32> = e
            .orient
            .iter()
            .map(|t| (t + std::f32::consts::FRAC_PI_2).rem_euclid(std::f32::consts::PI))
            .collect();
        std::fs::write(dir.path().join(format!("e_{i}.f32")), le(&e.mag))?;
        std::fs::write(dir.path().join(format!("o_{i}.f32")), le(&normal))?;
        edges.push(e);
    }
    let signs: usize = frames.iter().map(|f| f.objects.len()).sum();
    println!(
        "Box search on identical edge maps: {} test frames (every {stride}th), {signs} signs, IoU 0.5",
        frames.len()
    );
    println!(
        "| implementation | settings | recall@200 | @500 | @1000 | @2000 | box search ms/frame (1 thread) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (name, cfg) in settings {
        let mut hits = [0usize; 4];
        let t = Instant::now();
        for (f, e) in frames.iter().zip(&edges) {
            let boxes: Vec<BBox> = proposals_from_edges(e, &cfg, 2000)
                .iter()
                .map(|p| p.bbox)
                .collect();
            let truth: Vec<BBox> = f.objects.iter().map(|o| o.1).collect();
            for (h, r) in hits.iter_mut().zip(recall_at(&boxes, &truth, &counts, 0.5)) {
                *h += r.0;
            }
        }
        let ms = t.elapsed().as_secs_f64() * 1e3 / frames.len() as f64;
        let r: Vec<String> = hits
            .iter()
            .map(|h| format!("{:.3}", *h as f64 / signs as f64))
            .collect();
        println!("| frugal | {name} | {} | {ms:.1} |", r.join(" | "));

        let out = Command::new(&python)
            .arg(script)
            .arg(dir.path())
            .args([frames.len(), w, h].map(|v| v.to_string()))
            .args(
                [cfg.alpha, cfg.beta, cfg.min_box_area, cfg.max_aspect_ratio]
                    .map(|v| v.to_string()),
            )
            .arg("2000")
            .output()?;
        if !out.status.success() {
            return Err(format!(
                "edgeboxes_peer.py failed: {}",
                String::from_utf8_lossy(&out.stderr)
            )
            .into());
        }
        let secs: f64 = String::from_utf8(out.stdout)?
            .lines()
            .find_map(|l| l.strip_prefix("seconds")?.trim().parse().ok())
            .ok_or("no timing from the peer")?;
        let mut hits = [0usize; 4];
        for (i, f) in frames.iter().enumerate() {
            let raw = std::fs::read(dir.path().join(format!("b_{i}.i32")))?;
            let v: Vec<i32> = raw
                .chunks_exact(4)
                .map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            let boxes: Vec<BBox> = v
                .chunks_exact(4)
                .map(|b| BBox::from_xywh(b[0] as f32, b[1] as f32, b[2] as f32, b[3] as f32))
                .collect();
            let truth: Vec<BBox> = f.objects.iter().map(|o| o.1).collect();
            for (h, r) in hits.iter_mut().zip(recall_at(&boxes, &truth, &counts, 0.5)) {
                *h += r.0;
            }
        }
        let r: Vec<String> = hits
            .iter()
            .map(|h| format!("{:.3}", *h as f64 / signs as f64))
            .collect();
        println!(
            "| OpenCV | {name} | {} | {:.1} |",
            r.join(" | "),
            secs * 1e3
        );
    }
    Ok(())
}
