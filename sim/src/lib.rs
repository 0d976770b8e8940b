//! The closed-loop maze simulator: the paper's end-to-end experiment (warehouse mazes,
//! a drone that turns at arrow signs, waits for pedestrians at WAIT signs and lands at
//! the STOP sign) with the real perception in the loop.
//!
//! - [`maze`]: the maze file format (below) and its parser;
//! - [`render`]: a first-person camera — DDA ray casting over the grid, textured
//!   walls (racks, boxes, panels), floor and ceiling, lighting with falloff and noise,
//!   sign boards drawn with `frugal_data::render_sign` (as in the training data) and
//!   pedestrians as sprites behind a per-column z-buffer — and the exact ground truth
//!   of each frame ([`FrameTruth`]);
//! - [`perception`]: the [`Perception`] trait the loop calls per frame,
//!   [`GroundTruthPerception`], [`DetectorPerception`] (any
//!   `frugal_runtime::Detector` every frame, timed: the static baseline), and
//!   [`DeviceProfile`] (compute time × slowdown = simulated time);
//! - [`flight`]: the navigator and the loop, [`fly`] → [`FlightResult`];
//! - [`report`]: the paper's table (mean ± spread), JSON / CSV, top views (plotters,
//!   PNG + SVG), annotated frames and GIFs.
//!
//! # Flying a maze
//!
//! ```
//! use frugal_sim::{CameraSpec, FlightConfig, GroundTruthPerception, Maze, Outcome};
//! let maze = Maze::parse(
//!     "cell 3\nstart 1 1 east\ngoal 3 1\nsign stop 3 1 e 1.2\nmap\n#####\n#...#\n#####\nend\n",
//!     "doc.maze".as_ref(),
//! )?;
//! let config = FlightConfig {
//!     camera: CameraSpec { width: 160, height: 90, ..CameraSpec::default() },
//!     ..FlightConfig::default()
//! };
//! let result = frugal_sim::fly(&maze, &config, &mut GroundTruthPerception::default(), 1, None)?;
//! assert_eq!(result.outcome, Outcome::Success);
//! // 5 ms per frame × the tx2-like slowdown 6 = 30 ms: 33 fps, so the 0.4 m/s cap holds.
//! assert!((result.fps - 33.3).abs() < 0.1);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Plugging in a detector
//!
//! Implement [`Perception`] (or pass a closure): it gets the rendered RGB frame and the
//! simulated clock, returns detections and the compute time it used. The loop turns
//! that time into simulated seconds with the device's slowdown, so a slow detector
//! really slows the flight (`v ≤ react_distance × fps`).
//!
//! ```
//! use frugal_sim::{FrameInput, Percept, PerceptionError};
//! let mut nothing = |input: &FrameInput<'_>| -> Result<Percept, PerceptionError> {
//!     let started = std::time::Instant::now();
//!     let _pixels = input.image.rgb; // run a detector on these
//!     Ok(Percept { detections: Vec::new(), compute_ms: started.elapsed().as_secs_f64() * 1e3, ..Percept::default() })
//! };
//! # let _ = &mut nothing;
//! ```
//!
//! # Maze files
//!
//! Plain text, one statement per line; `#` starts a comment outside the map block;
//! blank lines are ignored. Cells are `col row`, 0-based, row 0 at the top (north) of
//! the map; `x` grows east and `y` grows south. Anything outside the map is wall.
//!
//! | statement | meaning | default |
//! |---|---|---|
//! | `name <text>` | display name | the file stem |
//! | `cell <m>` | cell edge (aisle width), metres | 3 |
//! | `wall_height <m>` | wall and ceiling height | 3.5 |
//! | `sign_size <m>` | edge of the square sign boards | 0.45 |
//! | `light normal\|low` | lighting (low: dim, tinted, noisy) | normal |
//! | `start <col> <row> <heading>` | take-off cell and heading (`n e s w` or names) | required |
//! | `goal <col> <row>` | the cell the drone must land in | required |
//! | `sign <class> <col> <row> <wall> <height> [flat\|flag]` | a board with the sign `class` (name such as `turn_left` or code such as `B5`) fixed to the `wall` side of the cell, centre `height` m above the floor; `flat` lies on the wall facing into the cell, `flag` sticks out of the wall, printed on both faces, seen by a drone flying along that wall | flat |
//! | `wait <col> <row> ns\|ew <period> <duty> [phase]` | a WAIT zone: a pedestrian crosses the cell along the axis, walking 1.5 cells either side of its centre, during the first `duty` fraction of every `period` seconds (direction alternates); `phase` shifts the schedule, and each flight's seed adds a random shift | phase 0 |
//! | `map` … `end` | the grid: one line per row, `#` wall, `.` floor, all rows equally long | required |
//!
//! A malformed file gives a [`MazeError`] naming the file and the line.
//!
//! # The navigator
//!
//! The drone flies along its heading at `min(v_max, react_distance / frame interval)`.
//! It estimates the distance of each detected sign from its box height,
//! `d = f · sign_size / h`; a centred turn sign closer than half a cell makes it turn
//! 90° in place; a WAIT sign closer than 3 m makes it hover (at least 1 s, and while a
//! pedestrian is in view; pedestrians come from a separate person sensor, i.e. the
//! renderer's ground truth), and for the next three cells it hovers whenever a
//! pedestrian is in view; a centred STOP sign closer than half a cell makes it land
//! (success if in the goal cell). Touching a wall ends the flight as a collision; not
//! landing within the time limit ends it as a failure.
#![deny(missing_docs)]

pub mod adaptive;
pub mod flight;
pub mod maze;
pub mod perception;
pub mod record;
pub mod render;
pub mod report;
pub mod texture;

pub use adaptive::{AdaptivePerception, static_onnx};
pub use flight::{
    ConfirmationRead, FlightConfig, FlightError, FlightResult, FrameView, Mode, NavCommand,
    NavConfig, Outcome, fly,
};
pub use maze::{Dir, Lighting, LineProblem, Maze, MazeError, Mount, SignSpec, WaitZone};
pub use perception::{
    DetectorPerception, DeviceProfile, FrameInput, GroundTruthPerception, Percept, Perception,
    PerceptionError,
};
pub use record::{FootageRecorder, flight_log_file, percepts_file};
pub use render::{CameraSpec, FrameTruth, PedestrianTruth, Pose, Renderer, SignTruth};
