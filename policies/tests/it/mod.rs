//! Test modules and the shared fixture.

mod budget;
mod bundle;
mod doc_example;
mod estimate;
mod eval;
pub mod fixture;
mod stream;
