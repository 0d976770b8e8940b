//! The int8 vocabulary shared by calibration ([`crate::compress::quant`]) and the QDQ
//! exporter ([`super::export`]): the uint8 parameters of an activation
//! ([`ActQuant`]), what a QDQ export quantizes ([`QuantSpec`]), and the arithmetic —
//! symmetric per-channel int8 weights, asymmetric uint8 activations with ONNX
//! `QuantizeLinear` / `DequantizeLinear` semantics.

/// uint8 quantization parameters of one activation (`x ≈ (q - zero_point) · scale`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ActQuant {
    /// Step size.
    pub scale: f32,
    /// The uint8 value that stands for 0.
    pub zero_point: u8,
}

/// What to quantize in a QDQ export: `activations` maps activation points (`image`,
/// a layer's name for its ReLU output, `roi_head.pooled`) to uint8 parameters, each
/// exported as a `QuantizeLinear` → `DequantizeLinear` pair; a layer in `layers` whose
/// input is such a point gets int8 per-output-channel weights and int32 biases behind
/// `DequantizeLinear` (axis 0), so ONNX Runtime fuses it into an integer kernel.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct QuantSpec {
    /// uint8 parameters per activation point.
    pub activations: std::collections::BTreeMap<String, ActQuant>,
    /// Layers whose weights are quantized.
    pub layers: std::collections::BTreeSet<String>,
}

/// Symmetric per-output-channel int8 quantization of a weight tensor laid out with
/// the output channel first (`[O, …]`, `len = O × per_channel`): values in
/// `[-127, 127]`, one scale `max |w_c| / 127` per channel.
pub fn quantize_weights_per_channel(w: &[f32], out_channels: usize) -> (Vec<i8>, Vec<f32>) {
    let per = w.len() / out_channels.max(1);
    let mut q = Vec::with_capacity(w.len());
    let mut scales = Vec::with_capacity(out_channels);
    for c in w.chunks(per.max(1)).take(out_channels) {
        let m = c.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let s = if m > 0.0 { m / 127.0 } else { 1e-8 };
        scales.push(s);
        q.extend(c.iter().map(|v| (v / s).round().clamp(-127.0, 127.0) as i8));
    }
    (q, scales)
}

/// uint8 parameters `(scale, zero_point)` covering `[lo, hi]` (widened to include 0,
/// so zero is exactly representable, as ONNX padding needs).
pub fn uint8_params(lo: f32, hi: f32) -> ActQuant {
    let lo = lo.min(0.0);
    let hi = hi.max(0.0);
    let scale = if hi > lo { (hi - lo) / 255.0 } else { 1e-8 };
    let zero_point = (-lo / scale).round().clamp(0.0, 255.0) as u8;
    ActQuant { scale, zero_point }
}

/// ONNX `QuantizeLinear` to uint8 (round half to even, saturate).
pub fn quantize_u8(x: f32, q: ActQuant) -> u8 {
    ((x / q.scale).round_ties_even() + f32::from(q.zero_point)).clamp(0.0, 255.0) as u8
}

/// ONNX `DequantizeLinear` from uint8.
pub fn dequantize_u8(v: u8, q: ActQuant) -> f32 {
    (f32::from(v) - f32::from(q.zero_point)) * q.scale
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantize_dequantize_error_is_within_half_a_step() {
        let q = uint8_params(-1.3, 4.1);
        assert!(q.zero_point > 0);
        // zero is exact
        assert_eq!(dequantize_u8(quantize_u8(0.0, q), q), 0.0);
        for i in 0..=1000 {
            let x = -1.3 + 5.4 * i as f32 / 1000.0;
            let err = (dequantize_u8(quantize_u8(x, q), q) - x).abs();
            assert!(
                err <= q.scale / 2.0 + 1e-6,
                "x {x}: err {err} > {}",
                q.scale / 2.0
            );
        }
        // outside the range it saturates
        assert_eq!(quantize_u8(100.0, q), 255);
        assert_eq!(quantize_u8(-100.0, q), 0);
    }

    #[test]
    fn per_channel_scales_on_a_hand_made_tensor() {
        // two output channels of three weights each
        let w = [1.0f32, -2.0, 0.5, 0.1, 0.2, -0.3];
        let (q, s) = quantize_weights_per_channel(&w, 2);
        assert_eq!(s.len(), 2);
        assert!((s[0] - 2.0 / 127.0).abs() < 1e-9);
        assert!((s[1] - 0.3 / 127.0).abs() < 1e-9);
        assert_eq!(q, vec![64, -127, 32, 42, 85, -127]);
        for (i, v) in w.iter().enumerate() {
            let d = f32::from(q[i]) * s[i / 3];
            assert!((d - v).abs() <= s[i / 3] / 2.0 + 1e-7);
        }
        // an all-zero channel gets a tiny positive scale, not a division by zero
        let (q, s) = quantize_weights_per_channel(&[0.0, 0.0, 1.0, -1.0], 2);
        assert!(s[0] > 0.0 && q[..2] == [0, 0] && q[2..] == [127, -127]);
    }
}
