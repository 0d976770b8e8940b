//! Detector-based perception through the deployment path: a static ONNX variant every
//! frame ([`static_onnx`]), or the adaptive runtime ([`AdaptivePerception`]): the
//! policy bundle's perception from `frugal-nav` ([`BundlePerception`]: controller + KLT
//! trackers deciding per frame, the chosen variant run through ONNX Runtime) — the same
//! code the drone-side program (`frugal-pilot`) runs.
use crate::perception::{DetectorPerception, FrameInput, Percept, Perception, PerceptionError};
use frugal_nav::BundlePerception;
use frugal_runtime::Bundle;
use frugal_runtime::onnx::OrtDetector;
use frugal_runtime::pilot::Carry;
use std::path::Path;

pub use frugal_nav::{BUNDLE_FILE, CNN_REPORT_SCORE};

/// One ONNX variant every frame (the paper's static baseline), reporting detections
/// scoring at least [`CNN_REPORT_SCORE`].
pub fn static_onnx(
    dir: &Path,
    threads: usize,
) -> Result<DetectorPerception<OrtDetector>, PerceptionError> {
    let detector = OrtDetector::open(dir, threads)?;
    let name = dir
        .file_name()
        .map_or("onnx".into(), |n| n.to_string_lossy().into_owned());
    let mut p = DetectorPerception::new(format!("static-{name}"), detector);
    // the CNN family's reporting threshold T_c (a softmax probability), as the replay
    // evaluation and the adaptive runtime use
    p.min_score = CNN_REPORT_SCORE;
    Ok(p)
}

/// The adaptive runtime in the loop.
pub struct AdaptivePerception(BundlePerception);

impl AdaptivePerception {
    /// Open the bundle folder `dir` ([`BundlePerception::open`]).
    pub fn open(dir: &Path, threads: usize) -> Result<Self, PerceptionError> {
        BundlePerception::open(dir, threads).map(Self)
    }

    /// Carry detections from `carry`'s bucket up ([`BundlePerception::with_carry`]).
    pub fn with_carry(self, carry: Carry) -> Self {
        Self(self.0.with_carry(carry))
    }

    /// The parsed bundle.
    pub fn bundle(&self) -> &Bundle<'static> {
        self.0.bundle()
    }
}

impl Perception for AdaptivePerception {
    fn name(&self) -> String {
        self.0.name()
    }

    fn perceive(&mut self, input: &FrameInput<'_>) -> Result<Percept, PerceptionError> {
        self.0.perceive(input.image, input.index)
    }

    /// The bundle's reference variant (the most accurate) on this frame
    /// ([`BundlePerception::confirm`]).
    fn confirm(&mut self, input: &FrameInput<'_>) -> Result<Option<Percept>, PerceptionError> {
        self.0.confirm(input.image).map(Some)
    }

    /// [`BundlePerception::counts`].
    fn counts(&self) -> Vec<(String, u64)> {
        self.0.counts()
    }
}
