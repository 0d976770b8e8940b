//! The bundle's writer and zero-copy reader: round trips, old versions read and never
//! misread, and every flipped byte, truncation, extension and structural error refused.
//! About 900 lines of independent cases that share the sample bundles at the top.

use frugal_runtime::bundle::write::{
    BudgetSpec, BundleWriter, FamilySpec, ScheduleSpec, VariantSpec, WriteError,
};
use frugal_runtime::bundle::{
    BUCKET_COUNT, Bucket, Bundle, BundleError, FORMAT_VERSION, HEADER_LEN, MAGIC, MAX_ACCESSES,
    MIN_FORMAT_VERSION, SECTION_ENTRY_LEN, ScoreBuckets, SectionKind, Thresholds,
};
use frugal_runtime::crc::{Crc32, crc32};
use frugal_runtime::schedule::{
    BudgetInfo, CONTENT_STATES, Content, ContentEdges, MAX_BUDGETS, ScheduleAction, state_index,
};
use proptest::prelude::*;

const CNN: ScoreBuckets = ScoreBuckets {
    c_opt: 0.9,
    c_ge: 0.6,
    c_ua: 0.3,
    t_c: 0.5,
};

fn writer() -> BundleWriter {
    let mut onnx = VariantSpec::new("cnn-int8-pruned50", 0, 1.0, 3.25);
    onnx.onnx_file = "variants/cnn-int8-pruned50.onnx".into();
    onnx.sha256 = core::array::from_fn(|i| i as u8 * 7 + 1);
    BundleWriter::new(Thresholds {
        iou_threshold: 0.45,
        min_track_quality: 0.25,
        mdp_period: 90,
        reinit_period: 12,
        accesses_per_image: 3,
    })
    .family(FamilySpec {
        name: "cnn".into(),
        buckets: CNN,
    })
    .family(FamilySpec {
        name: "hog".into(),
        buckets: ScoreBuckets::PAPER_SVM,
    })
    .variant(onnx)
    .variant(VariantSpec::new("cnn-fp32", 0, 4.5, 14.5))
    .variant(VariantSpec::new("hog-1000-2-8-9", 1, 9.0, 29.0))
    // rows: optimal, good enough, inadequate, miss; columns: current variant 0, 1, 2
    .policy(1, vec![0, 0, 1, 0, 1, 2, 1, 2, 2, 2, 2, 2])
    .metadata("trained-on", "seeds 0..80")
    .metadata("note", "ünïcödé ✓")
}

fn sample() -> Vec<u8> {
    writer().finish().expect("valid bundle")
}

const PERIODS: [u32; 3] = [1, 3, 8];

/// The action of budget `k` in state `i` of [`scheduled_writer`]'s tables (3 variants).
fn action_of(k: usize, i: usize) -> ScheduleAction {
    ScheduleAction {
        variant: ((i / CONTENT_STATES + k) % 3) as u16,
        period: PERIODS[(i * 7 + k) % 3],
        track: true,
    }
}

fn budget_info(k: usize) -> BudgetInfo {
    BudgetInfo {
        budget_ms: 40.0 / (k + 1) as f32,
        slowdown: 39.0,
        expected_ms: 30.0 / (k + 1) as f32,
        p95_ms: 38.5 / (k + 1) as f32,
    }
}

fn schedule_spec(budgets: usize) -> ScheduleSpec {
    let states = BUCKET_COUNT * 3 * CONTENT_STATES;
    ScheduleSpec {
        edges: ContentEdges {
            size_px: [20.0, 50.5],
            motion_px: [0.5, 3.0],
        },
        periods: PERIODS.to_vec(),
        initial: ScheduleAction {
            variant: 2,
            period: 3,
            track: true,
        },
        frame_ms: 1e3 / 25.0,
        budgets: (0..budgets)
            .map(|k| BudgetSpec {
                info: budget_info(k),
                actions: (0..states).map(|i| action_of(k, i)).collect(),
            })
            .collect(),
    }
}

/// [`writer`] with two budget schedules.
fn scheduled_writer() -> BundleWriter {
    writer().schedules(schedule_spec(2))
}

fn scheduled_sample() -> Vec<u8> {
    scheduled_writer().finish().expect("valid bundle")
}

/// Recomputes every section checksum (where the section is in bounds) and the file
/// checksum, so that corruption reaches the structural checks behind them.
fn fix_checksums(b: &mut [u8]) {
    let n = b
        .get(6..8)
        .map_or(0, |s| u16::from_le_bytes([s[0], s[1]]) as usize);
    for i in 0..n.min(16) {
        let e = HEADER_LEN + i * SECTION_ENTRY_LEN;
        let Some(entry) = b.get(e..e + 16) else { break };
        let off = u32::from_le_bytes(entry[4..8].try_into().unwrap()) as usize;
        let len = u32::from_le_bytes(entry[8..12].try_into().unwrap()) as usize;
        if let Some(body) = off.checked_add(len).and_then(|end| b.get(off..end)) {
            let c = crc32(body).to_le_bytes();
            b[e + 12..e + 16].copy_from_slice(&c);
        }
    }
    if b.len() >= HEADER_LEN {
        let mut c = Crc32::new();
        c.update(&b[..12]);
        c.update(&[0; 4]);
        c.update(&b[HEADER_LEN..]);
        b[12..16].copy_from_slice(&c.finish().to_le_bytes());
    }
}

