//! Data frugal did not draw: the whole pipeline on a real video (TUD-Campus, MOT
//! format), datasets with class lists of their own (3 and 37 classes), and full-HD
//! frames trained at a smaller input size without a manual resize.
use super::{frugal, json, p, tiny_dataset};
use std::path::{Path, PathBuf};

/// `../shared/data/tud-campus` (CC BY-NC-SA 3.0, not in the repository), if present.
fn tud_campus() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/tud-campus");
    if dir.join("gt/gt.txt").is_file() {
        Some(dir)
    } else {
        eprintln!("skipped: {} is absent", dir.display());
        None
    }
}

/// A tiny-profile run config importing `import` (a TOML `[import]` body) with extra
/// sections `more`.
fn run_config(dir: &Path, import: &str, more: &str) -> PathBuf {
    let path = dir.join("run.toml");
    std::fs::write(
        &path,
        format!("profile = \"tiny\"\n[import]\n{import}\n{more}"),
    )
    .expect("write config");
    path
}

fn run(config: &Path, out: &Path, until: Option<&str>) {
    let mut args = vec!["run", "--quiet", "--out", p(out), p(config)];
    if let Some(u) = until {
        args.extend(["--until", u]);
    }
    frugal(&args).unwrap_or_else(|e| panic!("frugal run {}: {e}", config.display()));
}

/// The classes the run's model was trained for (its saved config).
fn model_classes(run: &Path) -> u64 {
    json(&run.join("detector/model/config.json"))["model"]["num_classes"]
        .as_u64()
        .expect("num_classes")
}

#[test]
fn tud_campus_runs_every_stage_to_a_verified_bundle_and_skips_the_maze_flights() {
    let Some(tud) = tud_campus() else { return };
    let tmp = tempfile::tempdir().expect("tempdir");
    let gt = tud.join("gt/gt.txt");
    let config = run_config(
        tmp.path(),
        &format!(
            "format = \"mot\"\nannotations = {:?}\nfps = 25.0\ntime_split = [0.7, 0.15, 0.15]\nactions = {{ pedestrian = \"wait\" }}",
            p(&gt)
        ),
        "[detector.model]\ninput_size = [160, 120]\nanchor_sizes = [24.0, 48.0]\nanchor_ratios = [2.0]\n",
    );
    let out = tmp.path().join("run");
    run(&config, &out, None);
    let manifest = json(&out.join("data/dataset/manifest.json"));
    assert_eq!(manifest["counts"]["train"]["frames"], 50);
    assert_eq!(manifest["counts"]["val"]["frames"], 11);
    assert_eq!(manifest["counts"]["test"]["frames"], 10);
    assert_eq!(manifest["classes"][0]["name"], "pedestrian");
    assert_eq!(manifest["classes"][0]["action"], "wait");
    assert_eq!(model_classes(&out), 1);
    let model = json(&out.join("detector/model/config.json"));
    assert_eq!(model["model"]["input_size"], serde_json::json!([160, 120]));
    // every stage ran; the bundle verifies; the flights say why they did not fly
    for stage in [
        "detector",
        "variants",
        "pareto",
        "replay",
        "policy",
        "evaluation",
        "budget",
    ] {
        assert!(out.join(stage).join(".stamp.json").is_file(), "{stage}");
    }
    frugal(&["bundle", "verify", p(&out.join("bundle"))]).expect("bundle verifies");
    let why = std::fs::read_to_string(out.join("flights/skipped.txt")).expect("skipped.txt");
    assert!(why.contains("pedestrian") && why.contains("signs"), "{why}");
    let report = std::fs::read_to_string(out.join("report.md")).expect("report");
    assert!(report.contains("Pareto"), "the report covers the run");

    // the imported set exports as COCO with videos and MOT, and both import back
    let data = out.join("data/dataset");
    let cv = tmp.path().join("export-cv");
    frugal(&[
        "data",
        "export",
        "--format",
        "coco-video",
        p(&data),
        "--out",
        p(&cv),
    ])
    .expect("export coco-video");
    let back = tmp.path().join("back-cv");
    frugal(&[
        "data",
        "import",
        "--quiet",
        "--format",
        "coco-video",
        p(&cv.join("annotations.json")),
        "--out",
        p(&back),
    ])
    .expect("import coco-video");
    let counts = &json(&back.join("manifest.json"))["counts"];
    let total = |what: &str| -> u64 {
        ["train", "val", "test"]
            .iter()
            .map(|s| counts[s][what].as_u64().expect("count"))
            .sum()
    };
    assert_eq!((total("frames"), total("objects")), (71, 359));
    let mot = tmp.path().join("export-mot");
    frugal(&[
        "data",
        "export",
        "--format",
        "mot",
        "--split",
        "test",
        p(&data),
        "--out",
        p(&mot),
    ])
    .expect("export mot");
    let seqs: Vec<PathBuf> = std::fs::read_dir(&mot)
        .expect("mot folder")
        .map(|e| e.expect("entry").path())
        .collect();
    assert_eq!(seqs.len(), 1, "one test video: {seqs:?}");
    let back = tmp.path().join("back-mot");
    frugal(&[
        "data",
        "import",
        "--quiet",
        "--format",
        "mot",
        p(&seqs[0].join("gt/gt.txt")),
        "--split",
        "test",
        "--out",
        p(&back),
    ])
    .expect("import mot");
    let counts = &json(&back.join("manifest.json"))["counts"]["test"];
    assert_eq!(counts["frames"], 10);
}

