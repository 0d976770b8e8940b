//! Reading the variant folders `frugal compress` wrote, and writing the variants file
//! `frugal policy record --variants` reads.
use crate::ParetoError;
use crate::files::write_json;
use frugal_models::compress::{VARIANT_FILE, VariantRecord, read_record};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// A compressed variant on disk.
#[derive(Clone, Debug)]
pub struct VariantDir {
    /// Its folder (holding the ONNX graphs).
    pub dir: PathBuf,
    /// Its `variant.json`.
    pub record: VariantRecord,
}

/// Every sub-folder of `root` with a `variant.json`, in the order they were made
/// (then by name).
pub fn read_variants(root: &Path) -> Result<Vec<VariantDir>, ParetoError> {
    let entries = std::fs::read_dir(root).map_err(|e| ParetoError::io(root, e))?;
    let mut out = Vec::new();
    for e in entries {
        let e = e.map_err(|e| ParetoError::io(root, e))?;
        let file = e.path().join(VARIANT_FILE);
        if file.is_file() {
            let record = read_record(&file).map_err(|e| ParetoError::Input(e.to_string()))?;
            let modified = std::fs::metadata(&file)
                .and_then(|m| m.modified())
                .map_err(|e| ParetoError::io(&file, e))?;
            out.push((
                modified,
                VariantDir {
                    dir: e.path(),
                    record,
                },
            ));
        }
    }
    if out.is_empty() {
        return Err(ParetoError::Input(format!(
            "{}: no variant folders (sub-folders with {VARIANT_FILE}); run `frugal compress` first",
            root.display()
        )));
    }
    out.sort_by(|a, b| {
        a.0.cmp(&b.0)
            .then_with(|| a.1.record.name.cmp(&b.1.record.name))
    });
    Ok(out.into_iter().map(|(_, v)| v).collect())
}

#[derive(Serialize)]
struct Source {
    kind: &'static str,
    dir: PathBuf,
}

#[derive(Serialize)]
struct Entry {
    name: String,
    family: &'static str,
    latency_ms: f64,
    precision: &'static str,
    source: Source,
}

#[derive(Serialize)]
struct File {
    /// The reference detector's latency (fastest run) on the same machine, same timing.
    reference_ms: f64,
    /// The int8 reference detector's, the same way.
    reference_int8_ms: f64,
    variants: Vec<Entry>,
}

/// The variants file of `frugal policy record` (`{"reference_ms", "reference_int8_ms",
/// "variants": [{"name", "family": "cnn", "latency_ms", "precision": "int8" | "fp32",
/// "source": {"kind": "onnx", "dir"}}]}`) for `(variant, latency)` pairs and the
/// reference detectors' latencies, fp32 and int8 (each the fastest of its timed runs,
/// [`Latency::cost_ms`](crate::stats::Latency::cost_ms))
/// ([`frugal_models::onnx::export_reference`], [`export_reference_int8`](frugal_models::onnx::export_reference_int8))
/// timed with them, written atomically.
pub fn write_variants_file(
    path: &Path,
    variants: &[(&VariantDir, f64)],
    reference_ms: f64,
    reference_int8_ms: f64,
) -> Result<(), ParetoError> {
    let file = File {
        reference_ms,
        reference_int8_ms,
        variants: variants
            .iter()
            .map(|(v, ms)| Entry {
                name: v.record.name.clone(),
                family: "cnn",
                latency_ms: *ms,
                precision: if v.record.int8 { "int8" } else { "fp32" },
                source: Source {
                    kind: "onnx",
                    dir: std::path::absolute(&v.dir).unwrap_or_else(|_| v.dir.clone()),
                },
            })
            .collect(),
    };
    write_json(path, &file)
}
