//! The crate docs' example, run as a test (doctests cannot load libtorch).

use frugal_data::{Clutter, Light, Split};
use frugal_policies::replay::{Det, FrameLog, MemoryFrames, RgbFrame, VideoLog, record};
use frugal_policies::variants::*;
use frugal_policies::{PolicyConfig, VariantSet, train::train};
use frugal_runtime::bundle::Bucket;

#[test]
fn crate_docs_example() -> Result<(), frugal_policies::PolicyError> {
    // One training video of 20 blank frames with one sign; two synthetic variants:
    // a cheap one with good-enough scores and a costly one with optimal scores.
    let mut frames = MemoryFrames::default();
    let mut logs = Vec::new();
    for i in 0..20 {
        frames.frames.insert(
            (0, i),
            RgbFrame {
                width: 64,
                height: 48,
                rgb: vec![0; 64 * 48 * 3],
            },
        );
        let truth = vec![Det {
            class: 0,
            score: 1.0,
            bbox: [10.0, 10.0, 30.0, 30.0],
        }];
        logs.push(FrameLog {
            index: i,
            truth,
            detections: vec![],
            ignore: Vec::new(),
            time_s: None,
        });
    }
    let video = VideoLog {
        id: 0,
        clutter: Clutter::Low,
        light: Light::Normal,
        split: Split::Train,
        width: 64,
        height: 48,
        frames: logs,
    };
    let spec = |seed, score| SyntheticSpec {
        seed,
        score,
        ..SyntheticSpec::default()
    };
    let family = FamilyInfo {
        name: "cnn".into(),
        buckets: CNN_BUCKETS,
    };
    let info = |name: &str, ms, s: &SyntheticSpec| VariantInfo {
        name: name.into(),
        family: 0,
        latency_ms: ms,
        relative_cost: 1.0,
        precision: Default::default(),
        source: VariantSource::Synthetic(s.clone()),
    };
    let (cheap, costly) = (spec(1, [0.6, 0.8]), spec(2, [0.95, 1.0]));
    let mut set = VariantSet::new(
        vec![family],
        vec![info("cheap", 2.0, &cheap), info("costly", 10.0, &costly)],
        vec![
            Box::new(SyntheticDetector(cheap)),
            Box::new(SyntheticDetector(costly)),
        ],
    );
    let log = record(&mut set, &frames, vec![video], "".into(), 1, 8, false)?;
    let policy = train(&log, &PolicyConfig::default())?;
    // Good enough on the cheap variant: stay on it.
    assert_eq!(policy.action(Bucket::GoodEnough, 0), 0);
    Ok(())
}
