//! The policy bundle: one versioned binary file with everything the drone needs to
//! decide, per frame, which detector variant to run (or to track).
//!
//! The reader ([`Bundle::parse`]) is zero-copy: it borrows the input `&[u8]`, does not
//! assume any alignment, checks every offset, length, count and index once, and returns
//! a typed [`BundleError`] for corrupt, truncated, wrong-version or wrong-endian input.
//! After a successful parse every per-frame lookup ([`Policy::action`],
//! [`Schedules::action`], [`Bundle::variant_family`], [`Bundle::family_buckets`]) is
//! O(1) and cannot fail for in-range indices. The writer lives in `bundle::write`
//! (feature `std`).
//!
//! Over 1,000 lines on purpose: the format's specification (the table below) and the
//! one zero-copy reader that enforces it, section by section, so that each check sits
//! in the same file as the table row it enforces.
//!
//! # Format, version 5 (this table is the specification)
//!
//! Version 4 added the optional schedules section (kind 6). Version 5 has the same
//! bytes and changes what the schedules' initial action means: in version 5 the first
//! detection takes the current budget table's action at the state the scheduler starts
//! in (the miss bucket, the initial action's variant, nothing shown), as every later
//! detection does, where version 4 ran the initial action itself (one action for every
//! budget); [`Schedules::first_from_table`] tells which. The reader also reads versions
//! 4 and 3; version 3 is version 4 without the schedules section: in a version-3 file a
//! kind-6 section is an unknown kind and is skipped, as a version-3 reader would. An
//! old bundle is read, never misread; any other version is
//! [`BundleError::UnsupportedVersion`].
//!
//! All integers and floats are **little-endian**; `f32` is IEEE-754 binary32. Offsets
//! are in bytes. Nothing is assumed about alignment when reading; the writer starts
//! every section at a multiple of 4 and fills gaps with zero bytes.
//!
//! ## Header (16 bytes, at offset 0)
//!
//! | offset | size | type | field |
//! |-------:|-----:|------|-------|
//! | 0  | 4 | u32 | magic `0x4250_5246` — the bytes `"FRPB"`; the byte-swapped value (`"BPRF"`) means a big-endian writer: [`BundleError::WrongEndian`] |
//! | 4  | 2 | u16 | format version, [`FORMAT_VERSION`] = 7 (the reader also takes 6, 5, 4 and [`MIN_FORMAT_VERSION`] = 3) |
//! | 6  | 2 | u16 | section count `n`, 1 ..= [`MAX_SECTIONS`] |
//! | 8  | 4 | u32 | total file length in bytes (must equal the input length) |
//! | 12 | 4 | u32 | CRC-32 (IEEE, as zlib) of the whole file with these 4 bytes taken as zero |
//!
//! ## Section table (`n` × 16 bytes, at offset 16)
//!
//! | offset | size | type | field |
//! |-------:|-----:|------|-------|
//! | 0  | 4 | u32 | kind: 1 thresholds, 2 families, 3 variants, 4 policy, 5 metadata, 6 schedules (version 4 on); other kinds are skipped (their checksum is still checked) |
//! | 4  | 4 | u32 | offset of the section body from the start of the file, `>= 16 + 16 n` |
//! | 8  | 4 | u32 | length of the body in bytes (`offset + length <= file length`) |
//! | 12 | 4 | u32 | CRC-32 of the body |
//!
//! Kinds 1–5 must each appear exactly once; kind 6 at most once.
//!
//! ## Strings
//!
//! A string is referenced by a u32 offset into its section's *pool* (the bytes after the
//! section's records). At that offset: a u16 byte length `L`, then `L` bytes of UTF-8.
//!
//! ## 1 — Thresholds and periods (exactly 20 bytes), see [`Thresholds`]
//!
//! | offset | size | type | field |
//! |-------:|-----:|------|-------|
//! | 0  | 4 | f32 | `θ_th`: tracker/detector IoU below which the policy is re-asked (paper 0.5), in `[0, 1]` |
//! | 4  | 4 | f32 | `T_m`: least fraction of the tracker's points still tracked for the track to be trusted, in `[0, 1]` |
//! | 8  | 4 | u32 | `N`: re-run the MDP policy every `N` frames (paper 100), `>= 1` |
//! | 12 | 4 | u32 | `M`: re-initialise the tracker from a detection every `M` frames (paper 10), `>= 1` |
//! | 16 | 4 | u32 | most MDP accesses (detections) per image (paper 5), 1 ..= [`MAX_ACCESSES`] |
//!
//! ## 2 — Detector families and their confidence buckets, see [`Family`]
//!
//! | offset | size | type | field |
//! |-------:|-----:|------|-------|
//! | 0 | 4 | u32 | family count `F`, 1 ..= 256 |
//! | 4 + 20 i | 4 | u32 | name (string in the pool) |
//! | 8 + 20 i | 4 | f32 | `c_opt` (paper 0.9 on the SVM margin scale) |
//! | 12 + 20 i | 4 | f32 | `c_ge` (paper 0) |
//! | 16 + 20 i | 4 | f32 | `c_ua` (paper −0.5); finite, `c_opt >= c_ge >= c_ua` |
//! | 20 + 20 i | 4 | f32 | `T_c`: a detection scoring below it re-asks the policy (paper 0 on KUL, −1 on BU-RU) |
//! | 4 + 20 F | … | | string pool |
//!
//! ## 3 — Variants (the detectors the policy chooses from), see [`Variant`]
//!
//! | offset | size | type | field |
//! |-------:|-----:|------|-------|
//! | 0 | 4 | u32 | variant count `V`, 1 ..= 65535; a [`VariantId`] is an index `< V` |
//! | 4 + 52 i | 4 | u32 | name (string in the pool) |
//! | 8 + 52 i | 4 | u32 | ONNX file name, relative to the bundle (string in the pool; may be empty for non-ONNX variants) |
//! | 12 + 52 i | 2 | u16 | family index `< F` |
//! | 14 + 52 i | 2 | u16 | reserved, 0 |
//! | 16 + 52 i | 4 | f32 | relative cost `r(s)` versus the cheapest variant, finite, `> 0` |
//! | 20 + 52 i | 4 | f32 | measured latency in milliseconds, finite, `>= 0` |
//! | 24 + 52 i | 32 | bytes | SHA-256 of the ONNX file (zeros when there is none) |
//! | 4 + 52 V | … | | string pool |
//!
//! ## 4 — Policy (state → action), see [`Policy`]
//!
//! | offset | size | type | field |
//! |-------:|-----:|------|-------|
//! | 0 | 2 | u16 | bucket count, must be [`BUCKET_COUNT`] = 4 |
//! | 2 | 2 | u16 | variant count, must equal `V` |
//! | 4 | 2 | u16 | initial variant `< V` (used as the current variant before any detection) |
//! | 6 | 2 | u16 | reference variant `< V`: the most accurate one (the replay's static variant), which the drone runs to confirm a sign before it acts on it ([`Policy::reference`]) |
//! | 8 + 2 (b V + v) | 2 | u16 | action for the state (bucket `b`, current variant `v`): the next variant, `< V` |
//!
//! The section is exactly `8 + 2 · 4 · V` bytes. Buckets are numbered as [`Bucket`]:
//! 0 optimal, 1 good enough, 2 inadequate, 3 miss.
//!
//! ## 5 — Metadata (free key/value UTF-8 pairs)
//!
//! | offset | size | type | field |
//! |-------:|-----:|------|-------|
//! | 0 | 4 | u32 | pair count `K` |
//! | 4 + 8 i | 4 | u32 | key (string in the pool) |
//! | 8 + 8 i | 4 | u32 | value (string in the pool) |
//! | 4 + 8 K | … | | string pool |
//!
//! ## 6 — Schedules (optional, version 4 on): per-budget tables of (variant, period), see [`Schedules`] and [`crate::schedule`]
//!
//! | offset | size | type | field |
//! |-------:|-----:|------|-------|
//! | 0  | 2 | u16 | size bucket count, must be [`SIZE_BUCKETS`] = 3 |
//! | 2  | 2 | u16 | motion bucket count, must be [`MOTION_BUCKETS`] = 3 |
//! | 4  | 2 | u16 | count bucket count, must be [`COUNT_BUCKETS`] = 3 |
//! | 6  | 2 | u16 | period count `P`, 1 ..= [`MAX_PERIODS`] = 4 |
//! | 8  | 8 | 2 × f32 | size edges in pixels of height, finite, `0 <= e0 <= e1` ([`ContentEdges::size_px`]) |
//! | 16 | 8 | 2 × f32 | motion edges in pixels per frame, finite, `0 <= e0 <= e1` ([`ContentEdges::motion_px`]) |
//! | 24 | 8 | 4 × u16 | periods in frames: the first `P` strictly ascending in 1 ..= 255, the rest 0 |
//! | 32 | 2 | u16 | budget count `K`, 1 ..= [`MAX_BUDGETS`] = 8 |
//! | 34 | 2 | u16 | initial action `< V · P`: version 5 on, its variant is the current variant before the first detection, which takes the table's action (its period is not used); version 4, run on the first frame |
//! | 36 | 4 | f32 | version 6 on: the frame interval `F` in ms the tables count (periods, budgets per frame, motion per frame), finite, `> 0` ([`Schedules::frame_ms`]); absent before |
//! | `H` + 16 k | 4 | f32 | budget `k`: latency budget in ms, finite, `> 0` ([`BudgetInfo`]) |
//! | `H` + 4 + 16 k | 4 | f32 | slowdown of the target versus the measuring machine, finite, `> 0` |
//! | `H` + 8 + 16 k | 4 | f32 | expected latency per frame in ms, finite, `>= 0` |
//! | `H` + 12 + 16 k | 4 | f32 | 95th percentile latency per frame in ms, finite, `>= 0` |
//! | `H` + 16 K + 2 (k S + s) | 2 | u16 | budget `k`'s action for state `s`, `< V · P` |
//!
//! `S = 4 · V · 27` is the number of states of a table; a state's index is
//! [`crate::schedule::state_index`]: `(bucket · V + current variant) · 27 + content
//! index`, the content index being `(size · 3 + motion) · 3 + count`
//! ([`crate::schedule::Content::index`]). An action `a`
//! encodes the variant `a / P` and the period index `a % P`. The header is `H` = 40
//! bytes from version 6 on (36 before), and the section is exactly `H + 16 K + 2 K S`
//! bytes.
//!
//! Version 7 has the bytes of version 6 and adds actions that leave the frames between
//! two detections alone: an action `a` of a version-7 table (the initial one too) is
//! `< 2 · V · P`; `a < V · P` is read as above and tracks the detection's boxes in
//! between ([`ScheduleAction::track`]), and `a >= V · P` is the action `a − V · P` that
//! starts no tracker, the detection's boxes standing until the next one. In a bundle of
//! version 6 or older an action `>= V · P` is [`BundleError::BadScheduleAction`], and
//! every action tracks.
//!
//! One file on purpose: the byte layout documented above and the zero-copy parser that
//! checks every field of it are read side by side (the writer is `write.rs`).

