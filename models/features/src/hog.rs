//! Histograms of oriented gradients (Dalal & Triggs 2005).
//!
//! The computation is scikit-image's `skimage.feature.hog` (so that the two can be
//! compared value for value):
//!
//! * gradients are unnormalised central differences (`I[y+1] − I[y−1]`); the row
//!   derivative is zero on the first and last row, the column derivative on the first
//!   and last column; on colour images each pixel takes the channel with the largest
//!   gradient magnitude (the first one on ties);
//! * orientations are unsigned, in `[0°, 180°)`, split into `bins` equal bins;
//! * a cell's histogram is the mean gradient magnitude per bin over its `cell × cell`
//!   pixels; pixels beyond the last whole cell are ignored;
//! * blocks of `block × block` cells, stride one cell, are L2-Hys normalised
//!   (L2 with ε = 1e-5, clip at 0.2, L2 again); the feature vector is the blocks in
//!   row-major order, each as (cell row, cell column, bin).
//!
//! By default a pixel votes for one orientation bin, as scikit-image does. With
//! [`HogConfig::orientation_interpolation`] its vote is split linearly between the
//! two nearest bin centres (Dalal & Triggs); spatial (trilinear) interpolation
//! between cells is not done.

use crate::error::{Error, Result};

/// HoG settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct HogConfig {
    /// Cell side in pixels.
    pub cell: usize,
    /// Block side in cells.
    pub block: usize,
    /// Orientation bins over 0-180°.
    pub bins: usize,
    /// Split each vote between the two nearest orientation bins.
    pub orientation_interpolation: bool,
}

impl Default for HogConfig {
    fn default() -> Self {
        Self {
            cell: 8,
            block: 2,
            bins: 9,
            orientation_interpolation: false,
        }
    }
}

impl HogConfig {
    /// Cells along a side of `len` pixels.
    pub fn cells(&self, len: usize) -> usize {
        len.checked_div(self.cell).unwrap_or(0)
    }

    /// Length of the feature vector of a `width × height` image (0 when the image
    /// holds less than one block).
    pub fn len(&self, width: usize, height: usize) -> usize {
        let (cx, cy) = (self.cells(width), self.cells(height));
        if self.block == 0 || cx < self.block || cy < self.block {
            return 0;
        }
        (cx - self.block + 1) * (cy - self.block + 1) * self.block * self.block * self.bins
    }

    /// Check the settings for a `size × size` window.
    pub fn validate(&self, size: usize) -> Result<()> {
        let bad = |name: &'static str, reason: String| Err(Error::Param { name, reason });
        if self.cell == 0 {
            return bad("cell", "must be at least 1 pixel".into());
        }
        if self.block == 0 {
            return bad("block", "must be at least 1 cell".into());
        }
        if !(2..=64).contains(&self.bins) {
            return bad("bins", format!("{} is not in 2..=64", self.bins));
        }
        if self.len(size, size) == 0 {
            return bad(
                "block",
                format!(
                    "a {size}×{size} window holds no {0}×{0}-cell block of {1}-pixel cells",
                    self.block, self.cell
                ),
            );
        }
        Ok(())
    }
}

/// Reusable buffers for [`hog_into`].
#[derive(Clone, Debug, Default)]
pub struct HogScratch {
    hist: Vec<f32>,
    gr: Vec<f32>,
    gc: Vec<f32>,
}

/// HoG features of an interleaved image with `channels` channels (1 or 3; values on
/// any scale, e.g. `0..=255`), written to `out` (cleared first).
pub fn hog(img: &[f32], width: usize, height: usize, channels: usize, cfg: &HogConfig) -> Vec<f32> {
    let mut out = Vec::new();
    hog_into(
        img,
        width,
        height,
        channels,
        cfg,
        &mut HogScratch::default(),
        &mut out,
    );
    out
}

