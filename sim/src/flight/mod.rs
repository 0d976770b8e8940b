//! The closed loop: render → perceive → decide → fly, with simulated time advanced by
//! the perception's compute time × the device slowdown.
//!
//! Timing model. Frame `k` is captured at simulated time `t_k` (the world — drone pose,
//! pedestrians — as it is then). Perception takes `dt_k = compute_ms / 1000 × slowdown`
//! seconds (at least one camera period; the part spent in int8 detectors × the
//! profile's int8 slowdown when it states one, [`crate::DeviceProfile::device_ms`]);
//! during `[t_k, t_k + dt_k]` the drone keeps
//! flying on the command decided from the previous frame; at `t_{k+1} = t_k + dt_k`
//! the navigator decides from frame `k`'s detections and the next frame is captured.
//!
//! Speed cap. The drone may not fly further than `react_distance` between two
//! processed frames: `v = min(v_max, react_distance / dt̄)` with `dt̄` an exponential
//! average of recent frame intervals, so slow perception really slows the flight.
//!
//! The parts: the loop ([`fly`]), its parameters ([`FlightConfig`], [`NavConfig`]),
//! what it produces ([`FlightResult`], [`Outcome`], [`FrameView`]), the drone's place
//! in the maze ([`start_pose`], [`collides`]), and its readings against the renderer's ground truth
//! (`ground_truth`).
mod closed_loop;
mod config;
mod geometry;
mod ground_truth;
mod result;

pub use closed_loop::fly;
pub use config::{FlightConfig, NavConfig};
pub use geometry::{collides, start_pose};
pub use result::{
    ConfirmationRead, Event, FlightError, FlightResult, FrameView, Mode, NavCommand, Outcome,
    TrackPoint,
};
