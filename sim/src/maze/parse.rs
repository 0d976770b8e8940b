//! The maze file parser, [`Maze::parse`]: one statement per line, then the checks
//! that need the whole map (cells inside it and on floor, signs against a wall and
//! between floor and ceiling).
use super::{Dir, Lighting, LineProblem, Maze, MazeError, Mount, SignSpec, WaitZone};
use frugal_data::Sign;
use std::path::Path;

/// A cell reference still to be checked against the map, with its line.
struct PendingCell {
    line: usize,
    cell: (usize, usize),
}

impl Maze {
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
}