/// [`hog`] with caller-provided buffers. An image too small for one block, or whose
/// slice is shorter than `width * height * channels`, gives an empty vector.
pub fn hog_into(
    img: &[f32],
    width: usize,
    height: usize,
    channels: usize,
    cfg: &HogConfig,
    scratch: &mut HogScratch,
    out: &mut Vec<f32>,
) {
    out.clear();
    let len = cfg.len(width, height);
    let need = width
        .checked_mul(height)
        .and_then(|n| n.checked_mul(channels));
    if len == 0
        || channels == 0
        || need.is_none_or(|n| img.len() < n)
        || !(2..=64).contains(&cfg.bins)
    {
        return;
    }
    let (ncx, ncy) = (cfg.cells(width), cfg.cells(height));
    let bins = cfg.bins;
    let hist = &mut scratch.hist;
    hist.clear();
    hist.resize(ncx * ncy * bins, 0.0);
    let step = 180.0 / bins as f64;
    // Unit vectors of the inner bin boundaries, for binning without atan2.
    let bounds: Vec<(f32, f32)> = (1..bins)
        .map(|k| {
            let t = (k as f64 * step).to_radians();
            (t.cos() as f32, t.sin() as f32)
        })
        .collect();
    let (wmax, hmax) = (ncx * cfg.cell, ncy * cfg.cell);
    let stride = width * channels;
    let rgr = &mut scratch.gr;
    let rgc = &mut scratch.gc;
    rgr.clear();
    rgr.resize(wmax, 0.0);
    rgc.clear();
    rgc.resize(wmax, 0.0);
    // Offset of each column's cell histogram within a row of cells.
    let cell_off: Vec<usize> = (0..wmax).map(|x| x / cfg.cell * bins).collect();
    for y in 0..hmax {
        let cy = y / cfg.cell;
        let row = &img[y * stride..(y + 1) * stride];
        // Each derivative is zero on its own axis' border only (as scikit-image).
        let rows = (y > 0 && y + 1 < height).then(|| {
            (
                &img[(y - 1) * stride..y * stride],
                &img[(y + 1) * stride..(y + 2) * stride],
            )
        });
        match channels {
            1 => gradient_row::<1>(row, rows, width, rgr, rgc),
            3 => gradient_row::<3>(row, rows, width, rgr, rgc),
            _ => gradient_row_dyn(row, rows, width, channels, rgr, rgc),
        }
        let cells = &mut hist[cy * ncx * bins..(cy + 1) * ncx * bins];
        for ((&gr, &gc), &off) in rgr.iter().zip(rgc.iter()).zip(cell_off.iter()) {
            let m2 = gr * gr + gc * gc;
            if m2 <= 0.0 {
                continue;
            }
            let mag = m2.sqrt();
            let cell = &mut cells[off..off + bins];
            if cfg.orientation_interpolation {
                let p = fast_angle(gr, gc) * (bins as f32 / std::f32::consts::PI) - 0.5;
                let k0 = p.floor();
                let f = p - k0;
                let k0 = if k0 < 0.0 {
                    bins - 1
                } else {
                    (k0 as usize).min(bins - 1)
                };
                cell[k0] += mag * (1.0 - f);
                cell[(k0 + 1) % bins] += mag * f;
            } else {
                cell[hard_bin(gr, gc, step, &bounds)] += mag;
            }
        }
    }
    let area = (cfg.cell * cfg.cell) as f32;
    hist.iter_mut().for_each(|v| *v /= area);
    // Blocks.
    let b = cfg.block;
    let (nbx, nby) = (ncx - b + 1, ncy - b + 1);
    let blen = b * b * bins;
    out.reserve(len);
    const EPS2: f32 = 1e-10;
    for by in 0..nby {
        for bx in 0..nbx {
            let start = out.len();
            for cy in by..by + b {
                out.extend_from_slice(&hist[(cy * ncx + bx) * bins..(cy * ncx + bx + b) * bins]);
            }
            let blk = &mut out[start..start + blen];
            let n = (blk.iter().map(|v| v * v).sum::<f32>() + EPS2).sqrt();
            blk.iter_mut().for_each(|v| *v = (*v / n).min(0.2));
            let n = (blk.iter().map(|v| v * v).sum::<f32>() + EPS2).sqrt();
            blk.iter_mut().for_each(|v| *v /= n);
        }
    }
}

/// Rows above and below the current one, when the row derivative is defined.
type Neighbours<'a> = Option<(&'a [f32], &'a [f32])>;

