//! The one error type of the crate: every variant names the file and, where there is
//! one, the record (line, annotation id, object index) that was wrong.
use std::path::PathBuf;

/// What can go wrong while generating, loading, importing or exporting a dataset.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DataError {
    /// Reading or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// An image could not be decoded or encoded.
    #[error("{}: image: {source}", path.display())]
    Image {
        /// The image file.
        path: PathBuf,
        /// The decoder's error.
        #[source]
        source: image::ImageError,
    },
    /// A JSON file is malformed or has the wrong shape (the message has line and column).
    #[error("{}: malformed JSON: {source}", path.display())]
    Json {
        /// The JSON file.
        path: PathBuf,
        /// The parser's error, with line and column.
        #[source]
        source: serde_json::Error,
    },
    /// A Pascal VOC XML file is malformed.
    #[error("{}: malformed XML: {message}", path.display())]
    Xml {
        /// The XML file.
        path: PathBuf,
        /// What the parser said.
        message: String,
    },
    /// A GTSDB-style CSV file is malformed.
    #[error("{}: {record}: malformed CSV: {message}", path.display())]
    Csv {
        /// The CSV file.
        path: PathBuf,
        /// Which record (e.g. `line 12`).
        record: String,
        /// What was wrong.
        message: String,
    },
    /// A configuration or class-map file is malformed or has invalid values.
    #[error("{}: {message}", path.display())]
    Config {
        /// The file (or `<built-in>` for the defaults).
        path: PathBuf,
        /// What was wrong.
        message: String,
    },
    /// A record names a class that is neither a frugal class nor in the class map.
    #[error("{}: {record}: unknown class {class:?} (map it with --class-map, or drop unmapped classes)", path.display())]
    UnknownClass {
        /// The annotation file.
        path: PathBuf,
        /// Which record.
        record: String,
        /// The class name or id as written in the file.
        class: String,
    },
    /// A record refers to an image file that does not exist.
    #[error("{}: {record}: image {} not found", path.display(), image.display())]
    MissingImage {
        /// The annotation file.
        path: PathBuf,
        /// Which record.
        record: String,
        /// The image path that was looked for.
        image: PathBuf,
    },
    /// A box is degenerate or lies (partly) outside its image.
    #[error("{}: {record}: box [{x1}, {y1}, {x2}, {y2}] is empty or outside the {width}x{height} image", path.display())]
    BoxOutside {
        /// The annotation file.
        path: PathBuf,
        /// Which record.
        record: String,
        /// Left edge.
        x1: f32,
        /// Top edge.
        y1: f32,
        /// Right edge (exclusive).
        x2: f32,
        /// Bottom edge (exclusive).
        y2: f32,
        /// Image width.
        width: u32,
        /// Image height.
        height: u32,
    },
    /// Any other inconsistency in one record (duplicate id, dangling reference, …).
    #[error("{}: {record}: {problem}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Which record.
        record: String,
        /// What was wrong.
        problem: String,
    },
    /// The input holds no images (or none survive the class filter).
    #[error("{}: empty dataset: {reason}", path.display())]
    Empty {
        /// The input file or folder.
        path: PathBuf,
        /// Why it is empty.
        reason: String,
    },
}

impl DataError {
    /// Wrap an I/O error with its path.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    /// Wrap a JSON error with its path.
    pub fn json(path: impl Into<PathBuf>, source: serde_json::Error) -> Self {
        Self::Json {
            path: path.into(),
            source,
        }
    }

    /// Wrap an image error with its path.
    pub fn image(path: impl Into<PathBuf>, source: image::ImageError) -> Self {
        Self::Image {
            path: path.into(),
            source,
        }
    }

    /// A record-level inconsistency.
    pub fn invalid(
        path: impl Into<PathBuf>,
        record: impl Into<String>,
        problem: impl Into<String>,
    ) -> Self {
        Self::Invalid {
            path: path.into(),
            record: record.into(),
            problem: problem.into(),
        }
    }
}
