//! Integration tests of frugal-runtime: bundle round trips and corruption, the
//! controller loop, the tracker on synthetic clips, and parity with OpenCV.

mod it;
// Shared with the klt_vs_opencv example, which reads the fields the test does not.
#[allow(dead_code)]
mod parity;
