//! The detector variants a policy chooses from: their families and confidence buckets,
//! measured latencies, relative costs, and the detectors themselves behind one boxed
//! trait object.
//!
//! # Confidence buckets per family
//!
//! The MDP state is (confidence bucket, variant), and the bucket edges live on each
//! family's own score scale:
//!
//! - **HoG + SVM** (`hog`): the score is the SVM margin `wᵀx + b`; the paper's edges
//!   `c_opt = 0.9`, `c_ge = 0`, `c_ua = −0.5` ([`HOG_BUCKETS`]).
//! - **CNN** (`cnn`): the score is a softmax probability in `[0, 1]`. The margin edges
//!   do not transfer (a probability is never negative), so [`CNN_BUCKETS`] maps them by
//!   what they *mean*: the SVM's decision boundary (margin 0) becomes the point where the
//!   sign class is more likely than everything else together, `c_ge = 0.5`; "clearly past
//!   the boundary" (margin 0.9, about one margin unit) becomes `c_opt = 0.9`, the usual
//!   high-confidence cut of a softmax detector; "plausible but below the boundary"
//!   (margin −0.5, half a unit on the wrong side) becomes `c_ua = 0.3`, below which a
//!   detection is treated as a miss. `T_c` is `c_ge` for both families: a detection
//!   that is not at least good enough makes the controller re-ask the policy (the
//!   paper's KUL setting, `T_c = 0` on the margin scale).
//!
//! A variants file may override the buckets of any family.
//!
//! # Detectors
//!
//! Real detectors implement [`frugal_runtime::Detector`]; wrap them in
//! [`RuntimeDetector`]. Test and demonstration detectors derived from the ground truth
//! ([`SyntheticDetector`]) also see the frame's truth through [`FrameContext`]; real
//! detectors ignore it.
//!
//! Over 600 lines only with its unit tests (the last 50).

use crate::error::{PolicyError, Result};
use frugal_data::{Clutter, Light};
use frugal_runtime::bundle::ScoreBuckets;
use frugal_runtime::{BBox, ClassId, Detection, Detector, FrameRef};
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// One family's bucket edges and `T_c`, on the family's score scale (serde form of
/// [`ScoreBuckets`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Buckets {
    /// Lower edge of the optimal bucket.
    pub c_opt: f32,
    /// Lower edge of the good-enough bucket.
    pub c_ge: f32,
    /// Lower edge of the inadequate bucket; below is a miss.
    pub c_ua: f32,
    /// A best score below this re-asks the policy; also the score at which a detection
    /// is reported (and tracked).
    pub t_c: f32,
}

impl Buckets {
    /// The runtime's form.
    pub fn to_runtime(self) -> ScoreBuckets {
        ScoreBuckets {
            c_opt: self.c_opt,
            c_ge: self.c_ge,
            c_ua: self.c_ua,
            t_c: self.t_c,
        }
    }
}

/// The paper's SVM-margin buckets for the HoG family (`T_c = c_ge = 0`).
pub const HOG_BUCKETS: Buckets = Buckets {
    c_opt: 0.9,
    c_ge: 0.0,
    c_ua: -0.5,
    t_c: 0.0,
};

/// Softmax-probability buckets for the CNN family (see the module docs for why).
pub const CNN_BUCKETS: Buckets = Buckets {
    c_opt: 0.9,
    c_ge: 0.5,
    c_ua: 0.3,
    t_c: 0.5,
};

/// The default buckets of a family by name: `hog…` gets [`HOG_BUCKETS`], anything else
/// (the CNN family, synthetic detectors) [`CNN_BUCKETS`].
pub fn default_buckets(family: &str) -> Buckets {
    if family.starts_with("hog") {
        HOG_BUCKETS
    } else {
        CNN_BUCKETS
    }
}

/// A detector family.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FamilyInfo {
    /// Its name (`cnn`, `hog`, …).
    pub name: String,
    /// Its buckets.
    pub buckets: Buckets,
}

/// Where a variant's detector comes from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum VariantSource {
    /// An exported CNN: a folder of ONNX graphs run by ONNX Runtime.
    Onnx {
        /// The folder.
        dir: PathBuf,
    },
    /// A HoG + SVM variant: a trained feature model file and the variant's parameter
    /// tuple `"proposals,block,cell,bins"` (e.g. `"1000,2,8,9"`).
    Hog {
        /// The `frugal-features` model file.
        model: PathBuf,
        /// The parameter tuple.
        params: String,
    },
    /// A detector derived from the ground truth with controlled noise (tests, demos).
    Synthetic(SyntheticSpec),
}

