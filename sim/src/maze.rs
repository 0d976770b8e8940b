//! Maze files: a small line-based text format (specified in the crate docs and in
//! `sim/mazes/README.md`) and its parser.
//!
//! Coordinates: cell `(col, row)` has its top-left corner at world `(col·cell,
//! row·cell)` metres; `x` grows east, `y` grows south (row 0 is the top line of the
//! map, the north edge). Everything outside the map counts as wall.
use frugal_data::Sign;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// A compass direction: a heading, or the side of a cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Dir {
    /// −y (up in the map).
    North,
    /// +x.
    East,
    /// +y (down in the map).
    South,
    /// −x.
    West,
}

impl Dir {
    /// Parse `n|e|s|w|north|east|south|west` (case-insensitive).
    pub fn parse(s: &str) -> Option<Dir> {
        match s.to_ascii_lowercase().as_str() {
            "n" | "north" => Some(Dir::North),
            "e" | "east" => Some(Dir::East),
            "s" | "south" => Some(Dir::South),
            "w" | "west" => Some(Dir::West),
            _ => None,
        }
    }

    /// The unit vector `(dx, dy)` in world coordinates (`y` grows south).
    pub fn vector(self) -> (f64, f64) {
        match self {
            Dir::North => (0.0, -1.0),
            Dir::East => (1.0, 0.0),
            Dir::South => (0.0, 1.0),
            Dir::West => (-1.0, 0.0),
        }
    }

    /// The grid step `(dcol, drow)`.
    pub fn step(self) -> (i64, i64) {
        match self {
            Dir::North => (0, -1),
            Dir::East => (1, 0),
            Dir::South => (0, 1),
            Dir::West => (-1, 0),
        }
    }

    /// The yaw angle in radians (0 = east, +π/2 = south, as `atan2(dy, dx)`).
    pub fn yaw(self) -> f64 {
        let (dx, dy) = self.vector();
        dy.atan2(dx)
    }
}

/// Scene lighting.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Lighting {
    /// Bright warehouse lighting, slight sensor noise.
    Normal,
    /// Dim, tinted, stronger falloff and sensor noise (like the dataset's low light).
    Low,
}

/// How a sign board is fixed to its wall.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mount {
    /// Flat on the wall face, facing into the cell (seen by a drone flying towards
    /// that wall).
    Flat,
    /// Sticking out of the wall, perpendicular to it, at the middle of the cell's
    /// side; printed on both faces (seen by a drone flying along that wall).
    Flag,
}

/// One sign board.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SignSpec {
    /// The sign drawn on the board.
    #[serde(with = "sign_name")]
    pub sign: Sign,
    /// The cell the board is in.
    pub cell: (usize, usize),
    /// The wall (side of the cell) it is fixed to; the neighbour on that side is a wall.
    pub wall: Dir,
    /// Height of the board's centre above the floor, metres.
    pub height: f64,
    /// Flat on the wall or sticking out of it.
    pub mount: Mount,
    /// The line of the maze file that declared it.
    pub line: usize,
}

mod sign_name {
    use frugal_data::Sign;
    pub fn serialize<S: serde::Serializer>(s: &Sign, ser: S) -> Result<S::Ok, S::Error> {
        ser.serialize_str(s.name())
    }
    pub fn deserialize<'de, D: serde::Deserializer<'de>>(de: D) -> Result<Sign, D::Error> {
        let name = <String as serde::Deserialize>::deserialize(de)?;
        Sign::from_name(&name)
            .ok_or_else(|| serde::de::Error::custom(format!("unknown sign {name}")))
    }
}

/// A WAIT zone: a cell that a pedestrian crosses on a schedule.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WaitZone {
    /// The zone's cell.
    pub cell: (usize, usize),
    /// The axis the pedestrian walks along (`North` = north–south, `East` = east–west).
    pub axis: Dir,
    /// Schedule period, seconds.
    pub period: f64,
    /// Fraction of the period during which a pedestrian is crossing, `(0, 1]`.
    pub duty: f64,
    /// Schedule offset, seconds (the flight's seed adds a random offset on top).
    pub phase: f64,
}

