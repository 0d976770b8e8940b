//! The closed loop: render → perceive → decide → fly, with simulated time advanced by
//! the perception's compute time × the device slowdown.
//!
//! Timing model. Frame `k` is captured at simulated time `t_k` (the world — drone pose,
//! pedestrians — as it is then). Perception takes `dt_k = compute_ms / 1000 × slowdown`
//! seconds (at least one camera period); during `[t_k, t_k + dt_k]` the drone keeps
//! flying on the command decided from the previous frame; at `t_{k+1} = t_k + dt_k`
//! the navigator decides from frame `k`'s detections and the next frame is captured.
//!
//! Speed cap. The drone may not fly further than `react_distance` between two
//! processed frames: `v = min(v_max, react_distance / dt̄)` with `dt̄` an exponential
//! average of recent frame intervals, so slow perception really slows the flight.
use crate::maze::{Maze, cell_center};
use crate::perception::{DeviceProfile, FrameInput, Perception, PerceptionError};
use crate::render::{CameraSpec, FrameTruth, Pose, Renderer, SignTruth, Walker};
use crate::texture::{hash_n, unit};
use frugal_data::{NavAction, Sign};
use frugal_runtime::{BBox, Detection, FrameRef};
use std::f64::consts::{FRAC_PI_2, TAU};
use std::time::Instant;
use thiserror::Error;

/// A turn or STOP sign read ahead: its action, where it stands on the odometer, the
/// last distance read, and its support: +1 per agreeing reading, × [`SUPPORT_DECAY`]
/// per processed frame that neither reads it nor carries a tracked box onto it, so
/// only a sign read on most recent detection frames reaches `confirm_frames`.
#[derive(Clone, Copy, Debug)]
struct Sighting {
    action: NavAction,
    at: f64,
    dist: f64,
    /// The renderer's depth of the sign under the last reading's box, when its box
    /// overlaps one: not used to navigate, only to report how far off a reading was.
    true_dist: Option<f64>,
    support: f64,
    /// The highest support reached; a sighting that reached `confirm_frames` is
    /// kept (and acted on) even when the sign is no longer readable close up.
    peak: f64,
    /// Confirmed by the perception's most accurate detector ([`Perception::confirm`]),
    /// or by its readings alone when it has nothing more accurate: only a verified
    /// sighting is acted on.
    verified: bool,
    /// Its action was read by the most accurate detector: readings of any turn or STOP
    /// at its spot support it (a cheap detector that mirrors an arrow steadily still
    /// places it right).
    settled: bool,
    /// The most accurate detector's readings of it so far, by action
    /// ([`action_index`]): re-read every [`RECONFIRM_EVERY`] metres while it is
    /// approached, the majority decides its action (one accurate reading of a small
    /// far arrow can be mirrored too).
    votes: [f64; 4],
    /// Re-readings by the most accurate detector that found no turn or STOP sign at its
    /// spot. A sign it once read can be missed on a frame, so one such reading abstains;
    /// but once they outnumber the votes of its action, the first reading was a false
    /// alarm and the sighting is dropped (without this rule, a confirmed false "turn
    /// left" on a wall, never read again over 2.4 m, turned the drone into that wall;
    /// rule added in a931b6b).
    blanks: f64,
    /// Odometer at its last confirmation.
    confirmed_at: f64,
    /// A tracker carried a box onto it this frame: its support does not fade.
    held: bool,
    /// Least-squares fit of the distance read against the odometer over the
    /// sighting's readings: a sign that stands still comes closer by as much as the
    /// drone flies (slope −1). A far sign whose box a detector cannot draw small enough
    /// is read at the same distance however far the drone flies (slope ≈ 0): its spot
    /// moves with the drone, and acting on it turns the drone metres early.
    fit: LineFit,
}

/// Per-frame decay of a sighting's support.
const SUPPORT_DECAY: f64 = 0.8;
/// A sighting is acted on only once its readings span this much flight, metres …
const MIN_SPAN: f64 = 0.5;
/// … and its distance shrinks at least this fast per metre flown.
const MIN_APPROACH: f64 = 0.5;
/// Readings spanning this much flight whose distance shrinks slower than
/// [`RESTART_APPROACH`] per metre flown: the spot has moved with the drone, and the
/// sighting starts again from the latest reading (a far sign read too close, then
/// really approached, is not held back by its early readings).
const RESTART_SPAN: f64 = 1.0;
/// See [`RESTART_SPAN`].
const RESTART_APPROACH: f64 = 0.25;
/// A confirmed sign is read again by the most accurate detector every this many
/// metres flown until the drone acts on it.
const RECONFIRM_EVERY: f64 = 1.0;

