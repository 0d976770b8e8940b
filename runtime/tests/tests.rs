//! Integration tests of frugal-runtime: bundle round trips and corruption, the
//! controller loop, the tracker on synthetic clips, and parity with OpenCV.

mod it;
