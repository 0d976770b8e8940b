//! The navigator's parameters ([`NavConfig`]): speeds, the distances at which a sign
//! is acted on, how many readings confirm it.
/// Navigation parameters.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
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

/// The distances of a [`NavConfig`] with its `None`s resolved for a corridor grid of
/// `cell` metres (a maze cell, or the spacing of junctions on a real course).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NavDistances {
    /// Turn when a confirmed turn sign is this close, metres.
    pub turn: f64,
    /// Land when a confirmed STOP sign is this close, metres.
    pub land: f64,
    /// Turn and STOP signs count only from this close, metres.
    pub commit: f64,
    /// Length of the zone after a WAIT stop, metres.
    pub wait_zone: f64,
    /// Distance after a turn before another turn sign is obeyed, metres.
    pub rearm: f64,
}

impl NavConfig {
    /// Resolve the distances left to their defaults for a grid of `cell` metres.
    pub fn distances(&self, cell: f64) -> NavDistances {
        let half_cell = cell / 2.0;
        let turn = self.turn_distance.unwrap_or(half_cell);
        let land = self.land_distance.unwrap_or(half_cell);
        NavDistances {
            turn,
            land,
            commit: self
                .commit_distance
                .unwrap_or(2.0 * cell)
                .max(turn)
                .max(land),
            wait_zone: self.wait_zone_length.unwrap_or(3.0 * cell),
            rearm: self.rearm_distance.unwrap_or(half_cell),
        }
    }

    /// Forward speed while cruising, m/s: the top speed, capped so that the drone flies
    /// at most `react_distance` between two processed frames `dt_avg` seconds apart.
    pub fn cruise_speed(&self, dt_avg: f64) -> f64 {
        self.v_max.min(self.react_distance / dt_avg)
    }
}