/// One reading per sign: a detection is dropped when a higher-scoring one of any class
/// covers the same box (IoU ≥ 0.5). The detectors suppress overlaps per class, so a
/// WAIT pictogram can come back as WAIT at 0.9 and as a turn at 0.55; without this,
/// a confirmation found the turn among the reference detector's boxes and the drone
/// turned 21 m early into a wall (hard maze, tx2-like device; fixed in a09cb98).
fn outranked_dropped(detections: &[Detection]) -> impl Iterator<Item = &Detection> {
    detections.iter().filter(move |d| {
        !detections
            .iter()
            .any(|e| e.score > d.score && e.bbox.iou(&d.bbox) >= 0.5)
    })
}

/// How far apart (metres) two readings of a sign `dist` ahead may place it and still
/// be the same sign: box heights are read to about 15 %.
fn spot_tolerance(dist: f64) -> f64 {
    0.5 + 0.15 * dist
}

fn action_index(a: NavAction) -> usize {
    match a {
        NavAction::TurnLeft => 0,
        NavAction::TurnRight => 1,
        NavAction::Stop => 2,
        NavAction::Wait => 3,
    }
}

/// Running least-squares line through (odometer, distance read) points.
#[derive(Clone, Copy, Debug, Default)]
struct LineFit {
    n: f64,
    sx: f64,
    sy: f64,
    sxx: f64,
    sxy: f64,
    x_min: f64,
    x_max: f64,
}

impl LineFit {
    fn new(x: f64, y: f64) -> Self {
        let mut f = Self {
            x_min: x,
            x_max: x,
            ..Self::default()
        };
        f.add(x, y);
        f
    }

    fn add(&mut self, x: f64, y: f64) {
        self.n += 1.0;
        self.sx += x;
        self.sy += y;
        self.sxx += x * x;
        self.sxy += x * y;
        self.x_min = self.x_min.min(x);
        self.x_max = self.x_max.max(x);
    }

    /// Odometer span of the points, metres.
    fn span(&self) -> f64 {
        self.x_max - self.x_min
    }

    /// How fast the distance read shrinks per metre flown (1 for a sign standing
    /// still); `None` with fewer than two distinct odometer readings.
    fn approach(&self) -> Option<f64> {
        let var = self.n * self.sxx - self.sx * self.sx;
        (var > 1e-9 * self.n * self.n).then(|| -(self.n * self.sxy - self.sx * self.sy) / var)
    }
}

impl Sighting {
    fn new(action: NavAction, odo: f64, dist: f64, true_dist: Option<f64>) -> Self {
        Self {
            action,
            at: odo + dist,
            dist,
            true_dist,
            support: 1.0,
            peak: 1.0,
            verified: false,
            settled: false,
            votes: [0.0; 4],
            blanks: 0.0,
            confirmed_at: f64::NEG_INFINITY,
            held: false,
            fit: LineFit::new(odo, dist),
        }
    }

    /// Another reading of this sign, `dist` ahead at odometer `odo` (`true_dist`: see
    /// [`Sighting::true_dist`]).
    fn read(&mut self, odo: f64, dist: f64, true_dist: Option<f64>) {
        self.fit.add(odo, dist);
        if self.fit.span() >= RESTART_SPAN
            && self.fit.approach().is_some_and(|a| a < RESTART_APPROACH)
        {
            *self = Self::new(self.action, odo, dist, true_dist);
            return;
        }
        self.support += 1.0;
        self.peak = self.peak.max(self.support);
        self.at = odo + dist; // the closer reading is the better one
        self.dist = dist;
        self.true_dist = true_dist;
    }

    /// A tracker carried a box onto it ([`Percept::tracked`](crate::Percept::tracked)):
    /// the sign is still in view, so its support does not fade this frame. The box is
    /// the tracker's prediction from the last detection, not a new reading: it adds no
    /// support (a weak false detection carried for `M` frames would otherwise build
    /// the support of a measured sign and be confirmed), and its size does not place
    /// the sign.
    fn hold(&mut self) {
        self.held = true;
    }

    /// The most accurate detector read it as `action`, `dist` ahead at `odo`: a vote,
    /// and the majority of the votes is its action (a tie goes to this reading).
    fn confirmed(&mut self, action: NavAction, odo: f64, dist: f64, true_dist: Option<f64>) {
        self.read(odo, dist, true_dist);
        self.votes[action_index(action)] += 1.0;
        let mine = self.votes[action_index(action)];
        if self.votes[action_index(self.action)] <= mine {
            self.action = action;
        }
        self.verified = true;
        self.settled = true;
        self.confirmed_at = odo;
    }

