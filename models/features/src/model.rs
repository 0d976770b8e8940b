//! Trained SVMs per HoG configuration, their file format, and the detector.

use crate::edgeboxes::{EdgeBoxesConfig, Proposal, proposals};
use crate::error::{Error, Result};
use crate::frame::Rgb;
use crate::hog::{HogScratch, hog_into};
use crate::params::HogParams;
use crate::svm::LinearSvm;
use frugal_runtime::{BBox, ClassId, Detection, Detector, FrameRef};
use rayon::prelude::*;
use std::io::Write as _;
use std::path::Path;

/// Version of the model file format written by [`FeatureModel::save`].
pub const MODEL_FORMAT: u32 = 2;

/// The paper's confidence thresholds on the SVM margin: `c_opt = 0.9`, `c_ge = 0`,
/// `c_ua = −0.5`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ScoreThresholds {
    /// At or above: optimal.
    pub opt: f32,
    /// At or above (and below `opt`): good enough.
    pub ge: f32,
    /// At or above (and below `ge`): unacceptable but still a detection; below it the
    /// detector reports nothing.
    pub ua: f32,
}

impl ScoreThresholds {
    /// The paper's values.
    pub const PAPER: ScoreThresholds = ScoreThresholds {
        opt: 0.9,
        ge: 0.0,
        ua: -0.5,
    };

    /// The confidence bucket of a frame's best score (`None`: nothing detected).
    pub fn bucket(&self, best: Option<f32>) -> Confidence {
        match best {
            Some(s) if s >= self.opt => Confidence::Optimal,
            Some(s) if s >= self.ge => Confidence::GoodEnough,
            _ => Confidence::Unacceptable,
        }
    }
}

impl Default for ScoreThresholds {
    fn default() -> Self {
        Self::PAPER
    }
}

/// The MDP's three confidence categories.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Confidence {
    /// Below `c_ge`, or no detection.
    Unacceptable,
    /// In `[c_ge, c_opt)`.
    GoodEnough,
    /// At least `c_opt`.
    Optimal,
}

/// One SVM per class for one HoG configuration.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HogSvms {
    /// Block side in cells.
    pub block: u8,
    /// Cell side in pixels.
    pub cell: u8,
    /// Orientation bins.
    pub bins: u8,
    /// One-vs-rest classifiers, indexed by class id.
    pub svms: Vec<LinearSvm>,
}

/// A trained feature-based detector family: the shared settings and one SVM set per
/// HoG configuration; any ⟨proposals, block, cell, bins⟩ whose HoG part was trained is
/// a usable variant.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FeatureModel {
    /// File format version ([`MODEL_FORMAT`]).
    pub format: u32,
    /// Class names, indexed by class id.
    pub classes: Vec<String>,
    /// Side of the square reference window: a variant's cell grid is `window / cell`
    /// cells a side (see [`HogParams::geometry`]).
    pub window: usize,
    /// Proposal settings.
    pub edgeboxes: EdgeBoxesConfig,
    /// Whether HoG votes are split between orientation bins.
    pub orientation_interpolation: bool,
    /// Confidence thresholds; detections below `thresholds.ua` are not reported.
    pub thresholds: ScoreThresholds,
    /// IoU above which a lower-scoring detection is suppressed.
    pub nms_iou: f32,
    /// The trained SVM sets.
    pub hogs: Vec<HogSvms>,
}

impl FeatureModel {
    /// The SVM set of a HoG configuration.
    pub fn svms(&self, block: u8, cell: u8, bins: u8) -> Result<&HogSvms> {
        self.hogs
            .iter()
            .find(|h| (h.block, h.cell, h.bins) == (block, cell, bins))
            .ok_or(Error::MissingHog { block, cell, bins })
    }

    /// Every variant the model supports for the given proposal counts.
    pub fn variants(&self, proposals: &[u32]) -> Vec<HogParams> {
        let mut v: Vec<HogParams> = proposals
            .iter()
            .flat_map(|&p| {
                self.hogs.iter().map(move |h| HogParams {
                    proposals: p,
                    block: h.block,
                    cell: h.cell,
                    bins: h.bins,
                })
            })
            .collect();
        v.sort();
        v
    }

