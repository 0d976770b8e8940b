//! The drone's place in the maze: where it starts for a seed (and the per-seed random
//! numbers a flight draws), when its disc touches a wall, and yaw wrapping.
use crate::maze::{Maze, cell_center};
use crate::render::Pose;
use crate::texture::{hash_n, unit};

/// A per-seed random number in `[0, 1)`.
pub(super) fn rnd(seed: u64, k: i64) -> f64 {
    f64::from(unit(hash_n(&[seed as i64, k, 0x51])))
}

/// Where the drone starts for `seed`: the start cell's centre, moved up to ±0.15 m
/// sideways and ±0.3 m along the heading.
pub fn start_pose(maze: &Maze, seed: u64) -> Pose {
    let (cx, cy) = cell_center(maze.start, maze.cell);
    let (dx, dy) = maze.heading.vector();
    let along = (rnd(seed, 1) * 2.0 - 1.0) * 0.3;
    let side = (rnd(seed, 2) * 2.0 - 1.0) * 0.15;
    Pose {
        x: cx + dx * along - dy * side,
        y: cy + dy * along + dx * side,
        yaw: maze.heading.yaw(),
    }
}

/// True when a disc of `radius` at `(x, y)` overlaps a wall cell.
pub fn collides(maze: &Maze, x: f64, y: f64, radius: f64) -> bool {
    let cell = maze.cell;
    let (c, r) = ((x / cell).floor() as i64, (y / cell).floor() as i64);
    for dr in -1..=1 {
        for dc in -1..=1 {
            let (cc, rr) = (c + dc, r + dr);
            if !maze.is_wall(cc, rr) {
                continue;
            }
            let (x0, y0) = (cc as f64 * cell, rr as f64 * cell);
            let nx = x.clamp(x0, x0 + cell);
            let ny = y.clamp(y0, y0 + cell);
            if (nx - x).powi(2) + (ny - y).powi(2) < radius * radius {
                return true;
            }
        }
    }
    false
}

/// Yaw wrapping, shared with the navigator.
pub(super) use frugal_nav::heading::wrap;

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;
    use std::path::Path;

    #[test]
    fn collision_disc_against_cells() {
        let m = Maze::parse(
            "start 1 1 e\ngoal 1 1\nmap\n###\n#.#\n###\nend\n",
            Path::new("m"),
        )
        .unwrap();
        assert!(!collides(&m, 4.5, 4.5, 0.25));
        assert!(collides(&m, 3.1, 4.5, 0.25));
        assert!(collides(&m, 5.9, 5.9, 0.25));
    }

    #[test]
    fn start_pose_stays_near_the_start_cell_centre() {
        let m = Maze::parse(
            "start 1 1 s\ngoal 1 1\nmap\n###\n#.#\n###\nend\n",
            Path::new("m"),
        )
        .unwrap();
        for seed in 0..20 {
            let p = start_pose(&m, seed);
            assert!(
                (p.x - 4.5).abs() <= 0.15 + 1e-9 && (p.y - 4.5).abs() <= 0.3 + 1e-9,
                "{p:?}"
            );
            assert!((p.yaw - FRAC_PI_2).abs() < 1e-12);
        }
        assert_ne!(start_pose(&m, 1), start_pose(&m, 2));
    }
}