/// One row's gradient (strongest of `C` channels) into `gr`, `gc` (their length is the
/// number of columns to compute).
fn gradient_row<const C: usize>(
    row: &[f32],
    rows: Neighbours<'_>,
    width: usize,
    gr: &mut [f32],
    gc: &mut [f32],
) {
    for x in 0..gr.len() {
        let mut r = [0.0f32; C];
        let mut c = [0.0f32; C];
        if let Some((up, down)) = rows {
            let (u, d) = (&up[x * C..x * C + C], &down[x * C..x * C + C]);
            for ch in 0..C {
                r[ch] = d[ch] - u[ch];
            }
        }
        if x > 0 && x + 1 < width {
            let (l, rt) = (&row[(x - 1) * C..x * C], &row[(x + 1) * C..(x + 2) * C]);
            for ch in 0..C {
                c[ch] = rt[ch] - l[ch];
            }
        }
        let (mut br, mut bc, mut m2) = (r[0], c[0], r[0] * r[0] + c[0] * c[0]);
        for ch in 1..C {
            let m = r[ch] * r[ch] + c[ch] * c[ch];
            // Branch-free select: which channel wins is unpredictable.
            let better = m > m2;
            br = if better { r[ch] } else { br };
            bc = if better { c[ch] } else { bc };
            m2 = if better { m } else { m2 };
        }
        gr[x] = br;
        gc[x] = bc;
    }
}

/// [`gradient_row`] for any channel count.
fn gradient_row_dyn(
    row: &[f32],
    rows: Neighbours<'_>,
    width: usize,
    channels: usize,
    gr: &mut [f32],
    gc: &mut [f32],
) {
    for x in 0..gr.len() {
        let col_in = x > 0 && x + 1 < width;
        let (mut br, mut bc, mut m2) = (0.0f32, 0.0f32, -1.0f32);
        for ch in 0..channels {
            let r = rows.map_or(0.0, |(up, down)| {
                down[x * channels + ch] - up[x * channels + ch]
            });
            let c = if col_in {
                row[(x + 1) * channels + ch] - row[(x - 1) * channels + ch]
            } else {
                0.0
            };
            let m = r * r + c * c;
            if m > m2 {
                (br, bc, m2) = (r, c, m);
            }
        }
        gr[x] = br;
        gc[x] = bc;
    }
}

/// The orientation bin of gradient `(row, col)`, exactly as scikit-image assigns it
/// (`floor(deg(atan2(row, col)) mod 180 / step)`): the count of bin boundaries whose
/// cross product with the gradient is positive, falling back to `atan2` in `f64` (what
/// scikit-image computes) next to a boundary.
fn hard_bin(gr: f32, gc: f32, step: f64, bounds: &[(f32, f32)]) -> usize {
    // Fold into the upper half plane: angle in [0°, 180°).
    let flip = gr < 0.0 || (gr == 0.0 && gc < 0.0);
    let (y, x) = if flip { (-gr, -gc) } else { (gr, gc) };
    // Count the boundaries at or below the angle, without branches; remember how
    // close the nearest boundary is.
    let mut bin = 0usize;
    let mut nearest = f32::INFINITY;
    for &(c, s) in bounds {
        let cross = y * c - x * s; // >= 0 when the angle >= the boundary
        bin += usize::from(cross > 0.0);
        nearest = nearest.min(cross.abs());
    }
    if nearest <= (x.abs() + y.abs()) * 1e-5 {
        return exact_bin(gr as f64, gc as f64, step, bounds.len() + 1);
    }
    bin
}

/// The unsigned orientation of gradient `(row, col)` in `[0, π)`, to about 1e-5 rad
/// (a minimax polynomial for atan on `[0, 1]`).
fn fast_angle(gr: f32, gc: f32) -> f32 {
    let (y, x) = if gr < 0.0 || (gr == 0.0 && gc < 0.0) {
        (-gr, -gc)
    } else {
        (gr, gc)
    };
    let (ax, ay) = (x.abs(), y);
    let (num, den) = if ax >= ay { (ay, ax) } else { (ax, ay) };
    if den == 0.0 {
        return 0.0;
    }
    let z = num / den;
    let z2 = z * z;
    let mut a = z
        * (0.999_977_26
            + z2 * (-0.332_623_47
                + z2 * (0.193_543_46
                    + z2 * (-0.116_432_87 + z2 * (0.052_653_32 + z2 * -0.011_721_2)))));
    if ay > ax {
        a = std::f32::consts::FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = std::f32::consts::PI - a;
    }
    if a >= std::f32::consts::PI { 0.0 } else { a }
}

