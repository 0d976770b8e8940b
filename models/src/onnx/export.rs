//! Export of the [`FasterRcnn`] detector as two ONNX graphs.
//!
//! **Why a split.** The detector is exported as two graphs with the Rust glue of
//! [`crate::glue`] between them, exactly where the tch model splits:
//!
//! 1. `backbone_rpn.onnx`: `image [1, 3, H, W]` → `features [1, C, h, w]`,
//!    `objectness [1, A, h, w]`, `deltas [1, 4A, h, w]`;
//! 2. proposals in Rust ([`crate::glue::proposals`]: decode, clip, top-k, NMS);
//! 3. `roi_head.onnx`: `features`, `rois [R, 4]`, `batch_indices [R]` (int64) →
//!    `class_logits [R, K+1]`, `box_deltas [R, 4K]` (ONNX `RoiAlign`, `half_pixel`);
//! 4. detections in Rust ([`crate::glue::detections`]: softmax, decode, per-class NMS).
//!
//! The alternative, one graph with ONNX `NonMaxSuppression`, `TopK` and the box decoding
//! as tensor ops, would save one hand-over of the feature map per frame but ties the
//! NMS semantics (ordering of ties, per-class handling, score threshold) to ONNX
//! Runtime's kernels; with the split, the tch model and the ONNX executor share the
//! same post-processing code and agree by construction. The hand-over's cost is
//! measured by the latency harness (the `glue` column of `frugal bench`).
//!
//! Every graph records the glue's parameters in its metadata (`frugal.*` keys), so an
//! exported pair is self-describing: an executor needs nothing but the two files.

use super::builder::{Dim, GraphBuilder, attr_float, attr_int, attr_ints, attr_string};
use super::proto::{ModelProto, data_type};
use super::qdq::quantize_weights_per_channel;
use crate::{FasterRcnn, ModelError};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use tch::{Kind, Tensor};

pub use super::qdq::{ActQuant, QuantSpec};
pub use frugal_runtime::onnx::{BACKBONE_RPN_FILE, ROI_HEAD_FILE};

/// The two graphs of an exported detector, in memory.
pub struct DetectorGraphs {
    /// `image → features, objectness, deltas`.
    pub backbone_rpn: ModelProto,
    /// `features, rois, batch_indices → class_logits, box_deltas`.
    pub roi_head: ModelProto,
}

/// Where [`export_detector`] wrote the graphs.
#[derive(Clone, Debug)]
pub struct ExportedFiles {
    /// `backbone_rpn.onnx`.
    pub backbone_rpn: PathBuf,
    /// `roi_head.onnx`.
    pub roi_head: PathBuf,
}

/// A weight tensor as `(shape, values)`.
fn weights(vars: &HashMap<String, Tensor>, name: &str) -> Result<(Vec<i64>, Vec<f32>), ModelError> {
    let t = vars.get(name).ok_or_else(|| ModelError::Config {
        file: "model".into(),
        msg: format!("the model has no tensor `{name}` to export"),
    })?;
    let values =
        Vec::<f32>::try_from(t.detach().to_kind(Kind::Float).flatten(0, -1)).map_err(|e| {
            ModelError::Torch {
                file: name.into(),
                msg: e.to_string(),
            }
        })?;
    Ok((t.size(), values))
}