/// Everything a valid bundle offers can be read without failing.
fn exercise(b: &Bundle<'_>) {
    assert!(b.thresholds().is_valid());
    for f in 0..b.family_count() {
        assert!(b.family(f).is_some());
    }
    assert_eq!(b.variants().count(), b.variant_count());
    let v = b.policy().variant_count();
    assert!(b.policy().initial() < v);
    for cur in 0..v {
        assert!(b.variant_buckets(cur).is_some());
        for bucket in Bucket::ALL {
            assert!(b.policy().action(bucket, cur).is_some_and(|a| a < v));
        }
    }
    assert_eq!(b.metadata().count(), b.metadata_len());
    if let Some(s) = b.schedules() {
        assert!(s.edges().is_valid());
        let p = s.period_count();
        assert!((1..=4).contains(&p));
        let periods: Vec<u32> = (0..p).map(|i| s.period(i).unwrap()).collect();
        assert!(periods.windows(2).all(|w| w[0] < w[1]) && periods[0] >= 1);
        assert_eq!(s.period(p), None);
        assert!(s.initial().variant < v && periods.contains(&s.initial().period));
        assert!((1..=MAX_BUDGETS).contains(&s.budget_count()));
        assert_eq!(
            s.state_count(),
            BUCKET_COUNT * usize::from(v) * CONTENT_STATES
        );
        for k in 0..s.budget_count() {
            assert!(s.budget(k).unwrap().is_valid());
            for i in 0..s.state_count() {
                let a = s.action(k, i).unwrap();
                assert!(a.variant < v && periods.contains(&a.period));
            }
            assert_eq!(s.action(k, s.state_count()), None);
        }
        assert_eq!(s.budget(s.budget_count()), None);
        assert_eq!(s.action(s.budget_count(), 0), None);
    }
}

#[test]
fn round_trip_keeps_every_field() {
    let bytes = sample();
    assert_eq!(&bytes[..4], b"FRPB");
    let b = Bundle::parse(&bytes).unwrap();
    assert_eq!(
        b.thresholds(),
        Thresholds {
            iou_threshold: 0.45,
            min_track_quality: 0.25,
            mdp_period: 90,
            reinit_period: 12,
            accesses_per_image: 3,
        }
    );
    assert_eq!(b.family_count(), 2);
    let f0 = b.family(0).unwrap();
    assert_eq!((f0.name, f0.buckets), ("cnn", CNN));
    assert_eq!(b.family(1).unwrap().buckets, ScoreBuckets::PAPER_SVM);
    assert!(b.family(2).is_none());
    assert_eq!(b.variant_count(), 3);
    let v0 = b.variant(0).unwrap();
    assert_eq!(v0.name, "cnn-int8-pruned50");
    assert_eq!(v0.onnx_file, "variants/cnn-int8-pruned50.onnx");
    assert_eq!(
        v0.sha256,
        core::array::from_fn::<u8, 32, _>(|i| i as u8 * 7 + 1)
    );
    assert_eq!((v0.family, v0.relative_cost, v0.latency_ms), (0, 1.0, 3.25));
    let v2 = b.variant(2).unwrap();
    assert_eq!(
        (v2.name, v2.family, v2.onnx_file, v2.sha256),
        ("hog-1000-2-8-9", 1, "", [0; 32])
    );
    assert!(b.variant(3).is_none());
    assert_eq!(b.variant_family(2), Some(1));
    let p = b.policy();
    assert_eq!((p.initial(), p.variant_count()), (1, 3));
    // unset, the reference is the costliest variant (hog-1000-2-8-9, cost 9)
    assert_eq!(p.reference(), 2);
    assert_eq!(p.action(Bucket::Optimal, 2), Some(1));
    assert_eq!(p.action(Bucket::GoodEnough, 1), Some(1));
    assert_eq!(p.action(Bucket::Inadequate, 0), Some(1));
    assert_eq!(p.action(Bucket::Miss, 0), Some(2));
    assert_eq!(p.action(Bucket::Miss, 3), None);
    let meta: Vec<_> = b.metadata().collect();
    assert_eq!(meta, [("trained-on", "seeds 0..80"), ("note", "ünïcödé ✓")]);
    assert_eq!(b.metadata_get("note"), Some("ünïcödé ✓"));
    assert_eq!(b.metadata_get("missing"), None);
    exercise(&b);
    // Deterministic output.
    assert_eq!(bytes, sample());
}

