//! Where mazes come from: the shipped mazes, compiled in and found by name, and maze
//! files read from disk.
use super::{Maze, MazeError};
use std::path::Path;

/// The shipped mazes (`sim/mazes/*.maze`), compiled in: the paper's Easy (one turn),
/// Medium (two turns, one WAIT) and Hard (four turns, two WAITs).
pub const BUILTIN_MAZES: [(&str, &str); 3] = [
    ("easy", include_str!("../../mazes/easy.maze")),
    ("medium", include_str!("../../mazes/medium.maze")),
    ("hard", include_str!("../../mazes/hard.maze")),
];

/// The shipped training mazes (`sim/mazes/train/`): flown only to record footage the
/// policy learns from (`frugal fly --record`), never in an evaluation.
pub const TRAINING_MAZES: [(&str, &str); 3] = [
    ("train-a", include_str!("../../mazes/train/train-a.maze")),
    ("train-b", include_str!("../../mazes/train/train-b.maze")),
    ("train-c", include_str!("../../mazes/train/train-c.maze")),
];

impl Maze {
    /// A shipped maze by name: an evaluation maze of [`BUILTIN_MAZES`] (`easy`,
    /// `medium`, `hard`) or a training maze of [`TRAINING_MAZES`] (`train-a` …).
    pub fn builtin(name: &str) -> Option<Maze> {
        if let Some((n, text)) = BUILTIN_MAZES.iter().find(|(n, _)| *n == name) {
            return Maze::parse(text, Path::new(&format!("sim/mazes/{n}.maze"))).ok();
        }
        let (n, text) = TRAINING_MAZES.iter().find(|(n, _)| *n == name)?;
        Maze::parse(text, Path::new(&format!("sim/mazes/train/{n}.maze"))).ok()
    }

    /// A maze file, or a shipped maze by name (see [`Maze::builtin`]) when no file of
    /// that name exists.
    pub fn resolve(arg: &Path) -> Result<Maze, MazeError> {
        if !arg.exists()
            && let Some(m) = arg.to_str().and_then(Maze::builtin)
        {
            return Ok(m);
        }
        Maze::load(arg)
    }

    /// Read and parse a maze file.
    pub fn load(path: &Path) -> Result<Maze, MazeError> {
        let text = std::fs::read_to_string(path).map_err(|source| MazeError::Io {
            path: path.to_owned(),
            source,
        })?;
        Maze::parse(&text, path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_mazes_are_built_in_and_resolve_by_name() {
        for (name, _) in BUILTIN_MAZES.iter().chain(&TRAINING_MAZES) {
            let m = Maze::builtin(name).unwrap_or_else(|| panic!("{name} parses"));
            assert!(m.goal_connected(), "{name}");
            let r = Maze::resolve(Path::new(name)).unwrap();
            assert_eq!(
                (r.width, r.height, r.signs.len()),
                (m.width, m.height, m.signs.len())
            );
        }
        assert!(Maze::builtin("nowhere").is_none());
        let e = Maze::resolve(Path::new("nowhere")).unwrap_err().to_string();
        assert!(e.contains("nowhere") && e.contains("cannot read"), "{e}");
    }

    #[test]
    fn unreadable_file_names_the_path() {
        let e = Maze::load(Path::new("/nonexistent/x.maze")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/x.maze"), "{e}");
    }
}
