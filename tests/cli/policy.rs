//! `frugal policy record|train|eval` and `frugal bundle write|verify|inspect` on a tiny
//! generated dataset with synthetic (ground-truth-derived) detector variants.
use super::{frugal, json, p};

const VARIANTS: &str = r#"
[[variants]]
name = "full"
family = "cnn"
latency_ms = 12.0
source = { kind = "synthetic", seed = 3, miss = 0.0, miss_low_light = 0.0, miss_high_clutter = 0.0, score = [0.92, 1.0] }

[[variants]]
name = "fast"
family = "cnn"
latency_ms = 3.0
source = { kind = "synthetic", seed = 1, miss = 0.0, miss_low_light = 0.9, miss_high_clutter = 0.1, score = [0.6, 0.85] }
"#;

#[test]
fn record_train_eval_and_bundle_on_a_tiny_dataset() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, run) = (tmp.path().join("data"), tmp.path().join("run"));
    frugal(&[
        "data",
        "generate",
        "--profile",
        "tiny",
        "--frames",
        "8",
        "--out",
        p(&data),
        "--quiet",
    ])
    .unwrap();
    let variants = tmp.path().join("variants.toml");
    std::fs::write(&variants, VARIANTS).unwrap();
    let log = run.join("replay.json");
    frugal(&[
        "policy",
        "record",
        "--data",
        p(&data),
        "--variants",
        p(&variants),
        "--out",
        p(&log),
        "--quiet",
    ])
    .unwrap();

    let policy_dir = run.join("policy");
    // the paper's reward and α, whose "good enough" bucket is the fast variant's range
    frugal(&[
        "policy",
        "train",
        "--log",
        p(&log),
        "--out",
        p(&policy_dir),
        "--reward",
        "confidence",
        "--alpha",
        "1",
    ])
    .unwrap();
    let policy: serde_json::Value =
        serde_json::from_slice(&std::fs::read(policy_dir.join("policy.json")).unwrap()).unwrap();
    assert_eq!(policy["config"]["reward"], "confidence");
    // Cheapest first; the policy keeps the fast variant while it is good enough.
    assert_eq!(policy["variants"][0]["name"], "fast");
    assert_eq!(policy["variants"][1]["relative_cost"], 4.0);
    assert_eq!(
        policy["actions"][2], 0,
        "good enough on fast → stay on fast"
    );
    for f in ["sweep.json", "sweep.csv", "sweep.png", "sweep.svg"] {
        assert!(policy_dir.join(f).is_file(), "{f}");
    }

    let eval = run.join("eval");
    frugal(&[
        "policy",
        "eval",
        "--log",
        p(&log),
        "--policy",
        p(&policy_dir.join("policy.json")),
        "--out",
        p(&eval),
    ])
    .unwrap();
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(eval.join("eval.json")).unwrap()).unwrap();
    assert_eq!(report["static_variant"], "full");
    let scores = report["scores"].as_array().unwrap();
    assert!(
        scores
            .iter()
            .any(|s| s["scenario"] == "low-light" && s["strategy"] == "mdp+tracker")
    );
    for f in [
        "eval.csv",
        "bars-time.png",
        "bars-f1.svg",
        "clip.png",
        "states.svg",
        "per_class.csv",
        "per_class-precision.png",
        "per_class-time.svg",
    ] {
        assert!(eval.join(f).is_file(), "{f}");
    }
    // Per class: one row per class and strategy plus an all row per strategy, whose
    // counts are the classes' sums.
    let per_class = json(&eval.join("per_class.json"));
    let rows = per_class.as_array().unwrap();
    let classes = rows.iter().filter(|r| r["strategy"] == "mdp").count() - 1;
    assert!(classes >= 1);
    assert_eq!(rows.len(), 6 * (classes + 1));
    for key in ["tp", "fp", "fn_"] {
        let of = |all: bool| -> u64 {
            rows.iter()
                .filter(|r| r["strategy"] == "mdp" && r["class"].is_null() == all)
                .map(|r| r[key].as_u64().unwrap())
                .sum()
        };
        assert_eq!(of(false), of(true), "{key}");
    }
    let kul = std::fs::read_to_string(eval.join("kul.md")).unwrap();
    assert!(
        kul.contains("\"Good Enough\"") && kul.contains("| **all** |"),
        "{kul}"
    );

    let bundle = run.join("bundle");
    frugal(&[
        "bundle",
        "write",
        "--policy",
        p(&policy_dir.join("policy.json")),
        "--out",
        p(&bundle),
    ])
    .unwrap();
    frugal(&["bundle", "verify", p(&bundle)]).unwrap();
    frugal(&["bundle", "inspect", p(&bundle)]).unwrap();

    let file = bundle.join("policy.frpb");
    let mut bytes = std::fs::read(&file).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 1;
    std::fs::write(&file, bytes).unwrap();
    let err = frugal(&["bundle", "verify", p(&bundle)]).unwrap_err();
    assert!(
        err.contains("policy.frpb") && err.contains("checksum"),
        "{err}"
    );

    // A variants file with an unknown key names the file and the key.
    std::fs::write(
        &variants,
        VARIANTS.replace("latency_ms = 3.0", "latency_ms = 3.0\nspeed = 1"),
    )
    .unwrap();
    let err = frugal(&[
        "policy",
        "record",
        "--data",
        p(&data),
        "--variants",
        p(&variants),
        "--out",
        p(&log),
    ])
    .unwrap_err();
    assert!(
        err.contains("variants.toml") && err.contains("speed"),
        "{err}"
    );
}
