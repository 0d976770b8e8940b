//! `frugal features train|eval|proposals` on the tiny data profile.
use super::{frugal, json, p, tiny_dataset};
use std::path::PathBuf;

/// A temporary folder with the tiny dataset in `data/`, and the output folder `name/`.
fn tiny(name: &str) -> (tempfile::TempDir, PathBuf, PathBuf) {
    let tmp = tempfile::tempdir().expect("tempdir");
    let data = tmp.path().join("data");
    tiny_dataset(&data);
    let out = tmp.path().join(name);
    (tmp, data, out)
}

#[test]
fn train_eval_and_proposal_recall_on_the_tiny_profile() {
    let (tmp, data, out) = tiny("hog");
    frugal(&[
        "features",
        "train",
        "--data",
        p(&data),
        "--out",
        p(&out),
        "--stride",
        "1",
        "--params",
        "200,2,8,9",
        "--params",
        "<100,1,12,6>",
        "--quiet",
    ])
    .expect("train");
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("model.json")).expect("model file"))
            .expect("json");
    assert_eq!(model["classes"].as_array().map(Vec::len), Some(10));
    assert_eq!(model["hogs"].as_array().map(Vec::len), Some(2));

    let report = tmp.path().join("eval.json");
    frugal(&[
        "features",
        "eval",
        "--model",
        p(&out),
        "--data",
        p(&data),
        "--stride",
        "1",
        "--params",
        "200,2,8,9",
        "--params",
        "100,1,12,6",
        "--out",
        p(&report),
    ])
    .expect("eval");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("json");
    let reports = v.as_array().expect("a list of reports");
    assert_eq!(reports.len(), 2);
    assert_eq!(reports[0]["params"], "<200,2,8,9>");
    assert_eq!(reports[0]["per_class"].as_array().map(Vec::len), Some(10));
    // Every sign of the split is a hit or a miss.
    let signs: u64 = reports[0]["per_class"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["tp"].as_u64().unwrap() + c["missed"].as_u64().unwrap())
        .sum();
    assert!(signs > 0);
    assert!(reports[0]["mean_ms"].as_f64().unwrap() > 0.0);

    frugal(&[
        "features",
        "proposals",
        "--data",
        p(&data),
        "--stride",
        "1",
        "--counts",
        "10,100",
    ])
    .expect("proposals");
}

#[test]
fn bad_inputs_are_one_line_errors() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let model = tmp.path().join("model.json");
    std::fs::write(&model, "{\"format\": 1, \"classes\": [").unwrap();
    let err = frugal(&[
        "features",
        "eval",
        "--model",
        p(&model),
        "--data",
        p(tmp.path()),
    ])
    .unwrap_err();
    assert!(
        err.contains("model.json") && err.contains("not a valid frugal-features model"),
        "{err}"
    );

    let err = frugal(&[
        "features",
        "train",
        "--data",
        p(tmp.path()),
        "--out",
        p(tmp.path()),
        "--params",
        "1000,2,8",
    ])
    .unwrap_err();
    assert!(err.contains("1000,2,8"), "{err}");

    let err = frugal(&[
        "features",
        "proposals",
        "--data",
        p(&tmp.path().join("missing")),
    ])
    .unwrap_err();
    assert!(err.contains("missing"), "{err}");
}

#[test]
fn grid_front_holds_no_dominated_tuple() {
    let (_tmp, data, out) = tiny("grid");
    let grid = |split: &str, extra: &[&str]| {
        let mut args = vec![
            "features",
            "grid",
            "--data",
            p(&data),
            "--out",
            p(&out),
            "--split",
            split,
        ];
        args.extend_from_slice(extra);
        frugal(&args)
    };
    grid(
        "val",
        &[
            "--stride",
            "1",
            "--train-stride",
            "1",
            "--proposals",
            "20,100",
            "--blocks",
            "1,2",
            "--cells",
            "8",
            "--bins",
            "6,9",
            "--quiet",
        ],
    )
    .expect("grid");
    for f in [
        "model.json",
        "grid.json",
        "grid.csv",
        "grid.png",
        "grid.svg",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let v = json(&out.join("grid.json"));
    let points = v["points"].as_array().expect("points");
    assert_eq!(points.len(), 2 * 2 * 2);
    let at = |i: usize| {
        (
            points[i]["f1"].as_f64().unwrap(),
            points[i]["ms_per_frame"].as_f64().unwrap(),
        )
    };
    let front: Vec<usize> = v["front"]
        .as_array()
        .expect("front")
        .iter()
        .map(|i| i.as_u64().unwrap() as usize)
        .collect();
    assert!(!front.is_empty());
    for i in 0..points.len() {
        let (f1, ms) = at(i);
        assert!(ms > 0.0 && (0.0..=1.0).contains(&f1));
        let dominated = (0..points.len()).any(|j| {
            let (g, t) = at(j);
            g >= f1 && t <= ms && (g > f1 || t < ms)
        });
        // On the front exactly when nothing dominates it.
        assert_eq!(front.contains(&i), !dominated, "tuple {i}: {:?}", points[i]);
        assert_eq!(points[i]["on_front"].as_bool(), Some(!dominated));
    }
    let csv = std::fs::read_to_string(out.join("grid.csv")).expect("csv");
    assert_eq!(csv.lines().count(), 1 + points.len());
    // The train split is refused: the grid is scored on held-out frames only.
    let err = grid("train", &[]).unwrap_err();
    assert!(err.contains("held-out"), "{err}");
}