/// The glue parameters an executor needs, as `frugal.*` metadata entries.
fn glue_metadata(model: &FasterRcnn, height: usize, width: usize) -> Vec<(&'static str, String)> {
    let c = model.config();
    let list = |v: &[f32]| {
        v.iter()
            .map(|x| x.to_string())
            .collect::<Vec<_>>()
            .join(",")
    };
    vec![
        ("frugal.format", "faster-rcnn-split/1".into()),
        ("frugal.input_height", height.to_string()),
        ("frugal.input_width", width.to_string()),
        ("frugal.num_classes", c.num_classes.to_string()),
        ("frugal.stride", c.stride().to_string()),
        ("frugal.anchor_sizes", list(&c.anchor_sizes)),
        ("frugal.anchor_ratios", list(&c.anchor_ratios)),
        ("frugal.pixel_mean", list(&c.pixel_mean)),
        ("frugal.pixel_std", list(&c.pixel_std)),
        ("frugal.pre_nms", c.pre_nms_test.to_string()),
        ("frugal.post_nms", c.post_nms_test.to_string()),
        ("frugal.rpn_nms_iou", c.rpn_nms_iou.to_string()),
        ("frugal.min_box_size", c.min_box_size.to_string()),
        ("frugal.score_threshold", c.score_threshold.to_string()),
        ("frugal.nms_iou", c.nms_iou.to_string()),
        ("frugal.max_detections", c.max_detections.to_string()),
        (
            "frugal.config",
            serde_json::to_string(c).unwrap_or_default(),
        ),
    ]
}

/// A value in the graph and, when it is the output of a `DequantizeLinear`, its
/// quantization.
#[derive(Clone)]
struct Val {
    name: String,
    q: Option<ActQuant>,
    /// `(QuantizeLinear output, scale, zero point)` when `name` is a dequantized value,
    /// so another consumer can get its own `DequantizeLinear`.
    quantized: Option<[String; 3]>,
}

/// Insert `QuantizeLinear` → `DequantizeLinear` at activation point `point` when the
/// spec quantizes it.
fn qdq(g: &mut GraphBuilder, quant: Option<&QuantSpec>, x: Val, point: &str) -> Val {
    let Some(p) = quant.and_then(|q| q.activations.get(point)).copied() else {
        return x;
    };
    let s = g.constant_f32(&format!("{point}.act_scale"), &[], &[p.scale]);
    let z = g.constant_u8(&format!("{point}.act_zero_point"), &[], &[p.zero_point]);
    let q = g.node(
        "QuantizeLinear",
        &format!("{point}.quant"),
        &[&x.name, &s, &z],
        vec![],
    );
    let d = g.node(
        "DequantizeLinear",
        &format!("{point}.dequant"),
        &[&q, &s, &z],
        vec![],
    );
    Val {
        name: d,
        q: Some(p),
        quantized: Some([q, s, z]),
    }
}

/// Weight and bias inputs of layer `prefix`: fp32 initializers, or — when the layer is
/// quantized and its input is a quantized value — int8 per-channel weights and int32
/// biases (scale `input_scale · weight_scale[c]`) behind `DequantizeLinear`.
fn layer_params(
    g: &mut GraphBuilder,
    vars: &HashMap<String, Tensor>,
    x: &Val,
    prefix: &str,
    quant: Option<&QuantSpec>,
) -> Result<(String, String, Vec<i64>), ModelError> {
    let (wshape, w) = weights(vars, &format!("{prefix}.weight"))?;
    let (bshape, b) = weights(vars, &format!("{prefix}.bias"))?;
    let input_q =
        x.q.filter(|_| quant.is_some_and(|q| q.layers.contains(prefix)));
    let Some(iq) = input_q else {
        let wn = g.constant_f32(&format!("{prefix}.weight"), &wshape, &w);
        let bn = g.constant_f32(&format!("{prefix}.bias"), &bshape, &b);
        return Ok((wn, bn, wshape));
    };
    let out = wshape.first().copied().unwrap_or(1) as usize;
    let (qw, ws) = quantize_weights_per_channel(&w, out);
    let bs: Vec<f32> = ws.iter().map(|s| s * iq.scale).collect();
    let qb: Vec<i32> = b
        .iter()
        .zip(&bs)
        .map(|(v, s)| (f64::from(*v) / f64::from(*s)).round() as i32)
        .collect();
    let o = [out as i64];
    let wq = g.constant_i8(&format!("{prefix}.weight_quantized"), &wshape, &qw);
    let wsn = g.constant_f32(&format!("{prefix}.weight_scale"), &o, &ws);
    let wz = g.constant_i8(&format!("{prefix}.weight_zero_point"), &o, &vec![0; out]);
    let bq = g.constant_i32(&format!("{prefix}.bias_quantized"), &bshape, &qb);
    let bsn = g.constant_f32(&format!("{prefix}.bias_scale"), &o, &bs);
    let wn = g.node(
        "DequantizeLinear",
        &format!("{prefix}.weight"),
        &[&wq, &wsn, &wz],
        vec![attr_int("axis", 0)],
    );
    let bn = g.node(
        "DequantizeLinear",
        &format!("{prefix}.bias"),
        &[&bq, &bsn],
        vec![attr_int("axis", 0)],
    );
    Ok((wn, bn, wshape))
}