#[cfg(feature = "std")]
pub mod write;

use crate::content::{
    BudgetInfo, CONTENT_STATES, COUNT_BUCKETS, ContentEdges, MAX_BUDGETS, MAX_PERIOD, MAX_PERIODS,
    MOTION_BUCKETS, SIZE_BUCKETS, ScheduleAction,
};
use crate::crc::Crc32;
use crate::geom::VariantId;
use core::fmt;

/// The magic number, stored little-endian as the bytes `"FRPB"`.
pub const MAGIC: u32 = 0x4250_5246;
/// The format version the writer writes and the newest the reader understands (2 added
/// the accesses per image, 3 the reference variant, 4 the schedules section, 5 the
/// first detection read from the schedule table, 6 the frame interval the schedules
/// count).
pub const FORMAT_VERSION: u16 = 7;
/// The oldest format version the reader understands.
pub const MIN_FORMAT_VERSION: u16 = 3;
/// Header length in bytes.
pub const HEADER_LEN: usize = 16;
/// Section table entry length in bytes.
pub const SECTION_ENTRY_LEN: usize = 16;
/// Most sections a bundle may have.
pub const MAX_SECTIONS: usize = 16;
/// Number of confidence buckets (states per variant).
pub const BUCKET_COUNT: usize = 4;
/// Most detector families a bundle may have.
pub const MAX_FAMILIES: usize = 256;
/// Most MDP accesses per image a bundle may ask for.
pub const MAX_ACCESSES: u32 = 16;

