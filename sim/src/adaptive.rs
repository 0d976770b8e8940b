//! Detector-based perception through the deployment path: a static ONNX variant every
//! frame ([`static_onnx`]), or the adaptive runtime ([`AdaptivePerception`]): the
//! policy bundle's perception from `frugal-nav` ([`BundlePerception`]: controller + KLT
//! trackers deciding per frame, the chosen variant run through ONNX Runtime) — the same
//! code the drone-side program (`frugal-pilot`) runs.
use crate::perception::{
    DetectorPerception, DeviceProfile, FrameInput, Percept, Perception, PerceptionError,
};
use frugal_nav::BundlePerception;
use frugal_runtime::onnx::OrtDetector;
use frugal_runtime::pilot::Carry;
use frugal_runtime::{Bundle, FrameClock};
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
    /// Flying a budget table, it numbers the frames by their capture times on the
    /// tables' clock (the bundle's frame interval, or the camera's for a bundle of
    /// format 5 or older), so that frames taken while perception was busy count.
    inner: BundlePerception,
    /// Camera frames dropped because they fell on a frame the clock had numbered.
    dropped: u64,
}

impl AdaptivePerception {
    /// Open the bundle folder `dir` ([`BundlePerception::open`]).
    pub fn open(dir: &Path, threads: usize) -> Result<Self, PerceptionError> {
        BundlePerception::open(dir, threads).map(|inner| Self { inner, dropped: 0 })
    }

    /// Fails when `device` charges int8 by a slowdown of its own and the bundle does not
    /// mark its variants' precision ([`frugal_nav::bundle::NO_PRECISION`]): its int8
    /// variants would be charged as fp32.
    pub fn check_device(&self, device: &DeviceProfile) -> Result<(), PerceptionError> {
        if device.slowdown_int8.is_some() {
            frugal_nav::bundle::int8_variants_or_refuse(self.inner.bundle())?;
        }
        Ok(())
    }

    /// Carry detections from `carry`'s bucket up ([`BundlePerception::with_carry`]).
    pub fn with_carry(self, carry: Carry) -> Self {
        Self {
            inner: self.inner.with_carry(carry),
            dropped: 0,
        }
    }

    /// Fly the bundle's budget table for `budget_ms` device ms per frame
    /// ([`BundlePerception::with_budget`]), with a budget keeper of `keep_window` frames
    /// (0: none) debited every frame's compute on `device` as the flight charges it
    /// ([`DeviceProfile::device_ms`]: the int8 variants' time by the profile's int8
    /// slowdown when it states one, which the bundle's `precision:` metadata names, and
    /// the time outside the variants by its tracker slowdown).
    /// The table's periods and the keeper's credit count frames
    /// on the clock the tables were made on (the bundle's frame interval), by their
    /// capture times, those the camera took while perception was busy included, as on
    /// the drone; a camera faster than that clock has its extra frames dropped
    /// ([`Perception::camera_wait_s`]). A bundle of format 5 or older does not say its
    /// tables' rate: its periods count the camera's frames, at `camera_fps`. Call it
    /// after [`AdaptivePerception::with_carry`].
    pub fn with_budget(
        self,
        budget_ms: f32,
        keep_window: u32,
        device: &DeviceProfile,
        camera_fps: f64,
    ) -> Result<Self, PerceptionError> {
        if !(camera_fps > 0.0 && camera_fps.is_finite()) {
            return Err(format!("camera frame rate must be positive, got {camera_fps}").into());
        }
        device.check()?;
        let inner = self
            .inner
            .with_budget(budget_ms, keep_window)?
            .with_debit(device.slowdowns())?
            .with_fallback_clock(1e3 / camera_fps)?;
        Ok(Self { inner, dropped: 0 })
    }

    /// The parsed bundle.
    pub fn bundle(&self) -> &Bundle<'static> {
        self.inner.bundle()
    }
}

/// Whole camera frames of `camera_dt_s` from `ready_s` to the first frame `clock`
/// numbers (0: the frame at `ready_s`). A frame interval spans at most a few hundred
/// camera frames; the bound only guards against a clock that takes nothing.
fn frames_to_wait(clock: &FrameClock, ready_s: f64, camera_dt_s: f64) -> u32 {
    (0..10_000u32)
        .find(|&k| {
            clock
                .peek((ready_s + f64::from(k) * camera_dt_s) * 1e3)
                .is_some()
        })
        .unwrap_or(0)
}

impl Perception for AdaptivePerception {
    fn name(&self) -> String {
        self.inner.name()
    }

    fn perceive(&mut self, input: &FrameInput<'_>) -> Result<Percept, PerceptionError> {
        // with the paper's controller, the processed frame's number; flying a budget
        // table, the frame's on the tables' clock (the flight waits for a frame the
        // clock takes: `camera_wait_s`; should one fall on the same number anyway, it
        // is perceived as that frame again)
        let n = match self.inner.frame_number(input.time_s, input.index) {
            Some(n) => n,
            None => self
                .inner
                .table_clock()
                .map_or(input.index, |c| u64::from(c.last())),
        };
        self.inner.perceive(input.image, n)
    }

    /// Flying a budget table: the wait, in whole camera frames of `camera_dt_s`, from
    /// `ready_s` to the first frame the tables' clock numbers; the frames in between
    /// are dropped (a camera faster than the tables' rate).
    fn camera_wait_s(&mut self, ready_s: f64, camera_dt_s: f64) -> f64 {
        let Some(c) = self.inner.table_clock() else {
            return 0.0;
        };
        let k = frames_to_wait(c, ready_s, camera_dt_s);
        self.dropped += u64::from(k);
        f64::from(k) * camera_dt_s
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
            c.push(("dropped camera frames".into(), self.dropped));
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_camera_faster_than_the_tables_waits_for_the_tables_next_frame() {
        let cam = 1.0 / 60.0;
        let mut c = FrameClock::new(1e3 / 30.0).unwrap();
        assert_eq!(frames_to_wait(&c, 0.5, cam), 0);
        assert_eq!(c.frame(500.0), Some(0));
        // ready one camera frame on: that frame is table frame 0 again, the next is 1
        assert_eq!(frames_to_wait(&c, 0.5 + cam, cam), 1);
        assert_eq!(c.frame((0.5 + 2.0 * cam) * 1e3), Some(1));
        // ready after 3.2 camera frames of compute: table frame 2 is already due
        assert_eq!(frames_to_wait(&c, 0.5 + 5.2 * cam, cam), 0);
        assert_eq!(c.frame((0.5 + 5.2 * cam) * 1e3), Some(2));
        // a camera at the tables' rate, or slower, never waits
        for fps in [30.0, 25.0] {
            let mut c = FrameClock::new(1e3 / 30.0).unwrap();
            let mut t = 0.0;
            for k in 0..300 {
                assert_eq!(frames_to_wait(&c, t, 1.0 / fps), 0, "{fps} fps, frame {k}");
                assert!(c.frame(t * 1e3).is_some());
                t += 1.0 / fps;
            }
        }
    }
}
