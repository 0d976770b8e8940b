//! The bundle writer (feature `std`): a builder taking owned structs, producing the
//! bytes of format version [`FORMAT_VERSION`] (see the [module docs](super) for the
//! layout). A bundle without schedules has the sections of version 3; only the
//! version field (and so the file checksum) differs.
//!
//! ```
//! use frugal_runtime::bundle::write::{BundleWriter, FamilySpec, VariantSpec};
//! use frugal_runtime::bundle::{Bundle, ScoreBuckets, Thresholds, BUCKET_COUNT};
//!
//! let bytes = BundleWriter::new(Thresholds::PAPER)
//!     .family(FamilySpec { name: "hog".into(), buckets: ScoreBuckets::PAPER_SVM })
//!     .variant(VariantSpec::new("hog-fast", 0, 1.0, 12.0))
//!     .variant(VariantSpec::new("hog-full", 0, 3.0, 40.0))
//!     .policy(0, vec![0, 0, 0, 1, 1, 1, 1, 1]) // BUCKET_COUNT rows x 2 variants
//!     .metadata("trained-on", "seeds 0..100")
//!     .finish()?;
//! let bundle = Bundle::parse(&bytes)?;
//! assert_eq!(bundle.variant_count(), 2);
//! assert_eq!(bundle.metadata_get("trained-on"), Some("seeds 0..100"));
//! # assert_eq!(BUCKET_COUNT, 4);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use super::{
    BUCKET_COUNT, BUDGET_RECORD, Bundle, BundleError, FORMAT_VERSION, HEADER_LEN, MAGIC,
    SCHEDULES_HEADER, SECTION_ENTRY_LEN, ScoreBuckets, SectionKind, Thresholds,
};
use crate::content::{
    BudgetInfo, CONTENT_STATES, COUNT_BUCKETS, ContentEdges, MAX_BUDGETS, MAX_PERIOD, MAX_PERIODS,
    MOTION_BUCKETS, SIZE_BUCKETS, ScheduleAction,
};
use crate::crc::{Crc32, crc32};
use crate::geom::VariantId;
use std::fmt;
use std::string::String;
use std::vec::Vec;

/// A detector family with its confidence buckets.
#[derive(Clone, Debug, PartialEq)]
pub struct FamilySpec {
    /// Family name.
    pub name: String,
    /// Its buckets and `T_c`, on the family's score scale.
    pub buckets: ScoreBuckets,
}

/// A detector variant.
#[derive(Clone, Debug, PartialEq)]
pub struct VariantSpec {
    /// Variant name.
    pub name: String,
    /// Index of its family (order of [`BundleWriter::family`] calls).
    pub family: u16,
    /// Cost relative to the cheapest variant, `> 0`.
    pub relative_cost: f32,
    /// Measured latency in milliseconds, `>= 0`.
    pub latency_ms: f32,
    /// ONNX file name relative to the bundle; empty when there is none.
    pub onnx_file: String,
    /// SHA-256 of the ONNX file (zeros when there is none).
    pub sha256: [u8; 32],
}

impl VariantSpec {
    /// A variant without an ONNX file.
    pub fn new(name: &str, family: u16, relative_cost: f32, latency_ms: f32) -> Self {
        Self {
            name: name.into(),
            family,
            relative_cost,
            latency_ms,
            onnx_file: String::new(),
            sha256: [0; 32],
        }
    }
}

/// The budget schedules of a bundle ([`crate::bundle::Schedules`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ScheduleSpec {
    /// The edges of the size and motion buckets.
    pub edges: ContentEdges,
    /// The detection periods in frames: 1 ..= [`MAX_PERIODS`] of them, strictly
    /// ascending, each in 1 ..= 255.
    pub periods: Vec<u32>,
    /// The action of the first frame.
    pub initial: ScheduleAction,
    /// The interval in ms between the frames the tables count (their periods, budgets
    /// per frame and motion edges per frame), finite and positive: 1000 / 30 for tables
    /// made on 30 fps video.
    pub frame_ms: f32,
    /// One table per latency budget, 1 ..= [`MAX_BUDGETS`] of them.
    pub budgets: Vec<BudgetSpec>,
}

/// One latency budget's table.
#[derive(Clone, Debug, PartialEq)]
pub struct BudgetSpec {
    /// What the table was made for.
    pub info: BudgetInfo,
    /// The action of every state, in [`crate::schedule::state_index`] order:
    /// `BUCKET_COUNT · V · CONTENT_STATES` (108 `V`) of them.
    pub actions: Vec<ScheduleAction>,
}

