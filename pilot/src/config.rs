//! The pilot's configuration file (TOML): the camera's intrinsics and frame size, the
//! signs' size and the corridor grid, the navigator's parameters, the MAVLink ids and
//! the input's retry policy. Every table and key is optional; unknown keys are
//! refused, naming the file.
//!
//! ```toml
//! [camera]
//! width = 480          # frames are scaled to this size, pixels
//! height = 270
//! hfov_deg = 70.0      # horizontal field of view (or focal_px = …)
//!
//! [signs]
//! size_m = 0.45        # height of a sign board, metres
//! cell_m = 3.0         # junction spacing: default turn / land / commit distances
//!
//! [nav]                # the navigator's parameters (frugal_nav::NavConfig)
//! confirm_frames = 3
//!
//! [mavlink]
//! system_id = 1        # this program's ids
//! component_id = 191   # MAV_COMP_ID_ONBOARD_COMPUTER
//! target_system = 1    # the autopilot's
//! target_component = 1
//! heartbeat_hz = 1.0
//! turn_tolerance_deg = 3.0   # --mavlink-odometry: a turn is over this close to its target
//!
//! [input]
//! retries = 5          # reconnections in a row before giving up
//! backoff_ms = 500     # first wait, doubled on each failure (capped at 8 s)
//! stall_timeout_ms = 2000
//! queue = 1            # frames that may wait for perception; the oldest drops first
//! ```
use frugal_nav::NavConfig;
use std::path::{Path, PathBuf};

/// A configuration file that cannot be used.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct ConfigError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong.
    pub message: String,
}

/// The camera.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    /// Frame width the input is scaled to, pixels.
    pub width: u32,
    /// Frame height the input is scaled to, pixels.
    pub height: u32,
    /// Horizontal field of view, degrees (used when `focal_px` is not given).
    pub hfov_deg: f64,
    /// Focal length at `width`, pixels (from a calibration).
    pub focal_px: Option<f64>,
}

impl Default for CameraConfig {
    /// The simulator's camera: 480×270, 70°.
    fn default() -> Self {
        Self {
            width: 480,
            height: 270,
            hfov_deg: 70.0,
            focal_px: None,
        }
    }
}

impl CameraConfig {
    /// The focal length in pixels: `focal_px`, else `width / 2 / tan(hfov / 2)`.
    pub fn focal(&self) -> f64 {
        self.focal_px.unwrap_or_else(|| {
            f64::from(self.width) / 2.0 / (self.hfov_deg.to_radians() / 2.0).tan()
        })
    }
}

/// The signs and the course.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SignConfig {
    /// Height of a sign board, metres.
    pub size_m: f64,
    /// Spacing of the junctions, metres: the navigator's distances left unset default
    /// to fractions of it.
    pub cell_m: f64,
    /// What the drone does on each of the detector's classes, by class id:
    /// `turn_left`, `turn_right`, `stop`, `wait` or `none` (as the dataset's manifest
    /// lists them). Unset: the ten synthetic signs' meanings.
    pub actions: Option<Vec<String>>,
}

impl SignConfig {
    /// The action table the navigator flies by (`None`: the ten signs').
    pub fn action_table(&self) -> Result<Option<Vec<Option<frugal_data::NavAction>>>, String> {
        let Some(names) = &self.actions else {
            return Ok(None);
        };
        names
            .iter()
            .enumerate()
            .map(|(class, name)| match name.trim() {
                "none" | "" => Ok(None),
                n => frugal_data::NavAction::from_name(n).map(Some).ok_or_else(|| {
                    format!(
                        "signs: actions[{class}] is {n:?} (turn_left, turn_right, stop, wait or none)"
                    )
                }),
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Some)
    }
}

impl Default for SignConfig {
    /// The simulator's mazes: 0.45 m boards, 3 m cells.
    fn default() -> Self {
        Self {
            size_m: 0.45,
            cell_m: 3.0,
            actions: None,
        }
    }
}

/// MAVLink identities and rates.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MavlinkConfig {
    /// This program's system id.
    pub system_id: u8,
    /// This program's component id.
    pub component_id: u8,
    /// The autopilot's system id (commands' target).
    pub target_system: u8,
    /// The autopilot's component id.
    pub target_component: u8,
    /// HEARTBEATs per second.
    pub heartbeat_hz: f64,
    /// With `--mavlink-odometry`: a turn is over when the autopilot's heading is this
    /// close to the turn's target, degrees.
    pub turn_tolerance_deg: f64,
}

