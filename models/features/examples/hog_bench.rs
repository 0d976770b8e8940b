//! Time per window of frugal-features' HoG against scikit-image's `hog` and OpenCV's
//! `HOGDescriptor` (through the Python interpreter in `FRUGAL_PYTHON`), one thread
//! each, on the same deterministic 48×48 RGB windows. Prints a table.
//!
//! `cargo run --release -p frugal-features --example hog_bench`

use frugal_features::hog::{HogConfig, HogScratch, hog_into};
use std::process::Command;
use std::time::Instant;

fn windows(n: usize, size: usize) -> Vec<u8> {
    let mut s: u64 = 0x9e37_79b9;
    (0..n * size * size * 3)
        .map(|i| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let p = i / 3 % (size * size);
            let (x, y) = (p % size, p / size);
            let blob = if (x as i32 - 24).pow(2) + (y as i32 - 20).pow(2) < 150 {
                180
            } else {
                40
            };
            (blob + (s % 32) as i32) as u8
        })
        .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (n, size) = (64, 48);
    let px = windows(n, size);
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("windows.u8");
    std::fs::write(&path, &px)?;
    let python = std::env::var("FRUGAL_PYTHON")
        .map_err(|_| "FRUGAL_PYTHON is not set (run through cargo)")?;
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/peers/hog_peer.py");
    let floats: Vec<Vec<f32>> = px
        .chunks_exact(size * size * 3)
        .map(|w| w.iter().map(|&v| v as f32).collect())
        .collect();
    println!("HoG of a 48×48 RGB window, µs per window (1 thread)");
    println!(
        "| cell | block | bins | features | frugal | frugal+interp | skimage | opencv | skimage/frugal | opencv/frugal |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for (cell, block, bins) in [(8, 2, 9), (6, 2, 9), (12, 1, 9), (12, 2, 6), (4, 2, 9)] {
        let mut cfg = HogConfig {
            cell,
            block,
            bins,
            orientation_interpolation: false,
        };
        let time = |cfg: &HogConfig| {
            let mut scratch = HogScratch::default();
            let mut out = Vec::new();
            let reps = 200;
            let t = Instant::now();
            for _ in 0..reps {
                for w in &floats {
                    hog_into(w, size, size, 3, cfg, &mut scratch, &mut out);
                }
            }
            (
                t.elapsed().as_secs_f64() / (reps * n) as f64 * 1e6,
                out.len(),
            )
        };
        let (ours, len) = time(&cfg);
        cfg.orientation_interpolation = true;
        let (interp, _) = time(&cfg);
        let out = Command::new(&python)
            .arg(script)
            .arg("bench")
            .arg(&path)
            .args([n, size, cell, block, bins].map(|v| v.to_string()))
            .output()?;
        if !out.status.success() {
            return Err(format!(
                "hog_peer.py failed: {}",
                String::from_utf8_lossy(&out.stderr)
            )
            .into());
        }
        let text = String::from_utf8(out.stdout)?;
        let peer = |name: &str| -> f64 {
            text.lines()
                .find_map(|l| l.strip_prefix(name)?.trim().parse::<f64>().ok())
                .map_or(f64::NAN, |s| s * 1e6)
        };
        let (sk, cv) = (peer("skimage"), peer("opencv"));
        println!(
            "| {cell} | {block} | {bins} | {len} | {ours:.1} | {interp:.1} | {sk:.1} | {cv:.1} | {:.1}× | {:.2}× |",
            sk / ours,
            cv / ours
        );
    }
    Ok(())
}
