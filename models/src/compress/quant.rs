//! Post-training static int8 quantization: activation calibration (min-max, percentile,
//! entropy / KL divergence) and the per-layer activation statistics collected by a
//! traced forward pass of the tch model. The arithmetic (symmetric per-channel int8
//! weights, asymmetric uint8 activations) is shared with the exporter and re-exported
//! here.
//!
//! The exporter ([`crate::onnx::export`]) turns a [`QuantSpec`] into an ONNX QDQ graph.
use crate::onnx::qdq::QuantSpec;
use crate::{FasterRcnn, ModelError};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use tch::{Kind, Tensor};

pub use crate::onnx::qdq::{
    dequantize_u8, quantize_u8, quantize_weights_per_channel, uint8_params,
};

/// Number of histogram bins kept per activation for percentile and entropy calibration.
pub const HIST_BINS: usize = 2048;

/// How an activation's clipping range is chosen from calibration data.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "method", rename_all = "snake_case", deny_unknown_fields)]
pub enum Calibration {
    /// The observed minimum and maximum.
    MinMax,
    /// Clip `|x|` at this percentile (e.g. 99.99) of the observed magnitudes.
    Percentile {
        /// Percentile in `(0, 100]`.
        percentile: f64,
    },
    /// The threshold minimising the KL divergence between the clipped histogram and its
    /// quantized version (the TensorRT entropy calibrator's criterion).
    Entropy,
}

impl Default for Calibration {
    fn default() -> Self {
        Calibration::Percentile { percentile: 99.99 }
    }
}

/// Statistics of one activation over the calibration frames.
#[derive(Clone, Debug, PartialEq)]
pub struct ActStats {
    /// Smallest value seen.
    pub min: f32,
    /// Largest value seen.
    pub max: f32,
    /// Histogram of `|x|` over `[0, max(|min|, |max|)]` in [`HIST_BINS`] bins.
    pub hist: Vec<f64>,
}

impl ActStats {
    fn abs_max(&self) -> f32 {
        self.min.abs().max(self.max.abs())
    }

    fn bin_width(&self) -> f32 {
        self.abs_max() / self.hist.len().max(1) as f32
    }

    /// The clipping range `[lo, hi]` chosen by `method`.
    pub fn range(&self, method: Calibration) -> (f32, f32) {
        let t = match method {
            Calibration::MinMax => return (self.min, self.max),
            Calibration::Percentile { percentile } => self.percentile_threshold(percentile),
            Calibration::Entropy => {
                let levels = if self.min >= 0.0 { 255 } else { 127 };
                self.entropy_threshold(levels)
            }
        };
        (self.min.max(-t), self.max.min(t))
    }

    fn percentile_threshold(&self, p: f64) -> f32 {
        let total: f64 = self.hist.iter().sum();
        if total <= 0.0 {
            return self.abs_max();
        }
        let want = total * (p / 100.0).clamp(0.0, 1.0);
        let mut acc = 0.0;
        for (i, h) in self.hist.iter().enumerate() {
            acc += h;
            if acc >= want {
                return (i + 1) as f32 * self.bin_width();
            }
        }
        self.abs_max()
    }

    /// The threshold (a bin edge) minimising KL(P ‖ Q), P the histogram clipped at
    /// the threshold (outliers folded into its last bin), Q its `levels`-level version.
    fn entropy_threshold(&self, levels: usize) -> f32 {
        let n = self.hist.len();
        if n <= levels || self.hist.iter().sum::<f64>() <= 0.0 {
            return self.abs_max();
        }
        let mut best = (f64::INFINITY, n);
        let mut i = levels;
        while i <= n {
            let mut p: Vec<f64> = self.hist[..i].to_vec();
            let outliers: f64 = self.hist[i..].iter().sum();
            p[i - 1] += outliers;
            // merge the i bins into `levels` groups, spread each group's mass evenly
            // over its non-empty bins
            let mut q = vec![0.0f64; i];
            for g in 0..levels {
                let a = g * i / levels;
                let b = ((g + 1) * i / levels).max(a + 1).min(i);
                let mass: f64 = self.hist[a..b].iter().sum();
                let nonzero = self.hist[a..b].iter().filter(|v| **v > 0.0).count();
                if nonzero > 0 {
                    for (qk, h) in q[a..b].iter_mut().zip(&self.hist[a..b]) {
                        if *h > 0.0 {
                            *qk = mass / nonzero as f64;
                        }
                    }
                }
            }
            let (sp, sq): (f64, f64) = (p.iter().sum(), q.iter().sum());
            let mut kl = 0.0;
            for (pv, qv) in p.iter().zip(&q) {
                if *pv > 0.0 {
                    let pn = pv / sp;
                    let qn = (qv / sq.max(1e-30)).max(1e-12);
                    kl += pn * (pn / qn).ln();
                }
            }
            if kl < best.0 {
                best = (kl, i);
            }
            i += 16;
        }
        best.1 as f32 * self.bin_width()
    }
}