    /// Read over enough flight to tell, and coming closer as a standing sign does.
    fn stands_still(&self) -> bool {
        self.fit.span() >= MIN_SPAN && self.fit.approach().is_some_and(|a| a >= MIN_APPROACH)
    }
}

/// Navigation parameters.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NavConfig {
    /// Top speed, m/s.
    pub v_max: f64,
    /// Furthest the drone may fly between two processed frames, metres.
    pub react_distance: f64,
    /// Turn when a centred turn sign is estimated this close, metres (`None`: half a
    /// cell, i.e. at the junction's centre when the sign is on its far wall).
    pub turn_distance: Option<f64>,
    /// Land when a centred STOP sign is estimated this close (`None`: half a cell).
    pub land_distance: Option<f64>,
    /// A centred turn or STOP sign read at most this far away (`None`: two cells)
    /// schedules the manoeuvre by odometry, at `turn_distance` / `land_distance` from
    /// the sign; later readings refine the schedule. Close up, where a sign fills the
    /// frame, the drone need not read it again.
    pub commit_distance: Option<f64>,
    /// Stop and hover when a WAIT sign is estimated this close, metres.
    pub wait_distance: f64,
    /// Shortest hover at a WAIT sign, seconds.
    pub wait_min_s: f64,
    /// After a WAIT stop, for this many metres travelled the drone hovers whenever a
    /// pedestrian is in view closer than `pedestrian_distance` (`None`: three cells).
    pub wait_zone_length: Option<f64>,
    /// Pedestrians further than this (depth, metres) are ignored.
    pub pedestrian_distance: f64,
    /// Turn and STOP signs count only when their box centre is within this fraction
    /// of the image width from the centre.
    pub centre_band: f64,
    /// Yaw rate while turning, degrees per second (the drone hovers while it turns).
    pub yaw_rate_deg: f64,
    /// Distance to travel after a turn before another turn sign is obeyed (`None`:
    /// half a cell).
    pub rearm_distance: Option<f64>,
    /// Drone radius for collisions with walls, metres.
    pub radius: f64,
    /// Simulated time after which a flight that has not landed fails, seconds.
    pub time_limit_s: f64,
    /// The camera delivers at most this many frames per second.
    pub camera_fps: f64,
    /// A sign makes the drone act only after this many readings agree on it: for
    /// WAIT, this many processed frames in a row; for a turn or STOP, readings of the
    /// same action that place the sign at the same spot ahead (within 0.5 m + 15 % of
    /// the distance), counted with a decay of 0.8 per processed frame (so it must be
    /// read on most recent frames), and more than any other action read there.
    pub confirm_frames: u32,
}

impl Default for NavConfig {
    /// The paper's regime: 40 cm/s top speed, 3 cm reaction distance (so 1.9 fps
    /// gives ≈ 5.7 cm/s, as the paper's static model), 90°/s turns.
    fn default() -> Self {
        Self {
            v_max: 0.4,
            react_distance: 0.03,
            turn_distance: None,
            land_distance: None,
            commit_distance: None,
            wait_distance: 3.0,
            wait_min_s: 1.0,
            wait_zone_length: None,
            pedestrian_distance: 8.0,
            centre_band: 0.3,
            yaw_rate_deg: 90.0,
            rearm_distance: None,
            radius: 0.25,
            time_limit_s: 3600.0,
            camera_fps: 60.0,
            confirm_frames: 3,
        }
    }
}

/// Everything a flight needs besides the maze and the perception.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FlightConfig {
    /// The camera.
    pub camera: CameraSpec,
    /// Navigation parameters.
    pub nav: NavConfig,
    /// The on-board computer.
    pub device: DeviceProfile,
}

impl Default for FlightConfig {
    fn default() -> Self {
        Self {
            camera: CameraSpec::default(),
            nav: NavConfig::default(),
            device: DeviceProfile::tx2_like(),
        }
    }
}

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

/// The navigator's state.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// Flying along the corridor.
    Cruise,
    /// Hovering while a pedestrian is in view in a WAIT zone.
    HoldForPedestrian,
    /// Turning in place towards a new heading.
    Turning,
    /// Hovering at a WAIT sign.
    Waiting,
    /// Landed (or crashed); the flight is over.
    Done,
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
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub perception_counts: Vec<(String, u64)>,
    /// Trajectory, sampled every 0.25 s and at every mode change.
    pub track: Vec<TrackPoint>,
    /// Turns, waits, landing, collision.
    pub events: Vec<Event>,
}