#[test]
fn schedules_round_trip() {
    let bytes = scheduled_sample();
    let b = Bundle::parse(&bytes).unwrap();
    assert_eq!(b.version(), FORMAT_VERSION);
    assert_eq!(FORMAT_VERSION, 7);
    let s = b.schedules().expect("schedules");
    assert_eq!(s.frame_ms(), Some(40.0));
    assert_eq!(
        s.edges(),
        ContentEdges {
            size_px: [20.0, 50.5],
            motion_px: [0.5, 3.0],
        }
    );
    assert_eq!(s.period_count(), 3);
    assert_eq!(
        (0..4).map(|i| s.period(i)).collect::<Vec<_>>(),
        [Some(1), Some(3), Some(8), None]
    );
    assert_eq!(
        s.initial(),
        ScheduleAction {
            variant: 2,
            period: 3,
            track: true,
        }
    );
    assert_eq!(s.budget_count(), 2);
    assert_eq!(s.budget(0), Some(budget_info(0)));
    assert_eq!(s.budget(1), Some(budget_info(1)));
    assert_eq!(s.budget(2), None);
    assert_eq!(s.state_count(), 4 * 3 * 27);
    for k in 0..2 {
        for i in 0..s.state_count() {
            assert_eq!(
                s.action(k, i),
                Some(action_of(k, i)),
                "budget {k} state {i}"
            );
        }
    }
    // the state index names the state the writer meant
    let c = Content {
        size: 2,
        motion: 1,
        count: 0,
    };
    let i = state_index(Bucket::Inadequate, 1, c, 3);
    assert_eq!(i, (2 * 3 + 1) * 27 + 21);
    assert_eq!(s.action(1, i), Some(action_of(1, i)));
    // everything else is as without schedules
    let plain_bytes = sample();
    let plain = Bundle::parse(&plain_bytes).unwrap();
    assert!(plain.schedules().is_none());
    assert_eq!(b.thresholds(), plain.thresholds());
    assert_eq!(b.metadata().count(), plain.metadata().count());
    exercise(&b);
    assert_eq!(bytes, scheduled_sample());
}

/// `bytes` with its version field set to `version` and the checksums fixed; for a
/// version before 6, the schedules section (if any) laid out as then, without the
/// frame interval.
pub(super) fn with_version(bytes: &[u8], version: u16) -> Vec<u8> {
    let mut b = bytes.to_vec();
    b[4..6].copy_from_slice(&version.to_le_bytes());
    let n = u16::from_le_bytes([b[6], b[7]]) as usize;
    let u32_at = |b: &[u8], at: usize| u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
    let schedules = (0..n)
        .map(|i| HEADER_LEN + i * SECTION_ENTRY_LEN)
        .find(|&e| u32_at(&b, e) == SectionKind::Schedules as u32);
    if let (true, Some(entry)) = (version < 6, schedules) {
        let cut = u32_at(&b, entry + 4) as usize + 36;
        b.drain(cut..cut + 4);
        let len = u32_at(&b, entry + 8) - 4;
        b[entry + 8..entry + 12].copy_from_slice(&len.to_le_bytes());
        for i in 0..n {
            let e = HEADER_LEN + i * SECTION_ENTRY_LEN;
            let off = u32_at(&b, e + 4);
            if off as usize > cut {
                b[e + 4..e + 8].copy_from_slice(&(off - 4).to_le_bytes());
            }
        }
        let total = u32_at(&b, 8) - 4;
        b[8..12].copy_from_slice(&total.to_le_bytes());
    }
    fix_checksums(&mut b);
    b
}

/// A version-5 bundle (no frame interval) is read as written, its tables as version 6
/// holds them, and says it does not know the tables' frame interval; the same bytes
/// with only the version field changed are never misread.
#[test]
fn a_version_5_bundle_is_read_and_never_misread() {
    let bytes = scheduled_sample();
    let new = Bundle::parse(&bytes).unwrap();
    let v5 = with_version(&bytes, 5);
    assert_eq!(v5.len(), bytes.len() - 4);
    let old = Bundle::parse(&v5).unwrap();
    assert_eq!(old.version(), 5);
    let (s, s5) = (new.schedules().unwrap(), old.schedules().unwrap());
    assert_eq!(s.frame_ms(), Some(40.0));
    assert_eq!(s5.frame_ms(), None);
    assert!(s5.first_from_table());
    assert_eq!(s5.budget_count(), s.budget_count());
    for k in 0..s.budget_count() {
        assert_eq!(s5.budget(k), s.budget(k));
        for i in 0..s.state_count() {
            assert_eq!(s5.action(k, i), s.action(k, i), "budget {k} state {i}");
        }
    }
    exercise(&old);
    // a version-6 layout called 5, or the reverse, is an error, not another reading
    let mut relabelled = bytes.clone();
    relabelled[4..6].copy_from_slice(&5u16.to_le_bytes());
    fix_checksums(&mut relabelled);
    assert!(Bundle::parse(&relabelled).is_err());
    let mut relabelled = v5.clone();
    relabelled[4..6].copy_from_slice(&6u16.to_le_bytes());
    fix_checksums(&mut relabelled);
    assert!(Bundle::parse(&relabelled).is_err());
}

