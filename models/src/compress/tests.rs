//! Tests of the compression driver's pieces that need more than one sub-module.
use super::*;
use crate::onnx::export_detector;
use crate::testing::{python_check, tiny_model, write_f32};
use tch::{Kind, Tensor};

/// Every kind of exported variant (int8 QDQ, channel-pruned, block-removed, smaller
/// input) passes the ONNX checker and runs in Python onnxruntime; the fp32 ones match
/// tch, the int8 one stays within a few quantization steps of it.
#[test]
fn exported_variants_pass_the_onnx_checker_and_run_in_onnxruntime() {
    let base = tiny_model(4, &[(8, 2, 1), (16, 2, 1)]);
    let dir = tempfile::tempdir().unwrap();
    let (h, w) = (40usize, 56usize);
    let images: Vec<Tensor> = (0..4)
        .map(|_| Tensor::rand([1, 3, h as i64, w as i64], (Kind::Float, Device::Cpu)) * 2.0 - 1.0)
        .collect();
    let stats = quant::collect_stats(&base, &images).unwrap();
    assert!(stats.contains_key("image") && stats.contains_key("rpn.conv"));
    let layers = quant::default_quantized_layers(&base);
    let spec = quant::quant_spec(&stats, Calibration::MinMax, &layers);
    let (pruned, _) = prune::prune_channels(&base, 0.5).unwrap();
    let dropped = prune::drop_blocks(&base, &[1]).unwrap();
    type Case<'a> = (
        &'a str,
        &'a FasterRcnn,
        Option<&'a QuantSpec>,
        (usize, usize),
    );
    let cases: Vec<Case> = vec![
        ("int8", &base, Some(&spec), (h, w)),
        ("channels", &pruned, None, (h, w)),
        ("dropped", &dropped, None, (h, w)),
        ("resolution", &base, None, (h / 2, w / 2)),
    ];
    for (name, model, q, (hh, ww)) in cases {
        let d = dir.path().join(name);
        let files = export_detector_quantized(model, hh, ww, q, &d).unwrap();
        let image = images[0].upsample_bilinear2d([hh as i64, ww as i64], false, None, None);
        let out = tch::no_grad(|| model.backbone_rpn(&image));
        let p = |n: &str| d.join(n);
        write_f32(&p("image.bin"), &image);
        write_f32(&p("objectness.bin"), &out.objectness);
        write_f32(&p("deltas.bin"), &out.deltas);
        let diffs = python_check(
            &files.backbone_rpn,
            serde_json::json!({
                "inputs": {"image": {"shape": [1, 3, hh, ww], "dtype": "float32", "file": p("image.bin")}},
                "outputs": {"objectness": {"file": p("objectness.bin")}, "deltas": {"file": p("deltas.bin")}},
            }),
            &d,
        );
        let scale = out.objectness.abs().max().double_value(&[]).max(1e-3);
        for (o, diff) in &diffs {
            let tol = if q.is_some() { 0.1 * scale } else { 1e-4 };
            assert!(
                *diff < tol,
                "{name}/{o}: max abs diff {diff} (tolerance {tol})"
            );
        }
        // the RoI head graph on a few boxes
        let rois = [[2.0f32, 3.0, 20.0, 30.0], [10.5, 0.0, 55.0, 39.0]];
        let rois_t = Tensor::from_slice(&rois.concat()).reshape([2, 4]) * (hh as f64 / h as f64);
        let (logits, _) = tch::no_grad(|| model.roi_head(&out.features, &rois_t, &[0, 0]));
        write_f32(&p("features.bin"), &out.features);
        write_f32(&p("rois.bin"), &rois_t);
        std::fs::write(
            p("batch.bin"),
            [0i64; 2]
                .iter()
                .flat_map(|x| x.to_le_bytes())
                .collect::<Vec<u8>>(),
        )
        .unwrap();
        write_f32(&p("logits.bin"), &logits);
        let diffs = python_check(
            &files.roi_head,
            serde_json::json!({
                "inputs": {
                    "features": {"shape": out.features.size(), "dtype": "float32", "file": p("features.bin")},
                    "rois": {"shape": [2, 4], "dtype": "float32", "file": p("rois.bin")},
                    "batch_indices": {"shape": [2], "dtype": "int64", "file": p("batch.bin")},
                },
                "outputs": {"class_logits": {"file": p("logits.bin")}},
            }),
            &d,
        );
        let scale = logits.abs().max().double_value(&[]).max(1e-3);
        let tol = if q.is_some() { 0.1 * scale } else { 1e-4 };
        assert!(
            diffs["class_logits"] < tol,
            "{name}: logits diff {}",
            diffs["class_logits"]
        );
    }
    // the int8 graph really holds int8 weights: smaller than the fp32 one
    let fp = dir.path().join("fp32");
    let f = export_detector(&base, h, w, &fp).unwrap();
    let size = |p: &Path| std::fs::metadata(p).unwrap().len();
    assert!(size(&dir.path().join("int8").join(ROI_HEAD_FILE)) * 3 < size(&f.roi_head));
}

