//! Writing output files atomically: the bytes go to a temporary file beside the
//! target, which is then renamed over it, so a failed write never leaves a truncated
//! file at the target's path.
use crate::ParetoError;
use serde::Serialize;
use std::path::Path;

pub(crate) fn write_json<T: Serialize>(path: &Path, v: &T) -> Result<(), ParetoError> {
    let json = serde_json::to_vec_pretty(v).map_err(|e| ParetoError::Input(e.to_string()))?;
    write_atomic(path, &json)
}

pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ParetoError> {
    let tmp = path.with_extension("partial");
    std::fs::write(&tmp, bytes).map_err(|e| ParetoError::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| ParetoError::io(path, e))
}