const FAMILY_RECORD: usize = 20;
const VARIANT_RECORD: usize = 52;
const META_RECORD: usize = 8;
const THRESHOLDS_LEN: usize = 20;
const POLICY_HEADER: usize = 8;
/// The schedules header before version 6, and from version 6 on (the frame interval).
const SCHEDULES_HEADER_V5: usize = 36;
const SCHEDULES_HEADER: usize = 40;
const BUDGET_RECORD: usize = 16;

/// Section kinds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum SectionKind {
    /// [`Thresholds`].
    Thresholds = 1,
    /// Detector families and their confidence buckets.
    Families = 2,
    /// The variant table.
    Variants = 3,
    /// The policy table.
    Policy = 4,
    /// Free key/value metadata.
    Metadata = 5,
    /// The budget schedules (optional; format version 4).
    Schedules = 6,
}

impl SectionKind {
    /// All kinds, in the order the writer emits them.
    pub const ALL: [SectionKind; 6] = [
        SectionKind::Thresholds,
        SectionKind::Families,
        SectionKind::Variants,
        SectionKind::Policy,
        SectionKind::Metadata,
        SectionKind::Schedules,
    ];

    /// The first format version that has this kind.
    pub const fn since(self) -> u16 {
        match self {
            SectionKind::Schedules => 4,
            _ => 1,
        }
    }

    /// The kind numbered `v` in a file of format `version`; `None` for a kind that
    /// version does not know (such a section is skipped).
    fn from_u32(v: u32, version: u16) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|k| *k as u32 == v && k.since() <= version)
    }
}

/// Why a bundle was rejected. Field-less and `Copy`, so it costs nothing to return.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BundleError {
    /// The input is shorter than the header, the section table or the length the header states.
    Truncated,
    /// The first four bytes are not the bundle magic.
    BadMagic,
    /// The magic is byte-swapped: the file was written big-endian.
    WrongEndian,
    /// The format version is neither [`FORMAT_VERSION`] nor an older one the reader
    /// still understands ([`MIN_FORMAT_VERSION`]).
    UnsupportedVersion,
    /// The input is longer than the length the header states.
    LengthMismatch,
    /// The whole-file CRC-32 does not match.
    FileChecksum,
    /// A section's CRC-32 does not match.
    SectionChecksum,
    /// Zero sections or more than [`MAX_SECTIONS`].
    BadSectionCount,
    /// A section lies (partly) outside the file or over the header/section table.
    SectionOutOfBounds,
    /// A section kind appears twice.
    DuplicateSection,
    /// A required section is absent.
    MissingSection,
    /// A section's length does not match its fixed size or its record count.
    BadSectionLength,
    /// A string reference points outside its section's pool.
    BadString,
    /// A string is not valid UTF-8.
    BadUtf8,
    /// A count is zero where at least one is needed, or above its limit.
    BadCount,
    /// A variant names a family index that does not exist.
    BadFamily,
    /// A number is not finite, out of its range, or thresholds are out of order.
    BadValue,
    /// The policy's bucket or variant count does not match the bundle.
    BadPolicyShape,
    /// A policy action, the initial or the reference variant is not a valid variant index.
    BadAction,
    /// The schedules section has the wrong bucket counts, a bad period list or budget
    /// count, or an edge or budget figure out of range.
    BadSchedule,
    /// A schedule action or the initial action is not below `V · P`.
    BadScheduleAction,
}

impl fmt::Display for BundleError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let msg = match self {
            Self::Truncated => "policy bundle is truncated",
            Self::BadMagic => "not a policy bundle (bad magic)",
            Self::WrongEndian => "policy bundle was written big-endian (byte-swapped magic)",
            Self::UnsupportedVersion => "unsupported policy bundle format version",
            Self::LengthMismatch => "policy bundle has trailing bytes after its stated length",
            Self::FileChecksum => "policy bundle file checksum mismatch",
            Self::SectionChecksum => "policy bundle section checksum mismatch",
            Self::BadSectionCount => "policy bundle has a bad section count",
            Self::SectionOutOfBounds => "policy bundle section lies outside the file",
            Self::DuplicateSection => "policy bundle repeats a section",
            Self::MissingSection => "policy bundle lacks a required section",
            Self::BadSectionLength => "policy bundle section has a bad length",
            Self::BadString => "policy bundle string reference is out of bounds",
            Self::BadUtf8 => "policy bundle string is not valid UTF-8",
            Self::BadCount => "policy bundle count is zero or too large",
            Self::BadFamily => "policy bundle variant refers to an unknown family",
            Self::BadValue => "policy bundle number is not finite or out of range",
            Self::BadPolicyShape => "policy bundle policy table has the wrong shape",
            Self::BadAction => "policy bundle policy action is not a valid variant",
            Self::BadSchedule => "policy bundle schedules have a bad shape or value",
            Self::BadScheduleAction => "policy bundle schedule action is out of range",
        };
        f.write_str(msg)
    }
}

impl core::error::Error for BundleError {}