/// A 3×3 (or 1×1) conv with padding `k / 2` from the VarStore layer `prefix`.
fn conv(
    g: &mut GraphBuilder,
    vars: &HashMap<String, Tensor>,
    x: &Val,
    prefix: &str,
    stride: i64,
    quant: Option<&QuantSpec>,
) -> Result<String, ModelError> {
    let (wn, bn, wshape) = layer_params(g, vars, x, prefix, quant)?;
    let k = wshape.get(2).copied().unwrap_or(1);
    let p = k / 2;
    Ok(g.node(
        "Conv",
        prefix,
        &[&x.name, &wn, &bn],
        vec![
            attr_ints("kernel_shape", &[k, k]),
            attr_ints("strides", &[stride, stride]),
            attr_ints("pads", &[p, p, p, p]),
        ],
    ))
}

/// A fully connected layer `y = x Wᵀ + b` (ONNX `Gemm` with `transB = 1`).
fn linear(
    g: &mut GraphBuilder,
    vars: &HashMap<String, Tensor>,
    x: &Val,
    prefix: &str,
    quant: Option<&QuantSpec>,
) -> Result<String, ModelError> {
    let (wn, bn, _) = layer_params(g, vars, x, prefix, quant)?;
    Ok(g.node(
        "Gemm",
        prefix,
        &[&x.name, &wn, &bn],
        vec![attr_int("transB", 1)],
    ))
}

fn plain(name: String) -> Val {
    Val {
        name,
        q: None,
        quantized: None,
    }
}

/// Build both graphs for `height × width` input frames.
pub fn detector_graphs(
    model: &FasterRcnn,
    height: usize,
    width: usize,
) -> Result<DetectorGraphs, ModelError> {
    detector_graphs_quantized(model, height, width, None)
}

