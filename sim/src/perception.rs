//! The perception interface the flight loop calls once per processed frame, the
//! ground-truth implementation, and device profiles that turn measured compute time
//! into simulated time.
use crate::render::FrameTruth;
use frugal_runtime::{Detection, Detector, FrameRef};
use std::time::Instant;

/// What perception is given for one frame.
#[derive(Clone, Copy, Debug)]
pub struct FrameInput<'a> {
    /// The rendered camera image (RGB8, the camera's size).
    pub image: FrameRef<'a>,
    /// Simulated time at which the frame was captured, seconds since take-off.
    pub time_s: f64,
    /// Index of the processed frame (0, 1, 2, …).
    pub index: u64,
    /// The renderer's ground truth for this frame. Only [`GroundTruthPerception`]
    /// (and scoring) may read it; a detector-based implementation must ignore it.
    pub truth: &'a FrameTruth,
}

pub use frugal_nav::bundle::Slowdowns;
pub use frugal_nav::{Percept, PerceptionError};

/// Turns camera frames into sign detections, reporting the compute time it used.
///
/// Implementations: [`GroundTruthPerception`] here; later a static detector (one ONNX
/// variant every frame) and the adaptive runtime (controller + tracker + bundle
/// variants). A detector-based implementation measures its own wall-clock time per
/// frame (e.g. with `std::time::Instant`) and reports it in [`Percept::compute_ms`].
///
/// Any `FnMut(&FrameInput) -> Result<Percept, PerceptionError>` closure is a
/// `Perception` too.
pub trait Perception {
    /// A short label for tables and file names, e.g. `ground-truth`, `static-int8`.
    fn name(&self) -> String;
    /// Process one frame.
    fn perceive(&mut self, input: &FrameInput<'_>) -> Result<Percept, PerceptionError>;

    /// Read the frame again with the most accurate detector this perception has, to
    /// confirm a sign before the drone acts on it (a turn, a landing), since one
    /// misread there costs the flight. `None`: nothing more accurate than what
    /// [`Perception::perceive`] ran (ground truth, a static detector), so its readings
    /// stand. The compute time is charged to the flight like a frame's.
    fn confirm(&mut self, _input: &FrameInput<'_>) -> Result<Option<Percept>, PerceptionError> {
        Ok(None)
    }

    /// How long the flight waits, from `ready_s` (when perception is free for the next
    /// frame), for a camera frame of interval `camera_dt_s` this perception takes: a
    /// whole number of camera frames, those in between dropped. 0 (the default): it
    /// takes the frame at `ready_s`. The adaptive runtime flying a budget table drops
    /// the frames of a camera faster than the tables' clock.
    fn camera_wait_s(&mut self, _ready_s: f64, _camera_dt_s: f64) -> f64 {
        0.0
    }

    /// What it ran since it was made, by name (the adaptive runtime: detections by
    /// the controller's trigger and by variant); empty when there is nothing to tell.
    fn counts(&self) -> Vec<(String, u64)> {
        Vec::new()
    }
}

impl<F> Perception for F
where
    F: FnMut(&FrameInput<'_>) -> Result<Percept, PerceptionError>,
{
    fn name(&self) -> String {
        "closure".to_owned()
    }
    fn perceive(&mut self, input: &FrameInput<'_>) -> Result<Percept, PerceptionError> {
        self(input)
    }
}

/// Perfect perception: the projected boxes of the visible signs, with a fixed compute
/// time. Boards smaller than `min_height_px` or less than `min_visible` visible are
/// left out, as a real detector would miss them.
#[derive(Clone, Debug, PartialEq)]
pub struct GroundTruthPerception {
    /// Compute time reported per frame, ms (before the device slowdown).
    pub compute_ms: f64,
    /// Smallest box height reported, pixels.
    pub min_height_px: f32,
    /// Smallest visible fraction of the board reported.
    pub min_visible: f64,
}

impl Default for GroundTruthPerception {
    /// 5 ms per frame, boxes from 8 px tall, at least half the board visible.
    fn default() -> Self {
        Self {
            compute_ms: 5.0,
            min_height_px: 8.0,
            min_visible: 0.5,
        }
    }
}

impl GroundTruthPerception {
    /// Whether this perception reports `sign`: tall and visible enough.
    pub fn reports(&self, sign: &crate::render::SignTruth) -> bool {
        sign.bbox.height() >= self.min_height_px && sign.visible_fraction >= self.min_visible
    }
}

impl Perception for GroundTruthPerception {
    fn name(&self) -> String {
        "ground-truth".to_owned()
    }

    fn perceive(&mut self, input: &FrameInput<'_>) -> Result<Percept, PerceptionError> {
        let detections = input
            .truth
            .signs
            .iter()
            .filter(|s| self.reports(s))
            .map(|s| Detection {
                bbox: s.bbox,
                score: 1.0,
                class: s.class,
            })
            .collect();
        Ok(Percept {
            tracked: false,
            detections,
            compute_ms: self.compute_ms,
            ..Percept::default()
        })
    }
}

/// Any [`frugal_runtime::Detector`] (the ONNX Runtime executor, the HoG pipeline, the
/// tch CNN) run on every frame — the paper's "static" baseline — with its wall-clock
/// time per call as the compute time. It never reads the ground truth.
#[derive(Debug)]
pub struct DetectorPerception<D> {
    /// The detector.
    pub detector: D,
    /// Label for tables, e.g. `static-int8`.
    pub label: String,
    /// Most detections kept per frame.
    pub max_detections: usize,
    /// Detections scoring below this are dropped (on the family's score scale).
    pub min_score: f32,
    /// The detector runs in int8: its time is reported as [`Percept::int8_ms`] too, for
    /// a device profile with an int8 speed of its own.
    pub int8: bool,
    out: Vec<Detection>,
}

impl<D: Detector> DetectorPerception<D> {
    /// Wrap `detector`, keeping up to 16 detections of any score.
    pub fn new(label: impl Into<String>, detector: D) -> Self {
        Self {
            detector,
            label: label.into(),
            max_detections: 16,
            min_score: f32::NEG_INFINITY,
            int8: false,
            out: Vec::new(),
        }
    }
}

impl<D> Perception for DetectorPerception<D>
where
    D: Detector,
    D::Error: std::fmt::Display,
{
    fn name(&self) -> String {
        self.label.clone()
    }

    fn perceive(&mut self, input: &FrameInput<'_>) -> Result<Percept, PerceptionError> {
        self.out.clear();
        self.out.resize(self.max_detections, Detection::default());
        let started = Instant::now();
        let n = self
            .detector
            .detect(input.image, &mut self.out)
            .map_err(|e| PerceptionError::from(e.to_string()))?;
        let compute_ms = started.elapsed().as_secs_f64() * 1e3;
        let detections = self.out[..n.min(self.out.len())]
            .iter()
            .filter(|d| d.score >= self.min_score)
            .copied()
            .collect();
        Ok(Percept {
            tracked: false,
            detections,
            compute_ms,
            int8_ms: if self.int8 { compute_ms } else { 0.0 },
            tracker_ms: 0.0,
        })
    }
}

/// How much slower the simulated drone's computer is than the machine that measured
/// the compute time: simulated seconds per frame = `compute_ms / 1000 × slowdown`, the
/// part spent in int8 detectors charged by `slowdown_int8` and the part outside the
/// detectors by `slowdown_tracker` when the profile states them
/// ([`DeviceProfile::device_ms`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DeviceProfile {
    /// Label, e.g. `tx2-like`.
    pub name: String,
    /// Multiplier on measured compute time (1 = the measuring machine itself).
    pub slowdown: f64,
    /// Multiplier on the compute time of int8 detectors ([`Percept::int8_ms`]), when the
    /// device's int8 speed relative to the measuring machine is not its fp32 one (as
    /// between an x86 host with fast int8 instructions and an ARM board); `None`:
    /// `slowdown` for everything.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slowdown_int8: Option<f64>,
    /// Multiplier on the compute time outside the detectors ([`Percept::tracker_ms`]:
    /// the tracker and the decision), when the device's speed on that work relative to
    /// the measuring machine is not its fp32 detectors' (the budget stage states it by
    /// the reference tracker); `None`: `slowdown`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slowdown_tracker: Option<f64>,
}

impl DeviceProfile {
    /// The measuring machine itself (slowdown 1).
    pub fn host() -> DeviceProfile {
        DeviceProfile {
            name: "host".into(),
            slowdown: 1.0,
            slowdown_int8: None,
            slowdown_tracker: None,
        }
    }

