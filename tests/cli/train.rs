//! `frugal train` and `frugal eval` on a tiny generated dataset with a tiny model.
use super::{frugal, json, p, tiny_dataset, train_tiny};

/// Per epoch of a training's `state.json`, whether it was validated.
fn validated(state: &serde_json::Value) -> Vec<bool> {
    state["history"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["val_map"].is_f64())
        .collect()
}

#[test]
fn train_resume_and_eval_on_a_tiny_dataset() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let out = tmp.path().join("model");
    let cfg = tmp.path().join("tiny.toml");
    std::fs::write(&cfg, frugal::run::TINY_DETECTOR).unwrap();
    tiny_dataset(&data);

    // an interrupted run (one epoch), then --resume finishes it
    train_tiny(&data, &cfg, &out, &["--stop-after", "1"]);
    let state = json(&out.join("checkpoint/state.json"));
    assert_eq!(state["epochs_done"], 1);
    frugal(&[
        "train",
        "--data",
        p(&data),
        "--out",
        p(&out),
        "--resume",
        "--quiet",
    ])
    .unwrap();
    let state: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("checkpoint/state.json")).unwrap()).unwrap();
    assert_eq!(state["epochs_done"], 2);
    assert_eq!(state["history"].as_array().unwrap().len(), 2);
    // a finished run can be extended by a larger epoch count
    frugal(&[
        "train",
        "--data",
        p(&data),
        "--out",
        p(&out),
        "--resume",
        "--epochs",
        "3",
        "--quiet",
    ])
    .unwrap();
    let state: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("checkpoint/state.json")).unwrap()).unwrap();
    assert_eq!(state["epochs_done"], 3);
    for f in [
        "best.safetensors",
        "config.json",
        "curves.csv",
        "curves.png",
        "curves.svg",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }

    // the run stopped after epoch 1 and the last epochs validate whatever val_every says
    assert_eq!(validated(&state), [true, true, true]);
    // uninterrupted, val_every = 2 skips epoch 1's validation: epochs 2 and 3 (the
    // last) are validated, the best model is one of them, the CSV leaves the cell empty
    let out3 = tmp.path().join("model3");
    train_tiny(&data, &cfg, &out3, &["--epochs", "3"]);
    let state3 = json(&out3.join("checkpoint/state.json"));
    assert_eq!(validated(&state3), [false, true, true]);
    assert!(
        matches!(state3["best_epoch"].as_u64(), Some(2 | 3)),
        "{state3}"
    );
    let csv = std::fs::read_to_string(out3.join("curves.csv")).unwrap();
    let cells: Vec<&str> = csv.lines().nth(1).unwrap().split(',').collect();
    assert_eq!(cells[7], "", "{csv}");

    let ev = tmp.path().join("eval");
    frugal(&[
        "eval",
        "--model",
        p(&out),
        "--data",
        p(&data),
        "--split",
        "test",
        "--out",
        p(&ev),
        "--quiet",
    ])
    .unwrap();
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(ev.join("report.json")).unwrap()).unwrap();
    let map = report["overall"]["map"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&map));
    assert_eq!(report["classes"].as_array().unwrap().len(), 10);
    assert_eq!(report["overall"]["confusion"].as_array().unwrap().len(), 11);
    // the tiny dataset has every clutter × light combination in its test split
    assert_eq!(report["scenarios"].as_object().unwrap().len(), 6);
    assert!(
        std::fs::read_to_string(ev.join("report.txt"))
            .unwrap()
            .contains("mAP@0.5")
    );
}

#[test]
fn bad_inputs_give_errors_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = tmp.path().join("typo.toml");
    std::fs::write(&cfg, "[train]\nepochz = 2\n").unwrap();
    let err = frugal(&[
        "train",
        "--data",
        p(tmp.path()),
        "--config",
        p(&cfg),
        "--out",
        p(&tmp.path().join("o")),
    ])
    .unwrap_err();
    let msg = err;
    assert!(msg.contains("typo.toml") && msg.contains("epochz"), "{msg}");

    let model = tmp.path().join("model");
    std::fs::create_dir_all(&model).unwrap();
    std::fs::write(model.join("config.json"), "{}").unwrap();
    std::fs::write(model.join("best.safetensors"), b"garbage").unwrap();
    let msg = frugal(&["eval", "--model", p(&model), "--data", p(tmp.path())]).unwrap_err();
    assert!(msg.contains("best.safetensors"), "{msg}");
}