/// Version 7 adds actions that leave the frames between detections alone: written and
/// read back as they were meant, the initial action too; in a bundle of version 6 such
/// a code is an error, never read as another action, and a version-6 bundle's actions
/// all track.
#[test]
fn untracked_actions_are_read_from_version_7_on_and_rejected_before() {
    let mut spec = schedule_spec(2);
    for (k, b) in spec.budgets.iter_mut().enumerate() {
        for (i, a) in b.actions.iter_mut().enumerate() {
            a.track = (i + k) % 3 != 0;
        }
    }
    spec.initial.track = false;
    let bytes = writer().schedules(spec.clone()).finish().unwrap();
    let b = Bundle::parse(&bytes).unwrap();
    let s = b.schedules().unwrap();
    assert!(s.has_untracked());
    assert_eq!(s.initial(), spec.initial);
    for (k, budget) in spec.budgets.iter().enumerate() {
        for (i, a) in budget.actions.iter().enumerate() {
            assert_eq!(s.action(k, i), Some(*a), "budget {k} state {i}");
        }
    }
    assert!(s.action(0, 0).is_some_and(|a| !a.track));
    assert!(s.action(0, 1).is_some_and(|a| a.track));
    exercise(&b);
    assert_eq!(
        Bundle::parse(&with_version(&bytes, 6)).unwrap_err(),
        BundleError::BadScheduleAction
    );
    // an all-tracked bundle called 6 reads the same, every action tracking
    let tracked = scheduled_sample();
    let (s7, s6) = (
        Bundle::parse(&tracked).unwrap().schedules().unwrap(),
        with_version(&tracked, 6),
    );
    let s6 = Bundle::parse(&s6).unwrap().schedules().unwrap();
    assert!(!s6.has_untracked());
    for k in 0..s7.budget_count() {
        for i in 0..s7.state_count() {
            assert_eq!(s6.action(k, i), s7.action(k, i));
            assert!(s6.action(k, i).is_some_and(|a| a.track));
        }
    }
}

#[test]
fn a_version_3_bundle_is_read_and_never_misread() {
    assert_eq!(MIN_FORMAT_VERSION, 3);
    // the writer's sections without schedules are exactly those of version 3
    let v3 = with_version(&sample(), 3);
    let b = Bundle::parse(&v3).unwrap();
    assert_eq!(b.version(), 3);
    assert!(b.schedules().is_none());
    assert_eq!(b.variant_count(), 3);
    assert_eq!(b.policy().action(Bucket::Miss, 0), Some(2));
    exercise(&b);
    // a kind-6 section in a version-3 file is an unknown kind there: skipped
    let v3 = with_version(&scheduled_sample(), 3);
    let b = Bundle::parse(&v3).unwrap();
    assert!(b.schedules().is_none());
    exercise(&b);
    // versions the reader does not know, old or new
    for version in [0, 1, 2, 8, u16::MAX] {
        assert_eq!(
            Bundle::parse(&with_version(&scheduled_sample(), version)).unwrap_err(),
            BundleError::UnsupportedVersion,
            "version {version}"
        );
    }
}

#[test]
fn a_bundle_without_schedules_has_five_sections_as_before() {
    let bytes = sample();
    assert_eq!(u16::from_le_bytes([bytes[6], bytes[7]]), 5);
    let kinds: Vec<u32> = (0..5)
        .map(|i| {
            let e = HEADER_LEN + i * SECTION_ENTRY_LEN;
            u32::from_le_bytes(bytes[e..e + 4].try_into().unwrap())
        })
        .collect();
    assert_eq!(kinds, [1, 2, 3, 4, 5]);
    let scheduled = scheduled_sample();
    assert_eq!(u16::from_le_bytes([scheduled[6], scheduled[7]]), 6);
    assert_eq!(body_offset(&scheduled, 6) % 4, 0, "sections start aligned");
    assert_eq!(SectionKind::Schedules.since(), 4);
}

#[test]
fn every_change_to_a_bundle_with_schedules_is_an_error() {
    let bytes = scheduled_sample();
    for len in 0..bytes.len() {
        let e = Bundle::parse(&bytes[..len]).unwrap_err();
        assert_eq!(e, BundleError::Truncated, "length {len}");
    }
    let mut longer = bytes.clone();
    longer.push(0);
    assert_eq!(
        Bundle::parse(&longer).unwrap_err(),
        BundleError::LengthMismatch
    );
    for i in 0..bytes.len() {
        for mask in [0x01u8, 0x80, 0xFF] {
            let mut c = bytes.clone();
            c[i] ^= mask;
            assert!(
                Bundle::parse(&c).is_err(),
                "flipping byte {i} with {mask:#x} went unnoticed"
            );
        }
    }
}

