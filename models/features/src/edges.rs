//! Edge magnitude and orientation for EdgeBoxes.
//!
//! Zitnick & Dollár's EdgeBoxes runs on structured-forest edges; we have no trained
//! forest, so this module computes gradient edges instead, thinned by non-maximum
//! suppression along the gradient (as Canny does):
//!
//! 1. each RGB channel is smoothed with the separable `[1 2 1] / 4` kernel;
//! 2. central differences give a gradient per channel; per pixel the channel with the
//!    largest gradient wins (coloured signs on a grey background keep their edges);
//! 3. the magnitude is scaled by [`EdgeConfig::gain`] and clipped to `[0, 1]`, the
//!    range of structured-forest edge probabilities that EdgeBoxes' thresholds assume;
//! 4. a pixel survives only when its magnitude is not smaller than the magnitudes
//!    interpolated one pixel away on both sides along the gradient.
//!
//! The orientation stored is the edge (tangent) direction in `[0, π)`, perpendicular
//! to the gradient.

use crate::frame::Rgb;

/// Settings of the gradient edge detector.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EdgeConfig {
    /// Multiplier from the gradient of `[0, 1]` intensities to edge strength.
    pub gain: f32,
}

impl Default for EdgeConfig {
    fn default() -> Self {
        Self { gain: 4.0 }
    }
}

/// A thinned edge map: strength in `[0, 1]` and tangent orientation in `[0, π)`.
#[derive(Clone, Debug, Default)]
pub struct EdgeMap {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Edge strength per pixel, row-major; 0 where suppressed.
    pub mag: Vec<f32>,
    /// Edge tangent orientation per pixel, row-major, in `[0, π)`.
    pub orient: Vec<f32>,
}

/// Compute the thinned edge map of an RGB image.
pub fn edge_map(img: &Rgb<'_>, cfg: &EdgeConfig) -> EdgeMap {
    let (w, h) = (img.width, img.height);
    let n = w * h;
    let mut out = EdgeMap {
        width: w,
        height: h,
        mag: vec![0.0; n],
        orient: vec![0.0; n],
    };
    if w < 3 || h < 3 {
        return out;
    }
    // Smoothed channels, planar.
    let mut smooth = vec![0.0f32; 3 * n];
    let mut tmp = vec![0.0f32; n];
    for ch in 0..3 {
        for y in 0..h {
            let row = &img.data[y * w * 3..(y + 1) * w * 3];
            for x in 0..w {
                let l = row[x.saturating_sub(1) * 3 + ch] as f32;
                let c = row[x * 3 + ch] as f32;
                let r = row[(x + 1).min(w - 1) * 3 + ch] as f32;
                tmp[y * w + x] = (l + 2.0 * c + r) * (0.25 / 255.0);
            }
        }
        let plane = &mut smooth[ch * n..(ch + 1) * n];
        for y in 0..h {
            let up = y.saturating_sub(1) * w;
            let dn = (y + 1).min(h - 1) * w;
            for x in 0..w {
                plane[y * w + x] = 0.25 * (tmp[up + x] + 2.0 * tmp[y * w + x] + tmp[dn + x]);
            }
        }
    }
    // Gradient, strongest channel.
    let mut gx = vec![0.0f32; n];
    let mut gy = vec![0.0f32; n];
    let mut mag = vec![0.0f32; n];
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let i = y * w + x;
            let mut best = (0.0f32, 0.0f32, -1.0f32);
            for ch in 0..3 {
                let p = &smooth[ch * n..(ch + 1) * n];
                let dx = 0.5 * (p[i + 1] - p[i - 1]);
                let dy = 0.5 * (p[i + w] - p[i - w]);
                let m = dx * dx + dy * dy;
                if m > best.2 {
                    best = (dx, dy, m);
                }
            }
            gx[i] = best.0;
            gy[i] = best.1;
            mag[i] = (best.2.sqrt() * cfg.gain).min(1.0);
        }
    }
    // Non-maximum suppression along the gradient.
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let i = y * w + x;
            let m = mag[i];
            if m <= 0.0 {
                continue;
            }
            let norm = (gx[i] * gx[i] + gy[i] * gy[i]).sqrt();
            let (ux, uy) = (gx[i] / norm, gy[i] / norm);
            let a = bilinear(&mag, w, h, x as f32 + ux, y as f32 + uy);
            let b = bilinear(&mag, w, h, x as f32 - ux, y as f32 - uy);
            // Ties go to the pixel on the positive side, so a symmetric step keeps a
            // one-pixel-wide edge.
            if m < a || m <= b {
                continue;
            }
            out.mag[i] = m;
            let t = gy[i].atan2(gx[i]) + std::f32::consts::FRAC_PI_2;
            out.orient[i] = t.rem_euclid(std::f32::consts::PI);
        }
    }
    out
}

/// Bilinear sample of a single-channel image, clamped at the borders.
fn bilinear(img: &[f32], w: usize, h: usize, x: f32, y: f32) -> f32 {
    let x = x.clamp(0.0, (w - 1) as f32);
    let y = y.clamp(0.0, (h - 1) as f32);
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let top = img[y0 * w + x0] * (1.0 - fx) + img[y0 * w + x1] * fx;
    let bot = img[y1 * w + x0] * (1.0 - fx) + img[y1 * w + x1] * fx;
    top * (1.0 - fy) + bot * fy
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_vertical_step_gives_a_thin_vertical_edge() {
        let (w, h) = (20usize, 10usize);
        let mut px = vec![0u8; w * h * 3];
        for y in 0..h {
            for x in 10..w {
                px[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[200, 200, 200]);
            }
        }
        let img = Rgb::new(w, h, &px).unwrap();
        let e = edge_map(&img, &EdgeConfig::default());
        let row = &e.mag[5 * w..6 * w];
        let on: Vec<usize> = (0..w).filter(|&x| row[x] > 0.0).collect();
        assert!(on.len() == 1, "edge pixels in row: {on:?}");
        assert!(on.iter().all(|&x| (9..=10).contains(&x)));
        // Tangent of a vertical edge is vertical: π/2.
        let o = e.orient[5 * w + on[0]];
        assert!(
            (o - std::f32::consts::FRAC_PI_2).abs() < 1e-3,
            "orientation {o}"
        );
    }

    #[test]
    fn blank_and_tiny_images_have_no_edges() {
        for (w, h) in [(0usize, 0usize), (1, 1), (2, 5), (30, 30)] {
            let px = vec![77u8; w * h * 3];
            let e = edge_map(&Rgb::new(w, h, &px).unwrap(), &EdgeConfig::default());
            assert_eq!(e.mag.len(), w * h);
            assert!(e.mag.iter().all(|&m| m == 0.0));
        }
    }
}