#[test]
fn executor_resizes_frames_to_its_input_and_scales_boxes_back() {
    let model = tiny_model(9, &[(8, 2, 1), (16, 2, 1)]);
    let dir = tempfile::tempdir().unwrap();
    export_detector(&model, 24, 32, dir.path()).unwrap();
    let mut ort = OrtDetector::open(dir.path(), 1).unwrap();
    let (w, h) = (64u32, 48u32);
    let px: Vec<u8> = (0..w * h * 3).map(|i| ((i * 7) % 251) as u8).collect();
    let frame = frugal_runtime::FrameRef::new(w, h, &px).unwrap();
    let small = crate::onnx::executor::resize_bilinear(frame, 32, 24);
    let direct = ort
        .detect(frugal_runtime::FrameRef::new(32, 24, &small).unwrap())
        .unwrap();
    let resized = ort.detect(frame).unwrap();
    assert!(!direct.is_empty(), "no detections to compare");
    assert_eq!(direct.len(), resized.len());
    for (a, b) in direct.iter().zip(&resized) {
        assert_eq!((a.class, a.score), (b.class, b.score));
        assert!(
            (a.bbox.x1 * 2.0 - b.bbox.x1).abs() < 1e-3
                && (a.bbox.y2 * 2.0 - b.bbox.y2).abs() < 1e-3
        );
    }
    // resizing a constant image keeps it constant
    let grey = vec![77u8; 10 * 6 * 3];
    let r = crate::onnx::executor::resize_bilinear(
        frugal_runtime::FrameRef::new(10, 6, &grey).unwrap(),
        4,
        3,
    );
    assert!(r.len() == 36 && r.iter().all(|v| *v == 77));
}

#[test]
fn grid_defaults_and_errors() {
    let g = Grid::default();
    g.validate("default").unwrap();
    assert!(g.variants.len() >= 8);
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("g.toml");
    std::fs::write(
        &p,
        "calibration = { method = \"entropy\" }\n[finetune]\nsteps = 5\n[[variants]]\nname = \"a\"\ntechnique = { kind = \"channels\", keep = 0.5 }\n[[variants]]\nname = \"b\"\nparent = \"a\"\ntechnique = { kind = \"int8\" }\n",
    )
    .unwrap();
    let g = Grid::load(&p).unwrap();
    assert_eq!(g.finetune.steps, 5);
    assert_eq!(g.calibration, Calibration::Entropy);
    assert_eq!(g.variants[1].parent.as_deref(), Some("a"));
    std::fs::write(&p, "[finetune]\nstep = 5\n").unwrap();
    let e = Grid::load(&p).unwrap_err().to_string();
    assert!(e.contains("g.toml") && e.contains("step"), "{e}");
    std::fs::write(
        &p,
        "[[variants]]\nname = \"b\"\nparent = \"zz\"\ntechnique = { kind = \"base\" }\n",
    )
    .unwrap();
    let e = Grid::load(&p).unwrap_err().to_string();
    assert!(e.contains("parent `zz`"), "{e}");
}
