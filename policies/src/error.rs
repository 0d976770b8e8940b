//! The crate's error type: every variant names the file (or the variant) at fault.

use std::path::PathBuf;

/// What went wrong while recording, training, evaluating or bundling.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PolicyError {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A JSON or TOML file could not be parsed or written.
    #[error("{path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What the parser said.
        message: String,
    },
    /// A file parses but its content is wrong (field and reason given).
    #[error("{path}: {field}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The field or entry at fault.
        field: String,
        /// Why.
        message: String,
    },
    /// A detector variant failed on a frame.
    #[error("variant {variant} on video {video} frame {frame}: {message}")]
    Detector {
        /// The variant's name.
        variant: String,
        /// The video id.
        video: u32,
        /// The frame index.
        frame: u32,
        /// The detector's error.
        message: String,
    },
    /// The dataset could not be read.
    #[error(transparent)]
    Data(#[from] frugal_data::DataError),
    /// The MDP is malformed (a bug in estimation if it happens).
    #[error("MDP: {0}")]
    Mdp(#[from] crate::mdp::MdpError),
    /// The runtime rejected a bundle.
    #[error("{path}: {message}")]
    Bundle {
        /// The bundle file (or `<memory>`).
        path: PathBuf,
        /// The reader's or writer's reason.
        message: String,
    },
    /// A referenced file's SHA-256 does not match the bundle.
    #[error("{path}: SHA-256 mismatch: the bundle expects {expected}, the file has {actual}")]
    Hash {
        /// The referenced file.
        path: PathBuf,
        /// Hex digest stored in the bundle.
        expected: String,
        /// Hex digest of the file on disk.
        actual: String,
    },
    /// The KLT tracker's image handling failed (bad frame size).
    #[error("video {video} frame {frame}: tracker: {message}")]
    Tracker {
        /// The video id.
        video: u32,
        /// The frame index.
        frame: u32,
        /// What the tracker said.
        message: String,
    },
    /// Drawing a plot failed.
    #[error("cannot draw {path}: {message}")]
    Plot {
        /// The plot file.
        path: PathBuf,
        /// What the backend said.
        message: String,
    },
}

impl PolicyError {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    /// A content error in `path`.
    pub fn invalid(
        path: impl Into<PathBuf>,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Self::Invalid {
            path: path.into(),
            field: field.into(),
            message: message.into(),
        }
    }
}

/// Result with [`PolicyError`].
pub type Result<T, E = PolicyError> = std::result::Result<T, E>;

/// Read a serde file: TOML when the name ends in `.toml`, JSON otherwise; errors name
/// the file.
pub fn read_toml_or_json<T: serde::de::DeserializeOwned>(path: &std::path::Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| PolicyError::io(path, e))?;
    let parsed = if path.extension().is_some_and(|e| e == "toml") {
        toml::from_str(&text).map_err(|e| e.to_string())
    } else {
        serde_json::from_str(&text).map_err(|e| e.to_string())
    };
    parsed.map_err(|message| PolicyError::Parse {
        path: path.into(),
        message,
    })
}
