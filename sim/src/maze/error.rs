//! What can be wrong with a maze file: a problem on one line ([`LineProblem`]) and
//! the error that names the file ([`MazeError`]).
use super::Dir;
use std::path::PathBuf;
use thiserror::Error;

/// What was wrong on one line of a maze file.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum LineProblem {
    /// The first word is not a known keyword.
    #[error(
        "unknown keyword `{0}` (expected name, cell, wall_height, sign_size, light, start, goal, sign, wait or map)"
    )]
    UnknownKeyword(String),
    /// Too few or too many values after the keyword.
    #[error("`{keyword}` takes {expected}, got {got} value(s)")]
    Arity {
        /// The keyword.
        keyword: &'static str,
        /// What it takes, in words.
        expected: &'static str,
        /// How many were given.
        got: usize,
    },
    /// A value is not a number in the allowed range.
    #[error("`{value}` is not a valid {what}")]
    BadValue {
        /// What the value should be.
        what: &'static str,
        /// The text found.
        value: String,
    },
    /// Not a sign name or code.
    #[error("unknown sign `{0}` (use a class name such as turn_left or a code such as B5)")]
    UnknownSign(String),
    /// A keyword that may appear once appeared again.
    #[error("`{0}` given twice")]
    Duplicate(&'static str),
    /// A map row holds a character other than `#` and `.`.
    #[error("map character `{ch}` at column {col} (use `#` for wall and `.` for floor)")]
    MapChar {
        /// The character.
        ch: char,
        /// Its column (0-based).
        col: usize,
    },
    /// A map row's length differs from the first row's.
    #[error("map row has {got} cells, the first row has {expected}")]
    RaggedRow {
        /// This row's length.
        got: usize,
        /// The first row's length.
        expected: usize,
    },
    /// The map block was not closed by `end`.
    #[error("`map` block is not closed by `end`")]
    UnclosedMap,
    /// A cell is outside the map.
    #[error("cell ({col}, {row}) is outside the {width}×{height} map")]
    OutOfMap {
        /// Column.
        col: usize,
        /// Row.
        row: usize,
        /// Map width.
        width: usize,
        /// Map height.
        height: usize,
    },
    /// A cell that must be floor is a wall.
    #[error("cell ({col}, {row}) is a wall")]
    InWall {
        /// Column.
        col: usize,
        /// Row.
        row: usize,
    },
    /// A sign is fixed to a side of its cell that has no wall.
    #[error("cell ({col}, {row}) has no wall on its {side:?} side to fix the sign to")]
    NoWall {
        /// Column.
        col: usize,
        /// Row.
        row: usize,
        /// The side named.
        side: Dir,
    },
    /// Board does not fit between floor and ceiling.
    #[error(
        "sign centre height {height} m puts the {size} m board outside floor..ceiling ({wall_height} m)"
    )]
    SignHeight {
        /// Given centre height.
        height: f64,
        /// Board size.
        size: f64,
        /// Wall height.
        wall_height: f64,
    },
}

/// Why a maze could not be loaded.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum MazeError {
    /// The file could not be read.
    #[error("{}: cannot read maze file: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A line is malformed.
    #[error("{}:{line}: {problem}", path.display())]
    Line {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        problem: LineProblem,
    },
    /// A required part is missing.
    #[error("{}: no `{what}` line (a maze needs map, start and goal)", path.display())]
    Missing {
        /// The file.
        path: PathBuf,
        /// The keyword that is missing.
        what: &'static str,
    },
}

impl MazeError {
    /// The 1-based line number, for line errors.
    pub fn line(&self) -> Option<usize> {
        match self {
            MazeError::Line { line, .. } => Some(*line),
            _ => None,
        }
    }

    /// The line problem, for line errors.
    pub fn problem(&self) -> Option<&LineProblem> {
        match self {
            MazeError::Line { problem, .. } => Some(problem),
            _ => None,
        }
    }
}