impl Default for MavlinkConfig {
    /// System 1, component 191 (onboard computer), target 1/1, 1 Hz heartbeat.
    fn default() -> Self {
        Self {
            system_id: 1,
            component_id: 191,
            target_system: 1,
            target_component: 1,
            heartbeat_hz: 1.0,
            turn_tolerance_deg: 3.0,
        }
    }
}

/// How a live input is retried.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InputConfig {
    /// Failed (re)connections in a row before the program gives up.
    pub retries: u32,
    /// First wait before reconnecting, milliseconds; doubled on each failure in a row,
    /// at most 8 s.
    pub backoff_ms: u64,
    /// No frame for this long: the stream has stalled and is reconnected, ms.
    pub stall_timeout_ms: u64,
    /// Frames that may wait for perception (1..=8). When one more arrives, the oldest
    /// is dropped: perception is never more than this many frames behind the camera.
    /// 1 (the default) keeps only the newest, the lowest latency; more lets the fast
    /// tracked frames after a slow detection catch up instead of dropping, at the cost
    /// of acting on older frames.
    pub queue: usize,
}

impl Default for InputConfig {
    fn default() -> Self {
        Self {
            retries: 5,
            backoff_ms: 500,
            stall_timeout_ms: 2000,
            queue: 1,
        }
    }
}

/// The whole file.
#[derive(Clone, Debug, Default, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PilotConfig {
    /// The camera.
    pub camera: CameraConfig,
    /// The signs.
    pub signs: SignConfig,
    /// The navigator.
    pub nav: NavConfig,
    /// MAVLink.
    pub mavlink: MavlinkConfig,
    /// Live inputs.
    pub input: InputConfig,
}

impl PilotConfig {
    /// Read and check `path`.
    pub fn read(path: &Path) -> Result<Self, ConfigError> {
        let err = |message: String| ConfigError {
            path: path.to_owned(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
        let config: Self =
            toml::from_str(&text).map_err(|e| err(e.message().replace('\n', " ")))?;
        config.check().map_err(err)?;
        Ok(config)
    }

    /// Check the values.
    pub fn check(&self) -> Result<(), String> {
        let c = &self.camera;
        if c.width < 16 || c.height < 16 || c.width > 8192 || c.height > 8192 {
            return Err(format!(
                "camera size {}x{} is out of 16..=8192",
                c.width, c.height
            ));
        }
        if !(c.focal().is_finite() && c.focal() > 0.0 && (1.0..179.0).contains(&c.hfov_deg)) {
            return Err("camera: hfov_deg must be in 1..179 and focal_px positive".into());
        }
        let s = &self.signs;
        if !(s.size_m > 0.0 && s.size_m.is_finite() && s.cell_m > 0.0 && s.cell_m.is_finite()) {
            return Err("signs: size_m and cell_m must be positive".into());
        }
        s.action_table()?;
        let n = &self.nav;
        if !(n.v_max > 0.0 && n.react_distance > 0.0 && n.yaw_rate_deg > 0.0) {
            return Err("nav: v_max, react_distance and yaw_rate_deg must be positive".into());
        }
        if !(self.mavlink.heartbeat_hz > 0.0 && self.mavlink.heartbeat_hz.is_finite()) {
            return Err("mavlink: heartbeat_hz must be positive".into());
        }
        let tol = self.mavlink.turn_tolerance_deg;
        if !(tol > 0.0 && tol < 45.0) {
            return Err(format!(
                "mavlink: turn_tolerance_deg must be between 0 and 45, not {tol}"
            ));
        }
        if self.input.stall_timeout_ms == 0 {
            return Err("input: stall_timeout_ms must be positive".into());
        }
        if !(1..=8).contains(&self.input.queue) {
            return Err(format!(
                "input: queue must be between 1 and 8 frames, not {}",
                self.input.queue
            ));
        }
        Ok(())
    }
}
