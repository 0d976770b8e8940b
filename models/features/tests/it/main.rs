//! Integration tests of frugal-features: HoG parity with scikit-image, and the
//! detector trained on drawn scenes (tiny configurations).

mod detector;
mod peers;