/// The activation points the QDQ exporter quantizes, in forward order: the image,
/// every backbone conv's ReLU output, the RPN conv's ReLU output, the pooled RoI
/// features and the two hidden FC layers' ReLU outputs.
pub fn activation_points(model: &FasterRcnn) -> Vec<String> {
    let mut v = vec!["image".to_string()];
    for (i, b) in model.config().backbone.iter().enumerate() {
        for j in 0..b.convs {
            v.push(format!("backbone.block{i}.conv{j}"));
        }
    }
    v.extend(
        [
            "rpn.conv",
            "roi_head.pooled",
            "roi_head.fc1",
            "roi_head.fc2",
        ]
        .iter()
        .map(|s| s.to_string()),
    );
    v
}

/// The layers whose weights the default int8 variant quantizes: every backbone conv but
/// the first, the RPN's 3×3 conv and the two hidden FC layers. Measured on this CPU
/// class (ONNX Runtime 1.31, one thread), the first conv (3 input channels) ran slower
/// as `QLinearConv` than in fp32 (1.4 vs 1.1 ms) and needs the image quantized too; the
/// RPN's 1×1 output convs and the final class / box FC layers are small (under 3 % of
/// the compute), and their outputs are the scores and box deltas the MDP and the
/// metrics read, so they stay fp32.
pub fn default_quantized_layers(model: &FasterRcnn) -> Vec<String> {
    activation_points(model)
        .into_iter()
        .filter(|p| p != "image" && p != "roi_head.pooled" && p != "backbone.block0.conv0")
        .collect()
}

/// Run the network layer by layer on a normalised `[1, 3, H, W]` image and return the
/// value at every [`activation_points`] entry.
pub fn trace(model: &FasterRcnn, image: &Tensor) -> Result<Vec<(String, Tensor)>, ModelError> {
    let vars = model.var_store().variables();
    let get = |n: &str| {
        vars.get(n).ok_or_else(|| ModelError::Config {
            file: "model".into(),
            msg: format!("no tensor `{n}`"),
        })
    };
    tch::no_grad(|| {
        let mut out = vec![("image".to_string(), image.shallow_clone())];
        let mut x = image.shallow_clone();
        for (i, b) in model.config().backbone.iter().enumerate() {
            for j in 0..b.convs {
                let p = format!("backbone.block{i}.conv{j}");
                let s = if j == 0 { b.stride } else { 1 };
                let w = get(&format!("{p}.weight"))?;
                let k = w.size()[2];
                x = x
                    .conv2d(
                        w,
                        Some(get(&format!("{p}.bias"))?),
                        [s, s],
                        [k / 2, k / 2],
                        [1, 1],
                        1,
                    )
                    .relu();
                out.push((p, x.shallow_clone()));
            }
        }
        let h = x
            .conv2d(
                get("rpn.conv.weight")?,
                Some(get("rpn.conv.bias")?),
                [1, 1],
                [1, 1],
                [1, 1],
                1,
            )
            .relu();
        out.push(("rpn.conv".into(), h));
        let (ih, iw) = (image.size()[2] as usize, image.size()[3] as usize);
        let rpn = model.backbone_rpn(image);
        let props = model.proposals_of(&rpn, 0, (ih, iw), false);
        if !props.is_empty() {
            let pooled = crate::roi_align::roi_align_gather(
                &x,
                &props,
                &vec![0; props.len()],
                model.roi_align_params(),
            )
            .flatten(1, -1);
            let f1 = pooled
                .linear(get("roi_head.fc1.weight")?, Some(get("roi_head.fc1.bias")?))
                .relu();
            let f2 = f1
                .linear(get("roi_head.fc2.weight")?, Some(get("roi_head.fc2.bias")?))
                .relu();
            out.push(("roi_head.pooled".into(), pooled));
            out.push(("roi_head.fc1".into(), f1));
            out.push(("roi_head.fc2".into(), f2));
        }
        Ok(out)
    })
}

