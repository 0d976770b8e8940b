//! The MDP that picks, from classifier confidence, the cheapest good-enough variant.
#![deny(missing_docs)]

pub mod mdp;

pub use mdp::{Mdp, MdpError, Solution};
