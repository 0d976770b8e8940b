//! The decisions a drone takes from its camera, shared by the maze simulator
//! (`frugal-sim`) and the drone-side program (`frugal-pilot`), so that both fly the same
//! code:
//!
//! - [`BundlePerception`]: the policy bundle's controller and trackers choosing, frame
//!   by frame, which ONNX variant to run (or to track), and the reference variant
//!   re-reading a frame when the navigator asks;
//! - [`Navigator`]: a step function from one processed frame (time, distance flown,
//!   detections, whether the last turn is over) to a [`NavCommand`]: a sign is acted on
//!   once several readings agree on it, its distance read from its box height and the
//!   camera's focal length, its action confirmed by the reference variant, the turn or
//!   landing carried out when the odometer reaches it;
//! - [`FlightLog`]: per processed frame, what the navigator was given besides the image
//!   and what it decided, so that footage of a flight can be replayed by the drone-side
//!   program with the same inputs.
#![deny(missing_docs)]

pub mod bundle;
mod config;
pub mod flight_log;
pub mod heading;
mod navigator;
mod sighting;

pub use bundle::{
    BUNDLE_FILE, BundleError, BundlePerception, CNN_REPORT_SCORE, Percept, PerceptionError,
    Slowdowns, verify_files,
};
pub use config::{NavConfig, NavDistances};
pub use flight_log::{DetectionRecord, FlightLog, LogRow};
pub use navigator::{
    ConfirmationRead, Mode, NavCommand, NavInput, NavStep, Navigator, Optics, Truth,
};