/// scikit-image's bin test, via the same `atan2` and degree conversion.
fn exact_bin(gr: f64, gc: f64, step: f64, bins: usize) -> usize {
    let deg = gr.atan2(gc).to_degrees().rem_euclid(180.0);
    let mut k = ((deg / step) as usize).min(bins - 1);
    while k + 1 < bins && deg >= step * (k + 1) as f64 {
        k += 1;
    }
    while k > 0 && deg < step * k as f64 {
        k -= 1;
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed_single_cell() {
        // 4×4 grey image, one 4-pixel cell, one block, 4 bins of 45°.
        // Columns 0,1 = 0; columns 2,3 = 10: the column derivative is 10 at columns
        // 1 and 2 of every row (the row derivative is 0 everywhere).
        #[rustfmt::skip]
        let img = [
            0.0, 0.0, 10.0, 10.0,
            0.0, 0.0, 10.0, 10.0,
            0.0, 0.0, 10.0, 10.0,
            0.0, 0.0, 10.0, 10.0f32,
        ];
        let cfg = HogConfig {
            cell: 4,
            block: 1,
            bins: 4,
            orientation_interpolation: false,
        };
        let f = hog(&img, 4, 4, 1, &cfg);
        // Histogram: bin 0 gets 8 × 10 / 16 = 5; L2 → [1, 0, 0, 0]; clip 0.2 → [0.2,
        // 0, 0, 0]; L2 again → [1, 0, 0, 0] (up to ε).
        assert_eq!(f.len(), 4);
        assert!(
            (f[0] - 1.0).abs() < 1e-6 && f[1..].iter().all(|&v| v == 0.0),
            "{f:?}"
        );

        // A diagonal ramp I = x + y. Interior pixels: gradient (row 2, col 2), 45°,
        // magnitude √8, bin 1 (45° is a bin boundary, counted upwards). Pixels on the
        // top/bottom rows (not corners) have only a column derivative: 0°, magnitude
        // 2, bin 0; on the left/right columns only a row derivative: 90°, bin 2.
        // Histogram × 16: [4·2, 4·√8, 4·2, 0] = [8, 8√2, 8, 0]; L2 → [0.5, 0.707,
        // 0.5, 0]; clip → [0.2, 0.2, 0.2, 0]; L2 → 1/√3 each.
        let img: Vec<f32> = (0..16).map(|i| ((i % 4) + (i / 4)) as f32).collect();
        let f = hog(&img, 4, 4, 1, &cfg);
        let third = 1.0 / 3.0f32.sqrt();
        for (got, want) in f.iter().zip([third, third, third, 0.0]) {
            assert!((got - want).abs() < 1e-5, "{f:?}");
        }
        // 2-pixel cells, 9 bins of 20°: by symmetry every cell holds one corner (0),
        // one 0° pixel (bin 0, magnitude 2), one 90° pixel (bin 4, magnitude 2) and
        // one 45° pixel (bin 2, magnitude √8). The block's 12 non-zero values all clip
        // to 0.2 and renormalise to 1/√12.
        let cfg = HogConfig {
            cell: 2,
            block: 2,
            bins: 9,
            orientation_interpolation: false,
        };
        let f = hog(&img, 4, 4, 1, &cfg);
        assert_eq!(f.len(), 36);
        let twelfth = 1.0 / 12.0f32.sqrt();
        for (i, v) in f.iter().enumerate() {
            let want = if [0, 2, 4].contains(&(i % 9)) {
                twelfth
            } else {
                0.0
            };
            assert!((v - want).abs() < 1e-5, "feature {i} = {v}");
        }
    }

    #[test]
    fn interpolation_splits_votes_between_neighbouring_bins() {
        // The ramp again, 9 bins of 20° centred at 10°, 30°, …, 170°. Hard binning
        // fills bins 0 (0°), 2 (45°) and 4 (90°). With interpolation 45° splits
        // between bins 1 and 2 (¼, ¾), 0° between bins 8 and 0 (wrapping, ½ each),
        // 90° sits on bin 4's centre.
        let img: Vec<f32> = (0..16).map(|i| ((i % 4) + (i / 4)) as f32).collect();
        let nonzero = |interp| {
            let cfg = HogConfig {
                cell: 4,
                block: 1,
                bins: 9,
                orientation_interpolation: interp,
            };
            let f = hog(&img, 4, 4, 1, &cfg);
            (0..9).filter(|&k| f[k] > 0.0).collect::<Vec<_>>()
        };
        assert_eq!(nonzero(false), vec![0, 2, 4]);
        assert_eq!(nonzero(true), vec![0, 1, 2, 4, 8]);
    }

    #[test]
    fn colour_takes_the_strongest_channel() {
        // Red = x (column derivative 2), blue = 10·y (row derivative 20). Interior
        // and left/right-column pixels take blue: 90°, magnitude 20 (8 pixels).
        // Top/bottom-row pixels have no row derivative and take red: 0°, magnitude 2
        // (4 pixels). × 16: [8, 0, 160, 0] → L2 → [a, 0, b, 0] with a = 8 / √(8² +
        // 160²) → clip b to 0.2 → L2.
        let mut img = vec![0.0f32; 4 * 4 * 3];
        for y in 0..4 {
            for x in 0..4 {
                img[(y * 4 + x) * 3] = x as f32;
                img[(y * 4 + x) * 3 + 2] = 10.0 * y as f32;
            }
        }
        let cfg = HogConfig {
            cell: 4,
            block: 1,
            bins: 4,
            orientation_interpolation: false,
        };
        let f = hog(&img, 4, 4, 3, &cfg);
        let a = 8.0 / (8.0f32 * 8.0 + 160.0 * 160.0).sqrt();
        let n = (a * a + 0.2 * 0.2).sqrt();
        for (got, want) in f.iter().zip([a / n, 0.0, 0.2 / n, 0.0]) {
            assert!((got - want).abs() < 1e-4, "{f:?}");
        }
    }

    #[test]
    fn hard_bins_agree_with_atan2_bins() {
        let step = 20.0;
        let bounds: Vec<(f32, f32)> = (1..9)
            .map(|k| {
                let t = (k as f64 * step).to_radians();
                (t.cos() as f32, t.sin() as f32)
            })
            .collect();
        for gr in -12..=12 {
            for gc in -12..=12 {
                let (gr, gc) = (gr as f32 * 0.7, gc as f32 * 1.3);
                assert_eq!(
                    hard_bin(gr, gc, step, &bounds),
                    exact_bin(gr as f64, gc as f64, step, 9),
                    "({gr}, {gc})"
                );
            }
        }
    }

    #[test]
    fn fast_angle_is_close_to_atan2() {
        for k in 0..720 {
            let t = k as f32 * 0.5f32.to_radians() - std::f32::consts::PI;
            let (gr, gc) = (3.0 * t.sin(), 3.0 * t.cos());
            let want = (gr as f64)
                .atan2(gc as f64)
                .rem_euclid(std::f64::consts::PI);
            let got = fast_angle(gr, gc) as f64;
            let d = (got - want).abs();
            assert!(
                d.min(std::f64::consts::PI - d) < 1e-4,
                "angle {t}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn too_small_or_short_inputs_give_empty_features() {
        let cfg = HogConfig::default();
        assert!(hog(&[], 0, 0, 3, &cfg).is_empty());
        assert!(hog(&[1.0; 3], 1, 1, 3, &cfg).is_empty());
        assert!(hog(&[1.0; 10], 16, 16, 3, &cfg).is_empty());
        assert_eq!(hog(&vec![0.0; 16 * 16 * 3], 16, 16, 3, &cfg).len(), 36);
        assert!(cfg.validate(8).is_err());
        assert!(cfg.validate(48).is_ok());
    }
}
