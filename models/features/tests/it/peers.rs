//! Parity of frugal-features' HoG with scikit-image's `skimage.feature.hog`, run
//! through the Python interpreter in `FRUGAL_PYTHON` (set by `.cargo/config.toml`).

use frugal_features::hog::{HogConfig, hog};
use std::path::PathBuf;
use std::process::Command;

/// Deterministic test windows: shapes, gradients and noise, like sign crops.
pub fn test_windows(n: usize, size: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(n * size * size * 3);
    let mut s: u64 = 0x1234_5678;
    let mut rnd = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    for k in 0..n {
        let (cx, cy) = ((rnd() % size as u64) as f32, (rnd() % size as u64) as f32);
        let r = 6.0 + (rnd() % 16) as f32;
        let base = [
            (rnd() % 256) as f32,
            (rnd() % 256) as f32,
            (rnd() % 256) as f32,
        ];
        let fg = [
            (rnd() % 256) as f32,
            (rnd() % 256) as f32,
            (rnd() % 256) as f32,
        ];
        for y in 0..size {
            for x in 0..size {
                let (dx, dy) = (x as f32 - cx, y as f32 - cy);
                let inside = if k % 2 == 0 {
                    dx * dx + dy * dy < r * r
                } else {
                    dx.abs() + dy.abs() < r
                };
                for c in 0..3 {
                    let v = if inside {
                        fg[c]
                    } else {
                        base[c] + (x + 2 * y) as f32 * 0.7
                    };
                    let noise = (rnd() % 9) as f32 - 4.0;
                    out.push((v + noise).clamp(0.0, 255.0) as u8);
                }
            }
        }
    }
    out
}

fn python() -> PathBuf {
    let p = std::env::var_os("FRUGAL_PYTHON")
        .expect("FRUGAL_PYTHON is not set: run through cargo (see .cargo/config.toml) after `cargo xtask setup`");
    PathBuf::from(p)
}

fn peer_features(px: &[u8], n: usize, size: usize, cfg: &HogConfig) -> Vec<f64> {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("windows.u8");
    let output = dir.path().join("features.f64");
    std::fs::write(&input, px).unwrap();
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/peers/hog_peer.py");
    let status = Command::new(python())
        .arg(script)
        .arg("features")
        .arg(&input)
        .args([n, size, cfg.cell, cfg.block, cfg.bins].map(|v| v.to_string()))
        .arg(&output)
        .status()
        .expect("cannot start the Python peer");
    assert!(status.success(), "hog_peer.py failed: {status}");
    std::fs::read(&output)
        .unwrap()
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

fn ours(px: &[u8], n: usize, size: usize, cfg: &HogConfig) -> Vec<f32> {
    px.chunks_exact(size * size * 3)
        .take(n)
        .flat_map(|w| {
            let f: Vec<f32> = w.iter().map(|&v| v as f32).collect();
            hog(&f, size, size, 3, cfg)
        })
        .collect()
}

fn correlation(a: &[f32], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let ma = a.iter().map(|&v| v as f64).sum::<f64>() / n;
    let mb = b.iter().sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (&x, &y) in a.iter().zip(b) {
        let (x, y) = (x as f64 - ma, y - mb);
        sab += x * y;
        saa += x * x;
        sbb += y * y;
    }
    sab / (saa * sbb).sqrt()
}

#[test]
fn hog_equals_scikit_image() {
    let (n, size) = (24, 48);
    let px = test_windows(n, size);
    for (cell, block, bins) in [(8, 2, 9), (6, 2, 6), (12, 1, 9), (4, 3, 12), (5, 2, 9)] {
        let cfg = HogConfig {
            cell,
            block,
            bins,
            orientation_interpolation: false,
        };
        let a = ours(&px, n, size, &cfg);
        let b = peer_features(&px, n, size, &cfg);
        assert_eq!(a.len(), b.len(), "feature count for {cfg:?}");
        let max = a
            .iter()
            .zip(&b)
            .map(|(&x, &y)| (x as f64 - y).abs())
            .fold(0.0, f64::max);
        println!(
            "cell {cell} block {block} bins {bins}: {} features, max |diff| {max:.2e}",
            a.len()
        );
        assert!(max < 1e-5, "max abs difference {max} for {cfg:?}");

        // Soft orientation binning is a different (documented) choice: close, not equal.
        let soft = ours(
            &px,
            n,
            size,
            &HogConfig {
                orientation_interpolation: true,
                ..cfg
            },
        );
        let r = correlation(&soft, &b);
        println!("  with orientation interpolation: correlation {r:.4}");
        assert!(r > 0.7, "correlation {r} for {cfg:?}");
    }
}
