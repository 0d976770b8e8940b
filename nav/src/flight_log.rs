//! A flight log ([`FlightLog`]): one CSV row per processed frame with what the
//! navigator was given besides the image (decision time, distance flown, heading,
//! whether a pedestrian was close) and the command it issued. `frugal fly --record`
//! writes one per flight next to the footage; the drone-side program replays footage
//! with it (`frugal-pilot --odometry FILE`) in place of the autopilot's odometry.
//!
//! ```text
//! frame,capture_s,decision_s,odometer_m,yaw_rad,pedestrian_close,command
//! 0,0,0.0166667,0,0,false,
//! …
//! 212,3.52,3.53667,1.21,0,false,turn_left
//! ```
use crate::navigator::NavCommand;
use std::path::{Path, PathBuf};

/// One processed frame.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LogRow {
    /// The frame's number in the footage (0, 1, 2, …).
    pub frame: u64,
    /// Capture time, seconds.
    pub capture_s: f64,
    /// Time of the decision on it, seconds.
    pub decision_s: f64,
    /// Distance flown at the decision, metres.
    pub odometer_m: f64,
    /// Heading at the decision, radians.
    pub yaw_rad: f64,
    /// A pedestrian was in view within the navigator's pedestrian distance.
    pub pedestrian_close: bool,
    /// The command issued on this frame.
    pub command: Option<NavCommand>,
}

/// A bad or unreadable flight log.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct LogError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong.
    pub message: String,
}

/// The rows of one flight, in frame order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FlightLog {
    /// The rows.
    pub rows: Vec<LogRow>,
}

impl FlightLog {
    /// Read `path`; rows must come in frame order 0, 1, 2, … with times that never go
    /// back.
    pub fn read(path: &Path) -> Result<Self, LogError> {
        let err = |message: String| LogError {
            path: path.to_owned(),
            message,
        };
        let mut reader = csv::Reader::from_path(path).map_err(|e| err(e.to_string()))?;
        let mut rows: Vec<LogRow> = Vec::new();
        for (i, row) in reader.deserialize().enumerate() {
            let row: LogRow = row.map_err(|e| err(format!("row {}: {e}", i + 1)))?;
            if row.frame != i as u64 {
                return Err(err(format!(
                    "row {} is frame {}, expected frame {i}",
                    i + 1,
                    row.frame
                )));
            }
            let finite = [row.capture_s, row.decision_s, row.odometer_m, row.yaw_rad]
                .iter()
                .all(|v| v.is_finite());
            let back = rows.last().is_some_and(|p: &LogRow| {
                row.capture_s < p.capture_s || row.odometer_m < p.odometer_m
            });
            if !finite || back || row.decision_s < row.capture_s {
                return Err(err(format!(
                    "row {}: times and odometer must be finite and never go back",
                    i + 1
                )));
            }
            rows.push(row);
        }
        if rows.is_empty() {
            return Err(err("no rows".into()));
        }
        Ok(Self { rows })
    }

    /// Write the log to `path`.
    pub fn write(&self, path: &Path) -> Result<(), LogError> {
        let err = |message: String| LogError {
            path: path.to_owned(),
            message,
        };
        let mut w = csv::Writer::from_path(path).map_err(|e| err(e.to_string()))?;
        for row in &self.rows {
            w.serialize(row).map_err(|e| err(e.to_string()))?;
        }
        w.flush().map_err(|e| err(e.to_string()))
    }

    /// The commands issued, in order, with their frames.
    pub fn commands(&self) -> Vec<(u64, NavCommand)> {
        self.rows
            .iter()
            .filter_map(|r| r.command.map(|c| (r.frame, c)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_log_round_trips_and_bad_rows_name_the_file() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("flight.csv");
        let row = |frame: u64, command| LogRow {
            frame,
            capture_s: frame as f64 * 0.1,
            decision_s: frame as f64 * 0.1 + 0.05,
            odometer_m: frame as f64 * 0.01,
            yaw_rad: 0.0,
            pedestrian_close: false,
            command,
        };
        let log = FlightLog {
            rows: vec![
                row(0, None),
                row(1, Some(NavCommand::TurnLeft)),
                row(2, None),
            ],
        };
        log.write(&path).unwrap();
        assert_eq!(FlightLog::read(&path).unwrap(), log);
        assert_eq!(log.commands(), vec![(1, NavCommand::TurnLeft)]);
        let mut gap = log.clone();
        gap.rows.remove(1);
        gap.write(&path).unwrap();
        let e = FlightLog::read(&path).unwrap_err().to_string();
        assert!(
            e.contains("flight.csv") && e.contains("expected frame 1"),
            "{e}"
        );
        std::fs::write(&path, "frame,capture_s\n0,x\n").unwrap();
        let e = FlightLog::read(&path).unwrap_err().to_string();
        assert!(e.contains("flight.csv") && e.contains("row 1"), "{e}");
    }
}

/// One detection as the JSON lines of a flight's perception record and of the pilot's
/// output and `--detections` files write it: `{"class", "score", "box": [x1, y1, x2,
/// y2]}` in pixels of the camera.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct DetectionRecord {
    /// Class id.
    pub class: u16,
    /// Score.
    pub score: f32,
    /// `[x1, y1, x2, y2]`.
    #[serde(rename = "box")]
    pub bbox: [f32; 4],
}

impl From<&frugal_runtime::Detection> for DetectionRecord {
    fn from(d: &frugal_runtime::Detection) -> Self {
        Self {
            class: d.class,
            score: d.score,
            bbox: [d.bbox.x1, d.bbox.y1, d.bbox.x2, d.bbox.y2],
        }
    }
}
