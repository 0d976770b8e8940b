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
pub struct AdaptivePerception {
    inner: BundlePerception,
    /// Flying a budget table: the camera's frames, counted by their capture times.
    camera: Option<CameraClock>,
}

/// Numbers the frames perception takes as the camera's: a frame captured `dt` seconds
/// after the last one taken is `round(dt × fps)` frames on (at least one), so the
/// frames the camera took while perception was busy count, as on the drone.
#[derive(Clone, Copy, Debug)]
struct CameraClock {
    fps: f64,
    /// The camera frame and capture time of the last frame taken.
    last: Option<(u64, f64)>,
}

impl CameraClock {
    fn frame(&mut self, time_s: f64) -> u64 {
        let n = match self.last {
            None => 0,
            Some((n, t)) => {
                let taken = ((time_s - t) * self.fps).round();
                n.saturating_add(if taken >= 1.0 { taken as u64 } else { 1 })
            }
        };
        self.last = Some((n, time_s));
        n
    }
}

impl AdaptivePerception {
    /// Open the bundle folder `dir` ([`BundlePerception::open`]).
    pub fn open(dir: &Path, threads: usize) -> Result<Self, PerceptionError> {
        BundlePerception::open(dir, threads).map(|inner| Self {
            inner,
            camera: None,
        })
    }

    /// Carry detections from `carry`'s bucket up ([`BundlePerception::with_carry`]).
    pub fn with_carry(self, carry: Carry) -> Self {
        Self {
            inner: self.inner.with_carry(carry),
            camera: None,
        }
    }

    /// Fly the bundle's budget table for `budget_ms` device ms per frame
    /// ([`BundlePerception::with_budget`]), with a budget keeper of `keep_window` frames
    /// (0: none) debited every frame's compute × `slowdown` (the device profile's, as
    /// the flight charges it). The table's periods and the keeper's credit count the
    /// frames of the camera, at `camera_fps`, by their capture times, those it took
    /// while perception was busy included, as on the drone. A table's periods and its
    /// budget in ms per frame mean what they meant in the evaluation when the camera
    /// runs at the frame rate the tables were made for (`[budget] fps`). Call it after
    /// [`AdaptivePerception::with_carry`].
    pub fn with_budget(
        self,
        budget_ms: f32,
        keep_window: u32,
        slowdown: f64,
        camera_fps: f64,
    ) -> Result<Self, PerceptionError> {
        if !(camera_fps > 0.0 && camera_fps.is_finite()) {
            return Err(format!("camera frame rate must be positive, got {camera_fps}").into());
        }
        Ok(Self {
            inner: self
                .inner
                .with_budget(budget_ms, keep_window)?
                .with_debit_scale(slowdown as f32)?,
            camera: Some(CameraClock {
                fps: camera_fps,
                last: None,
            }),
        })
    }

    /// The parsed bundle.
    pub fn bundle(&self) -> &Bundle<'static> {
        self.inner.bundle()
    }
}

impl Perception for AdaptivePerception {
    fn name(&self) -> String {
        self.inner.name()
    }

    fn perceive(&mut self, input: &FrameInput<'_>) -> Result<Percept, PerceptionError> {
        // with the paper's controller, the processed frame's number; flying a budget
        // table, the camera frame's
        let n = match self.camera.as_mut() {
            Some(c) => c.frame(input.time_s),
            None => input.index,
        };
        self.inner.perceive(input.image, n)
    }

    /// The bundle's reference variant (the most accurate) on this frame
    /// ([`BundlePerception::confirm`]).
    fn confirm(&mut self, input: &FrameInput<'_>) -> Result<Option<Percept>, PerceptionError> {
        self.inner.confirm(input.image).map(Some)
    }

    /// [`BundlePerception::counts`], and flying a budget table, the detections its
    /// keeper postponed.
    fn counts(&self) -> Vec<(String, u64)> {
        let mut c = self.inner.counts();
        if self.inner.budget_ms().is_some() {
            c.push((
                "postponed detections".into(),
                u64::from(self.inner.postponed()),
            ));
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::CameraClock;

    #[test]
    fn the_camera_clock_counts_the_frames_taken_while_perception_was_busy() {
        let mut c = CameraClock {
            fps: 60.0,
            last: None,
        };
        // a frame every camera period, then one 4 periods on (3 taken while busy), then
        // one 2.6 periods on (rounded), then one only 0.2 periods on (still the next)
        let times = [0.5, 0.5 + 1.0 / 60.0, 0.5 + 5.0 / 60.0, 0.5 + 7.6 / 60.0];
        let got: Vec<u64> = times.iter().map(|&t| c.frame(t)).collect();
        assert_eq!(got, vec![0, 1, 5, 8]);
        assert_eq!(c.frame(0.5 + 7.8 / 60.0), 9);
        // float error in a whole number of periods does not skip or repeat a frame
        let mut c = CameraClock {
            fps: 30.0,
            last: None,
        };
        let mut t = 0.0;
        for k in 0..1000 {
            assert_eq!(c.frame(t), k);
            t += 1.0 / 30.0;
        }
    }
}
