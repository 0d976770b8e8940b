//! ONNX export, written from Rust: a prost encoding of the ONNX IR subset frugal needs
//! ([`proto`]), a graph builder ([`builder`]), and the detector exporter.
//!
//! The files are read on the drone by ONNX Runtime (through `frugal-runtime`'s `onnx`
//! feature); the drone never links protobuf code.

pub mod builder;
pub mod executor;
pub mod export;
pub mod parity;
pub mod proto;
pub(crate) mod qdq;

pub use builder::{Dim, GraphBuilder, OPSET, attr_float, attr_int, attr_ints, attr_string};
pub use executor::{GlueSpec, OrtDetector, OrtError, StageTimes};
pub use export::{
    BACKBONE_RPN_FILE, DetectorGraphs, ExportedFiles, REFERENCE_SIZE, ROI_HEAD_FILE,
    detector_graphs, detector_graphs_quantized, export_detector, export_detector_quantized,
    export_reference, export_reference_int8,
};
pub use parity::{ParityReport, parity};
pub use qdq::{ActQuant, QuantSpec};

use prost::Message;
use std::io::Write;
use std::path::Path;

/// Encode `model` and write it to `path` atomically (a temporary file in the same
/// folder, then a rename), so a failed write never replaces a good file.
pub fn save_model(model: &proto::ModelProto, path: &Path) -> std::io::Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)?;
    let mut tmp = tempfile::NamedTempFile::new_in(dir)?;
    tmp.write_all(&model.encode_to_vec())?;
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}