/// Build both graphs for `height × width` input frames, as QDQ graphs when `quant` is
/// given (see [`QuantSpec`]).
pub fn detector_graphs_quantized(
    model: &FasterRcnn,
    height: usize,
    width: usize,
    quant: Option<&QuantSpec>,
) -> Result<DetectorGraphs, ModelError> {
    let cfg = model.config();
    let vars = model.var_store().variables();
    let (fh, fw) = crate::glue::feature_size(cfg, height, width);
    let a = cfg.anchors_per_cell() as i64;
    let c = cfg.feature_channels();
    let meta = glue_metadata(model, height, width);

    let mut g = GraphBuilder::new("backbone_rpn");
    let image = g.input(
        "image",
        &[
            Dim::Fixed(1),
            3.into(),
            (height as i64).into(),
            (width as i64).into(),
        ],
    );
    let mut x = qdq(&mut g, quant, plain(image), "image");
    for (i, block) in cfg.backbone.iter().enumerate() {
        for j in 0..block.convs {
            let stride = if j == 0 { block.stride } else { 1 };
            let name = format!("backbone.block{i}.conv{j}");
            let y = conv(&mut g, &vars, &x, &name, stride, quant)?;
            let r = g.node("Relu", &format!("backbone.block{i}.relu{j}"), &[&y], vec![]);
            x = qdq(&mut g, quant, plain(r), &name);
        }
    }
    let features = g.node("Identity", "features", &[&x.name], vec![]);
    // the RPN conv reads its own DequantizeLinear of the quantized features: with the
    // `Identity` (the graph output) between them, ONNX Runtime would not fuse the conv
    let fv = match &x.quantized {
        Some([q, s, z]) => Val {
            name: g.node(
                "DequantizeLinear",
                "rpn.conv.input_dequant",
                &[q, s, z],
                vec![],
            ),
            q: x.q,
            quantized: x.quantized.clone(),
        },
        None => plain(features.clone()),
    };
    let h = conv(&mut g, &vars, &fv, "rpn.conv", 1, quant)?;
    let h = g.node("Relu", "rpn.relu", &[&h], vec![]);
    let h = qdq(&mut g, quant, plain(h), "rpn.conv");
    let obj = conv(&mut g, &vars, &h, "rpn.objectness", 1, quant)?;
    let obj = g.node("Identity", "objectness", &[&obj], vec![]);
    let del = conv(&mut g, &vars, &h, "rpn.deltas", 1, quant)?;
    let del = g.node("Identity", "deltas", &[&del], vec![]);
    let (fh, fw) = (fh as i64, fw as i64);
    g.output(
        &features,
        data_type::FLOAT,
        &[1.into(), c.into(), fh.into(), fw.into()],
    );
    g.output(
        &obj,
        data_type::FLOAT,
        &[1.into(), a.into(), fh.into(), fw.into()],
    );
    g.output(
        &del,
        data_type::FLOAT,
        &[1.into(), (4 * a).into(), fh.into(), fw.into()],
    );
    let backbone_rpn = g.finish(
        "frugal Faster-R-CNN-style detector, part 1: backbone + RPN head",
        &meta,
    );

    let mut g = GraphBuilder::new("roi_head");
    let features = g.input("features", &[1.into(), c.into(), fh.into(), fw.into()]);
    let rois = g.input("rois", &[Dim::Named("rois"), 4.into()]);
    let batch = g.input_typed("batch_indices", data_type::INT64, &[Dim::Named("rois")]);
    let ra = model.roi_align_params();
    let pooled = g.node(
        "RoiAlign",
        "roi_head.roi_align",
        &[&features, &rois, &batch],
        vec![
            attr_string("coordinate_transformation_mode", "half_pixel"),
            attr_string("mode", "avg"),
            attr_int("output_height", ra.output_size),
            attr_int("output_width", ra.output_size),
            attr_int("sampling_ratio", ra.sampling_ratio),
            attr_float("spatial_scale", ra.spatial_scale as f32),
        ],
    );
    let flat = g.node(
        "Flatten",
        "roi_head.flatten",
        &[&pooled],
        vec![attr_int("axis", 1)],
    );
    let flat = qdq(&mut g, quant, plain(flat), "roi_head.pooled");
    let h = linear(&mut g, &vars, &flat, "roi_head.fc1", quant)?;
    let h = g.node("Relu", "roi_head.relu1", &[&h], vec![]);
    let h = qdq(&mut g, quant, plain(h), "roi_head.fc1");
    let h = linear(&mut g, &vars, &h, "roi_head.fc2", quant)?;
    let h = g.node("Relu", "roi_head.relu2", &[&h], vec![]);
    let h = qdq(&mut g, quant, plain(h), "roi_head.fc2");
    let logits = linear(&mut g, &vars, &h, "roi_head.class_logits", quant)?;
    let logits = g.node("Identity", "class_logits", &[&logits], vec![]);
    let deltas = linear(&mut g, &vars, &h, "roi_head.box_deltas", quant)?;
    let deltas = g.node("Identity", "box_deltas", &[&deltas], vec![]);
    let k = cfg.num_classes as i64;
    g.output(
        &logits,
        data_type::FLOAT,
        &[Dim::Named("rois"), (k + 1).into()],
    );
    g.output(
        &deltas,
        data_type::FLOAT,
        &[Dim::Named("rois"), (4 * k).into()],
    );
    let roi_head = g.finish(
        "frugal Faster-R-CNN-style detector, part 2: RoI head",
        &meta,
    );
    Ok(DetectorGraphs {
        backbone_rpn,
        roi_head,
    })
}

