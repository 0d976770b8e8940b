//! The bundle's perception ([`BundlePerception`]): the policy bundle's [`Pilot`]
//! (the paper's controller, or one budget table's scheduler, + KLT trackers) deciding
//! per frame, the chosen variant run through ONNX
//! Runtime, and the reference variant's re-reading of a frame on the navigator's
//! request. The maze simulator flies it (`frugal_sim::AdaptivePerception`) and the
//! drone-side program runs it on camera frames.
//!
//! Opening checks the bundle's files first ([`verify_files`]): every ONNX graph it
//! names must hash to what the bundle records, so a bundle whose graphs were swapped or
//! damaged is refused before the first frame.
use frugal_runtime::onnx::OrtDetector;
use frugal_runtime::pilot::{Carry, Pilot};
use frugal_runtime::track::Pyramid;
use frugal_runtime::{Bundle, Decision, Detection, FrameClock, FrameRef, Trigger};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The bundle file inside a bundle folder (written by `frugal bundle write`).
pub const BUNDLE_FILE: &str = "policy.frpb";

/// The score at which a CNN detection is reported: the CNN family's `T_c`.
pub const CNN_REPORT_SCORE: f32 = 0.5;

/// What perception returns for one frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Percept {
    /// Sign detections in image pixels, on the detector family's score scale.
    pub detections: Vec<Detection>,
    /// Compute time this frame consumed on the machine that ran it, milliseconds.
    /// The flight multiplies it by the device profile's slowdown to advance the
    /// simulated clock.
    pub compute_ms: f64,
    /// The detections are boxes a tracker carried from an earlier frame's detection,
    /// not measured on this one: they say a sign is still there, but their size (and
    /// so the distance read from it) is the tracker's prediction, which drifts and
    /// keeps a misdrawn box's error. The navigator places signs by measured boxes only.
    pub tracked: bool,
    /// Of `compute_ms`, the time spent in int8 detectors (0 when none ran, or when the
    /// bundle does not mark its int8 variants). A device profile that runs int8 at
    /// another speed relative to the measuring machine than fp32 charges this part by
    /// its int8 slowdown.
    pub int8_ms: f64,
    /// Of `compute_ms`, the time outside the detectors: the tracker (pyramids, tracks)
    /// and the decision (0 for a detector alone). A device profile with a tracker speed
    /// of its own charges this part by its tracker slowdown, as the budget stage puts
    /// the tracker's costs on the device by the reference tracker.
    pub tracker_ms: f64,
}

/// An error from a perception implementation (boxed so any detector's error fits).
pub type PerceptionError = Box<dyn std::error::Error + Send + Sync>;

/// A bundle file that does not match the bundle.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BundleError {
    /// A file cannot be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The bundle file does not parse.
    #[error("{path}: not a valid bundle: {message}")]
    Parse {
        /// The bundle file.
        path: PathBuf,
        /// The reader's message.
        message: String,
    },
    /// A file the bundle names is missing.
    #[error("{path}: missing (named by {bundle})")]
    Missing {
        /// The file.
        path: PathBuf,
        /// The bundle file.
        bundle: PathBuf,
    },
    /// A file's SHA-256 differs from the one the bundle records.
    #[error("{path}: SHA-256 {actual} does not match the bundle's {expected}")]
    Hash {
        /// The file.
        path: PathBuf,
        /// The hash the bundle records.
        expected: String,
        /// The file's hash.
        actual: String,
    },
}

/// Bundle metadata keys naming a further file and its SHA-256 (`file:<path>`), as
/// `frugal bundle write` records the second graph of each ONNX variant.
pub const FILE_KEY: &str = "file:";

/// Bundle metadata key prefix of a variant's numeric precision (`precision:<variant>`
/// = [`INT8`] or [`FP32`]), as `frugal bundle write` marks every variant.
pub const PRECISION_KEY: &str = "precision:";

/// The value of [`PRECISION_KEY`] for an int8 variant.
pub const INT8: &str = "int8";

/// The value of [`PRECISION_KEY`] for an fp32 variant.
pub const FP32: &str = "fp32";

