//! What a flight produces: how it ended ([`Outcome`]), its record ([`FlightResult`]:
//! trajectory, events, detection counts, confirmations), what an observer sees of
//! each processed frame ([`FrameView`]), and why a flight could not be run
//! ([`FlightError`]).
use crate::perception::{DeviceProfile, PerceptionError};
use crate::render::{FrameTruth, Pose};
pub use frugal_nav::{ConfirmationRead, Mode, NavCommand};
use frugal_runtime::{Detection, FrameRef};
use thiserror::Error;

/// How a flight ended.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Outcome {
    /// Landed in the goal cell.
    Success,
    /// Landed at a STOP sign outside the goal cell.
    LandedOutsideGoal {
        /// The cell it landed in.
        cell: (usize, usize),
    },
    /// Touched a wall.
    Collision {
        /// Where, world metres.
        x: f64,
        /// Where, world metres.
        y: f64,
    },
    /// Did not land within the time limit.
    TimeLimit {
        /// The limit, seconds.
        limit_s: f64,
    },
}

impl Outcome {
    /// True for [`Outcome::Success`].
    pub fn is_success(&self) -> bool {
        matches!(self, Outcome::Success)
    }

    /// One line for people.
    pub fn describe(&self) -> String {
        match self {
            Outcome::Success => "landed at the goal".into(),
            Outcome::LandedOutsideGoal { cell } => {
                format!("landed at a STOP sign in cell {cell:?}, not the goal")
            }
            Outcome::Collision { x, y } => format!("collided with a wall at ({x:.2}, {y:.2}) m"),
            Outcome::TimeLimit { limit_s } => {
                format!("goal not reached within the {limit_s:.0} s time limit")
            }
        }
    }
}

/// A point of the trajectory.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrackPoint {
    /// Simulated time, s.
    pub t: f64,
    /// East, m.
    pub x: f64,
    /// South, m.
    pub y: f64,
    /// Yaw, rad.
    pub yaw: f64,
    /// Navigator mode.
    pub mode: Mode,
}

/// Something the navigator did.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Event {
    /// Simulated time, s.
    pub t: f64,
    /// East, m.
    pub x: f64,
    /// South, m.
    pub y: f64,
    /// What happened.
    pub what: String,
}

/// The record of one flight.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FlightResult {
    /// Maze name.
    pub maze: String,
    /// Seed.
    pub seed: u64,
    /// Perception label.
    pub perception: String,
    /// Device profile.
    pub device: DeviceProfile,
    /// How it ended.
    pub outcome: Outcome,
    /// Simulated duration, s.
    pub time_s: f64,
    /// Processed frames.
    pub frames: u64,
    /// Processed frames per simulated second.
    pub fps: f64,
    /// Distance flown, m.
    pub path_m: f64,
    /// `path_m / time_s`, m/s.
    pub avg_velocity: f64,
    /// Mean perception compute time (before the slowdown), ms.
    pub compute_ms_mean: f64,
    /// Of it, the mean time in int8 detectors ([`crate::Percept::int8_ms`]), ms: the
    /// part charged by the device's int8 slowdown when it states one.
    #[serde(default)]
    pub int8_ms_mean: f64,
    /// Of it, the mean time outside the detectors ([`crate::Percept::tracker_ms`]:
    /// tracker and decision), ms: the part charged by the device's tracker slowdown
    /// when it states one.
    #[serde(default)]
    pub tracker_ms_mean: f64,
    /// Mean wall-clock render time per frame on this machine, ms.
    pub render_ms_mean: f64,
    /// Simulated seconds spent hovering at WAIT signs or for pedestrians.
    pub wait_s: f64,
    /// Frames in which a sign was visible (≥ 8 px tall, ≥ half visible).
    pub sign_frames: u64,
    /// Of those, how many had a detection of the right class with IoU ≥ 0.5.
    pub sign_hits: u64,
    /// Detections matching no visible sign.
    pub false_detections: u64,
    /// Readings asked of the perception's most accurate detector to confirm a sign
    /// ([`Perception::confirm`]).
    ///
    /// [`Perception::confirm`]: crate::Perception::confirm
    #[serde(default)]
    pub confirmations: u64,
    /// Of the confirmations, those that dropped a sighting: the first reading of it
    /// found no turn or STOP sign at its spot (a re-reading that finds none abstains
    /// until such readings outnumber the votes of its action; see `Sighting::blanks`).
    #[serde(default)]
    pub rejections: u64,
    /// Every confirmation reading, against the renderer's ground truth: how often,
    /// and how far away, the most accurate detector misreads a sign.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub confirmation_reads: Vec<ConfirmationRead>,
    /// What the perception ran during the flight, by name ([`Perception::counts`]:
    /// for the adaptive runtime, frames detected by trigger and runs per variant).
    ///
    /// [`Perception::counts`]: crate::Perception::counts
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub perception_counts: Vec<(String, u64)>,
    /// Trajectory, sampled every 0.25 s and at every mode change.
    pub track: Vec<TrackPoint>,
    /// Turns, waits, landing, collision.
    pub events: Vec<Event>,
}

/// What an observer sees of each processed frame.
pub struct FrameView<'a> {
    /// Frame index.
    pub index: u64,
    /// Capture time, s.
    pub time_s: f64,
    /// Drone pose at capture.
    pub pose: Pose,
    /// The image.
    pub image: FrameRef<'a>,
    /// The ground truth.
    pub truth: &'a FrameTruth,
    /// What perception returned.
    pub detections: &'a [Detection],
    /// Those detections were carried by a tracker, not detected on this frame.
    pub tracked: bool,
    /// The navigator asked perception to read this frame again with its reference
    /// detector: `Some(None)` when perception has none (ground truth), `Some(Some(d))`
    /// with what it read; `None` when it did not ask.
    pub confirm: Option<Option<&'a [Detection]>>,
    /// The navigator's mode after deciding on this frame.
    pub mode: Mode,
    /// Time of the decision on this frame, s.
    pub decision_s: f64,
    /// Distance flown at the decision, m.
    pub odometer: f64,
    /// Heading given to the navigator at the decision, rad.
    pub yaw: f64,
    /// A pedestrian was in view within the navigator's pedestrian distance.
    pub pedestrian_close: bool,
    /// The command the navigator issued on this frame.
    pub command: Option<NavCommand>,
}

/// Why a flight could not be run (a failed flight is not an error: see [`Outcome`]).
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum FlightError {
    /// Perception failed on a frame.
    #[error("perception `{name}` failed on frame {frame}: {source}")]
    Perception {
        /// Perception label.
        name: String,
        /// Frame index.
        frame: u64,
        /// The cause.
        source: PerceptionError,
    },
    /// A nonsensical parameter.
    #[error("invalid flight parameter: {0}")]
    Config(String),
}