/// Export `model` for `height × width` frames into `dir` (both files written
/// atomically).
pub fn export_detector(
    model: &FasterRcnn,
    height: usize,
    width: usize,
    dir: &Path,
) -> Result<ExportedFiles, ModelError> {
    export_detector_quantized(model, height, width, None, dir)
}

/// As [`export_detector`], as QDQ graphs when `quant` is given.
pub fn export_detector_quantized(
    model: &FasterRcnn,
    height: usize,
    width: usize,
    quant: Option<&QuantSpec>,
    dir: &Path,
) -> Result<ExportedFiles, ModelError> {
    let graphs = detector_graphs_quantized(model, height, width, quant)?;
    let files = ExportedFiles {
        backbone_rpn: dir.join(BACKBONE_RPN_FILE),
        roi_head: dir.join(ROI_HEAD_FILE),
    };
    super::save_model(&graphs.backbone_rpn, &files.backbone_rpn)
        .map_err(|e| ModelError::io(&files.backbone_rpn, e))?;
    super::save_model(&graphs.roi_head, &files.roi_head)
        .map_err(|e| ModelError::io(&files.roi_head, e))?;
    Ok(files)
}

/// Input size (height, width) of the reference detector ([`export_reference`]).
pub const REFERENCE_SIZE: (usize, usize) = (270, 480);

/// Seed of the reference detector's weights.
const REFERENCE_SEED: i64 = 2026;

/// Exports the *reference detector* into `dir`: the default architecture
/// ([`crate::config::ModelConfig::default`], ten classes) at 480×270, fp32, with seeded
/// random weights. Its cost does not depend on what was trained (the weights change no
/// operation count, and its region proposal network keeps its 50 proposals as a trained
/// one does), so timing it next to the variants on any machine tells how fast that
/// machine runs this detector: a device profile states its speed as this detector's
/// latency on the device, and the variants' device latencies follow from the ratio
/// measured on the host (`frugal pareto`'s `reference_ms`).
pub fn export_reference(dir: &Path) -> Result<ExportedFiles, ModelError> {
    let (h, w) = REFERENCE_SIZE;
    export_detector_quantized(&reference_model()?, h, w, None, dir)
}

/// Seeded images the int8 reference is calibrated on ([`export_reference_int8`]).
const REFERENCE_CALIBRATION_IMAGES: usize = 4;

/// Exports the *int8 reference detector* into `dir`: the reference detector
/// ([`export_reference`]) quantized as the int8 variants are (QDQ, the layers of
/// [`crate::compress::quant::default_quantized_layers`], min-max ranges), calibrated on
/// seeded normal-noise images. Machines differ in how much faster they run int8 than
/// fp32 (integer dot-product instructions or not), so a device profile states the
/// speed of both; int8 variants scale from this one's latency, fp32 ones from the fp32
/// reference's (`frugal pareto`'s `reference_int8_ms`).
pub fn export_reference_int8(dir: &Path) -> Result<ExportedFiles, ModelError> {
    use crate::compress::quant;
    let (h, w) = REFERENCE_SIZE;
    let model = reference_model()?;
    let images: Vec<Tensor> = (0..REFERENCE_CALIBRATION_IMAGES)
        .map(|_| Tensor::randn([1, 3, h as i64, w as i64], (Kind::Float, tch::Device::Cpu)))
        .collect();
    let stats = quant::collect_stats(&model, &images)?;
    let layers = quant::default_quantized_layers(&model);
    let spec = quant::quant_spec(&stats, quant::Calibration::MinMax, &layers);
    export_detector_quantized(&model, h, w, Some(&spec), dir)
}

