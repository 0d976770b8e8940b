//! Linear SVM trained by dual coordinate descent (Hsieh et al., ICML 2008; the
//! LIBLINEAR solver for the L2-regularised hinge loss):
//!
//! `min_w ½‖w‖² + Σ_i C_i max(0, 1 − y_i (wᵀx_i + b))`, with the bias learnt as the
//! weight of a constant feature 1 (so it is regularised too, as LIBLINEAR's `-B 1`).
//!
//! Each epoch visits the examples in an order shuffled by a seeded generator, and
//! stops when the projected gradient's spread falls below `tol`, so training is
//! deterministic. Written here rather than taken from a crate: it is ~80 lines, needs
//! nothing but slices, and lets positives and negatives carry different `C`
//! (one-vs-rest sets are very unbalanced); `linfa-svm` would pull in `ndarray` and a
//! kernel-SMO solver this family does not need.

/// A linear classifier `wᵀx + b`.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LinearSvm {
    /// Weights, one per feature.
    pub w: Vec<f32>,
    /// Bias.
    pub b: f32,
}

impl LinearSvm {
    /// The margin `wᵀx + b` (features beyond `w`'s length are ignored).
    pub fn score(&self, x: &[f32]) -> f32 {
        dot(&self.w, x) + self.b
    }
}

/// Solver settings.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SvmConfig {
    /// Penalty `C` of a negative example.
    pub c: f32,
    /// Penalty multiplier of positive examples (`C₊ = c · positive_weight`).
    pub positive_weight: f32,
    /// Stop when `max PG − min PG` over an epoch is below this.
    pub tol: f32,
    /// Epoch limit.
    pub max_epochs: usize,
    /// Seed of the visiting order.
    pub seed: u64,
}

impl Default for SvmConfig {
    fn default() -> Self {
        Self {
            c: 0.1,
            positive_weight: 1.0,
            tol: 0.1,
            max_epochs: 500,
            seed: 0x5eed,
        }
    }
}

fn dot(a: &[f32], b: &[f32]) -> f32 {
    // Four accumulators let the compiler vectorise.
    let mut acc = [0.0f32; 8];
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut ca = a.chunks_exact(8);
    let mut cb = b.chunks_exact(8);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for k in 0..8 {
            acc[k] += x[k] * y[k];
        }
    }
    let tail: f32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    acc.iter().sum::<f32>() + tail
}

/// Train on rows of `x` (each `dim` long, row-major) with labels `y` (true =
/// positive). Returns a zero classifier when there are no examples.
pub fn train(x: &[f32], dim: usize, y: &[bool], cfg: &SvmConfig) -> LinearSvm {
    let n = x.len().checked_div(dim).unwrap_or(0).min(y.len());
    let mut w = vec![0.0f32; dim];
    let mut b = 0.0f32;
    if n == 0 {
        return LinearSvm { w, b };
    }
    let row = |i: usize| &x[i * dim..(i + 1) * dim];
    let qii: Vec<f32> = (0..n).map(|i| dot(row(i), row(i)) + 1.0).collect();
    let cap: Vec<f32> = y
        .iter()
        .take(n)
        .map(|&p| {
            if p {
                cfg.c * cfg.positive_weight
            } else {
                cfg.c
            }
        })
        .collect();
    let sign = |i: usize| if y[i] { 1.0f32 } else { -1.0 };
    let mut alpha = vec![0.0f32; n];
    let mut order: Vec<usize> = (0..n).collect();
    let mut rng = cfg.seed ^ 0x9e37_79b9_7f4a_7c15;
    for _ in 0..cfg.max_epochs {
        // Fisher-Yates with xorshift64*.
        for i in (1..n).rev() {
            rng ^= rng >> 12;
            rng ^= rng << 25;
            rng ^= rng >> 27;
            let r = rng.wrapping_mul(0x2545_f491_4f6c_dd1d);
            order.swap(i, (r % (i as u64 + 1)) as usize);
        }
        let (mut pg_max, mut pg_min) = (f32::NEG_INFINITY, f32::INFINITY);
        for &i in &order {
            let yi = sign(i);
            let g = yi * (dot(&w, row(i)) + b) - 1.0;
            let pg = if alpha[i] <= 0.0 {
                g.min(0.0)
            } else if alpha[i] >= cap[i] {
                g.max(0.0)
            } else {
                g
            };
            pg_max = pg_max.max(pg);
            pg_min = pg_min.min(pg);
            if pg.abs() > 1e-12 {
                let old = alpha[i];
                alpha[i] = (old - g / qii[i]).clamp(0.0, cap[i]);
                let d = (alpha[i] - old) * yi;
                if d != 0.0 {
                    for (wk, xk) in w.iter_mut().zip(row(i)) {
                        *wk += d * xk;
                    }
                    b += d;
                }
            }
        }
        if pg_max - pg_min < cfg.tol {
            break;
        }
    }
    LinearSvm { w, b }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn separates_a_separable_toy_set() {
        // Two clusters in 2-D around (2, 2) and (−2, −1), with a few points each.
        let pos = [[2.0, 2.0], [3.0, 1.5], [2.5, 3.0], [1.5, 2.5]];
        let neg = [
            [-2.0, -1.0],
            [-1.0, -2.0],
            [-3.0, 0.0],
            [-2.5, -2.5],
            [0.0, -1.0],
        ];
        let mut x = Vec::new();
        let mut y = Vec::new();
        for p in pos {
            x.extend(p);
            y.push(true);
        }
        for p in neg {
            x.extend(p);
            y.push(false);
        }
        let svm = train(
            &x,
            2,
            &y,
            &SvmConfig {
                c: 10.0,
                tol: 1e-3,
                ..SvmConfig::default()
            },
        );
        for (i, &label) in y.iter().enumerate() {
            let s = svm.score(&x[i * 2..i * 2 + 2]);
            assert!(
                if label { s >= 0.99 } else { s <= -0.99 },
                "example {i}: margin {s}"
            );
        }
        // Deterministic.
        assert_eq!(
            svm,
            train(
                &x,
                2,
                &y,
                &SvmConfig {
                    c: 10.0,
                    tol: 1e-3,
                    ..SvmConfig::default()
                }
            )
        );
    }

    #[test]
    fn empty_inputs_give_a_zero_classifier() {
        let svm = train(&[], 3, &[], &SvmConfig::default());
        assert_eq!(svm.w, vec![0.0; 3]);
        assert_eq!(svm.score(&[1.0, 2.0, 3.0]), 0.0);
        assert!(
            train(&[1.0], 0, &[true], &SvmConfig::default())
                .w
                .is_empty()
        );
    }
}
