//! Test modules and the shared fixture.

mod bundle;
mod estimate;
mod eval;
pub mod fixture;