/// Why a bundle could not be written.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WriteError {
    /// A string is longer than 65 535 bytes.
    StringTooLong,
    /// More variants or families than the format allows, or the file would exceed 4 GiB.
    TooLarge,
    /// No policy was given.
    MissingPolicy,
    /// The schedules' periods are none, more than [`MAX_PERIODS`], not strictly
    /// ascending, or outside 1 ..= 255.
    BadPeriods,
    /// The schedules' size or motion edges are not finite or not `0 <= e0 <= e1`.
    BadEdges,
    /// The schedules have no budget, or more than [`MAX_BUDGETS`].
    BadBudgetCount,
    /// The schedules' frame interval is not finite and positive.
    BadFrameInterval,
    /// A budget's figures are not finite, or its budget or slowdown is not positive,
    /// or a latency is negative.
    BadBudget,
    /// A budget table does not have one action per state (`BUCKET_COUNT · V ·
    /// CONTENT_STATES`).
    BadScheduleLength,
    /// A schedule action (or the initial one) names a variant that does not exist or
    /// a period that is not among the schedules' periods.
    BadScheduleAction,
    /// The written bytes do not pass the reader (the reason is the reader's).
    Invalid(BundleError),
}

impl fmt::Display for WriteError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::StringTooLong => f.write_str("bundle string longer than 65535 bytes"),
            Self::TooLarge => f.write_str("bundle too large for its format"),
            Self::MissingPolicy => f.write_str("bundle has no policy table"),
            Self::BadPeriods => f.write_str(
                "bundle schedule periods must be 1 to 4 strictly ascending values in 1..=255",
            ),
            Self::BadEdges => f.write_str(
                "bundle schedule content edges must be finite with 0 <= edge 0 <= edge 1",
            ),
            Self::BadBudgetCount => f.write_str("bundle schedules must have 1 to 8 budgets"),
            Self::BadFrameInterval => {
                f.write_str("bundle schedule frame interval must be finite and positive")
            }
            Self::BadBudget => f.write_str(
                "bundle schedule budget figures must be finite, budget and slowdown positive",
            ),
            Self::BadScheduleLength => {
                f.write_str("bundle schedule table does not have one action per state")
            }
            Self::BadScheduleAction => f.write_str(
                "bundle schedule action names an unknown variant or a period not offered",
            ),
            Self::Invalid(e) => write!(f, "bundle would be invalid: {e}"),
        }
    }
}

impl std::error::Error for WriteError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Invalid(e) => Some(e),
            _ => None,
        }
    }
}

/// Builds a bundle. Every input is validated by parsing the result with [`Bundle::parse`].
#[derive(Clone, Debug, Default)]
pub struct BundleWriter {
    thresholds: Thresholds,
    families: Vec<FamilySpec>,
    variants: Vec<VariantSpec>,
    policy: Option<(VariantId, Vec<VariantId>)>,
    reference: Option<VariantId>,
    metadata: Vec<(String, String)>,
    schedules: Option<ScheduleSpec>,
}

/// A section body under construction: records then a string pool.
struct Body {
    records: Vec<u8>,
    pool: Vec<u8>,
}

impl Body {
    fn new(count: usize) -> Result<Self, WriteError> {
        let count = u32::try_from(count).map_err(|_| WriteError::TooLarge)?;
        Ok(Self {
            records: count.to_le_bytes().to_vec(),
            pool: Vec::new(),
        })
    }

    fn string(&mut self, s: &str) -> Result<(), WriteError> {
        let len = u16::try_from(s.len()).map_err(|_| WriteError::StringTooLong)?;
        let off = u32::try_from(self.pool.len()).map_err(|_| WriteError::TooLarge)?;
        self.records.extend_from_slice(&off.to_le_bytes());
        self.pool.extend_from_slice(&len.to_le_bytes());
        self.pool.extend_from_slice(s.as_bytes());
        Ok(())
    }

    fn f32(&mut self, v: f32) {
        self.records.extend_from_slice(&v.to_le_bytes());
    }

    fn finish(mut self) -> Vec<u8> {
        self.records.extend_from_slice(&self.pool);
        self.records
    }
}

impl BundleWriter {
    /// A writer with these thresholds and nothing else yet.
    pub fn new(thresholds: Thresholds) -> Self {
        Self {
            thresholds,
            ..Self::default()
        }
    }

    /// Appends a family (its index is the number of families added before it).
    pub fn family(mut self, family: FamilySpec) -> Self {
        self.families.push(family);
        self
    }

    /// Appends a variant (its [`VariantId`] is the number of variants added before it).
    pub fn variant(mut self, variant: VariantSpec) -> Self {
        self.variants.push(variant);
        self
    }