#[test]
fn schedule_errors_behind_valid_checksums() {
    let bytes = scheduled_sample();
    let body = body_offset(&bytes, 6);
    let patched = |at: usize, value: &[u8]| {
        let mut b = bytes.clone();
        b[body + at..body + at + value.len()].copy_from_slice(value);
        fix_checksums(&mut b);
        Bundle::parse(&b).map(|_| ()).unwrap_err()
    };
    let u16le = |v: u16| v.to_le_bytes();
    let f32le = |v: f32| v.to_le_bytes();
    use BundleError::{BadSchedule, BadScheduleAction};
    for (what, at, value, error) in [
        ("4 size buckets", 0, u16le(4).to_vec(), BadSchedule),
        ("2 motion buckets", 2, u16le(2).to_vec(), BadSchedule),
        ("0 count buckets", 4, u16le(0).to_vec(), BadSchedule),
        ("0 periods", 6, u16le(0).to_vec(), BadSchedule),
        ("5 periods", 6, u16le(5).to_vec(), BadSchedule),
        ("NaN size edge", 8, f32le(f32::NAN).to_vec(), BadSchedule),
        (
            "size edges out of order",
            8,
            f32le(60.0).to_vec(),
            BadSchedule,
        ),
        (
            "negative motion edge",
            16,
            f32le(-0.5).to_vec(),
            BadSchedule,
        ),
        (
            "infinite motion edge",
            20,
            f32le(f32::INFINITY).to_vec(),
            BadSchedule,
        ),
        ("period 0", 24, u16le(0).to_vec(), BadSchedule),
        ("periods not ascending", 26, u16le(1).to_vec(), BadSchedule),
        ("period above 255", 28, u16le(256).to_vec(), BadSchedule),
        ("a period past P", 30, u16le(9).to_vec(), BadSchedule),
        ("0 budgets", 32, u16le(0).to_vec(), BadSchedule),
        (
            "initial action = 2 V P",
            34,
            u16le(18).to_vec(),
            BadScheduleAction,
        ),
        ("frame interval 0 ms", 36, f32le(0.0).to_vec(), BadSchedule),
        (
            "NaN frame interval",
            36,
            f32le(f32::NAN).to_vec(),
            BadSchedule,
        ),
        (
            "negative frame interval",
            36,
            f32le(-33.3).to_vec(),
            BadSchedule,
        ),
        ("budget 0 ms", 40, f32le(0.0).to_vec(), BadSchedule),
        ("NaN slowdown", 44, f32le(f32::NAN).to_vec(), BadSchedule),
        (
            "negative expected latency",
            48,
            f32le(-1.0).to_vec(),
            BadSchedule,
        ),
        (
            "infinite p95",
            64 + 4,
            f32le(f32::INFINITY).to_vec(),
            BadSchedule,
        ),
        (
            "an action = 2 V P",
            40 + 32,
            u16le(18).to_vec(),
            BadScheduleAction,
        ),
        (
            "the last action",
            40 + 32 + 2 * 2 * 324 - 2,
            u16le(u16::MAX).to_vec(),
            BadScheduleAction,
        ),
    ] {
        assert_eq!(patched(at, &value), error, "{what}");
    }
    // a changed budget count no longer matches the section's length
    assert_eq!(patched(32, &u16le(3)), BundleError::BadSectionLength);
    assert_eq!(patched(32, &u16le(9)), BadSchedule);
    // fewer periods: the unused slot must be 0
    assert_eq!(patched(6, &u16le(2)), BadSchedule);
    // the largest tracked action, and the largest action, are fine
    for (code, track) in [(8, true), (17, false)] {
        let mut ok = bytes.clone();
        ok[body + 72..body + 74].copy_from_slice(&u16le(code));
        fix_checksums(&mut ok);
        let b = Bundle::parse(&ok).unwrap();
        assert_eq!(
            b.schedules().unwrap().action(0, 0),
            Some(ScheduleAction {
                variant: 2,
                period: 8,
                track,
            })
        );
    }
    // the section twice
    let mut dup = bytes.clone();
    let e5 = HEADER_LEN + 4 * SECTION_ENTRY_LEN;
    let entry6 = dup[e5 + 16..e5 + 32].to_vec();
    dup[e5..e5 + 16].copy_from_slice(&entry6);
    fix_checksums(&mut dup);
    assert_eq!(
        Bundle::parse(&dup).unwrap_err(),
        BundleError::DuplicateSection
    );
}

/// A change to a schedule spec.
type Edit = dyn Fn(&mut ScheduleSpec);