impl WaitZone {
    /// Where the zone's pedestrian is at time `t` (world metres), or `None` when nobody
    /// is crossing. The walk goes from 1.5 cells before the zone's centre to 1.5 cells
    /// after it along `axis`, alternating direction every period.
    pub fn pedestrian_at(&self, t: f64, offset: f64, cell_size: f64) -> Option<(f64, f64)> {
        let tt = t + self.phase + offset;
        let cycle = (tt / self.period).floor();
        let within = tt - cycle * self.period;
        let active = self.duty * self.period;
        if within >= active {
            return None;
        }
        let mut s = within / active; // 0..1 along the walk
        if (cycle as i64).rem_euclid(2) == 1 {
            s = 1.0 - s;
        }
        let (cx, cy) = cell_center(self.cell, cell_size);
        let along = (s - 0.5) * 3.0 * cell_size;
        Some(match self.axis {
            Dir::North | Dir::South => (cx, cy + along),
            Dir::East | Dir::West => (cx + along, cy),
        })
    }
}

/// The centre of a cell in world metres.
pub fn cell_center(cell: (usize, usize), cell_size: f64) -> (f64, f64) {
    (
        (cell.0 as f64 + 0.5) * cell_size,
        (cell.1 as f64 + 0.5) * cell_size,
    )
}

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

/// A cell reference still to be checked against the map, with its line.
struct PendingCell {
    line: usize,
    cell: (usize, usize),
}

/// The shipped mazes (`sim/mazes/*.maze`), compiled in: the paper's Easy (one turn),
/// Medium (two turns, one WAIT) and Hard (four turns, two WAITs).
pub const BUILTIN_MAZES: [(&str, &str); 3] = [
    ("easy", include_str!("../mazes/easy.maze")),
    ("medium", include_str!("../mazes/medium.maze")),
    ("hard", include_str!("../mazes/hard.maze")),
];