/// The arithmetic a variant's graphs run in: a device profile states its speed for each
/// ([`crate::budget::BudgetConfig::device_reference_int8_ms`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// Floating point (and any detector that is not an int8 graph).
    #[default]
    Fp32,
    /// int8 QDQ graphs.
    Int8,
}

/// A variant's description (everything but the detector itself).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VariantInfo {
    /// Its name.
    pub name: String,
    /// Index into the family list.
    pub family: usize,
    /// Measured latency per frame, ms (the Pareto stage's fastest timed run).
    pub latency_ms: f64,
    /// `latency_ms` over the cheapest variant's (`r(s)` in the reward), `>= 1`.
    pub relative_cost: f64,
    /// Its arithmetic (logs written before it was recorded read as fp32).
    #[serde(default, skip_serializing_if = "is_fp32")]
    pub precision: Precision,
    /// Where the detector comes from.
    pub source: VariantSource,
}

fn is_fp32(p: &Precision) -> bool {
    *p == Precision::Fp32
}

/// What a detector is told about the frame besides its pixels.
#[derive(Clone, Copy, Debug)]
pub struct FrameContext<'a> {
    /// Video id.
    pub video: u32,
    /// Frame index in the video.
    pub index: u32,
    /// The video's clutter level.
    pub clutter: Clutter,
    /// The video's illumination.
    pub light: Light,
    /// The ground truth (only synthetic detectors may look at it).
    pub truth: &'a [(ClassId, BBox)],
}

/// A detector as the replay runs it: boxed, `Send`, errors as text.
pub trait FrameDetector: Send {
    /// Detections of `frame`, best first, at most `max`.
    fn detect(
        &mut self,
        frame: FrameRef<'_>,
        ctx: &FrameContext<'_>,
        max: usize,
    ) -> std::result::Result<Vec<Detection>, String>;
}

/// Adapts any [`frugal_runtime::Detector`] (the ONNX Runtime executor, the HoG
/// pipeline, the tch CNN) to [`FrameDetector`]; it never sees the truth.
#[derive(Debug)]
pub struct RuntimeDetector<D>(pub D);

impl<D> FrameDetector for RuntimeDetector<D>
where
    D: Detector + Send,
    D::Error: std::fmt::Display,
{
    fn detect(
        &mut self,
        frame: FrameRef<'_>,
        _ctx: &FrameContext<'_>,
        max: usize,
    ) -> std::result::Result<Vec<Detection>, String> {
        let mut out = vec![Detection::default(); max];
        let n = self.0.detect(frame, &mut out).map_err(|e| e.to_string())?;
        out.truncate(n);
        Ok(out)
    }
}

/// A ground-truth-derived detector: each object is missed with a probability that
/// depends on the scenario, otherwise reported with a jittered box and a score drawn
/// from a range; optional false alarms. Deterministic per (seed, video, frame).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SyntheticSpec {
    /// Seed (combine with video and frame).
    pub seed: u64,
    /// Miss probability in normal light, low/medium clutter.
    pub miss: f32,
    /// Miss probability in low light (any clutter).
    pub miss_low_light: f32,
    /// Miss probability in high clutter, normal light.
    pub miss_high_clutter: f32,
    /// Box jitter as a fraction of the box size (uniform, per edge).
    pub jitter: f32,
    /// Score range of a hit, `[lo, hi)`.
    pub score: [f32; 2],
    /// Probability of one false alarm per frame.
    pub false_alarm: f32,
    /// Score range of a false alarm.
    pub false_score: [f32; 2],
}

impl Default for SyntheticSpec {
    fn default() -> Self {
        Self {
            seed: 0,
            miss: 0.05,
            miss_low_light: 0.05,
            miss_high_clutter: 0.05,
            jitter: 0.05,
            score: [0.9, 1.0],
            false_alarm: 0.0,
            false_score: [0.3, 0.6],
        }
    }
}

/// [`SyntheticSpec`] as a detector.
#[derive(Clone, Debug)]
pub struct SyntheticDetector(pub SyntheticSpec);

fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn draw(rng: &mut impl Rng, range: [f32; 2]) -> f32 {
    if range[1] > range[0] {
        rng.random_range(range[0]..range[1])
    } else {
        range[0]
    }
}

impl FrameDetector for SyntheticDetector {
    fn detect(
        &mut self,
        frame: FrameRef<'_>,
        ctx: &FrameContext<'_>,
        max: usize,
    ) -> std::result::Result<Vec<Detection>, String> {
        let s = &self.0;
        let seed = mix(mix(mix(s.seed) ^ u64::from(ctx.video)) ^ u64::from(ctx.index));
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let miss = match (ctx.light, ctx.clutter) {
            (Light::Low, _) => s.miss_low_light,
            (Light::Normal, Clutter::High) => s.miss_high_clutter,
            _ => s.miss,
        };
        let (w, h) = (frame.width as f32, frame.height as f32);
        let mut out = Vec::new();
        for &(class, b) in ctx.truth {
            let roll: f32 = rng.random();
            let mut j = || rng.random_range(-1.0f32..=1.0) * s.jitter;
            let (bw, bh) = (b.width(), b.height());
            let bbox = BBox::new(
                b.x1 + j() * bw,
                b.y1 + j() * bh,
                b.x2 + j() * bw,
                b.y2 + j() * bh,
            )
            .clip(w, h);
            let score = draw(&mut rng, s.score);
            if roll >= miss && bbox.is_valid() {
                out.push(Detection { bbox, score, class });
            }
        }
        if rng.random::<f32>() < s.false_alarm {
            let size = rng.random_range(10.0f32..40.0).min(w.min(h) * 0.5);
            let x = rng.random_range(0.0..(w - size).max(1.0));
            let y = rng.random_range(0.0..(h - size).max(1.0));
            out.push(Detection {
                bbox: BBox::from_xywh(x, y, size, size),
                score: draw(&mut rng, s.false_score),
                class: 0,
            });
        }
        out.sort_by(|a, b| b.score.total_cmp(&a.score));
        out.truncate(max);
        Ok(out)
    }
}

/// The variants, sorted cheapest first (so that ties in the MDP go to the cheaper
/// variant), with their detectors.
pub struct VariantSet {
    /// The families.
    pub families: Vec<FamilyInfo>,
    /// The variants, cheapest first.
    pub variants: Vec<VariantInfo>,
    /// `detectors[i]` runs `variants[i]`.
    pub detectors: Vec<Box<dyn FrameDetector>>,
}

impl std::fmt::Debug for VariantSet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VariantSet")
            .field("families", &self.families)
            .field("variants", &self.variants)
            .finish_non_exhaustive()
    }
}

/// One variant in a variants file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VariantEntry {
    /// Its name (unique).
    pub name: String,
    /// Its family's name.
    pub family: String,
    /// Measured latency per frame, ms (`> 0`); when absent, `policy record` times the
    /// detector itself (one thread, the fastest of its runs over sample frames).
    #[serde(default)]
    pub latency_ms: Option<f64>,
    /// Its arithmetic, `"fp32"` (the default) or `"int8"`: which of the device
    /// profile's speeds its latency scales by.
    #[serde(default)]
    pub precision: Precision,
    /// Where the detector comes from.
    pub source: VariantSource,
}

/// A family entry in a variants file (to override the default buckets).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FamilyEntry {
    /// Family name.
    pub name: String,
    /// Its buckets.
    pub buckets: Buckets,
}

/// A variants file (JSON or TOML): the variants, optionally the families' buckets.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VariantsFile {
    /// Bucket overrides per family; families not listed get [`default_buckets`].
    #[serde(default)]
    pub families: Vec<FamilyEntry>,
    /// The variants.
    pub variants: Vec<VariantEntry>,
    /// Median latency (ms) of the reference detector timed with the variants on the
    /// machine that timed them (`frugal pareto` writes it); a replay log keeps it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_ms: Option<f64>,
    /// The same for the int8 reference detector; a replay log keeps it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_int8_ms: Option<f64>,
}