/// The reference detector's model, its weights drawn from [`REFERENCE_SEED`] (which
/// also seeds what is drawn after it).
fn reference_model() -> Result<FasterRcnn, ModelError> {
    let (h, w) = REFERENCE_SIZE;
    tch::manual_seed(REFERENCE_SEED);
    let cfg = crate::config::ModelConfig {
        input_size: Some([w, h]),
        ..crate::config::ModelConfig::default()
    };
    FasterRcnn::new(cfg, tch::Device::Cpu)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{python_check, tiny_model, write_f32};

    /// Run the Python checker and onnxruntime on one graph; returns the max abs diffs.

    #[test]
    fn exported_graphs_pass_the_onnx_checker_and_match_tch_in_onnxruntime() {
        let model = tiny_model(3, &[(8, 2, 1), (16, 2, 2)]);
        let dir = tempfile::tempdir().unwrap();
        let (h, w) = (40usize, 56usize);
        let files = export_detector(&model, h, w, dir.path()).unwrap();
        let image = Tensor::randn([1, 3, h as i64, w as i64], (Kind::Float, tch::Device::Cpu));
        let out = tch::no_grad(|| model.backbone_rpn(&image));
        let p = |n: &str| dir.path().join(n);
        write_f32(&p("image.bin"), &image);
        write_f32(&p("features.bin"), &out.features);
        write_f32(&p("objectness.bin"), &out.objectness);
        write_f32(&p("deltas.bin"), &out.deltas);
        let f = out.features.size();
        let diffs = python_check(
            &files.backbone_rpn,
            serde_json::json!({
                "inputs": {"image": {"shape": [1, 3, h, w], "dtype": "float32", "file": p("image.bin")}},
                "outputs": {
                    "features": {"file": p("features.bin")},
                    "objectness": {"file": p("objectness.bin")},
                    "deltas": {"file": p("deltas.bin")},
                },
            }),
            dir.path(),
        );
        for (name, d) in &diffs {
            assert!(*d < 1e-4, "{name}: max abs diff {d}");
        }

        // RoIs inside, across and partly outside the image.
        let rois = [
            [2.0f32, 3.0, 20.0, 30.0],
            [10.5, 0.0, 55.0, 39.0],
            [-4.0, 30.0, 12.0, 48.0],
        ];
        let rois_t = Tensor::from_slice(&rois.concat()).reshape([3, 4]);
        let (logits, deltas) = tch::no_grad(|| model.roi_head(&out.features, &rois_t, &[0, 0, 0]));
        write_f32(&p("rois.bin"), &rois_t);
        std::fs::write(
            p("batch.bin"),
            [0i64; 3]
                .iter()
                .flat_map(|x| x.to_le_bytes())
                .collect::<Vec<u8>>(),
        )
        .unwrap();
        write_f32(&p("logits.bin"), &logits);
        write_f32(&p("box_deltas.bin"), &deltas);
        let diffs = python_check(
            &files.roi_head,
            serde_json::json!({
                "inputs": {
                    "features": {"shape": f, "dtype": "float32", "file": p("features.bin")},
                    "rois": {"shape": [3, 4], "dtype": "float32", "file": p("rois.bin")},
                    "batch_indices": {"shape": [3], "dtype": "int64", "file": p("batch.bin")},
                },
                "outputs": {
                    "class_logits": {"file": p("logits.bin")},
                    "box_deltas": {"file": p("box_deltas.bin")},
                },
            }),
            dir.path(),
        );
        assert_eq!(diffs.len(), 2);
        for (name, d) in &diffs {
            assert!(*d < 1e-4, "{name}: max abs diff {d}");
        }
    }
}