/// The tiny synthetic set generated under `dir` and exported as COCO; returns the
/// annotation file (frames beside it).
fn tiny_coco(dir: &Path) -> PathBuf {
    let data = dir.join("synthetic");
    tiny_dataset(&data);
    let coco = dir.join("coco");
    frugal(&[
        "data",
        "export",
        "--format",
        "coco",
        p(&data),
        "--out",
        p(&coco),
    ])
    .expect("export");
    coco.join("annotations.json")
}

/// The tiny synthetic set exported as COCO, with its categories renamed by `rename`
/// (category id, annotation id) → class name, and the category list rebuilt.
fn coco_with_classes(dir: &Path, rename: impl Fn(u64, u64) -> String) -> PathBuf {
    let path = tiny_coco(dir);
    let mut v = json(&path);
    let mut names: Vec<String> = Vec::new();
    for a in v["annotations"].as_array_mut().expect("annotations") {
        let name = rename(
            a["category_id"].as_u64().expect("cat"),
            a["id"].as_u64().expect("id"),
        );
        let id = match names.iter().position(|n| *n == name) {
            Some(i) => i,
            None => {
                names.push(name);
                names.len() - 1
            }
        };
        a["category_id"] = id.into();
    }
    // category ids from 0 (valid in COCO), in first-use order
    v["categories"] = names
        .iter()
        .enumerate()
        .map(|(i, n)| serde_json::json!({ "id": i, "name": n }))
        .collect();
    std::fs::write(&path, serde_json::to_vec(&v).expect("json")).expect("write");
    path
}

#[test]
fn user_class_lists_of_3_and_37_classes_train_evaluate_export_and_bundle() {
    for (k, classes) in [(3u64, 3usize), (37, 37)] {
        let tmp = tempfile::tempdir().expect("tempdir");
        let coco = coco_with_classes(tmp.path(), |_, ann| format!("user_class_{:02}", ann % k));
        let config = run_config(
            tmp.path(),
            &format!(
                "format = \"coco\"\nannotations = {:?}\nclasses = \"source\"",
                p(&coco)
            ),
            // a two-epoch model spread over 37 classes may detect nothing on the few
            // validation frames, and the confidence calibration needs detections
            "[replay]\ncalibrate = false\n",
        );
        let out = tmp.path().join("run");
        run(&config, &out, Some("bundle"));
        let manifest = json(&out.join("data/dataset/manifest.json"));
        assert_eq!(
            manifest["classes"].as_array().expect("classes").len(),
            classes
        );
        assert_eq!(model_classes(&out), classes as u64);
        // the exported graphs know the class count; the test split was scored
        let onnx = std::fs::read(out.join("variants/base/roi_head.onnx")).expect("roi_head.onnx");
        // the graph's metadata entry `frugal.num_classes` = the class count
        let (key, value) = ("frugal.num_classes", classes.to_string());
        let at = onnx
            .windows(key.len())
            .position(|w| w == key.as_bytes())
            .expect("metadata key");
        let after = &onnx[at + key.len()..(at + key.len() + 8).min(onnx.len())];
        assert!(
            after.windows(value.len()).any(|w| w == value.as_bytes()),
            "{classes} classes: metadata {after:?}"
        );
        let eval = json(&out.join("detector/eval-test/report.json"));
        assert!(
            eval["overall"]["map"].as_f64().is_some(),
            "{classes} classes: {eval}"
        );
        frugal(&["bundle", "verify", p(&out.join("bundle"))]).expect("bundle verifies");
    }
}

#[test]
fn full_hd_frames_train_and_evaluate_at_a_smaller_input_with_boxes_in_source_pixels() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let path = tiny_coco(tmp.path());
    let coco = path.parent().expect("coco folder").to_owned();
    // every frame enlarged to 1920×1080 and every box with it
    let mut v = json(&path);
    let (mut sx, mut sy) = (0.0, 0.0);
    for img in v["images"].as_array_mut().expect("images") {
        let file = coco.join(img["file_name"].as_str().expect("file"));
        let small = image::open(&file).expect("frame").to_rgb8();
        sx = 1920.0 / f64::from(small.width());
        sy = 1080.0 / f64::from(small.height());
        image::imageops::resize(&small, 1920, 1080, image::imageops::FilterType::Nearest)
            .save(&file)
            .expect("save");
        img["width"] = 1920.into();
        img["height"] = 1080.into();
    }
    for a in v["annotations"].as_array_mut().expect("annotations") {
        let b: Vec<f64> = serde_json::from_value(a["bbox"].clone()).expect("bbox");
        a["bbox"] = serde_json::json!([b[0] * sx, b[1] * sy, b[2] * sx, b[3] * sy]);
    }
    std::fs::write(&path, serde_json::to_vec(&v).expect("json")).expect("write");
    let config = run_config(
        tmp.path(),
        &format!("format = \"coco\"\nannotations = {:?}", p(&path)),
        "",
    );
    let out = tmp.path().join("run");
    run(&config, &out, Some("detector"));
    let manifest = json(&out.join("data/dataset/manifest.json"));
    assert_eq!(
        manifest["counts"]["test"]["videos"].as_u64().map(|n| n > 0),
        Some(true)
    );
    // no input size configured: the 1920×1080 frames train at 640×360
    let model = json(&out.join("detector/model/config.json"));
    assert_eq!(model["model"]["input_size"], serde_json::json!([640, 360]));
    // evaluation ran on the full-HD test frames (boxes in their pixels)
    let eval = json(&out.join("detector/eval-test/report.json"));
    assert!(eval["overall"]["map"].as_f64().is_some(), "{eval}");
}