/// The shipped training mazes (`sim/mazes/train/`): flown only to record footage the
/// policy learns from (`frugal fly --record`), never in an evaluation.
pub const TRAINING_MAZES: [(&str, &str); 3] = [
    ("train-a", include_str!("../mazes/train/train-a.maze")),
    ("train-b", include_str!("../mazes/train/train-b.maze")),
    ("train-c", include_str!("../mazes/train/train-c.maze")),
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

    /// Parse maze text; `path` names the source in errors (and gives the default name).
    pub fn parse(text: &str, path: &Path) -> Result<Maze, MazeError> {
        let err = |line: usize, problem: LineProblem| MazeError::Line {
            path: path.to_owned(),
            line,
            problem,
        };
        let mut name: Option<String> = None;
        let mut cell = 3.0;
        let mut wall_height = 3.5;
        let mut sign_size = 0.45;
        let mut lighting = Lighting::Normal;
        let mut start: Option<(PendingCell, Dir)> = None;
        let mut goal: Option<PendingCell> = None;
        let mut signs: Vec<SignSpec> = Vec::new();
        let mut zones: Vec<(usize, WaitZone)> = Vec::new();
        let mut map: Option<(usize, Vec<Vec<bool>>)> = None;
        let mut seen: Vec<&'static str> = Vec::new();

        let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l));
        while let Some((ln, raw)) = lines.next() {
            let content = raw.split('#').next().unwrap_or("").trim();
            if content.is_empty() {
                continue;
            }
            let words: Vec<&str> = content.split_whitespace().collect();
            let (kw, args) = (words[0], &words[1..]);
            let once = |seen: &mut Vec<&'static str>, k: &'static str| {
                if seen.contains(&k) {
                    Err(err(ln, LineProblem::Duplicate(k)))
                } else {
                    seen.push(k);
                    Ok(())
                }
            };
            let arity = |k: &'static str, expected: &'static str, lo: usize, hi: usize| {
                if args.len() < lo || args.len() > hi {
                    Err(err(
                        ln,
                        LineProblem::Arity {
                            keyword: k,
                            expected,
                            got: args.len(),
                        },
                    ))
                } else {
                    Ok(())
                }
            };
            match kw {
                "name" => {
                    once(&mut seen, "name")?;
                    if args.is_empty() {
                        return Err(err(
                            ln,
                            LineProblem::Arity {
                                keyword: "name",
                                expected: "a name",
                                got: 0,
                            },
                        ));
                    }
                    name = Some(args.join(" "));
                }
                "cell" => {
                    once(&mut seen, "cell")?;
                    arity("cell", "1 (metres)", 1, 1)?;
                    cell = positive(args[0], "cell size in metres (0.5..=20)", 0.5, 20.0)
                        .map_err(|p| err(ln, p))?;
                }
                "wall_height" => {
                    once(&mut seen, "wall_height")?;
                    arity("wall_height", "1 (metres)", 1, 1)?;
                    wall_height = positive(args[0], "wall height in metres (1..=20)", 1.0, 20.0)
                        .map_err(|p| err(ln, p))?;
                }
                "sign_size" => {
                    once(&mut seen, "sign_size")?;
                    arity("sign_size", "1 (metres)", 1, 1)?;
                    sign_size = positive(args[0], "sign size in metres (0.05..=3)", 0.05, 3.0)
                        .map_err(|p| err(ln, p))?;
                }
                "light" => {
                    once(&mut seen, "light")?;
                    arity("light", "1 (normal or low)", 1, 1)?;
                    lighting = match args[0].to_ascii_lowercase().as_str() {
                        "normal" => Lighting::Normal,
                        "low" => Lighting::Low,
                        other => {
                            return Err(err(
                                ln,
                                LineProblem::BadValue {
                                    what: "lighting (normal or low)",
                                    value: other.to_owned(),
                                },
                            ));
                        }
                    };
                }
                "start" => {
                    once(&mut seen, "start")?;
                    arity("start", "3 (col row heading)", 3, 3)?;
                    let c = parse_cell(args[0], args[1]).map_err(|p| err(ln, p))?;
                    let h = parse_dir(args[2]).map_err(|p| err(ln, p))?;
                    start = Some((PendingCell { line: ln, cell: c }, h));
                }
                "goal" => {
                    once(&mut seen, "goal")?;
                    arity("goal", "2 (col row)", 2, 2)?;
                    let c = parse_cell(args[0], args[1]).map_err(|p| err(ln, p))?;
                    goal = Some(PendingCell { line: ln, cell: c });
                }
                "sign" => {
                    arity("sign", "5 or 6 (class col row wall height [flag])", 5, 6)?;
                    let sign = Sign::from_name(args[0])
                        .ok_or_else(|| err(ln, LineProblem::UnknownSign(args[0].to_owned())))?;
                    let c = parse_cell(args[1], args[2]).map_err(|p| err(ln, p))?;
                    let wall = parse_dir(args[3]).map_err(|p| err(ln, p))?;
                    let height = positive(args[4], "sign centre height in metres", 0.0, 20.0)
                        .map_err(|p| err(ln, p))?;
                    let mount = match args.get(5) {
                        None => Mount::Flat,
                        Some(m) if m.eq_ignore_ascii_case("flag") => Mount::Flag,
                        Some(m) if m.eq_ignore_ascii_case("flat") => Mount::Flat,
                        Some(m) => {
                            return Err(err(
                                ln,
                                LineProblem::BadValue {
                                    what: "mount (flat or flag)",
                                    value: (*m).to_owned(),
                                },
                            ));
                        }
                    };
                    signs.push(SignSpec {
                        sign,
                        cell: c,
                        wall,
                        height,
                        mount,
                        line: ln,
                    });
                }
                "wait" => {
                    arity("wait", "5 or 6 (col row axis period duty [phase])", 5, 6)?;
                    let c = parse_cell(args[0], args[1]).map_err(|p| err(ln, p))?;
                    let axis = match args[2].to_ascii_lowercase().as_str() {
                        "ns" => Dir::North,
                        "ew" => Dir::East,
                        other => {
                            return Err(err(
                                ln,
                                LineProblem::BadValue {
                                    what: "crossing axis (ns or ew)",
                                    value: other.to_owned(),
                                },
                            ));
                        }
                    };
                    let period = positive(args[3], "period in seconds (0.5..=3600)", 0.5, 3600.0)
                        .map_err(|p| err(ln, p))?;
                    let duty = positive(args[4], "duty fraction in (0, 1]", 1e-6, 1.0)
                        .map_err(|p| err(ln, p))?;
                    let phase = match args.get(5) {
                        Some(p) => {
                            positive(p, "phase in seconds", 0.0, 1e6).map_err(|pr| err(ln, pr))?
                        }
                        None => 0.0,
                    };
                    zones.push((
                        ln,
                        WaitZone {
                            cell: c,
                            axis,
                            period,
                            duty,
                            phase,
                        },
                    ));
                }
                "map" => {
                    once(&mut seen, "map")?;
                    arity("map", "nothing (rows follow, then `end`)", 0, 0)?;
                    let mut rows: Vec<Vec<bool>> = Vec::new();
                    let mut closed = false;
                    for (rln, row) in lines.by_ref() {
                        let row = row.trim_end();
                        if row.trim() == "end" {
                            closed = true;
                            break;
                        }
                        let mut cells = Vec::with_capacity(row.len());
                        for (col, ch) in row.chars().enumerate() {
                            match ch {
                                '#' => cells.push(true),
                                '.' => cells.push(false),
                                _ => return Err(err(rln, LineProblem::MapChar { ch, col })),
                            }
                        }
                        if let Some(first) = rows.first()
                            && first.len() != cells.len()
                        {
                            return Err(err(
                                rln,
                                LineProblem::RaggedRow {
                                    got: cells.len(),
                                    expected: first.len(),
                                },
                            ));
                        }
                        if cells.is_empty() {
                            return Err(err(
                                rln,
                                LineProblem::RaggedRow {
                                    got: 0,
                                    expected: rows.first().map_or(1, Vec::len),
                                },
                            ));
                        }
                        rows.push(cells);
                    }
                    if !closed {
                        return Err(err(ln, LineProblem::UnclosedMap));
                    }
                    map = Some((ln, rows));
                }
                other => return Err(err(ln, LineProblem::UnknownKeyword(other.to_owned()))),
            }
        }

        let missing = |what| MazeError::Missing {
            path: path.to_owned(),
            what,
        };
        let (map_line, rows) = map.ok_or_else(|| missing("map"))?;
        if rows.is_empty() {
            return Err(err(
                map_line,
                LineProblem::RaggedRow {
                    got: 0,
                    expected: 1,
                },
            ));
        }
        let (start, heading) = start.ok_or_else(|| missing("start"))?;
        let goal = goal.ok_or_else(|| missing("goal"))?;
        let height = rows.len();
        let width = rows[0].len();
        let walls: Vec<bool> = rows.into_iter().flatten().collect();
        let mut maze = Maze {
            name: name.unwrap_or_else(|| {
                path.file_stem()
                    .map_or_else(|| "maze".to_owned(), |s| s.to_string_lossy().into_owned())
            }),
            cell,
            wall_height,
            sign_size,
            lighting,
            width,
            height,
            walls,
            start: start.cell,
            heading,
            goal: goal.cell,
            signs: Vec::new(),
            zones: Vec::new(),
        };
        let floor_cell = |maze: &Maze, p: &PendingCell| -> Result<(), MazeError> {
            let (col, row) = p.cell;
            if col >= maze.width || row >= maze.height {
                return Err(err(
                    p.line,
                    LineProblem::OutOfMap {
                        col,
                        row,
                        width: maze.width,
                        height: maze.height,
                    },
                ));
            }
            if maze.is_wall(col as i64, row as i64) {
                return Err(err(p.line, LineProblem::InWall { col, row }));
            }
            Ok(())
        };
        floor_cell(&maze, &start)?;
        floor_cell(&maze, &goal)?;
        for s in &signs {
            floor_cell(
                &maze,
                &PendingCell {
                    line: s.line,
                    cell: s.cell,
                },
            )?;
            let (dc, dr) = s.wall.step();
            if !maze.is_wall(s.cell.0 as i64 + dc, s.cell.1 as i64 + dr) {
                return Err(err(
                    s.line,
                    LineProblem::NoWall {
                        col: s.cell.0,
                        row: s.cell.1,
                        side: s.wall,
                    },
                ));
            }
            let half = maze.sign_size / 2.0;
            if s.height - half < 0.0 || s.height + half > maze.wall_height {
                return Err(err(
                    s.line,
                    LineProblem::SignHeight {
                        height: s.height,
                        size: maze.sign_size,
                        wall_height: maze.wall_height,
                    },
                ));
            }
        }
        for (line, z) in &zones {
            floor_cell(
                &maze,
                &PendingCell {
                    line: *line,
                    cell: z.cell,
                },
            )?;
        }
        maze.signs = signs;
        maze.zones = zones.into_iter().map(|(_, z)| z).collect();
        Ok(maze)
    }

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