impl VariantsFile {
    /// Read a `.toml` or JSON variants file; relative ONNX folders are resolved against
    /// the file's folder.
    pub fn read(path: &Path) -> Result<Self> {
        let mut file: VariantsFile = crate::error::read_toml_or_json(path)?;
        let parent = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        let base = std::path::absolute(parent).map_err(|e| PolicyError::io(parent, e))?;
        for v in &mut file.variants {
            match &mut v.source {
                VariantSource::Onnx { dir } | VariantSource::Hog { model: dir, .. }
                    if dir.is_relative() =>
                {
                    *dir = base.join(&*dir);
                }
                _ => {}
            }
        }
        Ok(file)
    }

    /// Families and variants (cheapest first, relative costs filled in), checked;
    /// `path` names the file in errors.
    pub fn resolve(&self, path: &Path) -> Result<(Vec<FamilyInfo>, Vec<VariantInfo>)> {
        self.resolve_with(path, &[])
    }

    /// As [`VariantsFile::resolve`], with `measured[i]` standing in for variant `i`'s
    /// missing latency.
    pub fn resolve_with(
        &self,
        path: &Path,
        measured: &[Option<f64>],
    ) -> Result<(Vec<FamilyInfo>, Vec<VariantInfo>)> {
        if self.variants.is_empty() {
            return Err(PolicyError::invalid(path, "variants", "no variants"));
        }
        let mut families: Vec<FamilyInfo> = Vec::new();
        let mut variants = Vec::new();
        for (i, v) in self.variants.iter().enumerate() {
            let field = format!("variants[{i}] ({})", v.name);
            let latency = v
                .latency_ms
                .or(measured.get(i).copied().flatten())
                .unwrap_or(f64::NAN);
            if !(latency.is_finite() && latency > 0.0) {
                return Err(PolicyError::invalid(
                    path,
                    field,
                    format!("latency_ms must be given and > 0, got {latency}"),
                ));
            }
            if self.variants[..i].iter().any(|o| o.name == v.name) {
                return Err(PolicyError::invalid(path, field, "duplicate name"));
            }
            let family = match families.iter().position(|f| f.name == v.family) {
                Some(f) => f,
                None => {
                    let buckets = self
                        .families
                        .iter()
                        .find(|f| f.name == v.family)
                        .map_or_else(|| default_buckets(&v.family), |f| f.buckets);
                    if !buckets.to_runtime().is_valid() {
                        return Err(PolicyError::invalid(
                            path,
                            format!("families ({})", v.family),
                            "bucket edges must be finite with c_opt >= c_ge >= c_ua",
                        ));
                    }
                    families.push(FamilyInfo {
                        name: v.family.clone(),
                        buckets,
                    });
                    families.len() - 1
                }
            };
            variants.push(VariantInfo {
                name: v.name.clone(),
                family,
                latency_ms: latency,
                relative_cost: 1.0,
                precision: v.precision,
                source: v.source.clone(),
            });
        }
        finish_costs(&mut variants);
        Ok((families, variants))
    }
}

/// Sort cheapest first and fill in the relative costs.
pub fn finish_costs(variants: &mut [VariantInfo]) {
    variants.sort_by(|a, b| a.latency_ms.total_cmp(&b.latency_ms));
    let min = variants.first().map_or(1.0, |v| v.latency_ms);
    for v in variants.iter_mut() {
        v.relative_cost = v.latency_ms / min;
    }
}

impl VariantSet {
    /// A set from families, variants and their detectors (paired by position); sorts
    /// the pairs cheapest first and fills in the relative costs.
    pub fn new(
        families: Vec<FamilyInfo>,
        variants: Vec<VariantInfo>,
        detectors: Vec<Box<dyn FrameDetector>>,
    ) -> Self {
        let mut pairs: Vec<_> = variants.into_iter().zip(detectors).collect();
        pairs.sort_by(|a, b| a.0.latency_ms.total_cmp(&b.0.latency_ms));
        let (mut variants, detectors): (Vec<_>, Vec<_>) = pairs.into_iter().unzip();
        finish_costs(&mut variants);
        Self {
            families,
            variants,
            detectors,
        }
    }

