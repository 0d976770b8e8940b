//! What `frugal-pilot` refuses before the first frame: a bundle whose graphs do not hash
//! to its record, a missing graph, a bad configuration file. Each is one line naming
//! the file, and a failure status.
use frugal_runtime::bundle::ScoreBuckets;
use frugal_runtime::bundle::Thresholds;
use frugal_runtime::bundle::write::{BundleWriter, FamilySpec, VariantSpec};
use sha2::{Digest, Sha256};
use std::path::Path;
use std::process::Command;

/// A bundle folder with one variant whose graph file holds `graph`, recorded with the
/// hash of `recorded`.
fn bundle(dir: &Path, graph: &[u8], recorded: &[u8]) {
    let onnx = dir.join("onnx/v0");
    std::fs::create_dir_all(&onnx).unwrap();
    std::fs::write(onnx.join("backbone_rpn.onnx"), graph).unwrap();
    let mut v = VariantSpec::new("v0", 0, 1.0, 1.0);
    v.onnx_file = "onnx/v0/backbone_rpn.onnx".into();
    v.sha256 = Sha256::digest(recorded).into();
    let bytes = BundleWriter::new(Thresholds {
        iou_threshold: 0.45,
        min_track_quality: 0.25,
        mdp_period: 90,
        reinit_period: 12,
        accesses_per_image: 1,
    })
    .family(FamilySpec {
        name: "cnn".into(),
        buckets: ScoreBuckets {
            c_opt: 0.9,
            c_ge: 0.6,
            c_ua: 0.3,
            t_c: 0.5,
        },
    })
    .variant(v)
    .policy(0, vec![0, 0, 0, 0])
    .finish()
    .unwrap();
    std::fs::write(dir.join("policy.frpb"), bytes).unwrap();
}

fn pilot(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_frugal-pilot"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_bundle_whose_graph_does_not_match_its_hash_is_refused_at_start() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("bundle");
    bundle(&dir, b"graph as shipped, then damaged", b"graph as shipped");
    let input = tmp.path().join("frames");
    std::fs::create_dir_all(&input).unwrap();
    let (ok, err) = pilot(&[
        "--bundle",
        dir.to_str().unwrap(),
        "--input",
        input.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("onnx/v0/backbone_rpn.onnx") && err.contains("does not match"),
        "{err}"
    );
    // and a graph the bundle names that is not there
    std::fs::remove_file(dir.join("onnx/v0/backbone_rpn.onnx")).unwrap();
    let (ok, err) = pilot(&[
        "--bundle",
        dir.to_str().unwrap(),
        "--input",
        input.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(
        err.contains("backbone_rpn.onnx") && err.contains("missing"),
        "{err}"
    );
}

#[test]
fn a_bad_configuration_file_is_one_line_naming_it() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("bundle");
    bundle(&dir, b"g", b"g");
    let config = tmp.path().join("pilot.toml");
    // each bad file: one line naming the file and what is wrong in it
    for (text, needles) in [
        ("[camera]\nwidht = 480\n", &["widht"][..]),
        ("[signs]\nsize_m = -1\n", &["size_m"][..]),
        (
            "[signs]\nactions = [\"none\", \"hover\"]\n",
            &["actions[1]", "hover"][..],
        ),
        (
            "[input]\nqueue = 0\n",
            &["queue must be between 1 and 8"][..],
        ),
    ] {
        std::fs::write(&config, text).unwrap();
        let (ok, err) = pilot(&[
            "--bundle",
            dir.to_str().unwrap(),
            "--input",
            "/dev/video99",
            "--config",
            config.to_str().unwrap(),
        ]);
        assert!(!ok, "{text}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.contains("pilot.toml"), "{err}");
        for n in needles {
            assert!(err.contains(n), "{text}: {err}");
        }
    }
}