/// Collect [`ActStats`] at every activation point over `images` (normalised
/// `[1, 3, H, W]` tensors): a min / max pass, then a histogram pass.
pub fn collect_stats(
    model: &FasterRcnn,
    images: &[Tensor],
) -> Result<BTreeMap<String, ActStats>, ModelError> {
    let mut stats: BTreeMap<String, ActStats> = BTreeMap::new();
    for img in images {
        for (name, t) in trace(model, img)? {
            let (lo, hi) = (
                t.min().double_value(&[]) as f32,
                t.max().double_value(&[]) as f32,
            );
            let e = stats.entry(name).or_insert(ActStats {
                min: lo,
                max: hi,
                hist: vec![0.0; HIST_BINS],
            });
            e.min = e.min.min(lo);
            e.max = e.max.max(hi);
        }
    }
    for img in images {
        for (name, t) in trace(model, img)? {
            if let Some(e) = stats.get_mut(&name) {
                let m = f64::from(e.abs_max()).max(1e-12);
                let h = abs_histogram(&t, m);
                let h = Vec::<f64>::try_from(h).map_err(|e| ModelError::Torch {
                    file: "calibration".into(),
                    msg: e.to_string(),
                })?;
                for (a, b) in e.hist.iter_mut().zip(h) {
                    *a += b;
                }
            }
        }
    }
    Ok(stats)
}

/// Histogram of `|t|` over `[0, max]` in [`HIST_BINS`] bins (values above `max` in
/// the last bin), as a float64 tensor.
pub fn abs_histogram(t: &Tensor, max: f64) -> Tensor {
    let n = HIST_BINS as i64;
    let bins = (t.abs().to_kind(Kind::Double) * (n as f64 / max.max(1e-12)))
        .floor()
        .clamp(0.0, (n - 1) as f64)
        .to_kind(Kind::Int64)
        .flatten(0, -1);
    bins.bincount::<Tensor>(None, n).to_kind(Kind::Double)
}

/// The [`QuantSpec`] for `layers` from calibration statistics.
pub fn quant_spec(
    stats: &BTreeMap<String, ActStats>,
    method: Calibration,
    layers: &[String],
) -> QuantSpec {
    let first_quantized = layers.iter().any(|l| l == "backbone.block0.conv0");
    QuantSpec {
        activations: stats
            .iter()
            // the image is quantized only when the first conv is
            .filter(|(k, _)| first_quantized || k.as_str() != "image")
            .map(|(k, s)| {
                let (lo, hi) = s.range(method);
                (k.clone(), uint8_params(lo, hi))
            })
            .collect(),
        layers: layers.iter().cloned().collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stats_of(values: &[f32]) -> ActStats {
        let t = Tensor::from_slice(values);
        let min = values.iter().copied().fold(f32::MAX, f32::min);
        let max = values.iter().copied().fold(f32::MIN, f32::max);
        let m = f64::from(min.abs().max(max.abs()));
        let hist = Vec::<f64>::try_from(abs_histogram(&t, m)).unwrap();
        ActStats { min, max, hist }
    }

    #[test]
    fn calibration_methods_clip_outliers_and_min_max_does_not() {
        // 10 000 ReLU-like values in [0, 1] and two outliers at 50
        let mut v: Vec<f32> = (0..10_000).map(|i| (i % 1000) as f32 / 1000.0).collect();
        v.extend([50.0, 50.0]);
        let s = stats_of(&v);
        assert_eq!(s.range(Calibration::MinMax), (0.0, 50.0));
        let (lo, hi) = s.range(Calibration::Percentile { percentile: 99.9 });
        assert_eq!(lo, 0.0);
        assert!((0.99..1.1).contains(&hi), "percentile hi {hi}");
        let (_, hi) = s.range(Calibration::Entropy);
        assert!((0.9..10.0).contains(&hi), "entropy threshold {hi}");
    }
}