fn positive(s: &str, what: &'static str, lo: f64, hi: f64) -> Result<f64, LineProblem> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= lo && v <= hi => Ok(v),
        _ => Err(LineProblem::BadValue {
            what,
            value: s.to_owned(),
        }),
    }
}

fn parse_cell(c: &str, r: &str) -> Result<(usize, usize), LineProblem> {
    let one = |s: &str, what| {
        s.parse::<usize>().map_err(|_| LineProblem::BadValue {
            what,
            value: s.to_owned(),
        })
    };
    Ok((
        one(c, "column (0-based integer)")?,
        one(r, "row (0-based integer)")?,
    ))
}

fn parse_dir(s: &str) -> Result<Dir, LineProblem> {
    Dir::parse(s).ok_or_else(|| LineProblem::BadValue {
        what: "direction (n, e, s, w or north, east, south, west)",
        value: s.to_owned(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const OK: &str = "\
name tiny
cell 2
start 1 1 east
goal 3 1
sign stop 3 1 e 1.2
sign F49 2 1 n 2.0 flag
wait 2 1 ns 6 0.5 1
map
#####
#...#
#####
end
";

    fn parse(t: &str) -> Result<Maze, MazeError> {
        Maze::parse(t, Path::new("t.maze"))
    }

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
    fn parses_every_keyword() {
        let m = parse(OK).unwrap();
        assert_eq!(
            (m.name.as_str(), m.width, m.height, m.cell),
            ("tiny", 5, 3, 2.0)
        );
        assert_eq!((m.start, m.heading, m.goal), ((1, 1), Dir::East, (3, 1)));
        assert_eq!(m.signs.len(), 2);
        assert_eq!(
            (m.signs[1].sign, m.signs[1].mount, m.signs[1].line),
            (Sign::Wait, Mount::Flag, 6)
        );
        assert_eq!(m.zones[0].phase, 1.0);
        assert!(m.is_wall(0, 1) && !m.is_wall(1, 1) && m.is_wall(-1, 1) && m.is_wall(9, 9));
        assert!(m.goal_connected());
    }

    #[test]
    fn pedestrian_crosses_during_the_duty_part_and_alternates() {
        let z = WaitZone {
            cell: (2, 1),
            axis: Dir::North,
            period: 10.0,
            duty: 0.4,
            phase: 0.0,
        };
        let a = z.pedestrian_at(0.0, 0.0, 2.0).unwrap();
        let b = z.pedestrian_at(3.99, 0.0, 2.0).unwrap();
        assert!(
            (a.0 - 5.0).abs() < 1e-9 && (a.1 - 0.0).abs() < 1e-9,
            "{a:?}"
        );
        assert!(b.1 > 5.9, "{b:?}");
        assert!(z.pedestrian_at(5.0, 0.0, 2.0).is_none());
        let c = z.pedestrian_at(10.0, 0.0, 2.0).unwrap();
        assert!((c.1 - 6.0).abs() < 1e-9, "walks back: {c:?}");
    }

    #[test]
    fn malformed_lines_name_the_file_and_line() {
        type Check = fn(&LineProblem) -> bool;
        let cases: [(&str, usize, Check); 9] = [
            ("flyto 1 1\n", 1, |p| {
                matches!(p, LineProblem::UnknownKeyword(_))
            }),
            ("cell -2\n", 1, |p| {
                matches!(p, LineProblem::BadValue { .. })
            }),
            ("\n\nstart 1 1\n", 3, |p| {
                matches!(
                    p,
                    LineProblem::Arity {
                        keyword: "start",
                        ..
                    }
                )
            }),
            ("start 1 1 up\n", 1, |p| {
                matches!(p, LineProblem::BadValue { .. })
            }),
            ("sign yield 1 1 n 1\n", 1, |p| {
                matches!(p, LineProblem::UnknownSign(_))
            }),
            ("map\n###\n#x#\n###\nend\n", 3, |p| {
                matches!(p, LineProblem::MapChar { ch: 'x', col: 1 })
            }),
            ("map\n###\n#.\n###\nend\n", 3, |p| {
                matches!(
                    p,
                    LineProblem::RaggedRow {
                        got: 2,
                        expected: 3
                    }
                )
            }),
            ("light dark\n", 1, |p| {
                matches!(p, LineProblem::BadValue { .. })
            }),
            ("map\n###\n", 1, |p| matches!(p, LineProblem::UnclosedMap)),
        ];
        for (text, line, check) in cases {
            let e = parse(text).unwrap_err();
            assert_eq!(e.line(), Some(line), "{text:?}: {e}");
            assert!(check(e.problem().unwrap()), "{text:?}: {e}");
            assert!(
                e.to_string().starts_with(&format!("t.maze:{line}: ")),
                "{e}"
            );
        }
    }

    #[test]
    fn placement_errors_point_at_the_declaring_line() {
        let sub = |from: &str, to: &str| OK.replace(from, to);
        let e = parse(&sub("goal 3 1", "goal 0 1")).unwrap_err();
        assert_eq!(
            (e.line(), e.problem()),
            (Some(4), Some(&LineProblem::InWall { col: 0, row: 1 }))
        );
        let e = parse(&sub("start 1 1 east", "start 7 1 east")).unwrap_err();
        assert!(
            matches!(e.problem(), Some(LineProblem::OutOfMap { col: 7, .. })),
            "{e}"
        );
        let e = parse(&sub("sign stop 3 1 e 1.2", "sign stop 2 1 e 1.2")).unwrap_err();
        assert!(
            matches!(
                e.problem(),
                Some(LineProblem::NoWall {
                    side: Dir::East,
                    ..
                })
            ),
            "{e}"
        );
        assert_eq!(e.line(), Some(5));
        let e = parse(&sub("sign stop 3 1 e 1.2", "sign stop 3 1 e 3.4")).unwrap_err();
        assert!(
            matches!(e.problem(), Some(LineProblem::SignHeight { .. })),
            "{e}"
        );
        let e = parse(&sub("cell 2\n", "cell 2\ncell 3\n")).unwrap_err();
        assert_eq!(
            (e.line(), e.problem()),
            (Some(3), Some(&LineProblem::Duplicate("cell")))
        );
        let e = parse(&sub("goal 3 1\n", "")).unwrap_err();
        assert!(matches!(e, MazeError::Missing { what: "goal", .. }), "{e}");
        assert!(e.to_string().contains("t.maze"), "{e}");
    }

    #[test]
    fn unreadable_file_names_the_path() {
        let e = Maze::load(Path::new("/nonexistent/x.maze")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/x.maze"), "{e}");
    }
}