/// The controller's thresholds and periods (the paper's Table of thresholds).
///
/// The score threshold `T_c` depends on the detector family's score scale, so it lives
/// with each family's buckets ([`ScoreBuckets::t_c`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Thresholds {
    /// `θ_th`: when the IoU between the tracker's box and the last detection falls below
    /// this, the policy is re-asked and a detection runs (paper: 0.5).
    pub iou_threshold: f32,
    /// `T_m`: when fewer than this fraction of the tracker's points (relative to the
    /// points it started from) are still tracked, the track is treated as lost. The
    /// paper names `T_m` (tracked region versus template) without a value; 0.3 is ours.
    pub min_track_quality: f32,
    /// `N`: the policy is re-run every `N` frames even when nothing else asks (paper: 100).
    pub mdp_period: u32,
    /// `M`: the tracker is re-initialised from a fresh detection every `M` frames (paper: 10).
    pub reinit_period: u32,
    /// Most MDP accesses per image (paper: 5): when a detection scores below its
    /// family's `T_c`, the policy is asked again and its choice runs on the *same*
    /// image, up to this many detections in all (1: never on the same image).
    pub accesses_per_image: u32,
}

impl Thresholds {
    /// The values of the paper's table (and `T_m` = 0.3, which the paper leaves open).
    pub const PAPER: Thresholds = Thresholds {
        iou_threshold: 0.5,
        min_track_quality: 0.3,
        mdp_period: 100,
        reinit_period: 10,
        accesses_per_image: 5,
    };

    /// True when every field is in range (what the reader and writer accept).
    pub fn is_valid(&self) -> bool {
        (0.0..=1.0).contains(&self.iou_threshold)
            && (0.0..=1.0).contains(&self.min_track_quality)
            && self.mdp_period >= 1
            && self.reinit_period >= 1
            && (1..=MAX_ACCESSES).contains(&self.accesses_per_image)
    }
}

impl Default for Thresholds {
    fn default() -> Self {
        Self::PAPER
    }
}

/// A confidence bucket: the score part of an MDP state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum Bucket {
    /// `score >= c_opt`.
    Optimal = 0,
    /// `c_ge <= score < c_opt`.
    GoodEnough = 1,
    /// `c_ua <= score < c_ge`.
    Inadequate = 2,
    /// `score < c_ua`, or the detector found nothing.
    Miss = 3,
}

impl Bucket {
    /// All buckets in index order.
    pub const ALL: [Bucket; BUCKET_COUNT] = [
        Bucket::Optimal,
        Bucket::GoodEnough,
        Bucket::Inadequate,
        Bucket::Miss,
    ];

    /// The bucket's index in the policy table.
    pub const fn index(self) -> usize {
        self as usize
    }
}

/// One family's confidence thresholds, on that family's score scale (a softmax
/// probability for the CNN family, a signed SVM margin for the HoG family).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScoreBuckets {
    /// Lower edge of [`Bucket::Optimal`].
    pub c_opt: f32,
    /// Lower edge of [`Bucket::GoodEnough`].
    pub c_ge: f32,
    /// Lower edge of [`Bucket::Inadequate`]; below it is [`Bucket::Miss`].
    pub c_ua: f32,
    /// `T_c`: a detection scoring below this makes the controller re-ask the policy.
    pub t_c: f32,
}

impl ScoreBuckets {
    /// The paper's SVM-margin thresholds (`c_opt = 0.9, c_ge = 0, c_ua = −0.5`, `T_c = 0` as on KUL).
    pub const PAPER_SVM: ScoreBuckets = ScoreBuckets {
        c_opt: 0.9,
        c_ge: 0.0,
        c_ua: -0.5,
        t_c: 0.0,
    };

    /// The bucket of a detection score (`None`: the detector found nothing).
    /// A NaN score counts as a miss.
    pub fn bucket(&self, score: Option<f32>) -> Bucket {
        match score {
            Some(s) if s >= self.c_opt => Bucket::Optimal,
            Some(s) if s >= self.c_ge => Bucket::GoodEnough,
            Some(s) if s >= self.c_ua => Bucket::Inadequate,
            _ => Bucket::Miss,
        }
    }

    /// True when all thresholds are finite and `c_opt >= c_ge >= c_ua`.
    pub fn is_valid(&self) -> bool {
        self.c_opt.is_finite()
            && self.c_ge.is_finite()
            && self.c_ua.is_finite()
            && self.t_c.is_finite()
            && self.c_opt >= self.c_ge
            && self.c_ge >= self.c_ua
    }
}

/// A detector family as stored in the bundle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Family<'a> {
    /// Family name, e.g. `"cnn"` or `"hog"`.
    pub name: &'a str,
    /// Its confidence buckets.
    pub buckets: ScoreBuckets,
}

/// A detector variant as stored in the bundle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Variant<'a> {
    /// Variant name.
    pub name: &'a str,
    /// Index into the family table.
    pub family: u16,
    /// Relative cost versus the cheapest variant (`r(s)` in the paper's reward).
    pub relative_cost: f32,
    /// Measured latency in milliseconds.
    pub latency_ms: f32,
    /// ONNX file name relative to the bundle (empty for variants without one).
    pub onnx_file: &'a str,
    /// SHA-256 of the ONNX file.
    pub sha256: [u8; 32],
}

// ---- little-endian reading helpers: every access is checked -------------------------

fn bytes4(b: &[u8], off: usize) -> Option<[u8; 4]> {
    b.get(off..off.checked_add(4)?)?.try_into().ok()
}

fn rd_u16(b: &[u8], off: usize) -> Option<u16> {
    let s: [u8; 2] = b.get(off..off.checked_add(2)?)?.try_into().ok()?;
    Some(u16::from_le_bytes(s))
}

fn rd_u32(b: &[u8], off: usize) -> Option<u32> {
    bytes4(b, off).map(u32::from_le_bytes)
}

fn rd_f32(b: &[u8], off: usize) -> Option<f32> {
    bytes4(b, off).map(f32::from_le_bytes)
}

fn rd_str(pool: &[u8], off: u32) -> Result<&str, BundleError> {
    let off = off as usize;
    let len = rd_u16(pool, off).ok_or(BundleError::BadString)? as usize;
    let start = off.checked_add(2).ok_or(BundleError::BadString)?;
    let end = start.checked_add(len).ok_or(BundleError::BadString)?;
    let bytes = pool.get(start..end).ok_or(BundleError::BadString)?;
    core::str::from_utf8(bytes).map_err(|_| BundleError::BadUtf8)
}