#[test]
fn the_writer_checks_schedules() {
    let with = |f: &Edit| {
        let mut spec = schedule_spec(1);
        f(&mut spec);
        writer().schedules(spec).finish().map(|_| ())
    };
    assert_eq!(with(&|_| ()), Ok(()));
    let max_budgets = |s: &mut ScheduleSpec| {
        let one = s.budgets[0].clone();
        s.budgets = vec![one; MAX_BUDGETS];
    };
    assert_eq!(with(&max_budgets), Ok(()));
    let cases: [(&str, &Edit, WriteError); 15] = [
        ("no period", &|s| s.periods.clear(), WriteError::BadPeriods),
        (
            "5 periods",
            &|s| s.periods = vec![1, 2, 3, 4, 5],
            WriteError::BadPeriods,
        ),
        ("period 0", &|s| s.periods[0] = 0, WriteError::BadPeriods),
        (
            "period 256",
            &|s| s.periods[2] = 256,
            WriteError::BadPeriods,
        ),
        (
            "unordered",
            &|s| s.periods = vec![3, 1, 8],
            WriteError::BadPeriods,
        ),
        (
            "repeated",
            &|s| s.periods = vec![1, 3, 3],
            WriteError::BadPeriods,
        ),
        (
            "edges",
            &|s| s.edges.size_px = [5.0, 1.0],
            WriteError::BadEdges,
        ),
        (
            "no budget",
            &|s| s.budgets.clear(),
            WriteError::BadBudgetCount,
        ),
        (
            "9 budgets",
            &|s| s.budgets = vec![s.budgets[0].clone(); MAX_BUDGETS + 1],
            WriteError::BadBudgetCount,
        ),
        (
            "budget 0 ms",
            &|s| s.budgets[0].info.budget_ms = 0.0,
            WriteError::BadBudget,
        ),
        (
            "NaN p95",
            &|s| s.budgets[0].info.p95_ms = f32::NAN,
            WriteError::BadBudget,
        ),
        (
            "short table",
            &|s| {
                s.budgets[0].actions.pop();
            },
            WriteError::BadScheduleLength,
        ),
        (
            "unknown variant",
            &|s| s.budgets[0].actions[5].variant = 3,
            WriteError::BadScheduleAction,
        ),
        (
            "unoffered period",
            &|s| s.budgets[0].actions[7].period = 2,
            WriteError::BadScheduleAction,
        ),
        (
            "bad initial",
            &|s| s.initial.period = 4,
            WriteError::BadScheduleAction,
        ),
    ];
    for (what, f, error) in cases {
        assert_eq!(with(f), Err(error), "{what}");
        assert!(!error.to_string().is_empty());
    }
}

#[test]
fn parses_from_an_unaligned_slice() {
    let bytes = sample();
    let mut shifted = vec![0u8; bytes.len() + 1];
    shifted[1..].copy_from_slice(&bytes);
    let b = Bundle::parse(&shifted[1..]).unwrap();
    assert_eq!(b.variant(1).unwrap().name, "cnn-fp32");
}

#[test]
fn every_flipped_byte_is_an_error() {
    let bytes = sample();
    for i in 0..bytes.len() {
        for mask in [0x01u8, 0x80, 0xFF] {
            let mut c = bytes.clone();
            c[i] ^= mask;
            assert!(
                Bundle::parse(&c).is_err(),
                "flipping byte {i} with {mask:#x} went unnoticed"
            );
        }
    }
}

#[test]
fn every_truncation_and_extension_is_an_error() {
    let bytes = sample();
    for len in 0..bytes.len() {
        let e = Bundle::parse(&bytes[..len]).unwrap_err();
        assert_eq!(e, BundleError::Truncated, "length {len}");
    }
    let mut longer = bytes.clone();
    longer.push(0);
    assert_eq!(
        Bundle::parse(&longer).unwrap_err(),
        BundleError::LengthMismatch
    );
}

#[test]
fn header_errors_are_typed() {
    let bytes = sample();
    let mut swapped = bytes.clone();
    swapped[..4].copy_from_slice(&MAGIC.to_be_bytes());
    assert_eq!(
        Bundle::parse(&swapped).unwrap_err(),
        BundleError::WrongEndian
    );
    let mut magic = bytes.clone();
    magic[0] = b'X';
    assert_eq!(Bundle::parse(&magic).unwrap_err(), BundleError::BadMagic);
    let mut version = bytes.clone();
    version[4..6].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    assert_eq!(
        Bundle::parse(&version).unwrap_err(),
        BundleError::UnsupportedVersion
    );
    let mut body = bytes.clone();
    let last = body.len() - 1;
    body[last] ^= 1;
    assert_eq!(Bundle::parse(&body).unwrap_err(), BundleError::FileChecksum);
    // With the file checksum fixed, the section checksum still catches it.
    let mut c = Crc32::new();
    c.update(&body[..12]);
    c.update(&[0; 4]);
    c.update(&body[16..]);
    body[12..16].copy_from_slice(&c.finish().to_le_bytes());
    assert_eq!(
        Bundle::parse(&body).unwrap_err(),
        BundleError::SectionChecksum
    );
    // Errors print a sentence and are std errors.
    let e: Box<dyn std::error::Error> = Box::new(BundleError::WrongEndian);
    assert!(e.to_string().contains("big-endian"));
}