/// Why a bundle that does not mark its variants' precision cannot fly a device with an
/// int8 speed of its own.
pub const NO_PRECISION: &str = "the bundle does not mark its variants' precision (`precision:<variant>` metadata, written by `frugal bundle write` since 2026-12-05), so its int8 variants cannot be charged by the device's int8 slowdown: write the bundle again, or fly without an int8 slowdown";

/// The slowdowns of a device over the machine that stands in for it: fp32 detectors
/// (and whatever is not told apart), int8 detectors, the tracker.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slowdowns {
    /// Device time over measured time for fp32 detectors.
    pub fp32: f64,
    /// The same for int8 detectors.
    pub int8: f64,
    /// The same for the time outside the detectors ([`Percept::tracker_ms`]).
    pub tracker: f64,
}

impl Slowdowns {
    /// One slowdown for everything.
    pub fn uniform(slowdown: f64) -> Self {
        Self {
            fp32: slowdown,
            int8: slowdown,
            tracker: slowdown,
        }
    }

    /// Device ms for `compute_ms` measured, `int8_ms` of it in int8 detectors and
    /// `tracker_ms` outside the detectors: each part × its slowdown, the rest × the
    /// fp32 one (negative times count as 0; the int8 part is at most the whole, the
    /// tracker's at most what the int8 part leaves).
    pub fn device_ms(&self, compute_ms: f64, int8_ms: f64, tracker_ms: f64) -> f64 {
        let compute_ms = compute_ms.max(0.0);
        let int8_ms = int8_ms.clamp(0.0, compute_ms);
        let tracker_ms = tracker_ms.clamp(0.0, compute_ms - int8_ms);
        (compute_ms - int8_ms - tracker_ms) * self.fp32
            + int8_ms * self.int8
            + tracker_ms * self.tracker
    }

    /// Device ms for what `percept` reports it spent.
    pub fn percept_ms(&self, percept: &Percept) -> f64 {
        self.device_ms(percept.compute_ms, percept.int8_ms, percept.tracker_ms)
    }
}

/// Per variant of `bundle`, in bundle order: whether its metadata marks it int8;
/// `None` for a bundle that marks no variant's precision (written before bundles did),
/// whose int8 variants cannot be told.
pub fn int8_variants(bundle: &Bundle<'_>) -> Option<Vec<bool>> {
    if !bundle.metadata().any(|(k, _)| k.starts_with(PRECISION_KEY)) {
        return None;
    }
    Some(
        bundle
            .variants()
            .map(|(_, v)| {
                bundle
                    .metadata()
                    .any(|(k, val)| k.strip_prefix(PRECISION_KEY) == Some(v.name) && val == INT8)
            })
            .collect(),
    )
}

/// Per variant of `bundle`, whether it is int8 ([`int8_variants`]), for a device that
/// charges int8 by a speed of its own; fails with [`NO_PRECISION`] for a bundle that
/// does not mark its variants' precision, whose int8 variants would be charged as fp32.
pub fn int8_variants_or_refuse(bundle: &Bundle<'_>) -> Result<Vec<bool>, PerceptionError> {
    int8_variants(bundle).ok_or_else(|| NO_PRECISION.into())
}

