//! The crate's error type.

use std::path::PathBuf;

/// What can go wrong in the feature-based family.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A frame whose pixel slice does not match `width * height * 3`.
    #[error("frame is {width}×{height} but its RGB slice has {len} bytes (expected {expected})")]
    FrameSize {
        /// Declared width.
        width: u32,
        /// Declared height.
        height: u32,
        /// Bytes actually given.
        len: usize,
        /// Bytes a `width × height` RGB8 frame needs.
        expected: usize,
    },
    /// A parameter out of its valid range.
    #[error("invalid parameter {name}: {reason}")]
    Param {
        /// The parameter's name.
        name: &'static str,
        /// Why it is invalid.
        reason: String,
    },
    /// A parameter tuple that does not parse (`"1000,2,8,9"` or `"<1000,2,8,9>"`).
    #[error("cannot parse parameter tuple {text:?}: {reason}")]
    ParseParams {
        /// The text given.
        text: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The model has no SVMs for the HoG configuration a variant asks for.
    #[error("the model has no SVMs trained for block {block}, cell {cell}, bins {bins}")]
    MissingHog {
        /// Block size in cells.
        block: u8,
        /// Cell size in pixels.
        cell: u8,
        /// Orientation bins.
        bins: u8,
    },
    /// Training data that cannot train anything.
    #[error("cannot train: {0}")]
    Training(String),
    /// Reading a dataset failed.
    #[error(transparent)]
    Data(#[from] frugal_data::DataError),
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A model file that is not valid JSON for a model, or whose contents are
    /// inconsistent.
    #[error("{path}: not a valid frugal-features model: {reason}")]
    Model {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
}

/// The crate's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;
