//! Maze files: a small line-based text format (specified in the crate docs and in
//! `sim/mazes/README.md`) and its parser.
//!
//! Coordinates: cell `(col, row)` has its top-left corner at world `(col·cell,
//! row·cell)` metres; `x` grows east, `y` grows south (row 0 is the top line of the
//! map, the north edge). Everything outside the map counts as wall.
//!
//! The parts: what a maze holds (`elements`: [`Dir`], [`SignSpec`], [`WaitZone`] …),
//! the parser (`parse`, [`Maze::parse`]), its errors (`error`: [`MazeError`],
//! [`LineProblem`]) and the shipped mazes and files (`load`: [`Maze::builtin`],
//! [`Maze::load`]). The [`Maze`] itself and its grid queries are defined here.
mod elements;
mod error;
mod load;
mod parse;

pub use elements::{Dir, Lighting, Mount, SignSpec, WaitZone, cell_center};
pub use error::{LineProblem, MazeError};
pub use load::{BUILTIN_MAZES, TRAINING_MAZES};

/// A parsed maze.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Maze {
    /// Display name (`name` line, or the file stem).
    pub name: String,
    /// Cell edge, metres.
    pub cell: f64,
    /// Wall (and ceiling) height, metres.
    pub wall_height: f64,
    /// Sign board edge, metres (boards are square).
    pub sign_size: f64,
    /// Lighting.
    pub lighting: Lighting,
    /// Map width in cells.
    pub width: usize,
    /// Map height in cells.
    pub height: usize,
    /// `walls[row * width + col]`.
    pub walls: Vec<bool>,
    /// Start cell.
    pub start: (usize, usize),
    /// Initial heading.
    pub heading: Dir,
    /// The cell the drone must land in.
    pub goal: (usize, usize),
    /// Sign boards.
    pub signs: Vec<SignSpec>,
    /// WAIT zones.
    pub zones: Vec<WaitZone>,
}

impl Maze {
    /// True for wall cells and for everything outside the map.
    pub fn is_wall(&self, col: i64, row: i64) -> bool {
        if col < 0 || row < 0 || col >= self.width as i64 || row >= self.height as i64 {
            return true;
        }
        self.walls[row as usize * self.width + col as usize]
    }

    /// True when the world point `(x, y)` (metres) lies in a wall cell.
    pub fn is_wall_at(&self, x: f64, y: f64) -> bool {
        self.is_wall(
            (x / self.cell).floor() as i64,
            (y / self.cell).floor() as i64,
        )
    }

    /// The cell containing world point `(x, y)`, if inside the map.
    pub fn cell_of(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let (c, r) = ((x / self.cell).floor(), (y / self.cell).floor());
        (c >= 0.0 && r >= 0.0 && (c as usize) < self.width && (r as usize) < self.height)
            .then_some((c as usize, r as usize))
    }

    /// True when the goal cell can be reached from the start over floor cells
    /// (4-connected). Says nothing about whether the signs lead there.
    pub fn goal_connected(&self) -> bool {
        let mut seen = vec![false; self.walls.len()];
        let mut stack = vec![self.start];
        while let Some((c, r)) = stack.pop() {
            let i = r * self.width + c;
            if seen[i] {
                continue;
            }
            seen[i] = true;
            if (c, r) == self.goal {
                return true;
            }
            for d in [Dir::North, Dir::East, Dir::South, Dir::West] {
                let (dc, dr) = d.step();
                let (nc, nr) = (c as i64 + dc, r as i64 + dr);
                if !self.is_wall(nc, nr) {
                    stack.push((nc as usize, nr as usize));
                }
            }
        }
        false
    }
}
