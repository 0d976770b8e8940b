use frugal_runtime::bundle::write::{BundleWriter, FamilySpec, VariantSpec, WriteError};
use frugal_runtime::bundle::{
    BUCKET_COUNT, Bucket, Bundle, BundleError, FORMAT_VERSION, HEADER_LEN, MAGIC, MAX_ACCESSES,
    SECTION_ENTRY_LEN, ScoreBuckets, Thresholds,
};
use frugal_runtime::crc::{Crc32, crc32};
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
    let n = u16::from_le_bytes([b[6], b[7]]) as usize;
    (0..n)
        .map(|i| HEADER_LEN + i * SECTION_ENTRY_LEN)
        .find(|&e| u32::from_le_bytes(b[e..e + 4].try_into().unwrap()) == 4)
        .map(|e| u32::from_le_bytes(b[e + 4..e + 8].try_into().unwrap()) as usize)
        .expect("a policy section")
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
}
