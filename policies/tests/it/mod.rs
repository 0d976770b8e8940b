//! Test modules and the shared fixture.

mod bundle;
mod doc_example;
mod estimate;
mod eval;
pub mod fixture;