/// Lower-case hex of `bytes`.
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Check the bundle folder `dir`: its bundle parses and every file it names (each
/// variant's ONNX graph, and the `file:` metadata entries) exists and hashes to what
/// it records. Returns the files checked.
pub fn verify_files(dir: &Path) -> Result<Vec<PathBuf>, BundleError> {
    verify_bundle_file(&dir.join(BUNDLE_FILE))
}

/// [`verify_files`] for a bundle file of any name: the files it names are relative to
/// its folder.
pub fn verify_bundle_file(file: &Path) -> Result<Vec<PathBuf>, BundleError> {
    let file = file.to_owned();
    let dir = file.parent().unwrap_or(Path::new("."));
    let io = |path: &Path, e: std::io::Error| BundleError::Io {
        path: path.to_owned(),
        source: e,
    };
    let bytes = std::fs::read(&file).map_err(|e| io(&file, e))?;
    let bundle = Bundle::parse(&bytes).map_err(|e| BundleError::Parse {
        path: file.clone(),
        message: e.to_string(),
    })?;
    let mut refs: Vec<(String, String)> = bundle
        .variants()
        .filter(|(_, v)| !v.onnx_file.is_empty())
        .map(|(_, v)| (v.onnx_file.to_owned(), hex(&v.sha256)))
        .collect();
    refs.extend(bundle.metadata().filter_map(|(k, v)| {
        k.strip_prefix(FILE_KEY)
            .map(|f| (f.to_owned(), v.to_owned()))
    }));
    let mut checked = Vec::new();
    for (rel, expected) in refs {
        let path = dir.join(&rel);
        if !path.is_file() {
            return Err(BundleError::Missing {
                path,
                bundle: file.clone(),
            });
        }
        let data = std::fs::read(&path).map_err(|e| io(&path, e))?;
        let actual = hex(&Sha256::digest(&data));
        if actual != expected {
            return Err(BundleError::Hash {
                path,
                expected,
                actual,
            });
        }
        checked.push(path);
    }
    Ok(checked)
}

/// The adaptive runtime: the bundle's policy, controller, trackers and ONNX variants.
pub struct BundlePerception {
    bundle: Bundle<'static>,
    pilot: Pilot<'static, 4, 64>,
    detectors: Vec<OrtDetector>,
    prev: Vec<u8>,
    cur: Vec<u8>,
    size: (usize, usize),
    have_prev: bool,
    label: String,
    /// Runs and compute time (µs) per variant so far (confirmations included).
    runs_per_variant: Vec<VariantRuns>,
    /// Frames detected so far, by the controller's trigger (indexed as
    /// [`Trigger::ALL`]), and confirmations.
    detections_per_trigger: [u64; Trigger::ALL.len()],
    confirmations: u64,
    /// Frames the pilot only tracked.
    tracked_frames: u64,
    /// Compute time of tracked frames and of detection frames, µs (pyramid, tracking
    /// and the decision included).
    tracked_us: u64,
    detected_us: u64,
    /// The variants run on the last frame [`BundlePerception::perceive`] processed.
    last_run: Vec<usize>,
    /// The budget table flown ([`BundlePerception::with_budget`]), in device ms.
    budget_ms: Option<f32>,
    /// Device ms per measured ms, what the budget keeper is debited
    /// ([`BundlePerception::with_debit`]; 1 on the drone).
    debit: Slowdowns,
    /// Per variant, whether the bundle marks it int8 ([`int8_variants`]; none marked
    /// when the bundle does not say).
    int8: Vec<bool>,
    /// Flying a budget table of a bundle that records the tables' frame interval: the
    /// clock that numbers the frames ([`BundlePerception::frame_number`]).
    table_clock: Option<FrameClock>,
}

impl BundlePerception {
    /// Open the bundle in `dir` and every ONNX variant it names (up front, so opening
    /// is not counted as flight time). The bundle bytes live as long as the process
    /// (a few kilobytes), since the zero-copy reader borrows them.
    ///
    /// Fails, naming the file, when a graph does not hash to what the bundle records
    /// ([`verify_files`]).
    pub fn open(dir: &Path, threads: usize) -> Result<Self, PerceptionError> {
        verify_files(dir)?;
        let path = dir.join(BUNDLE_FILE);
        let bytes = std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        let bundle = Bundle::parse(bytes).map_err(|e| format!("{}: {e}", path.display()))?;
        let mut detectors = Vec::new();
        for (_, v) in bundle.variants() {
            let graph = dir.join(v.onnx_file);
            let vdir = graph.parent().ok_or_else(|| {
                format!("{}: variant {} has no ONNX file", path.display(), v.name)
            })?;
            detectors.push(OrtDetector::open(vdir, threads)?);
        }
        let n = detectors.len();
        Ok(Self {
            bundle,
            pilot: Pilot::new(bundle),
            detectors,
            prev: Vec::new(),
            cur: Vec::new(),
            size: (0, 0),
            have_prev: false,
            label: format!(
                "adaptive-{}",
                dir.file_name()
                    .map_or("bundle".into(), |n| n.to_string_lossy())
            ),
            runs_per_variant: vec![VariantRuns::default(); n],
            detections_per_trigger: [0; Trigger::ALL.len()],
            confirmations: 0,
            tracked_frames: 0,
            tracked_us: 0,
            detected_us: 0,
            last_run: Vec::new(),
            budget_ms: None,
            debit: Slowdowns::uniform(1.0),
            int8: int8_variants(&bundle).unwrap_or_default(),
            table_clock: None,
        })
    }

    /// Fly the bundle's budget table for `budget_ms` (device ms per frame) with the
    /// budget scheduler instead of the paper's controller ([`Pilot::scheduled`]): per
    /// detection, the table's variant and detection period for the content, confidence
    /// and current variant, the trackers in between. With `keep_window > 0` a budget
    /// keeper of that many frames holds the table to its budget on this device
    /// ([`Pilot::with_budget_keeper`]), debited every frame's measured compute,
    /// confirmations included: on the drone, the compute of the device the tables were
    /// made for. [`BundlePerception::perceive`]'s `index` is then the frame's number
    /// from [`BundlePerception::frame_number`]: on the tables' clock when the bundle
    /// records it, else in the input, frames skipped while perception was busy
    /// counted, because periods and the keeper's credit count arriving frames. Call it
    /// after [`BundlePerception::with_carry`], which flies the controller again. Fails, naming the budgets the bundle holds, when none is
    /// `budget_ms`.
    pub fn with_budget(
        mut self,
        budget_ms: f32,
        keep_window: u32,
    ) -> Result<Self, PerceptionError> {
        let schedules = self
            .bundle
            .schedules()
            .ok_or("the bundle holds no budget tables (`frugal policy budget` makes them)")?;
        let budgets: Vec<f32> = (0..schedules.budget_count())
            .filter_map(|k| schedules.budget(k).map(|b| b.budget_ms))
            .collect();
        let k = budgets
            .iter()
            .position(|&b| (b - budget_ms).abs() <= 1e-3 * b.abs().max(1.0))
            .ok_or_else(|| {
                let held: Vec<String> = budgets.iter().map(|b| format!("{b} ms")).collect();
                format!(
                    "no budget table for {budget_ms} ms; the bundle holds {}",
                    held.join(", ")
                )
            })?;
        self.pilot = Pilot::scheduled(self.bundle, k)?.with_budget_keeper(keep_window);
        self.budget_ms = Some(budgets[k]);
        self.table_clock = schedules.frame_ms().and_then(FrameClock::new);
        self.label.push_str(&format!("-budget-{}ms", budgets[k]));
        Ok(self)
    }

    /// The budget table flown, device ms per frame ([`BundlePerception::with_budget`]);
    /// `None` with the paper's controller.
    pub fn budget_ms(&self) -> Option<f32> {
        self.budget_ms
    }

    /// The interval between the frames the budget table flown counts, ms, when the
    /// bundle records it (format 6 on; [`frugal_runtime::Schedules::frame_ms`]) or
    /// [`BundlePerception::with_fallback_clock`] gave it.
    pub fn table_frame_ms(&self) -> Option<f64> {
        self.table_clock.map(|c| c.frame_ms())
    }

    /// The clock [`BundlePerception::frame_number`] numbers frames on, flying a budget
    /// table with one ([`BundlePerception::table_frame_ms`]).
    pub fn table_clock(&self) -> Option<&FrameClock> {
        self.table_clock.as_ref()
    }

    /// Flying a budget table of a bundle that does not record the tables' frame
    /// interval (format 5 or older): number the frames on a clock of `frame_ms` (the
    /// camera's interval, whose frames such tables count) instead of the caller's
    /// numbering. Nothing changes for a bundle that records it, or with the paper's
    /// controller. Call it after [`BundlePerception::with_budget`]. Fails unless
    /// `frame_ms` is positive and finite.
    pub fn with_fallback_clock(mut self, frame_ms: f64) -> Result<Self, PerceptionError> {
        let clock = FrameClock::new(frame_ms as f32)
            .ok_or_else(|| format!("the frame interval must be positive, got {frame_ms} ms"))?;
        if self.budget_ms.is_some() && self.table_clock.is_none() {
            self.table_clock = Some(clock);
        }
        Ok(self)
    }

    /// The number [`BundlePerception::perceive`] is to be given for the frame captured
    /// at `time_s`. Flying a budget table whose bundle records its frame interval: the
    /// frame's number on the tables' clock ([`FrameClock`]), or `None` when the frame
    /// falls on a frame already numbered (a camera faster than the rate the tables
    /// were made at) and is to be dropped, not perceived; the same with the clock of
    /// [`BundlePerception::with_fallback_clock`]. Otherwise (the paper's controller, a
    /// bundle of format 5 or older without a fallback clock): `fallback`, the caller's
    /// own numbering.
    pub fn frame_number(&mut self, time_s: f64, fallback: u64) -> Option<u64> {
        match self.table_clock.as_mut() {
            Some(c) => c.frame(time_s * 1e3).map(u64::from),
            None => Some(fallback),
        }
    }

    /// Debit the budget keeper device ms per measured ms by `slowdowns`, for a machine
    /// that stands in for the device (the simulator's device profile): the time in
    /// the variants the bundle marks int8 ([`int8_variants`]) by `slowdowns.int8`, the
    /// time outside the detectors ([`Percept::tracker_ms`]) by `slowdowns.tracker`, the
    /// rest by `slowdowns.fp32`. On the drone, the measured time is the device's: 1
    /// for all, the default. Fails unless every slowdown is positive and finite, and
    /// for a bundle that does not mark its variants' precision when the int8 slowdown
    /// is not the fp32 one ([`NO_PRECISION`]).
    pub fn with_debit(mut self, slowdowns: Slowdowns) -> Result<Self, PerceptionError> {
        for (what, s) in [
            ("", slowdowns.fp32),
            (" int8", slowdowns.int8),
            (" tracker", slowdowns.tracker),
        ] {
            if !(s > 0.0 && s.is_finite()) {
                return Err(
                    format!("the keeper's{what} debit scale must be positive, got {s}").into(),
                );
            }
        }
        if slowdowns.int8 != slowdowns.fp32 {
            int8_variants_or_refuse(&self.bundle)?;
        }
        self.debit = slowdowns;
        Ok(self)
    }

    /// The device ms the keeper is debited for `percept`'s compute.
    fn debit(&self, percept: &Percept) -> f32 {
        self.debit.percept_ms(percept) as f32
    }

    /// The time, ms, all variants ran since `us_before` (each variant's µs then).
    fn detector_ms_since(&self, us_before: &[u64]) -> f64 {
        let us: u64 = (self.runs_per_variant.iter().zip(us_before))
            .map(|(r, before)| r.us.saturating_sub(*before))
            .sum();
        us as f64 / 1e3
    }

    /// A frame's compute of `compute_ms`, the variants' runs since `us_before`: the
    /// percept's times (int8 and outside the detectors) with `detections`.
    fn timed(&self, detections: Vec<Detection>, compute_ms: f64, us_before: &[u64]) -> Percept {
        Percept {
            detections,
            compute_ms,
            tracked: false,
            int8_ms: self.int8_ms_since(us_before),
            tracker_ms: (compute_ms - self.detector_ms_since(us_before)).max(0.0),
        }
    }

    /// The time, ms, the int8 variants ran since `us_before` (each variant's µs then).
    fn int8_ms_since(&self, us_before: &[u64]) -> f64 {
        let us: u64 = (self.runs_per_variant.iter().zip(us_before))
            .zip(&self.int8)
            .filter(|(_, int8)| **int8)
            .map(|((r, before), _)| r.us.saturating_sub(*before))
            .sum();
        us as f64 / 1e3
    }

    /// Periodic detections the budget keeper has postponed so far (0 without one).
    pub fn postponed(&self) -> u32 {
        self.pilot
            .scheduler()
            .and_then(|s| s.keeper())
            .map_or(0, |k| k.postponed())
    }

    /// Carry detections from `carry`'s bucket up ([`Pilot::with_carry`]; the default
    /// is [`Carry::Optimal`]). Call before the first frame.
    pub fn with_carry(mut self, carry: Carry) -> Self {
        self.pilot = Pilot::new(self.bundle).with_carry(carry);
        self.budget_ms = None;
        self.table_clock = None;
        let kind = match carry {
            Carry::Optimal => "",
            Carry::GoodEnough => "-carry-ge",
            Carry::Reported => "-carry-reported",
        };
        self.label.push_str(kind);
        self
    }

    /// The parsed bundle.
    pub fn bundle(&self) -> &Bundle<'static> {
        &self.bundle
    }

    /// The names of the variants run on the last frame [`BundlePerception::perceive`]
    /// processed, in bundle order (empty: the frame was tracked).
    pub fn last_variants(&self) -> Vec<&'static str> {
        self.last_run
            .iter()
            .filter_map(|&i| self.bundle.variant(i as u16).map(|v| v.name))
            .collect()
    }

    /// A short label: `adaptive-<bundle folder>`.
    pub fn name(&self) -> String {
        self.label.clone()
    }

    /// Process frame number `index` (0, 1, 2, … in processing order): the policy
    /// decides to detect (with which variant) or to track, and the detections the
    /// drone acts on come back with the compute time.
    pub fn perceive(
        &mut self,
        frame: FrameRef<'_>,
        index: u64,
    ) -> Result<Percept, PerceptionError> {
        let started = Instant::now();
        let (w, h) = (frame.width as usize, frame.height as usize);
        let levels = 3;
        if (w, h) != self.size {
            let need = Pyramid::required_len(w, h, levels).ok_or("frame too small to track")?;
            self.prev = vec![0; need];
            self.cur = vec![0; need];
            self.size = (w, h);
            self.have_prev = false;
        }
        let mut cur = Pyramid::new(&mut self.cur, w, h, levels)?;
        // the pyramid only when the pilot reads it: not under a table action that
        // leaves the frames between detections alone ([`Pilot::tracks_between`])
        let mut built = self.pilot.tracks_between();
        if built {
            cur.build_rgb(&frame)?;
        }
        let prev = if self.have_prev {
            Some(Pyramid::new(&mut self.prev, w, h, levels)?)
        } else {
            None
        };
        let runs_before: Vec<u64> = self.runs_per_variant.iter().map(|r| r.runs).collect();
        let us_before: Vec<u64> = self.runs_per_variant.iter().map(|r| r.us).collect();
        let decision = self.pilot.decide(index as u32, prev.as_ref(), &cur);
        let detections = match decision {
            Decision::Detect { variant, reason } => {
                if let Some(n) = self.detections_per_trigger.get_mut(reason as usize) {
                    *n += 1;
                }
                // the detection's action tracks its boxes: the trackers start on it
                if !built && self.pilot.tracks_between() {
                    cur.build_rgb(&frame)?;
                    built = true;
                }
                // the first variant, then any the policy asks for on the same frame
                let (detectors, counts) = (&mut self.detectors, &mut self.runs_per_variant);
                let (_, mut found) = self.pilot.detect_with(&cur, variant, |variant| {
                    run_variant(detectors, counts, variant, frame)
                })?;
                // the drone acts on reported detections only, as the replay scores them:
                // those at least the finding variant's T_c
                let t_c = self.pilot.report_score();
                found.retain(|d| d.score >= t_c);
                found
            }
            Decision::Track => self.pilot.tracked().collect(),
        };
        std::mem::swap(&mut self.prev, &mut self.cur);
        self.have_prev = built;
        self.last_run = (self.runs_per_variant.iter().zip(runs_before))
            .enumerate()
            .filter(|(_, (r, before))| r.runs > *before)
            .map(|(i, _)| i)
            .collect();
        let elapsed = started.elapsed();
        let percept = Percept {
            tracked: decision == Decision::Track,
            ..self.timed(detections, elapsed.as_secs_f64() * 1e3, &us_before)
        };
        // the budget keeper's debit (a pilot over the controller ignores it)
        self.pilot.spent(self.debit(&percept));
        let us = u64::try_from(elapsed.as_micros()).unwrap_or(u64::MAX);
        if decision == Decision::Track {
            self.tracked_frames += 1;
            self.tracked_us = self.tracked_us.saturating_add(us);
        } else {
            self.detected_us = self.detected_us.saturating_add(us);
        }
        Ok(percept)
    }

    /// The bundle's reference variant (the most accurate) on this frame, reporting
    /// what scores at least its family's `T_c`. The pilot's state is left as it is:
    /// a confirmation is the navigator's question, not a step of the policy.
    pub fn confirm(&mut self, frame: FrameRef<'_>) -> Result<Percept, PerceptionError> {
        let started = Instant::now();
        self.confirmations += 1;
        let reference = self.bundle.policy().reference();
        let us_before: Vec<u64> = self.runs_per_variant.iter().map(|r| r.us).collect();
        let t_c = self
            .bundle
            .variant_buckets(reference)
            .map_or(CNN_REPORT_SCORE, |b| b.t_c);
        let mut detections = run_variant(
            &mut self.detectors,
            &mut self.runs_per_variant,
            reference,
            frame,
        )?;
        detections.retain(|d| d.score >= t_c);
        let percept = self.timed(
            detections,
            started.elapsed().as_secs_f64() * 1e3,
            &us_before,
        );
        self.pilot.spent(self.debit(&percept));
        Ok(percept)
    }

    /// `frames detected: <trigger>` per controller trigger (the frame's first
    /// detection; a second one on the same image counts under its variant only),
    /// `frames tracked`, the compute time of both kinds of frame (`µs on tracked
    /// frames`, `µs on detection frames`, confirmations not included), `confirmations`,
    /// and `runs of <variant>` per bundle variant (every detection, second ones and
    /// confirmations included).
    pub fn counts(&self) -> Vec<(String, u64)> {
        let triggers = Trigger::ALL
            .iter()
            .zip(self.detections_per_trigger)
            .map(|(t, n)| (format!("frames detected: {t:?}"), n));
        let variants =
            self.bundle
                .variants()
                .zip(&self.runs_per_variant)
                .flat_map(|((_, v), r)| {
                    [
                        (format!("runs of {}", v.name), r.runs),
                        (format!("µs in {}", v.name), r.us),
                    ]
                });
        triggers
            .chain({
                let t = self.pilot.track_stats();
                [
                    ("boxes tracked".to_string(), u64::from(t.started)),
                    ("boxes not carried".to_string(), u64::from(t.not_carried)),
                    (
                        "trackers failed to start".to_string(),
                        u64::from(t.failed_to_start),
                    ),
                    ("tracks lost".to_string(), u64::from(t.lost)),
                ]
            })
            .chain([
                ("frames tracked".to_string(), self.tracked_frames),
                ("µs on tracked frames".to_string(), self.tracked_us),
                ("µs on detection frames".to_string(), self.detected_us),
                ("confirmations".to_string(), self.confirmations),
            ])
            .chain(variants)
            .collect()
    }
}

/// How often one variant ran, and for how long.
#[derive(Clone, Copy, Debug, Default)]
struct VariantRuns {
    runs: u64,
    us: u64,
}

/// Run the bundle's variant `variant` on `frame`, counting it and its time.
fn run_variant(
    detectors: &mut [OrtDetector],
    counts: &mut [VariantRuns],
    variant: frugal_runtime::VariantId,
    frame: FrameRef<'_>,
) -> Result<Vec<Detection>, PerceptionError> {
    let v = usize::from(variant);
    let det = detectors
        .get_mut(v)
        .ok_or("the bundle names a variant it has no detector for")?;
    let started = Instant::now();
    let found = det.detect(frame)?;
    if let Some(c) = counts.get_mut(v) {
        c.runs += 1;
        let us = u64::try_from(started.elapsed().as_micros()).unwrap_or(u64::MAX);
        c.us = c.us.saturating_add(us);
    }
    Ok(found)
}