/// A counted table of fixed-size records followed by a string pool.
#[derive(Clone, Copy, Debug)]
struct Table<'a> {
    count: usize,
    records: &'a [u8],
    pool: &'a [u8],
    record_len: usize,
}

impl<'a> Table<'a> {
    fn parse(body: &'a [u8], record_len: usize, max: usize) -> Result<Self, BundleError> {
        let count = rd_u32(body, 0).ok_or(BundleError::BadSectionLength)? as usize;
        if count > max {
            return Err(BundleError::BadCount);
        }
        let rec_bytes = count
            .checked_mul(record_len)
            .ok_or(BundleError::BadSectionLength)?;
        let end = rec_bytes
            .checked_add(4)
            .ok_or(BundleError::BadSectionLength)?;
        let records = body.get(4..end).ok_or(BundleError::BadSectionLength)?;
        let pool = body.get(end..).ok_or(BundleError::BadSectionLength)?;
        Ok(Self {
            count,
            records,
            pool,
            record_len,
        })
    }

    fn record(&self, i: usize) -> Option<&'a [u8]> {
        if i >= self.count {
            return None;
        }
        let start = i.checked_mul(self.record_len)?;
        self.records.get(start..start.checked_add(self.record_len)?)
    }
}

/// The policy table: (confidence bucket, current variant) → next variant.
#[derive(Clone, Copy, Debug)]
pub struct Policy<'a> {
    actions: &'a [u8],
    variants: u16,
    initial: VariantId,
    reference: VariantId,
}

impl<'a> Policy<'a> {
    /// The action (next variant) for state (`bucket`, `current`); `None` only when
    /// `current` is not a variant of this bundle.
    pub fn action(&self, bucket: Bucket, current: VariantId) -> Option<VariantId> {
        if current >= self.variants {
            return None;
        }
        let idx = bucket
            .index()
            .checked_mul(self.variants as usize)?
            .checked_add(current as usize)?;
        rd_u16(self.actions, idx.checked_mul(2)?)
    }

    /// The variant used before any detection.
    pub const fn initial(&self) -> VariantId {
        self.initial
    }

    /// The reference variant: the most accurate one (the static baseline of the replay
    /// evaluation). The policy never needs it to decide; a drone runs it to confirm a
    /// sign a cheaper variant read before acting on it (a turn, a landing), where one
    /// misread costs the flight.
    pub const fn reference(&self) -> VariantId {
        self.reference
    }

    /// Number of variants (the policy's second state dimension).
    pub const fn variant_count(&self) -> u16 {
        self.variants
    }
}

/// The budget schedules: per latency budget, a table from (confidence bucket, current
/// variant, content state) to (variant, detection period). See [`crate::schedule`].
#[derive(Clone, Copy, Debug)]
pub struct Schedules<'a> {
    edges: ContentEdges,
    periods: [u32; MAX_PERIODS],
    period_count: u16,
    initial: ScheduleAction,
    /// Version 5 on: the first detection reads the table.
    first_from_table: bool,
    /// Version 6 on: the frame interval the tables count, ms.
    frame_ms: Option<f32>,
    /// Version 7 on: actions from `V · P` up leave the frames between detections alone.
    untracked: bool,
    /// `V · P`: the first code of an action that does not track.
    tracked_codes: usize,
    /// `budget_count` records of [`BUDGET_RECORD`] bytes.
    budgets: &'a [u8],
    budget_count: usize,
    /// `budget_count` tables of `states` u16 actions each.
    tables: &'a [u8],
    states: usize,
}

impl<'a> Schedules<'a> {
    /// The edges of the size and motion buckets.
    pub const fn edges(&self) -> ContentEdges {
        self.edges
    }

    /// Number of detection periods `P` (1 ..= [`MAX_PERIODS`]).
    pub const fn period_count(&self) -> usize {
        self.period_count as usize
    }

    /// Period `i` in frames, `None` for `i >= P`.
    pub fn period(&self, i: usize) -> Option<u32> {
        if i >= self.period_count() {
            return None;
        }
        self.periods.get(i).copied()
    }

    /// Number of budget tables `K` (1 ..= [`MAX_BUDGETS`]).
    pub const fn budget_count(&self) -> usize {
        self.budget_count
    }

    /// What budget table `k` was made for.
    pub fn budget(&self, k: usize) -> Option<BudgetInfo> {
        if k >= self.budget_count {
            return None;
        }
        let off = k.checked_mul(BUDGET_RECORD)?;
        budget_info(self.budgets.get(off..off.checked_add(BUDGET_RECORD)?)?)
    }

    /// The initial action: its variant is the scheduler's current variant before the
    /// first detection; in a version-4 bundle the first frame runs it
    /// ([`Schedules::first_from_table`]).
    pub const fn initial(&self) -> ScheduleAction {
        self.initial
    }

    /// True (format version 5 on) when the first detection takes the budget table's
    /// action at the starting state, as every later one does; false in a version-4
    /// bundle, whose first frame runs [`Schedules::initial`] under every budget.
    pub const fn first_from_table(&self) -> bool {
        self.first_from_table
    }

    /// The interval in ms between the frames the tables count (format version 6 on;
    /// `None` before): the tables' periods are in such frames, their budgets in device
    /// ms per such frame and the motion edges in pixels per such frame. A camera at
    /// another rate numbers its frames on this clock ([`crate::schedule::FrameClock`]),
    /// so that the tables mean on the drone what they meant where they were made.
    pub const fn frame_ms(&self) -> Option<f32> {
        self.frame_ms
    }

    /// Number of states of one table, `BUCKET_COUNT · V · CONTENT_STATES`.
    pub const fn state_count(&self) -> usize {
        self.states
    }