#[test]
fn structural_errors_behind_valid_checksums() {
    let bytes = sample();
    // Duplicate a section: point entry 1 (families) at the thresholds body with kind 1.
    let mut dup = bytes.clone();
    let kind0 = dup[16..20].to_vec();
    dup[32..36].copy_from_slice(&kind0);
    fix_checksums(&mut dup);
    assert_eq!(
        Bundle::parse(&dup).unwrap_err(),
        BundleError::DuplicateSection
    );
    // An unknown kind in place of metadata: skipped, so metadata is missing.
    let mut missing = bytes.clone();
    missing[16 + 4 * 16..16 + 4 * 16 + 4].copy_from_slice(&99u32.to_le_bytes());
    fix_checksums(&mut missing);
    assert_eq!(
        Bundle::parse(&missing).unwrap_err(),
        BundleError::MissingSection
    );
    // A section reaching past the end.
    let mut oob = bytes.clone();
    let len_field = 16 + 4 * 16 + 8;
    oob[len_field..len_field + 4].copy_from_slice(&(bytes.len() as u32).to_le_bytes());
    fix_checksums(&mut oob);
    assert_eq!(
        Bundle::parse(&oob).unwrap_err(),
        BundleError::SectionOutOfBounds
    );
    // A section overlapping the header.
    let mut over = bytes.clone();
    over[16 + 4..16 + 8].copy_from_slice(&8u32.to_le_bytes());
    fix_checksums(&mut over);
    assert_eq!(
        Bundle::parse(&over).unwrap_err(),
        BundleError::SectionOutOfBounds
    );
    // Zero sections.
    let mut none = bytes.clone();
    none[6..8].copy_from_slice(&0u16.to_le_bytes());
    fix_checksums(&mut none);
    assert_eq!(
        Bundle::parse(&none).unwrap_err(),
        BundleError::BadSectionCount
    );
}

#[test]
fn the_reference_variant_is_kept_and_checked() {
    let bytes = writer().reference(1).finish().unwrap();
    assert_eq!(Bundle::parse(&bytes).unwrap().policy().reference(), 1);
    // out of range behind valid checksums: the policy body's bytes 6..8
    let b = Bundle::parse(&bytes).unwrap();
    let body = policy_body_offset(&bytes);
    let mut bad = bytes.clone();
    let v = u16::try_from(b.variant_count()).unwrap();
    bad[body + 6..body + 8].copy_from_slice(&v.to_le_bytes());
    fix_checksums(&mut bad);
    assert_eq!(Bundle::parse(&bad).unwrap_err(), BundleError::BadAction);
}

/// Offset of the policy section's body (kind 4) from the section table.
fn policy_body_offset(b: &[u8]) -> usize {
    body_offset(b, 4)
}

/// Offset of the body of the section of kind `kind`, from the section table.
fn body_offset(b: &[u8], kind: u32) -> usize {
    let n = u16::from_le_bytes([b[6], b[7]]) as usize;
    (0..n)
        .map(|i| HEADER_LEN + i * SECTION_ENTRY_LEN)
        .find(|&e| u32::from_le_bytes(b[e..e + 4].try_into().unwrap()) == kind)
        .map(|e| u32::from_le_bytes(b[e + 4..e + 8].try_into().unwrap()) as usize)
        .expect("a section of that kind")
}

