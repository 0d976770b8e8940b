//! What a maze is made of besides its grid: compass directions, lighting, sign boards
//! and how they are mounted, WAIT zones and their pedestrians, and cell centres.
use frugal_data::Sign;

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

#[cfg(test)]
mod tests {
    use super::*;

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
}
