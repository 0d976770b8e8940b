//! `frugal data generate|summary|show|import|export` and `frugal run` (data stage) on
//! the tiny profile.
use super::{frugal, json, p};
use std::path::{Path, PathBuf};

fn count(v: &serde_json::Value, key: &str) -> usize {
    v[key].as_array().map_or(0, Vec::len)
}

#[test]
fn generate_show_export_import_and_summary_on_the_tiny_profile() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let data = tmp.path().join("data");
    frugal(&[
        "data",
        "generate",
        "--profile",
        "tiny",
        "--seed",
        "5",
        "--out",
        p(&data),
        "--quiet",
    ])
    .expect("generate");
    let manifest = json(&data.join("manifest.json"));
    assert_eq!(manifest["format"], "frugal-data");
    assert_eq!(manifest["source"]["config"]["seed"], 5);
    assert_eq!(count(&manifest, "classes"), 10);
    assert_eq!(count(&manifest, "videos"), 18);
    let frames: usize = ["train", "val", "test"]
        .iter()
        .map(|s| count(&json(&data.join(format!("annotations/{s}.json"))), "images"))
        .sum();
    assert_eq!(frames, 54);
    frugal(&["data", "summary", p(&data)]).expect("summary");
    frugal(&["data", "summary", p(&data), "--json"]).expect("summary json");

    // Pictures for people.
    let shown = tmp.path().join("shown");
    let sheet = tmp.path().join("sheet.png");
    frugal(&[
        "data",
        "show",
        p(&data),
        "--out",
        p(&shown),
        "--frames",
        "3",
        "--split",
        "val",
        "--sheet",
        p(&sheet),
    ])
    .expect("show");
    assert_eq!(std::fs::read_dir(&shown).expect("shown").count(), 3);
    let size = |path: &Path| {
        let bytes = std::fs::read(path).expect("png");
        assert_eq!(&bytes[1..4], b"PNG");
        let be =
            |i: usize| u32::from_be_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
        (be(16), be(20))
    };
    assert_eq!(
        size(&sheet),
        (4 * 242 + 2, 3 * 137 + 2),
        "4×3 grid of 240×135 thumbnails"
    );
    assert!(
        frugal(&["data", "show", p(&data)])
            .expect_err("nothing to do")
            .contains("--sheet")
    );

    // Export the test split to COCO and import it back.
    let coco = tmp.path().join("coco");
    frugal(&[
        "data",
        "export",
        "--format",
        "coco",
        p(&data),
        "--out",
        p(&coco),
        "--split",
        "test",
    ])
    .expect("export");
    let exported = json(&coco.join("annotations.json"));
    assert_eq!(count(&exported, "images"), 18);
    assert_eq!(
        exported["categories"][0]["id"], 1,
        "category_id = class id + 1"
    );
    let back = tmp.path().join("back");
    frugal(&[
        "data",
        "import",
        "--format",
        "coco",
        p(&coco.join("annotations.json")),
        "--out",
        p(&back),
    ])
    .expect("import");
    let test_before = json(&data.join("annotations/test.json"));
    let test_after = json(&back.join("annotations/test.json"));
    assert_eq!(test_before["annotations"], test_after["annotations"]);
    assert_eq!(
        count(&json(&back.join("annotations/train.json")), "images"),
        0
    );
}

#[test]
fn bad_input_gives_one_clear_error_and_leaves_the_output_alone() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let csv = tmp.path().join("gt.txt");
    std::fs::write(&csv, "a.ppm;1;2;30;40;stop\nb.ppm;1;2;3\n").expect("write");
    let out = tmp.path().join("out");
    let err = frugal(&[
        "data",
        "import",
        "--format",
        "gtsdb",
        p(&csv),
        "--out",
        p(&out),
    ])
    .expect_err("bad csv");
    assert!(err.contains("gt.txt") && err.contains("line 2"), "{err}");
    assert!(!out.exists());

    let config = tmp.path().join("gen.toml");
    std::fs::write(&config, "seed = 1\nvideo_count = 3\n").expect("write");
    let err = frugal(&["data", "generate", "--config", p(&config), "--out", p(&out)])
        .expect_err("unknown key");
    assert!(
        err.contains("gen.toml") && err.contains("video_count"),
        "{err}"
    );

    let err = frugal(&["data", "summary", p(&tmp.path().join("nowhere"))]).expect_err("no dataset");
    assert!(err.contains("manifest.json"), "{err}");
    assert!(!out.exists());
}

fn mtime(path: PathBuf) -> std::time::SystemTime {
    std::fs::metadata(path)
        .and_then(|m| m.modified())
        .expect("mtime")
}

#[test]
fn run_generates_the_data_stage_once_and_then_reuses_it() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let run = tmp.path().join("run");
    let until_data = |extra: &[&str]| {
        let mut args = vec![
            "run",
            "--out",
            p(&run),
            "--tiny",
            "--quiet",
            "--until",
            "data",
        ];
        args.extend_from_slice(extra);
        frugal(&args)
    };
    until_data(&[]).expect("first run");
    let manifest = run.join("data/dataset/manifest.json");
    let first = mtime(manifest.clone());
    let hash = json(&manifest)["source"]["config_hash"].clone();
    assert!(hash.as_str().is_some_and(|h| h.len() == 64));
    assert!(!run.join("detector").exists(), "--until data stops there");
    until_data(&[]).expect("second run");
    assert_eq!(
        mtime(manifest.clone()),
        first,
        "identical config: dataset reused, not rewritten"
    );
    let cfg = tmp.path().join("seed.toml");
    std::fs::write(&cfg, "profile = \"tiny\"\n[data]\nseed = 99\n").expect("write");
    until_data(&[p(&cfg)]).expect("another seed");
    assert_ne!(
        json(&manifest)["source"]["config_hash"],
        hash,
        "another config regenerates"
    );
}