    /// A Jetson-TX2-class on-board computer: slowdown 6, an assumption (a Cortex-A57
    /// class CPU against one core of the x86 workstation that measures the time), to
    /// be replaced by a calibration against real TX2 timings when they exist.
    pub fn tx2_like() -> DeviceProfile {
        DeviceProfile {
            name: "tx2-like".into(),
            slowdown: 6.0,
            slowdown_int8: None,
            slowdown_tracker: None,
        }
    }

    /// A profile by name (`host`, `tx2-like`).
    pub fn by_name(name: &str) -> Option<DeviceProfile> {
        match name {
            "host" => Some(DeviceProfile::host()),
            "tx2-like" | "tx2" => Some(DeviceProfile::tx2_like()),
            _ => None,
        }
    }

    /// Its slowdowns, part by part (those it does not state: `slowdown`).
    pub fn slowdowns(&self) -> Slowdowns {
        Slowdowns {
            fp32: self.slowdown,
            int8: self.slowdown_int8.unwrap_or(self.slowdown),
            tracker: self.slowdown_tracker.unwrap_or(self.slowdown),
        }
    }

    /// Device ms for what `percept` reports it spent ([`Slowdowns::percept_ms`]).
    pub fn device_ms(&self, percept: &Percept) -> f64 {
        self.slowdowns().percept_ms(percept)
    }