#[test]
fn writer_rejects_what_the_reader_would() {
    let bad_action = writer().policy(0, vec![3; BUCKET_COUNT * 3]).finish();
    assert_eq!(
        bad_action.unwrap_err(),
        WriteError::Invalid(BundleError::BadAction)
    );
    let bad_initial = writer().policy(3, vec![0; BUCKET_COUNT * 3]).finish();
    assert_eq!(
        bad_initial.unwrap_err(),
        WriteError::Invalid(BundleError::BadAction)
    );
    let bad_reference = writer().reference(3).finish();
    assert_eq!(
        bad_reference.unwrap_err(),
        WriteError::Invalid(BundleError::BadAction)
    );
    let short = writer().policy(0, vec![0; 5]).finish();
    assert_eq!(
        short.unwrap_err(),
        WriteError::Invalid(BundleError::BadSectionLength)
    );
    let bad_family = writer()
        .variant(VariantSpec::new("x", 7, 1.0, 1.0))
        .finish();
    // One more variant also breaks the policy shape, which is checked after families.
    assert_eq!(
        bad_family.unwrap_err(),
        WriteError::Invalid(BundleError::BadFamily)
    );
    let nan = writer()
        .variant(VariantSpec::new("x", 0, f32::NAN, 1.0))
        .finish();
    assert_eq!(nan.unwrap_err(), WriteError::Invalid(BundleError::BadValue));
    let unordered = writer()
        .family(FamilySpec {
            name: "bad".into(),
            buckets: ScoreBuckets {
                c_opt: 0.1,
                c_ge: 0.5,
                c_ua: 0.0,
                t_c: 0.0,
            },
        })
        .finish();
    assert_eq!(
        unordered.unwrap_err(),
        WriteError::Invalid(BundleError::BadValue)
    );
    // thresholds out of range: a zero period, no access per image, too many
    for (what, th) in [
        (
            "N = 0",
            Thresholds {
                mdp_period: 0,
                ..Thresholds::PAPER
            },
        ),
        (
            "0 accesses per image",
            Thresholds {
                accesses_per_image: 0,
                ..Thresholds::PAPER
            },
        ),
        (
            "too many accesses per image",
            Thresholds {
                accesses_per_image: MAX_ACCESSES + 1,
                ..Thresholds::PAPER
            },
        ),
    ] {
        let bad = BundleWriter::new(th)
            .family(FamilySpec {
                name: "cnn".into(),
                buckets: CNN,
            })
            .variant(VariantSpec::new("a", 0, 1.0, 1.0))
            .policy(0, vec![0; BUCKET_COUNT])
            .finish();
        assert_eq!(
            bad.unwrap_err(),
            WriteError::Invalid(BundleError::BadValue),
            "{what}"
        );
    }
    let no_policy = BundleWriter::new(Thresholds::PAPER)
        .family(FamilySpec {
            name: "cnn".into(),
            buckets: CNN,
        })
        .variant(VariantSpec::new("a", 0, 1.0, 1.0))
        .finish();
    assert_eq!(no_policy.unwrap_err(), WriteError::MissingPolicy);
    let no_variants = BundleWriter::new(Thresholds::PAPER)
        .family(FamilySpec {
            name: "cnn".into(),
            buckets: CNN,
        })
        .policy(0, vec![])
        .finish();
    assert_eq!(
        no_variants.unwrap_err(),
        WriteError::Invalid(BundleError::BadCount)
    );
    let long = writer().metadata("k", "x".repeat(70_000)).finish();
    assert_eq!(long.unwrap_err(), WriteError::StringTooLong);
}

#[test]
fn score_buckets_follow_the_paper() {
    let b = ScoreBuckets::PAPER_SVM;
    assert_eq!(b.bucket(Some(1.2)), Bucket::Optimal);
    assert_eq!(b.bucket(Some(0.9)), Bucket::Optimal);
    assert_eq!(b.bucket(Some(0.3)), Bucket::GoodEnough);
    assert_eq!(b.bucket(Some(0.0)), Bucket::GoodEnough);
    assert_eq!(b.bucket(Some(-0.2)), Bucket::Inadequate);
    assert_eq!(b.bucket(Some(-0.7)), Bucket::Miss);
    assert_eq!(b.bucket(None), Bucket::Miss);
    assert_eq!(b.bucket(Some(f32::NAN)), Bucket::Miss);
    assert_eq!(Thresholds::default(), Thresholds::PAPER);
    assert_eq!(
        (
            Thresholds::PAPER.iou_threshold,
            Thresholds::PAPER.mdp_period,
            Thresholds::PAPER.reinit_period,
            Thresholds::PAPER.accesses_per_image
        ),
        (0.5, 100, 10, 5)
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// Arbitrary bytes: never a panic, and anything accepted is fully readable.
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        if let Ok(b) = Bundle::parse(&bytes) {
            exercise(&b);
        }
    }

    /// Arbitrary bytes behind a valid header prefix with fixed checksums, so that the
    /// section and record checks are reached.
    #[test]
    fn arbitrary_sections_never_panic(tail in proptest::collection::vec(any::<u8>(), 0..400), n in 0u16..8) {
        let mut b = Vec::new();
        b.extend_from_slice(&MAGIC.to_le_bytes());
        b.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        b.extend_from_slice(&n.to_le_bytes());
        b.extend_from_slice(&((16 + tail.len()) as u32).to_le_bytes());
        b.extend_from_slice(&[0; 4]);
        b.extend_from_slice(&tail);
        fix_checksums(&mut b);
        if let Ok(b) = Bundle::parse(&b) {
            exercise(&b);
        }
    }

    /// A real bundle with random bytes overwritten and checksums fixed: Err or a fully
    /// readable bundle, never a panic.
    #[test]
    fn mutated_bundles_never_panic(edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6)) {
        let mut b = sample();
        for (i, v) in edits {
            let at = i.index(b.len());
            b[at] = v;
        }
        fix_checksums(&mut b);
        if let Ok(b) = Bundle::parse(&b) {
            exercise(&b);
        }
    }

    /// The same for a bundle with schedules, the edits inside the schedules section
    /// half of the time.
    #[test]
    fn mutated_scheduled_bundles_never_panic(
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>(), any::<bool>()), 1..6)
    ) {
        let mut b = scheduled_sample();
        let body = body_offset(&b, 6);
        for (i, v, in_schedules) in edits {
            let at = if in_schedules {
                body + i.index(b.len() - body)
            } else {
                i.index(b.len())
            };
            b[at] = v;
        }
        fix_checksums(&mut b);
        if let Ok(b) = Bundle::parse(&b) {
            exercise(&b);
        }
    }
}