    /// A detector for one variant.
    pub fn detector(&self, params: HogParams) -> Result<HogDetector<'_>> {
        params.validate(self.window)?;
        let svms = self.svms(params.block, params.cell, params.bins)?;
        Ok(HogDetector {
            model: self,
            svms,
            params,
        })
    }

    /// EdgeBoxes proposals of a frame, best first (the first `n` of a longer list are
    /// the list for `n`, so variants can share one call with the largest count).
    pub fn proposals(&self, img: &Rgb<'_>, n: usize) -> Result<Vec<Proposal>> {
        proposals(img, &self.edgeboxes, n)
    }

    /// Check internal consistency (class count vs SVM counts, feature lengths).
    pub fn validate(&self) -> std::result::Result<(), String> {
        if self.format != MODEL_FORMAT {
            return Err(format!(
                "format {} (this build reads {MODEL_FORMAT})",
                self.format
            ));
        }
        self.edgeboxes.validate().map_err(|e| e.to_string())?;
        if self.classes.is_empty() {
            return Err("no classes".into());
        }
        for h in &self.hogs {
            let p = HogParams {
                proposals: 1,
                block: h.block,
                cell: h.cell,
                bins: h.bins,
            };
            p.validate(self.window)
                .map_err(|e| format!("SVM set {p}: {e}"))?;
            let dim = p.feature_len(self.window);
            if h.svms.len() != self.classes.len() {
                return Err(format!(
                    "SVM set <·,{},{},{}> has {} classifiers for {} classes",
                    h.block,
                    h.cell,
                    h.bins,
                    h.svms.len(),
                    self.classes.len()
                ));
            }
            if let Some(s) = h.svms.iter().find(|s| s.w.len() != dim || !s.b.is_finite()) {
                return Err(format!(
                    "SVM set <·,{},{},{}>: a classifier has {} weights (expected {dim}) or a non-finite bias {}",
                    h.block,
                    h.cell,
                    h.bins,
                    s.w.len(),
                    s.b
                ));
            }
        }
        Ok(())
    }

    /// Write the model as JSON, atomically (temp file in the same folder, then rename).
    pub fn save(&self, path: &Path) -> Result<()> {
        let io = |source| Error::Io {
            path: path.to_owned(),
            source,
        };
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(io)?;
        serde_json::to_writer(std::io::BufWriter::new(&mut tmp), self)
            .map_err(|e| io(std::io::Error::other(e)))?;
        tmp.flush().map_err(io)?;
        tmp.persist(path).map_err(|e| io(e.error))?;
        Ok(())
    }

    /// Read and check a model written by [`FeatureModel::save`].
    pub fn load(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|source| Error::Io {
            path: path.to_owned(),
            source,
        })?;
        let model: FeatureModel = serde_json::from_slice(&bytes).map_err(|e| Error::Model {
            path: path.to_owned(),
            reason: e.to_string(),
        })?;
        model.validate().map_err(|reason| Error::Model {
            path: path.to_owned(),
            reason,
        })?;
        Ok(model)
    }
}

/// Per-thread buffers for window resampling and HoG.
#[derive(Default)]
pub(crate) struct Buffers {
    pub(crate) window: Vec<f32>,
    pub(crate) hog: HogScratch,
    pub(crate) feat: Vec<f32>,
}

/// One variant of the family, ready to run: EdgeBoxes top-`proposals`, HoG of each
/// proposal's window, every class's SVM; each proposal becomes a detection of its
/// best class with the margin as score, kept when the margin is at least
/// `thresholds.ua`, then greedy NMS across classes.
#[derive(Clone, Copy, Debug)]
pub struct HogDetector<'m> {
    model: &'m FeatureModel,
    svms: &'m HogSvms,
    params: HogParams,
}

impl HogDetector<'_> {
    /// The variant's parameters.
    pub fn params(&self) -> HogParams {
        self.params
    }

    /// Best class and margin for each box.
    pub fn classify(&self, img: &Rgb<'_>, boxes: &[BBox]) -> Vec<(ClassId, f32)> {
        let (size, cfg) = self
            .params
            .geometry(self.model.window, self.model.orientation_interpolation);
        boxes
            .par_iter()
            .with_min_len(16)
            .map_init(Buffers::default, |buf, b| {
                img.window(b, size, &mut buf.window);
                hog_into(
                    &buf.window,
                    size,
                    size,
                    3,
                    &cfg,
                    &mut buf.hog,
                    &mut buf.feat,
                );
                best_class(&self.svms.svms, &buf.feat)
            })
            .collect()
    }

    /// Detections from the given proposals (only the first `params.proposals` are
    /// used), best first.
    pub fn detect_proposals(&self, img: &Rgb<'_>, proposals: &[Proposal]) -> Vec<Detection> {
        let n = (self.params.proposals as usize).min(proposals.len());
        let boxes: Vec<BBox> = proposals[..n].iter().map(|p| p.bbox).collect();
        let scored = self.classify(img, &boxes);
        let mut dets: Vec<Detection> = boxes
            .iter()
            .zip(scored)
            .filter(|(_, (_, s))| *s >= self.model.thresholds.ua)
            .map(|(b, (class, score))| Detection {
                bbox: *b,
                score,
                class,
            })
            .collect();
        dets.sort_by(|a, b| b.score.total_cmp(&a.score));
        let mut kept: Vec<Detection> = Vec::new();
        for d in dets {
            if kept
                .iter()
                .all(|k| k.bbox.iou(&d.bbox) <= self.model.nms_iou)
            {
                kept.push(d);
            }
        }
        kept
    }

    /// All detections of a frame, best first.
    pub fn detect_all(&self, img: &Rgb<'_>) -> Result<Vec<Detection>> {
        let props = self.model.proposals(img, self.params.proposals as usize)?;
        Ok(self.detect_proposals(img, &props))
    }
}

/// The class with the highest margin (the first on ties) and that margin.
pub(crate) fn best_class(svms: &[LinearSvm], feat: &[f32]) -> (ClassId, f32) {
    let mut best = (0, f32::NEG_INFINITY);
    for (k, s) in svms.iter().enumerate() {
        let m = s.score(feat);
        if m > best.1 {
            best = (k as ClassId, m);
        }
    }
    best
}

impl Detector for HogDetector<'_> {
    type Error = Error;

    fn detect(&mut self, frame: FrameRef<'_>, out: &mut [Detection]) -> Result<usize> {
        let img = Rgb::from_frame(frame)?;
        let dets = self.detect_all(&img)?;
        let n = dets.len().min(out.len());
        out[..n].copy_from_slice(&dets[..n]);
        Ok(n)
    }
}