    /// Fails unless the slowdowns are positive and finite.
    pub fn check(&self) -> Result<(), String> {
        let ok = |s: f64| s > 0.0 && s.is_finite();
        if !ok(self.slowdown) {
            return Err(format!(
                "device slowdown must be positive, got {}",
                self.slowdown
            ));
        }
        for (what, s) in [
            ("int8", self.slowdown_int8),
            ("tracker", self.slowdown_tracker),
        ] {
            if let Some(s) = s.filter(|&s| !ok(s)) {
                return Err(format!("device {what} slowdown must be positive, got {s}"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use frugal_runtime::BBox;

    /// Reports three boxes with falling scores, fails on an all-black frame.
    struct Fake;

    impl Detector for Fake {
        type Error = String;
        fn detect(&mut self, frame: FrameRef<'_>, out: &mut [Detection]) -> Result<usize, String> {
            if frame.rgb.iter().all(|&v| v == 0) {
                return Err("black frame".into());
            }
            let mut n = 0;
            for (i, slot) in out.iter_mut().take(3).enumerate() {
                *slot = Detection {
                    bbox: BBox::new(0.0, 0.0, 10.0, 10.0 + i as f32),
                    score: 0.9 - 0.3 * i as f32,
                    class: i as u16,
                };
                n += 1;
            }
            Ok(n)
        }
    }

    #[test]
    fn detector_perception_passes_detections_through_and_reports_errors() {
        let truth = FrameTruth::default();
        let px = vec![7u8; 4 * 4 * 3];
        let input = FrameInput {
            image: FrameRef::new(4, 4, &px).unwrap(),
            time_s: 0.0,
            index: 0,
            truth: &truth,
        };
        let mut p = DetectorPerception::new("fake", Fake);
        let out = p.perceive(&input).unwrap();
        assert_eq!(
            out.detections.iter().map(|d| d.class).collect::<Vec<_>>(),
            [0, 1, 2]
        );
        assert!(out.compute_ms >= 0.0);
        p.min_score = 0.5;
        p.max_detections = 1;
        assert_eq!(p.perceive(&input).unwrap().detections.len(), 1);
        p.max_detections = 16;
        assert_eq!(p.perceive(&input).unwrap().detections.len(), 2);
        assert_eq!(p.name(), "fake");
        let black = vec![0u8; 4 * 4 * 3];
        let input = FrameInput {
            image: FrameRef::new(4, 4, &black).unwrap(),
            ..input
        };
        assert_eq!(p.perceive(&input).unwrap_err().to_string(), "black frame");
    }
}