    /// Budget table `k`'s action for the state of index `state`
    /// ([`crate::schedule::state_index`]); `None` only for an index out of range.
    pub fn action(&self, k: usize, state: usize) -> Option<ScheduleAction> {
        if k >= self.budget_count || state >= self.states {
            return None;
        }
        let i = k.checked_mul(self.states)?.checked_add(state)?;
        self.decode(rd_u16(self.tables, i.checked_mul(2)?)?)
    }

    /// True (format version 7 on) when the tables may hold actions that leave the
    /// frames between detections alone ([`ScheduleAction::track`] false).
    pub const fn has_untracked(&self) -> bool {
        self.untracked
    }

    /// The action encoded as `a` (`variant · P + period index`, plus `V · P` for one
    /// that does not track, version 7 on).
    fn decode(&self, a: u16) -> Option<ScheduleAction> {
        let p = self.period_count;
        let tracked = self.tracked_codes;
        let (a, track) = if usize::from(a) < tracked {
            (a, true)
        } else if self.untracked {
            (
                u16::try_from(usize::from(a).checked_sub(tracked)?).ok()?,
                false,
            )
        } else {
            return None;
        };
        Some(ScheduleAction {
            variant: a.checked_div(p)?,
            period: *self.periods.get(usize::from(a.checked_rem(p)?))?,
            track,
        })
    }
}

/// A parsed, fully validated policy bundle borrowing its bytes.
#[derive(Clone, Copy, Debug)]
pub struct Bundle<'a> {
    version: u16,
    thresholds: Thresholds,
    families: Table<'a>,
    variants: Table<'a>,
    policy: Policy<'a>,
    metadata: Table<'a>,
    schedules: Option<Schedules<'a>>,
}

struct Sections<'a> {
    version: u16,
    found: [Option<&'a [u8]>; SectionKind::ALL.len()],
}

fn parse_header(bytes: &[u8]) -> Result<Sections<'_>, BundleError> {
    let magic = rd_u32(bytes, 0).ok_or(BundleError::Truncated)?;
    if magic != MAGIC {
        return Err(if magic == MAGIC.swap_bytes() {
            BundleError::WrongEndian
        } else {
            BundleError::BadMagic
        });
    }
    let version = rd_u16(bytes, 4).ok_or(BundleError::Truncated)?;
    if !(MIN_FORMAT_VERSION..=FORMAT_VERSION).contains(&version) {
        return Err(BundleError::UnsupportedVersion);
    }
    let n = rd_u16(bytes, 6).ok_or(BundleError::Truncated)? as usize;
    let total = rd_u32(bytes, 8).ok_or(BundleError::Truncated)? as usize;
    let stored_crc = rd_u32(bytes, 12).ok_or(BundleError::Truncated)?;
    if bytes.len() < total {
        return Err(BundleError::Truncated);
    }
    if bytes.len() > total {
        return Err(BundleError::LengthMismatch);
    }
    if n == 0 || n > MAX_SECTIONS {
        return Err(BundleError::BadSectionCount);
    }
    let table_end = HEADER_LEN + n * SECTION_ENTRY_LEN;
    if bytes.len() < table_end {
        return Err(BundleError::Truncated);
    }
    let mut crc = Crc32::new();
    crc.update(bytes.get(..12).ok_or(BundleError::Truncated)?);
    crc.update(&[0u8; 4]);
    crc.update(bytes.get(HEADER_LEN..).ok_or(BundleError::Truncated)?);
    if crc.finish() != stored_crc {
        return Err(BundleError::FileChecksum);
    }
    let mut found: [Option<&[u8]>; SectionKind::ALL.len()] = [None; SectionKind::ALL.len()];
    for i in 0..n {
        let e = HEADER_LEN + i * SECTION_ENTRY_LEN;
        let kind = rd_u32(bytes, e).ok_or(BundleError::Truncated)?;
        let off = rd_u32(bytes, e + 4).ok_or(BundleError::Truncated)? as usize;
        let len = rd_u32(bytes, e + 8).ok_or(BundleError::Truncated)? as usize;
        let sec_crc = rd_u32(bytes, e + 12).ok_or(BundleError::Truncated)?;
        if off < table_end {
            return Err(BundleError::SectionOutOfBounds);
        }
        let end = off
            .checked_add(len)
            .ok_or(BundleError::SectionOutOfBounds)?;
        let body = bytes.get(off..end).ok_or(BundleError::SectionOutOfBounds)?;
        if crate::crc::crc32(body) != sec_crc {
            return Err(BundleError::SectionChecksum);
        }
        if let Some(k) = SectionKind::from_u32(kind, version) {
            let slot = found
                .get_mut(k as usize - 1)
                .ok_or(BundleError::MissingSection)?;
            if slot.is_some() {
                return Err(BundleError::DuplicateSection);
            }
            *slot = Some(body);
        }
    }
    Ok(Sections { version, found })
}