    /// The set of a variants file: synthetic detectors are built here, every other
    /// kind (ONNX, HoG) by the caller through `open`. The variants without a latency are
    /// timed together by `time` (ms per frame each, in the order given), so a
    /// timing harness can interleave them and a change of machine load hits them alike.
    pub fn from_file(
        file: &VariantsFile,
        path: &Path,
        mut open: impl FnMut(&VariantInfo) -> Result<Box<dyn FrameDetector>>,
        time: impl FnOnce(&mut [(&str, &mut dyn FrameDetector)]) -> Result<Vec<f64>>,
    ) -> Result<Self> {
        let mut detectors = Vec::with_capacity(file.variants.len());
        for entry in &file.variants {
            let info = VariantInfo {
                name: entry.name.clone(),
                family: 0,
                latency_ms: entry.latency_ms.unwrap_or(f64::NAN),
                relative_cost: 1.0,
                precision: entry.precision,
                source: entry.source.clone(),
            };
            detectors.push(match &info.source {
                VariantSource::Synthetic(spec) => {
                    Box::new(SyntheticDetector(spec.clone())) as Box<dyn FrameDetector>
                }
                VariantSource::Onnx { .. } | VariantSource::Hog { .. } => open(&info)?,
            });
        }
        let mut untimed: Vec<(&str, &mut dyn FrameDetector)> = file
            .variants
            .iter()
            .zip(detectors.iter_mut())
            .filter(|(entry, _)| entry.latency_ms.is_none())
            .map(|(entry, det)| (entry.name.as_str(), det.as_mut() as &mut dyn FrameDetector))
            .collect();
        let times = if untimed.is_empty() {
            Vec::new()
        } else {
            time(&mut untimed)?
        };
        if times.len() != untimed.len() {
            return Err(PolicyError::invalid(
                path,
                "latency_ms",
                format!("timed {} of {} variants", times.len(), untimed.len()),
            ));
        }
        drop(untimed);
        let mut times = times.into_iter();
        let measured: Vec<Option<f64>> = file
            .variants
            .iter()
            .map(|entry| entry.latency_ms.map_or_else(|| times.next(), |_| None))
            .collect();
        let (families, variants) = file.resolve_with(path, &measured)?;
        // `resolve_with` sorts; pair detectors with their variants by name.
        let mut named: Vec<(String, Box<dyn FrameDetector>)> = file
            .variants
            .iter()
            .map(|v| v.name.clone())
            .zip(detectors)
            .collect();
        let detectors = variants
            .iter()
            .map(|v| {
                let i = named.iter().position(|(n, _)| *n == v.name).unwrap_or(0);
                named.swap_remove(i).1
            })
            .collect();
        Ok(Self {
            families,
            variants,
            detectors,
        })
    }

    /// The bucket edges of variant `v`.
    pub fn buckets(&self, v: usize) -> Buckets {
        self.families[self.variants[v].family].buckets
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(name: &str, latency_ms: Option<f64>) -> VariantEntry {
        VariantEntry {
            name: name.into(),
            family: "cnn".into(),
            latency_ms,
            precision: Precision::Fp32,
            source: VariantSource::Synthetic(SyntheticSpec::default()),
        }
    }

    #[test]
    fn only_the_untimed_variants_are_timed_together_in_file_order() {
        let file = VariantsFile {
            families: Vec::new(),
            variants: vec![entry("a", Some(5.0)), entry("b", None), entry("c", None)],
            reference_ms: None,
            reference_int8_ms: None,
        };
        let mut asked = Vec::new();
        let set = VariantSet::from_file(
            &file,
            Path::new("variants.toml"),
            |_| unreachable!("synthetic variants are built in"),
            |dets| {
                asked = dets.iter().map(|(n, _)| n.to_string()).collect();
                Ok(vec![7.0, 3.0])
            },
        )
        .expect("set");
        assert_eq!(asked, ["b", "c"]);
        let ms = |n: &str| {
            set.variants
                .iter()
                .find(|v| v.name == n)
                .map(|v| v.latency_ms)
        };
        assert_eq!(
            (ms("a"), ms("b"), ms("c")),
            (Some(5.0), Some(7.0), Some(3.0))
        );
        assert_eq!(set.detectors.len(), 3);

        let Err(err) = VariantSet::from_file(
            &file,
            Path::new("variants.toml"),
            |_| unreachable!(),
            |_| Ok(vec![7.0]),
        ) else {
            panic!("a missing time is an error");
        };
        assert!(err.to_string().contains("timed 1 of 2"), "{err}");
    }
}
