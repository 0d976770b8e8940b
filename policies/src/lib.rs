//! Policies: which detector variant to run on the next frame, learned as an MDP from
//! replayed videos, evaluated by replaying the paper's strategies through the
//! runtime's own controller, and shipped as a policy bundle.
//!
//! - [`variants`]: the [`VariantSet`] (families, confidence buckets, latencies,
//!   relative costs, boxed detectors);
//! - [`replay`]: the [`ReplayLog`] — every variant run once on every frame;
//! - [`train`]: transition estimation, the reward, [`train::train`] and the α sweep;
//! - [`mdp`]: the MDP and its solvers;
//! - [`eval`]: the strategies, replayed with the runtime's controller and KLT tracker;
//! - [`bundle`]: writing, verifying and inspecting bundle folders;
//! - [`plot`]: the figures.
#![deny(missing_docs)]

pub mod bundle;
pub mod error;
pub mod eval;
pub mod mdp;
pub mod plot;
pub mod replay;
pub mod report;
pub mod sweep;
pub mod train;
pub mod variants;

pub use error::{PolicyError, Result};
pub use mdp::{Mdp, MdpError, Solution};
pub use replay::ReplayLog;
pub use train::{PolicyConfig, TrainedPolicy, Weights};
pub use variants::VariantSet;