impl<'a> Bundle<'a> {
    /// Parses and validates a bundle. Never panics; never allocates.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, BundleError> {
        let s = parse_header(bytes)?;
        let [th, fam, var, pol, meta, sched] = s.found;
        let (th, fam, var, pol, meta) = (
            th.ok_or(BundleError::MissingSection)?,
            fam.ok_or(BundleError::MissingSection)?,
            var.ok_or(BundleError::MissingSection)?,
            pol.ok_or(BundleError::MissingSection)?,
            meta.ok_or(BundleError::MissingSection)?,
        );
        let thresholds = parse_thresholds(th)?;
        let families = parse_families(fam)?;
        let variants = parse_variants(var, families.count)?;
        let policy = parse_policy(pol, variants.count)?;
        let metadata = Table::parse(meta, META_RECORD, usize::MAX)?;
        for i in 0..metadata.count {
            let r = metadata.record(i).ok_or(BundleError::BadSectionLength)?;
            rd_str(
                metadata.pool,
                rd_u32(r, 0).ok_or(BundleError::BadSectionLength)?,
            )?;
            rd_str(
                metadata.pool,
                rd_u32(r, 4).ok_or(BundleError::BadSectionLength)?,
            )?;
        }
        let schedules = match sched {
            Some(b) => Some(parse_schedules(b, variants.count, s.version)?),
            None => None,
        };
        Ok(Self {
            version: s.version,
            thresholds,
            families,
            variants,
            policy,
            metadata,
            schedules,
        })
    }

    /// The format version of the file this bundle was read from.
    pub const fn version(&self) -> u16 {
        self.version
    }

    /// The budget schedules, `None` when the bundle has none (every version-3 bundle).
    pub const fn schedules(&self) -> Option<Schedules<'a>> {
        self.schedules
    }

    /// Thresholds and periods.
    pub const fn thresholds(&self) -> Thresholds {
        self.thresholds
    }

    /// The policy table.
    pub const fn policy(&self) -> Policy<'a> {
        self.policy
    }

    /// Number of detector families.
    pub const fn family_count(&self) -> usize {
        self.families.count
    }

    /// Number of variants.
    pub const fn variant_count(&self) -> usize {
        self.variants.count
    }

    /// Family `i`.
    pub fn family(&self, i: usize) -> Option<Family<'a>> {
        let r = self.families.record(i)?;
        Some(Family {
            name: rd_str(self.families.pool, rd_u32(r, 0)?).ok()?,
            buckets: family_buckets(r)?,
        })
    }

    /// Family `i`'s confidence buckets (O(1), no string decoding).
    pub fn family_buckets(&self, i: usize) -> Option<ScoreBuckets> {
        family_buckets(self.families.record(i)?)
    }

    /// The family index of variant `v` (O(1)).
    pub fn variant_family(&self, v: VariantId) -> Option<u16> {
        rd_u16(self.variants.record(v as usize)?, 8)
    }

    /// The confidence buckets that apply to scores from variant `v` (O(1)).
    pub fn variant_buckets(&self, v: VariantId) -> Option<ScoreBuckets> {
        self.family_buckets(self.variant_family(v)? as usize)
    }

    /// Variant `v`.
    pub fn variant(&self, v: VariantId) -> Option<Variant<'a>> {
        let r = self.variants.record(v as usize)?;
        let pool = self.variants.pool;
        let sha: [u8; 32] = r.get(20..52)?.try_into().ok()?;
        Some(Variant {
            name: rd_str(pool, rd_u32(r, 0)?).ok()?,
            onnx_file: rd_str(pool, rd_u32(r, 4)?).ok()?,
            family: rd_u16(r, 8)?,
            relative_cost: rd_f32(r, 12)?,
            latency_ms: rd_f32(r, 16)?,
            sha256: sha,
        })
    }

    /// Iterates over all variants with their ids.
    pub fn variants(&self) -> impl Iterator<Item = (VariantId, Variant<'a>)> + '_ {
        (0..self.variants.count).filter_map(move |i| {
            let id = VariantId::try_from(i).ok()?;
            Some((id, self.variant(id)?))
        })
    }

    /// Number of metadata pairs.
    pub const fn metadata_len(&self) -> usize {
        self.metadata.count
    }

    /// Metadata pair `i` as `(key, value)`.
    pub fn metadata_pair(&self, i: usize) -> Option<(&'a str, &'a str)> {
        let r = self.metadata.record(i)?;
        let pool = self.metadata.pool;
        Some((
            rd_str(pool, rd_u32(r, 0)?).ok()?,
            rd_str(pool, rd_u32(r, 4)?).ok()?,
        ))
    }

    /// Iterates over the metadata pairs in file order.
    pub fn metadata(&self) -> impl Iterator<Item = (&'a str, &'a str)> + '_ {
        (0..self.metadata.count).filter_map(move |i| self.metadata_pair(i))
    }

    /// The value of the first metadata pair whose key is `key`.
    pub fn metadata_get(&self, key: &str) -> Option<&'a str> {
        self.metadata().find(|(k, _)| *k == key).map(|(_, v)| v)
    }
}

fn family_buckets(r: &[u8]) -> Option<ScoreBuckets> {
    Some(ScoreBuckets {
        c_opt: rd_f32(r, 4)?,
        c_ge: rd_f32(r, 8)?,
        c_ua: rd_f32(r, 12)?,
        t_c: rd_f32(r, 16)?,
    })
}

fn parse_thresholds(b: &[u8]) -> Result<Thresholds, BundleError> {
    if b.len() != THRESHOLDS_LEN {
        return Err(BundleError::BadSectionLength);
    }
    let t = (|| {
        Some(Thresholds {
            iou_threshold: rd_f32(b, 0)?,
            min_track_quality: rd_f32(b, 4)?,
            mdp_period: rd_u32(b, 8)?,
            reinit_period: rd_u32(b, 12)?,
            accesses_per_image: rd_u32(b, 16)?,
        })
    })()
    .ok_or(BundleError::BadSectionLength)?;
    if !t.is_valid() {
        return Err(BundleError::BadValue);
    }
    Ok(t)
}

fn parse_families(b: &[u8]) -> Result<Table<'_>, BundleError> {
    let t = Table::parse(b, FAMILY_RECORD, MAX_FAMILIES)?;
    if t.count == 0 {
        return Err(BundleError::BadCount);
    }
    for i in 0..t.count {
        let r = t.record(i).ok_or(BundleError::BadSectionLength)?;
        rd_str(t.pool, rd_u32(r, 0).ok_or(BundleError::BadSectionLength)?)?;
        let buckets = family_buckets(r).ok_or(BundleError::BadSectionLength)?;
        if !buckets.is_valid() {
            return Err(BundleError::BadValue);
        }
    }
    Ok(t)
}