/// One confirmation of a sighting by the most accurate detector
/// ([`Perception::confirm`]), next to what the renderer knows.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ConfirmationRead {
    /// Simulated time, s.
    pub t: f64,
    /// The sighting's action before this reading.
    pub sighting: NavAction,
    /// The turn or STOP sign read at the sighting's spot (`None`: none there).
    pub read: Option<NavAction>,
    /// Its distance from its box height, metres.
    pub read_m: Option<f64>,
    /// What the sign under the read box (the one it overlaps most) tells the drone to do …
    pub truth: Option<NavAction>,
    /// … and its depth, metres.
    pub true_m: Option<f64>,
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
    /// The navigator's mode after deciding on this frame.
    pub mode: Mode,
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

/// A per-seed random number in `[0, 1)`.
fn rnd(seed: u64, k: i64) -> f64 {
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

fn wrap(a: f64) -> f64 {
    let a = a.rem_euclid(TAU);
    if a > std::f64::consts::PI { a - TAU } else { a }
}

/// Fly `maze` once with `perception` and `seed`. `observer` sees every processed frame
/// (to save images); pass `None` when not needed.
pub fn fly(
    maze: &Maze,
    config: &FlightConfig,
    perception: &mut dyn Perception,
    seed: u64,
    mut observer: Option<&mut dyn FnMut(&FrameView<'_>)>,
) -> Result<FlightResult, FlightError> {
    let nav = &config.nav;
    let cam = config.camera;
    if !(nav.v_max > 0.0
        && nav.react_distance > 0.0
        && nav.time_limit_s > 0.0
        && nav.camera_fps > 0.0)
    {
        return Err(FlightError::Config(
            "v_max, react_distance, time_limit_s and camera_fps must be positive".into(),
        ));
    }
    if !(config.device.slowdown > 0.0 && config.device.slowdown.is_finite()) {
        return Err(FlightError::Config(format!(
            "device slowdown must be positive, got {}",
            config.device.slowdown
        )));
    }
    if cam.width < 16 || cam.height < 16 || !(1.0..179.0).contains(&cam.hfov_deg) {
        return Err(FlightError::Config(format!(
            "camera {}×{} with {}° field of view",
            cam.width, cam.height, cam.hfov_deg
        )));
    }
    let half_cell = maze.cell / 2.0;
    let turn_distance = nav.turn_distance.unwrap_or(half_cell);
    let land_distance = nav.land_distance.unwrap_or(half_cell);
    let commit_distance = nav
        .commit_distance
        .unwrap_or(2.0 * maze.cell)
        .max(turn_distance)
        .max(land_distance);
    let zone_length = nav.wait_zone_length.unwrap_or(3.0 * maze.cell);
    let rearm = nav.rearm_distance.unwrap_or(half_cell);
    let yaw_rate = nav.yaw_rate_deg.to_radians();
    let name = perception.name();

    let mut renderer = Renderer::new(maze, cam, seed);
    let offsets: Vec<f64> = (0..maze.zones.len())
        .map(|i| rnd(seed, 100 + i as i64) * maze.zones[i].period)
        .collect();
    let mut pose = start_pose(maze, seed);
    let mut target_yaw = pose.yaw;
    let mut mode = Mode::Cruise;
    let mut speed = 0.0; // hover until the first frame is processed
    let mut t = 0.0;
    let mut dt_avg: Option<f64> = None;
    let mut odo = 0.0;
    let mut turn_armed_at = 0.0;
    let mut wait_zone_until = f64::NEG_INFINITY;
    let mut wait_started = 0.0;
    let mut wait_s = 0.0;
    let mut streak: Option<(NavAction, u32)> = None;
    // turn and STOP signs read ahead, placed on the odometer
    let mut sightings: Vec<Sighting> = Vec::new();
    let mut rgb = Vec::new();
    let mut track = vec![TrackPoint {
        t,
        x: pose.x,
        y: pose.y,
        yaw: pose.yaw,
        mode,
    }];
    let mut events = Vec::new();
    let mut frames = 0u64;
    let (mut compute_total, mut render_total) = (0.0, 0.0);
    let (mut sign_frames, mut sign_hits, mut false_detections) = (0u64, 0u64, 0u64);
    let (mut confirmations, mut rejections) = (0u64, 0u64);
    let mut confirmation_reads = Vec::new();
    // compute time of confirmations, charged to the next interval
    let mut pending_ms = 0.0;
    let f_px = cam.focal_px();
    let min_dt = 1.0 / nav.camera_fps;
    let outcome;

    loop {
        // Capture.
        let walkers: Vec<Walker> = maze
            .zones
            .iter()
            .enumerate()
            .filter_map(|(i, z)| {
                z.pedestrian_at(t, offsets[i], maze.cell).map(|pos| Walker {
                    zone: i,
                    pos,
                    phase: (t + offsets[i]) * 5.0,
                })
            })
            .collect();
        let started = Instant::now();
        let truth = renderer.render(pose, &walkers, frames, &mut rgb);
        render_total += started.elapsed().as_secs_f64() * 1e3;
        let image = FrameRef {
            width: cam.width,
            height: cam.height,
            rgb: &rgb,
        };
        let input = FrameInput {
            image,
            time_s: t,
            index: frames,
            truth: &truth,
        };
        let percept = perception
            .perceive(&input)
            .map_err(|source| FlightError::Perception {
                name: name.clone(),
                frame: frames,
                source,
            })?;
        compute_total += percept.compute_ms;
        score(
            &truth,
            &percept.detections,
            &mut sign_frames,
            &mut sign_hits,
            &mut false_detections,
        );
        let compute_ms = percept.compute_ms.max(0.0) + std::mem::take(&mut pending_ms);
        let dt = (compute_ms / 1e3 * config.device.slowdown).max(min_dt);
        dt_avg = Some(dt_avg.map_or(dt, |a| a * 0.7 + dt * 0.3));

        // Fly the interval on the current command.
        let mut crashed = None;
        let mut remaining = dt.min(nav.time_limit_s - t + 1e-9);
        while remaining > 0.0 {
            let step = if speed > 0.0 {
                remaining.min(0.02 / speed)
            } else {
                remaining
            };
            if mode == Mode::Turning {
                let diff = wrap(target_yaw - pose.yaw);
                let turn = (yaw_rate * step).min(diff.abs());
                pose.yaw = wrap(pose.yaw + turn * diff.signum());
            } else if speed > 0.0 {
                let (nx, ny) = (
                    pose.x + pose.yaw.cos() * speed * step,
                    pose.y + pose.yaw.sin() * speed * step,
                );
                odo += speed * step;
                pose.x = nx;
                pose.y = ny;
                if collides(maze, nx, ny, nav.radius) {
                    crashed = Some((nx, ny));
                    t += step;
                    break;
                }
            }
            if matches!(mode, Mode::Waiting | Mode::HoldForPedestrian) {
                wait_s += step;
            }
            t += step;
            remaining -= step;
        }
        frames += 1;
        if let Some((x, y)) = crashed {
            events.push(Event {
                t,
                x,
                y,
                what: "collision".into(),
            });
            outcome = Outcome::Collision { x, y };
            break;
        }
        if t >= nav.time_limit_s {
            outcome = Outcome::TimeLimit {
                limit_s: nav.time_limit_s,
            };
            break;
        }

        // Decide on this frame's detections.
        let prev_mode = mode;
        let ped_close = truth
            .pedestrians
            .iter()
            .any(|p| p.depth <= nav.pedestrian_distance);
        let mut landed = false;
        match mode {
            Mode::Turning => {
                if wrap(target_yaw - pose.yaw).abs() < 1e-6 {
                    pose.yaw = target_yaw;
                    mode = Mode::Cruise;
                    turn_armed_at = odo + rearm;
                }
            }
            Mode::Waiting => {
                if t - wait_started >= nav.wait_min_s && !ped_close {
                    mode = Mode::Cruise;
                    wait_zone_until = odo + zone_length;
                    events.push(Event {
                        t,
                        x: pose.x,
                        y: pose.y,
                        what: "resume: WAIT zone clear".into(),
                    });
                }
            }
            Mode::Cruise | Mode::HoldForPedestrian => {
                mode = Mode::Cruise;
                // what a detection would make the drone do, and how far away the sign is
                let reading = |d: &Detection| {
                    let action = Sign::from_id(d.class)?.action()?;
                    let dist = f_px * maze.sign_size / f64::from(d.bbox.height()).max(1e-3);
                    let (cx, _) = d.bbox.center();
                    let centred = (f64::from(cx) - f64::from(cam.width) / 2.0).abs()
                        <= nav.centre_band * f64::from(cam.width);
                    let acts = match action {
                        NavAction::Stop => centred && dist <= commit_distance,
                        NavAction::TurnLeft | NavAction::TurnRight => {
                            centred && dist <= commit_distance && odo >= turn_armed_at
                        }
                        NavAction::Wait => dist <= nav.wait_distance && odo >= wait_zone_until,
                    };
                    acts.then_some((action, dist))
                };
                // the first detection this frame that would make the drone act …
                let candidate = outranked_dropped(&percept.detections)
                    .find_map(|d| reading(d).map(|(action, dist)| (action, dist, d.bbox)));
                let need = nav.confirm_frames.max(1);
                match candidate {
                    Some((NavAction::Wait, dist, _)) => {
                        // … a WAIT sign after `need` frames in a row …
                        streak = match streak {
                            Some((NavAction::Wait, n)) => Some((NavAction::Wait, n + 1)),
                            _ => Some((NavAction::Wait, 1)),
                        };
                        if streak.is_some_and(|(_, n)| n >= need) {
                            mode = Mode::Waiting;
                            wait_started = t;
                            streak = None;
                            events.push(Event {
                                t,
                                x: pose.x,
                                y: pose.y,
                                what: format!("stop at WAIT (estimated {dist:.2} m)"),
                            });
                        }
                    }
                    // … a turn or STOP sign is placed on the odometer, where readings
                    // of it accumulate
                    Some((action, dist, bbox)) => {
                        streak = None;
                        let at = odo + dist;
                        let tol = spot_tolerance(dist);
                        let true_dist = || true_sign(&truth, &bbox).map(|g| g.depth);
                        match sightings
                            .iter_mut()
                            .find(|s| (s.action == action || s.settled) && (s.at - at).abs() <= tol)
                        {
                            // a carried box holds a sighting's support but adds none,
                            // and neither places nor starts a sighting: it repeats the
                            // last detection (a weak false one would build support
                            // frame after frame) and its size is the tracker's
                            // prediction (a box stuck at one size close up would push
                            // the manoeuvre ahead of the drone)
                            Some(s) if percept.tracked => s.hold(),
                            Some(s) => s.read(odo, dist, true_dist()),
                            None if percept.tracked => {}
                            None => sightings.push(Sighting::new(action, odo, dist, true_dist())),
                        }
                    }
                    None => streak = None,
                }
                let need_f = f64::from(need);
                let trigger_of = |s: &Sighting| {
                    if s.action == NavAction::Stop {
                        land_distance
                    } else {
                        turn_distance
                    }
                };
                // a sighting that has just built enough support is read again by the
                // perception's most accurate detector before anything is scheduled on
                // it (one per frame), and again every RECONFIRM_EVERY metres until it
                // is due: the majority of its readings at the same spot decides the
                // action; where the first reads no turn or STOP sign, the sighting is
                // dropped
                if let Some(i) = sightings.iter().position(|s| {
                    s.peak >= need_f
                        && (!s.verified
                            || (s.settled
                                && odo - s.confirmed_at >= RECONFIRM_EVERY
                                && odo < s.at - trigger_of(s)))
                }) {
                    let check =
                        perception
                            .confirm(&input)
                            .map_err(|source| FlightError::Perception {
                                name: name.clone(),
                                frame: frames - 1,
                                source,
                            })?;
                    match check {
                        None => sightings
                            .iter_mut()
                            .filter(|s| s.peak >= need_f)
                            .for_each(|s| s.verified = true),
                        Some(check) => {
                            confirmations += 1;
                            pending_ms += check.compute_ms.max(0.0);
                            compute_total += check.compute_ms.max(0.0);
                            let s = &mut sightings[i];
                            let tol = |dist: f64| spot_tolerance(dist.max(s.dist));
                            let agrees = outranked_dropped(&check.detections)
                                .filter_map(|d| reading(d).map(|r| (r, d.bbox)))
                                .find(|&((action, dist), _)| {
                                    action != NavAction::Wait
                                        && (odo + dist - s.at).abs() <= tol(dist)
                                });
                            let seen = agrees.and_then(|(_, bbox)| true_sign(&truth, &bbox));
                            confirmation_reads.push(ConfirmationRead {
                                t,
                                sighting: s.action,
                                read: agrees.map(|((action, _), _)| action),
                                read_m: agrees.map(|((_, dist), _)| dist),
                                truth: seen.and_then(|g| Sign::from_id(g.class)?.action()),
                                true_m: seen.map(|g| g.depth),
                            });
                            if let Some(((action, dist), _)) = agrees {
                                let (before, was) = (s.action, s.verified);
                                let true_dist = seen.map(|g| g.depth);
                                s.confirmed(action, odo, dist, true_dist);
                                if !was || s.action != before {
                                    events.push(Event {
                                        t,
                                        x: pose.x,
                                        y: pose.y,
                                        what: format!(
                                            "{before:?} sign {dist:.2} m ahead{} confirmed as {:?}",
                                            truly(true_dist),
                                            s.action
                                        ),
                                    });
                                }
                            } else if s.verified {
                                // confirmed before: this reading abstains, unless such
                                // readings now outnumber the votes of its action
                                s.blanks += 1.0;
                                s.confirmed_at = odo;
                                let best = s.votes.iter().copied().fold(0.0, f64::max);
                                if s.blanks > best {
                                    let (action, at) = (s.action, s.at);
                                    events.push(Event {
                                        t,
                                        x: pose.x,
                                        y: pose.y,
                                        what: format!(
                                            "{action:?} sign {:.2} m ahead no longer confirmed ({} readings of nothing there)",
                                            at - odo,
                                            s.blanks
                                        ),
                                    });
                                    sightings.remove(i);
                                }
                            } else {
                                rejections += 1;
                                let at = s.at;
                                events.push(Event {
                                    t,
                                    x: pose.x,
                                    y: pose.y,
                                    what: format!(
                                        "{:?} sign {:.2} m ahead not confirmed",
                                        sightings[i].action,
                                        at - odo
                                    ),
                                });
                                sightings.remove(i);
                            }
                        }
                    }
                }
                // signs already passed, or not read for a while, are forgotten
                sightings.retain(|s| s.at > odo - 0.5 && (s.peak >= need_f || s.support > 0.05));
                // carry out the best-supported manoeuvre once the odometer reaches it
                let due = sightings
                    .iter()
                    .filter(|s| {
                        let trigger = trigger_of(s);
                        s.peak >= need_f && s.verified && s.stands_still() && odo >= s.at - trigger
                    })
                    .filter(|s| {
                        // contradicted at the same spot (within the matching tolerance of
                        // the farther reading) by another confirmed action last read
                        // closer (a sign read close up, its arrow a larger box, is the
                        // better reading; equally close: the better supported): not
                        // this one
                        !sightings.iter().any(|o| {
                            let tol = spot_tolerance(o.dist.max(s.dist)).max(1.0);
                            o.action != s.action
                                && (o.at - s.at).abs() <= tol
                                && o.peak >= need_f
                                && o.verified
                                && (o.dist < s.dist || (o.dist == s.dist && o.peak >= s.peak))
                        })
                    })
                    .filter(|s| {
                        // superseded by a sighting just beyond it that was read after
                        // its last reading: the same sign, read short from afar (its
                        // box too large) and then read right as the drone came closer
                        !sightings.iter().any(|o| {
                            let gap = o.at - s.at;
                            gap > 0.0
                                && gap <= 2.0 * spot_tolerance(s.dist)
                                && o.fit.x_max > s.fit.x_max
                                && o.peak >= need_f
                                && o.verified
                                && o.stands_still()
                        })
                    })
                    .max_by(|a, b| a.peak.total_cmp(&b.peak))
                    .copied();
                for s in &mut sightings {
                    if !std::mem::take(&mut s.held) {
                        s.support *= SUPPORT_DECAY;
                    }
                }
                match due {
                    Some(Sighting {
                        action: NavAction::Stop,
                        dist,
                        true_dist,
                        ..
                    }) if mode == Mode::Cruise => {
                        sightings.clear();
                        landed = true;
                        events.push(Event {
                            t,
                            x: pose.x,
                            y: pose.y,
                            what: format!(
                                "land at STOP (last read at {dist:.2} m{})",
                                truly(true_dist)
                            ),
                        });
                    }
                    Some(Sighting {
                        action: action @ (NavAction::TurnLeft | NavAction::TurnRight),
                        dist,
                        true_dist,
                        fit,
                        ..
                    }) if mode == Mode::Cruise => {
                        sightings.clear();
                        let left = action == NavAction::TurnLeft;
                        target_yaw = wrap(pose.yaw + if left { -FRAC_PI_2 } else { FRAC_PI_2 });
                        // Snap to the grid axes so turns do not accumulate error.
                        target_yaw = wrap((target_yaw / FRAC_PI_2).round() * FRAC_PI_2);
                        mode = Mode::Turning;
                        events.push(Event {
                            t,
                            x: pose.x,
                            y: pose.y,
                            what: format!(
                                "turn {} (last read at {dist:.2} m{}; {} readings over {:.2} m, approach {:.2})",
                                if left { "left" } else { "right" },
                                truly(true_dist),
                                fit.n,
                                fit.span(),
                                fit.approach().unwrap_or(f64::NAN)
                            ),
                        });
                    }
                    _ => {}
                }
                if mode == Mode::Cruise && odo < wait_zone_until && ped_close {
                    mode = Mode::HoldForPedestrian;
                }
            }
            Mode::Done => {}
        }
        speed = match mode {
            Mode::Cruise => nav.v_max.min(nav.react_distance / dt_avg.unwrap_or(dt)),
            _ => 0.0,
        };
        if landed {
            mode = Mode::Done;
        }
        if let Some(obs) = observer.as_mut() {
            obs(&FrameView {
                index: frames - 1,
                time_s: t - dt,
                pose,
                image,
                truth: &truth,
                detections: &percept.detections,
                mode,
            });
        }
        let last_t = track.last().map_or(0.0, |p| p.t);
        if mode != prev_mode || t - last_t >= 0.25 {
            track.push(TrackPoint {
                t,
                x: pose.x,
                y: pose.y,
                yaw: pose.yaw,
                mode,
            });
        }
        if landed {
            let cell = maze
                .cell_of(pose.x, pose.y)
                .unwrap_or((usize::MAX, usize::MAX));
            outcome = if cell == maze.goal {
                Outcome::Success
            } else {
                Outcome::LandedOutsideGoal { cell }
            };
            break;
        }
    }
    track.push(TrackPoint {
        t,
        x: pose.x,
        y: pose.y,
        yaw: pose.yaw,
        mode: Mode::Done,
    });
    let n = frames.max(1) as f64;
    Ok(FlightResult {
        maze: maze.name.clone(),
        seed,
        perception: name,
        device: config.device.clone(),
        outcome,
        time_s: t,
        frames,
        fps: if t > 0.0 { frames as f64 / t } else { 0.0 },
        path_m: odo,
        avg_velocity: if t > 0.0 { odo / t } else { 0.0 },
        compute_ms_mean: compute_total / n,
        render_ms_mean: render_total / n,
        wait_s,
        sign_frames,
        sign_hits,
        false_detections,
        confirmations,
        rejections,
        confirmation_reads,
        perception_counts: perception.counts(),
        track,
        events,
    })
}

/// The sign board that `bbox` overlaps most, if it overlaps one: what a reading of
/// that box should have said.
fn true_sign<'t>(truth: &'t FrameTruth, bbox: &BBox) -> Option<&'t SignTruth> {
    truth
        .signs
        .iter()
        .map(|s| (s.bbox.iou(bbox), s))
        .filter(|&(iou, _)| iou > 0.0)
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, s)| s)
}