    /// Sets the policy: the initial variant and the actions, row-major by bucket:
    /// `actions[bucket * V + current] = next` ([`BUCKET_COUNT`] × `V` entries).
    pub fn policy(mut self, initial: VariantId, actions: Vec<VariantId>) -> Self {
        self.policy = Some((initial, actions));
        self
    }

    /// Sets the reference variant ([`crate::bundle::Policy::reference`]): the most
    /// accurate one. Unset, it is the costliest variant, which on a Pareto front of
    /// cost against accuracy is the most accurate.
    pub fn reference(mut self, variant: VariantId) -> Self {
        self.reference = Some(variant);
        self
    }

    /// Sets the budget schedules (section 6). Checked in [`BundleWriter::finish`].
    pub fn schedules(mut self, schedules: ScheduleSpec) -> Self {
        self.schedules = Some(schedules);
        self
    }

    /// Appends a metadata pair.
    pub fn metadata(mut self, key: impl Into<String>, value: impl Into<String>) -> Self {
        self.metadata.push((key.into(), value.into()));
        self
    }

    fn sections(&self) -> Result<Vec<(SectionKind, Vec<u8>)>, WriteError> {
        let t = &self.thresholds;
        let mut th = Vec::with_capacity(20);
        th.extend_from_slice(&t.iou_threshold.to_le_bytes());
        th.extend_from_slice(&t.min_track_quality.to_le_bytes());
        th.extend_from_slice(&t.mdp_period.to_le_bytes());
        th.extend_from_slice(&t.reinit_period.to_le_bytes());
        th.extend_from_slice(&t.accesses_per_image.to_le_bytes());

        let mut fam = Body::new(self.families.len())?;
        for f in &self.families {
            fam.string(&f.name)?;
            fam.f32(f.buckets.c_opt);
            fam.f32(f.buckets.c_ge);
            fam.f32(f.buckets.c_ua);
            fam.f32(f.buckets.t_c);
        }

        let mut var = Body::new(self.variants.len())?;
        for v in &self.variants {
            var.string(&v.name)?;
            var.string(&v.onnx_file)?;
            var.records.extend_from_slice(&v.family.to_le_bytes());
            var.records.extend_from_slice(&0u16.to_le_bytes());
            var.f32(v.relative_cost);
            var.f32(v.latency_ms);
            var.records.extend_from_slice(&v.sha256);
        }

        let (initial, actions) = self.policy.as_ref().ok_or(WriteError::MissingPolicy)?;
        let v = u16::try_from(self.variants.len()).map_err(|_| WriteError::TooLarge)?;
        let mut pol = Vec::with_capacity(8 + 2 * actions.len());
        pol.extend_from_slice(&(BUCKET_COUNT as u16).to_le_bytes());
        pol.extend_from_slice(&v.to_le_bytes());
        let reference = match self.reference {
            Some(r) => r,
            None => self
                .variants
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.relative_cost.total_cmp(&b.1.relative_cost))
                .map_or(Ok(0), |(i, _)| u16::try_from(i))
                .map_err(|_| WriteError::TooLarge)?,
        };
        pol.extend_from_slice(&initial.to_le_bytes());
        pol.extend_from_slice(&reference.to_le_bytes());
        for a in actions {
            pol.extend_from_slice(&a.to_le_bytes());
        }

        let mut meta = Body::new(self.metadata.len())?;
        for (k, val) in &self.metadata {
            meta.string(k)?;
            meta.string(val)?;
        }

        let mut sections = std::vec![
            (SectionKind::Thresholds, th),
            (SectionKind::Families, fam.finish()),
            (SectionKind::Variants, var.finish()),
            (SectionKind::Policy, pol),
            (SectionKind::Metadata, meta.finish()),
        ];
        if let Some(spec) = &self.schedules {
            sections.push((
                SectionKind::Schedules,
                schedules_body(spec, self.variants.len())?,
            ));
        }
        Ok(sections)
    }

    /// The bundle's bytes, checked by parsing them back.
    pub fn finish(&self) -> Result<Vec<u8>, WriteError> {
        let sections = self.sections()?;
        let n = sections.len();
        let table_end = HEADER_LEN + n * SECTION_ENTRY_LEN;
        let mut out = std::vec![0u8; table_end];
        let mut entries = Vec::with_capacity(n * SECTION_ENTRY_LEN);
        for (kind, body) in &sections {
            while !out.len().is_multiple_of(4) {
                out.push(0);
            }
            let off = u32::try_from(out.len()).map_err(|_| WriteError::TooLarge)?;
            let len = u32::try_from(body.len()).map_err(|_| WriteError::TooLarge)?;
            entries.extend_from_slice(&(*kind as u32).to_le_bytes());
            entries.extend_from_slice(&off.to_le_bytes());
            entries.extend_from_slice(&len.to_le_bytes());
            entries.extend_from_slice(&crc32(body).to_le_bytes());
            out.extend_from_slice(body);
        }
        let total = u32::try_from(out.len()).map_err(|_| WriteError::TooLarge)?;
        let mut header = Vec::with_capacity(HEADER_LEN);
        header.extend_from_slice(&MAGIC.to_le_bytes());
        header.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        let n = u16::try_from(n).map_err(|_| WriteError::TooLarge)?;
        header.extend_from_slice(&n.to_le_bytes());
        header.extend_from_slice(&total.to_le_bytes());
        header.extend_from_slice(&[0; 4]);
        out.splice(0..table_end, header.into_iter().chain(entries));
        let mut crc = Crc32::new();
        crc.update(&out);
        let crc = crc.finish().to_le_bytes();
        if let Some(slot) = out.get_mut(12..16) {
            slot.copy_from_slice(&crc);
        }
        Bundle::parse(&out).map_err(WriteError::Invalid)?;
        Ok(out)
    }
}

