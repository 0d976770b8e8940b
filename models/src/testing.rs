//! Helpers shared by the crate's unit tests: tiny models, raw tensor files, and the
//! Python ONNX checker / onnxruntime peer.
use crate::FasterRcnn;
use crate::config::{BlockConfig, ModelConfig};
use std::collections::HashMap;
use std::path::Path;
use std::process::Command;
use tch::{Device, Kind, Tensor};

/// A tiny 3-class detector with the given backbone blocks `(out_channels, stride,
/// convs)`, seeded.
pub(crate) fn tiny_model(seed: i64, blocks: &[(i64, i64, usize)]) -> FasterRcnn {
    tch::manual_seed(seed);
    let cfg = ModelConfig {
        num_classes: 3,
        backbone: blocks
            .iter()
            .map(|&(out_channels, stride, convs)| BlockConfig {
                out_channels,
                stride,
                convs,
            })
            .collect(),
        rpn_channels: 8,
        roi_hidden: 32,
        ..ModelConfig::default()
    };
    FasterRcnn::new(cfg, Device::Cpu).unwrap()
}

/// Write a tensor as raw little-endian f32.
pub(crate) fn write_f32(path: &Path, t: &Tensor) {
    let v = Vec::<f32>::try_from(t.to_kind(Kind::Float).flatten(0, -1)).unwrap();
    std::fs::write(
        path,
        v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>(),
    )
    .unwrap();
}

/// Run the ONNX checker (full check) and Python onnxruntime on `model` with the inputs
/// and expected outputs of `spec` (see `tools/onnx_check.py`); returns the largest
/// absolute difference per output.
pub(crate) fn python_check(
    model: &Path,
    spec: serde_json::Value,
    dir: &Path,
) -> HashMap<String, f64> {
    let python = std::env::var_os("FRUGAL_PYTHON")
        .expect("FRUGAL_PYTHON is not set: run `cargo xtask setup`");
    let spec_path = dir.join(format!(
        "{}.json",
        model.file_stem().unwrap().to_string_lossy()
    ));
    std::fs::write(&spec_path, spec.to_string()).unwrap();
    let out = Command::new(python)
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tools/onnx_check.py"))
        .arg(model)
        .arg(&spec_path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["checker"], "ok");
    serde_json::from_value(v["max_abs_diff"].clone()).unwrap()
}