fn parse_variants(b: &[u8], families: usize) -> Result<Table<'_>, BundleError> {
    let t = Table::parse(b, VARIANT_RECORD, u16::MAX as usize)?;
    if t.count == 0 {
        return Err(BundleError::BadCount);
    }
    for i in 0..t.count {
        let r = t.record(i).ok_or(BundleError::BadSectionLength)?;
        let field = |off| rd_u32(r, off).ok_or(BundleError::BadSectionLength);
        rd_str(t.pool, field(0)?)?;
        rd_str(t.pool, field(4)?)?;
        let fam = rd_u16(r, 8).ok_or(BundleError::BadSectionLength)? as usize;
        if fam >= families {
            return Err(BundleError::BadFamily);
        }
        if rd_u16(r, 10) != Some(0) {
            return Err(BundleError::BadValue);
        }
        let cost = f32::from_bits(field(12)?);
        let latency = f32::from_bits(field(16)?);
        if !(cost.is_finite() && cost > 0.0 && latency.is_finite() && latency >= 0.0) {
            return Err(BundleError::BadValue);
        }
    }
    Ok(t)
}

fn parse_policy(b: &[u8], variants: usize) -> Result<Policy<'_>, BundleError> {
    let buckets = rd_u16(b, 0).ok_or(BundleError::BadSectionLength)? as usize;
    let v = rd_u16(b, 2).ok_or(BundleError::BadSectionLength)?;
    let initial = rd_u16(b, 4).ok_or(BundleError::BadSectionLength)?;
    let reference = rd_u16(b, 6).ok_or(BundleError::BadSectionLength)?;
    if buckets != BUCKET_COUNT || v as usize != variants {
        return Err(BundleError::BadPolicyShape);
    }
    let expected = POLICY_HEADER + 2 * BUCKET_COUNT * variants;
    if b.len() != expected {
        return Err(BundleError::BadSectionLength);
    }
    let actions = b
        .get(POLICY_HEADER..)
        .ok_or(BundleError::BadSectionLength)?;
    if initial >= v
        || reference >= v
        || actions
            .chunks_exact(2)
            .any(|c| <[u8; 2]>::try_from(c).map_or(u16::MAX, u16::from_le_bytes) >= v)
    {
        return Err(BundleError::BadAction);
    }
    Ok(Policy {
        actions,
        variants: v,
        initial,
        reference,
    })
}

fn budget_info(r: &[u8]) -> Option<BudgetInfo> {
    Some(BudgetInfo {
        budget_ms: rd_f32(r, 0)?,
        slowdown: rd_f32(r, 4)?,
        expected_ms: rd_f32(r, 8)?,
        p95_ms: rd_f32(r, 12)?,
    })
}

fn parse_schedules(b: &[u8], variants: usize, version: u16) -> Result<Schedules<'_>, BundleError> {
    let u16_at = |off| rd_u16(b, off).ok_or(BundleError::BadSectionLength);
    let f32_at = |off| rd_f32(b, off).ok_or(BundleError::BadSectionLength);
    let shape = [u16_at(0)?, u16_at(2)?, u16_at(4)?].map(usize::from);
    let period_count = u16_at(6)?;
    if shape != [SIZE_BUCKETS, MOTION_BUCKETS, COUNT_BUCKETS]
        || period_count == 0
        || usize::from(period_count) > MAX_PERIODS
    {
        return Err(BundleError::BadSchedule);
    }
    let edges = ContentEdges {
        size_px: [f32_at(8)?, f32_at(12)?],
        motion_px: [f32_at(16)?, f32_at(20)?],
    };
    if !edges.is_valid() {
        return Err(BundleError::BadSchedule);
    }
    let mut periods = [0u32; MAX_PERIODS];
    let mut previous = 0;
    for (i, slot) in periods.iter_mut().enumerate() {
        let p = u32::from(u16_at(24 + 2 * i)?);
        let ok = if i < usize::from(period_count) {
            p > previous && p <= MAX_PERIOD
        } else {
            p == 0
        };
        if !ok {
            return Err(BundleError::BadSchedule);
        }
        *slot = p;
        previous = p;
    }
    let budget_count = usize::from(u16_at(32)?);
    if budget_count == 0 || budget_count > MAX_BUDGETS {
        return Err(BundleError::BadSchedule);
    }
    let initial = u16_at(34)?;
    let (header, frame_ms) = if version >= 6 {
        let f = f32_at(36)?;
        if !(f.is_finite() && f > 0.0) {
            return Err(BundleError::BadSchedule);
        }
        (SCHEDULES_HEADER, Some(f))
    } else {
        (SCHEDULES_HEADER_V5, None)
    };
    let states = variants
        .checked_mul(crate::bundle::BUCKET_COUNT * CONTENT_STATES)
        .ok_or(BundleError::BadSectionLength)?;
    let budgets_end = header + BUDGET_RECORD * budget_count;
    let expected = states
        .checked_mul(budget_count)
        .and_then(|n| n.checked_mul(2))
        .and_then(|n| n.checked_add(budgets_end))
        .ok_or(BundleError::BadSectionLength)?;
    if b.len() != expected {
        return Err(BundleError::BadSectionLength);
    }
    let budgets = b
        .get(header..budgets_end)
        .ok_or(BundleError::BadSectionLength)?;
    if budgets
        .chunks_exact(BUDGET_RECORD)
        .any(|r| !budget_info(r).is_some_and(|i| i.is_valid()))
    {
        return Err(BundleError::BadSchedule);
    }
    let tables = b.get(budgets_end..).ok_or(BundleError::BadSectionLength)?;
    // every action, and the initial one, below V · P (2 · V · P from version 7 on)
    let tracked_codes = variants.saturating_mul(usize::from(period_count));
    let limit = tracked_codes.saturating_mul(if version >= 7 { 2 } else { 1 });
    let in_range = |a: u16| usize::from(a) < limit;
    if !in_range(initial)
        || tables
            .chunks_exact(2)
            .any(|c| !in_range(<[u8; 2]>::try_from(c).map_or(u16::MAX, u16::from_le_bytes)))
    {
        return Err(BundleError::BadScheduleAction);
    }
    let mut s = Schedules {
        edges,
        periods,
        period_count,
        initial: ScheduleAction::tracked(0, 1),
        first_from_table: version >= 5,
        frame_ms,
        untracked: version >= 7,
        tracked_codes,
        budgets,
        budget_count,
        tables,
        states,
    };
    s.initial = s.decode(initial).ok_or(BundleError::BadScheduleAction)?;
    Ok(s)
}