/// The body of the schedules section for a bundle of `variants` variants, checked.
fn schedules_body(spec: &ScheduleSpec, variants: usize) -> Result<Vec<u8>, WriteError> {
    let periods = &spec.periods;
    if periods.is_empty()
        || periods.len() > MAX_PERIODS
        || periods.iter().any(|p| !(1..=MAX_PERIOD).contains(p))
        || periods.windows(2).any(|w| w.first() >= w.get(1))
    {
        return Err(WriteError::BadPeriods);
    }
    if !spec.edges.is_valid() {
        return Err(WriteError::BadEdges);
    }
    if spec.budgets.is_empty() || spec.budgets.len() > MAX_BUDGETS {
        return Err(WriteError::BadBudgetCount);
    }
    if !(spec.frame_ms.is_finite() && spec.frame_ms > 0.0) {
        return Err(WriteError::BadFrameInterval);
    }
    if spec.budgets.iter().any(|b| !b.info.is_valid()) {
        return Err(WriteError::BadBudget);
    }
    let states = variants
        .checked_mul(BUCKET_COUNT * CONTENT_STATES)
        .ok_or(WriteError::TooLarge)?;
    if spec.budgets.iter().any(|b| b.actions.len() != states) {
        return Err(WriteError::BadScheduleLength);
    }
    // an action is stored as variant · P + period index, plus V · P when it does not
    // track, which must fit a u16
    let encode = |a: &ScheduleAction| -> Result<u16, WriteError> {
        let period = periods
            .iter()
            .position(|p| *p == a.period)
            .ok_or(WriteError::BadScheduleAction)?;
        if usize::from(a.variant) >= variants {
            return Err(WriteError::BadScheduleAction);
        }
        let untracked = if a.track { 0 } else { variants * periods.len() };
        let code = usize::from(a.variant) * periods.len() + period + untracked;
        u16::try_from(code).map_err(|_| WriteError::TooLarge)
    };
    let len16 = |n: usize| u16::try_from(n).map_err(|_| WriteError::TooLarge);
    let mut b =
        Vec::with_capacity(SCHEDULES_HEADER + spec.budgets.len() * (BUDGET_RECORD + 2 * states));
    for n in [SIZE_BUCKETS, MOTION_BUCKETS, COUNT_BUCKETS, periods.len()] {
        b.extend_from_slice(&len16(n)?.to_le_bytes());
    }
    let ContentEdges {
        size_px: [s0, s1],
        motion_px: [m0, m1],
    } = spec.edges;
    for e in [s0, s1, m0, m1] {
        b.extend_from_slice(&e.to_le_bytes());
    }
    for i in 0..MAX_PERIODS {
        let p = periods.get(i).map_or(Ok(0), |p| u16::try_from(*p));
        b.extend_from_slice(&p.map_err(|_| WriteError::BadPeriods)?.to_le_bytes());
    }
    b.extend_from_slice(&len16(spec.budgets.len())?.to_le_bytes());
    b.extend_from_slice(&encode(&spec.initial)?.to_le_bytes());
    b.extend_from_slice(&spec.frame_ms.to_le_bytes());
    for budget in &spec.budgets {
        let i = budget.info;
        for v in [i.budget_ms, i.slowdown, i.expected_ms, i.p95_ms] {
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    for budget in &spec.budgets {
        for a in &budget.actions {
            b.extend_from_slice(&encode(a)?.to_le_bytes());
        }
    }
    Ok(b)
}
