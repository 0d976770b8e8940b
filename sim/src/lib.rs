//! Closed-loop maze simulator (being written).
#![deny(missing_docs)]

pub mod flight;
pub mod maze;
pub mod perception;
pub mod render;
pub mod texture;

pub use flight::{FlightConfig, FlightError, FlightResult, FrameView, Mode, NavConfig, Outcome, fly};
pub use maze::{Dir, LineProblem, Lighting, Maze, MazeError, Mount, SignSpec, WaitZone};
pub use perception::{DeviceProfile, FrameInput, GroundTruthPerception, Percept, Perception, PerceptionError};
pub use render::{CameraSpec, FrameTruth, PedestrianTruth, Pose, Renderer, SignTruth};