/// ", truly X m" for an event, when the renderer knows the distance.
fn truly(true_dist: Option<f64>) -> String {
    true_dist.map_or_else(String::new, |d| format!(", truly {d:.2} m"))
}

/// In-loop detection quality against the renderer's ground truth.
fn score(
    truth: &FrameTruth,
    dets: &[Detection],
    frames: &mut u64,
    hits: &mut u64,
    false_dets: &mut u64,
) {
    let visible: Vec<_> = truth
        .signs
        .iter()
        .filter(|s| s.bbox.height() >= 8.0 && s.visible_fraction >= 0.5)
        .collect();
    if !visible.is_empty() {
        *frames += 1;
        let found = visible.iter().any(|s| {
            dets.iter()
                .any(|d| d.class == s.class && d.bbox.iou(&s.bbox) >= 0.5)
        });
        if found {
            *hits += 1;
        }
    }
    *false_dets += dets
        .iter()
        .filter(|d| {
            !truth
                .signs
                .iter()
                .any(|s| s.class == d.class && d.bbox.iou(&s.bbox) >= 0.3)
        })
        .count() as u64;
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn a_sign_read_as_two_classes_counts_once_as_its_best_class() {
        use frugal_runtime::BBox;
        let det = |class: Sign, score: f32, x: f32| Detection {
            bbox: BBox::new(x, 100.0, x + 24.0, 124.0),
            score,
            class: class.id(),
        };
        // the WAIT pictogram, also read as a turn at a lower score (per-class NMS
        // keeps both), and a real turn sign elsewhere in the frame
        let dets = [
            det(Sign::TurnRight, 0.55, 101.0),
            det(Sign::Wait, 0.9, 100.0),
            det(Sign::TurnRight, 0.6, 300.0),
        ];
        let kept: Vec<(Option<Sign>, f32)> = outranked_dropped(&dets)
            .map(|d| (Sign::from_id(d.class), d.score))
            .collect();
        assert_eq!(
            kept,
            vec![(Some(Sign::Wait), 0.9), (Some(Sign::TurnRight), 0.6)]
        );
        // boxes that merely touch are two signs
        let apart = [
            det(Sign::Wait, 0.9, 100.0),
            det(Sign::TurnRight, 0.55, 118.0),
        ];
        assert_eq!(outranked_dropped(&apart).count(), 2);
    }

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
