//! `frugal compress` and `frugal pareto` on a tiny generated dataset with a tiny model.
use super::{frugal, json, p, tiny_dataset, train_tiny};
use std::path::Path;

const GRID: &str = r#"
calibration_frames = 3
drift_frames = 2
calibration = { method = "entropy" }
[finetune]
steps = 2
frames = 6
[[variants]]
name = "base"
technique = { kind = "base" }
[[variants]]
name = "base-int8"
parent = "base"
technique = { kind = "int8", calibration = { method = "min_max" } }
[[variants]]
name = "mag50"
technique = { kind = "magnitude", sparsity = 0.5 }
[[variants]]
name = "ch50"
technique = { kind = "channels", keep = 0.5 }
[[variants]]
name = "drop2"
technique = { kind = "drop_blocks", blocks = [2] }
[[variants]]
name = "p5"
technique = { kind = "proposals", count = 5 }
[[variants]]
name = "res050"
technique = { kind = "resolution", scale = 0.5 }
[[variants]]
name = "res050-int8"
parent = "res050"
technique = { kind = "int8" }
"#;

#[test]
fn compress_then_pareto_on_a_tiny_model() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, model, vars, out) = (
        tmp.path().join("data"),
        tmp.path().join("model"),
        tmp.path().join("variants"),
        tmp.path().join("pareto"),
    );
    let cfg = tmp.path().join("tiny.toml");
    std::fs::write(&cfg, frugal::run::TINY_DETECTOR).unwrap();
    let grid = tmp.path().join("grid.toml");
    std::fs::write(&grid, GRID).unwrap();
    tiny_dataset(&data);
    train_tiny(&data, &cfg, &model, &[]);

    // a grid with an unknown field is refused, naming the file and the field
    let bad = tmp.path().join("bad.toml");
    std::fs::write(&bad, "[finetune]\nstepz = 1\n").unwrap();
    let e = frugal(&[
        "compress",
        "--model",
        p(&model),
        "--data",
        p(&data),
        "--out",
        p(&vars),
        "--config",
        p(&bad),
    ])
    .unwrap_err();
    assert!(e.contains("bad.toml") && e.contains("stepz"), "{e}");
    // pareto on a folder without variants says so
    let e = frugal(&[
        "pareto",
        "--variants",
        p(tmp.path()),
        "--data",
        p(&data),
        "--out",
        p(&out),
    ])
    .unwrap_err();
    assert!(e.contains("no variant folders"), "{e}");

    frugal(&[
        "compress",
        "--model",
        p(&model),
        "--data",
        p(&data),
        "--out",
        p(&vars),
        "--config",
        p(&grid),
        "--quiet",
    ])
    .unwrap();
    let names = [
        "base",
        "base-int8",
        "mag50",
        "ch50",
        "drop2",
        "p5",
        "res050",
        "res050-int8",
    ];
    for n in names {
        let rec = json(&vars.join(n).join("variant.json"));
        assert_eq!(rec["name"], n);
        for f in rec["files"].as_array().unwrap() {
            let file = vars.join(n).join(f["file"].as_str().unwrap());
            let bytes = std::fs::read(&file).unwrap();
            assert_eq!(f["bytes"], bytes.len());
            let sum = std::process::Command::new("sha256sum")
                .arg(&file)
                .output()
                .unwrap();
            let hex = String::from_utf8_lossy(&sum.stdout)
                .split(' ')
                .next()
                .unwrap()
                .to_string();
            assert_eq!(f["sha256"], hex, "{n}");
        }
    }
    let rec = |n: &str| json(&vars.join(n).join("variant.json"));
    let base_params = rec("base")["parameters"].as_u64().unwrap();
    // magnitude pruning keeps the parameter count but zeroes half of the weights
    let mag = rec("mag50");
    assert_eq!(mag["parameters"].as_u64().unwrap(), base_params);
    let nz = mag["nonzero_parameters"].as_u64().unwrap() as f64;
    assert!(
        nz < 0.56 * base_params as f64 && nz > 0.4 * base_params as f64,
        "{nz}"
    );
    // channel pruning and block removal make physically smaller models
    assert!(rec("ch50")["parameters"].as_u64().unwrap() < base_params / 2);
    assert!(rec("drop2")["parameters"].as_u64().unwrap() < base_params);
    assert_eq!(rec("p5")["parameters"].as_u64().unwrap(), base_params);
    // the resolution knob halves the exported input; int8 records its drift
    assert_eq!(
        rec("res050")["input_width"],
        rec("base")["input_width"].as_u64().unwrap() / 2
    );
    assert_eq!(
        rec("res050-int8")["input_width"],
        rec("res050")["input_width"]
    );
    let drift = &rec("base-int8")["drift"];
    assert!(
        drift["max_abs_diff"]["features"]
            .as_f64()
            .unwrap()
            .is_finite()
    );
    assert_eq!(rec("base-int8")["calibration"]["method"], "min_max");

    // four validation frames, one warm-up; `timed` of them timed; `more` flags
    let pareto = |out: &std::path::Path, timed: &str, more: &[&str]| {
        let mut args = vec![
            "pareto",
            "--variants",
            p(&vars),
            "--data",
            p(&data),
            "--out",
            p(out),
            "--frames",
            "4",
            "--timed-frames",
            timed,
            "--warmup",
            "1",
            "--quiet",
        ];
        args.extend_from_slice(more);
        frugal(&args)
    };
    pareto(&out, "0", &[]).unwrap();
    let report = json(&out.join("pareto.json"));
    let vs = report["variants"].as_array().unwrap();
    assert_eq!(vs.len(), names.len());
    for metric in ["map", "f1", "iou"] {
        let front = report["fronts"][metric].as_array().unwrap();
        assert!(!front.is_empty());
        for v in vs {
            let on = front.iter().any(|f| f == &v["name"]);
            assert_eq!(v["on_front"][metric], on);
            // on the front exactly when nothing dominates it
            assert_eq!(
                on,
                v["dominated_by"][metric].as_array().unwrap().is_empty(),
                "{metric} {}",
                v["name"]
            );
        }
        for ext in ["png", "svg"] {
            assert!(out.join(format!("pareto_{metric}.{ext}")).is_file());
        }
    }
    for v in vs {
        assert!(v["latency"]["median_ms"].as_f64().unwrap() > 0.0);
        let conf = v["confidence"].as_object().unwrap();
        let frames: u64 = conf.values().map(|h| h["frames"].as_u64().unwrap()).sum();
        assert_eq!(frames, 4);
    }
    let csv = std::fs::read_to_string(out.join("pareto.csv")).unwrap();
    assert_eq!(csv.lines().count(), names.len() + 1);
    // the variants file lists the mAP front in the shape `frugal policy record` reads
    let vf = json(&out.join("variants.json"));
    let listed = vf["variants"].as_array().unwrap();
    assert_eq!(
        listed.len(),
        report["fronts"]["map"].as_array().unwrap().len()
    );
    for v in listed {
        assert_eq!(v["family"], "cnn");
        assert_eq!(v["source"]["kind"], "onnx");
        assert!(
            Path::new(v["source"]["dir"].as_str().unwrap())
                .join("backbone_rpn.onnx")
                .is_file()
        );
        assert!(v["latency_ms"].as_f64().unwrap() > 0.0);
        // each says its arithmetic, which the device profile's speeds scale by
        let int8 = rec(v["name"].as_str().unwrap())["int8"].as_bool().unwrap();
        assert_eq!(v["precision"], if int8 { "int8" } else { "fp32" });
    }
    // both reference detectors' costs, as the report has them
    assert_eq!(vf["reference_ms"], report["reference"]["min_ms"]);
    assert_eq!(vf["reference_int8_ms"], report["reference_int8"]["min_ms"]);
    assert_eq!(report["timed_frames"], 4);
    // every timed run is kept, frame by frame, and summarised as reported
    let t = json(&out.join("timings.json"));
    assert_eq!(t["frames"], serde_json::json!([0, 1, 2, 3]));
    assert_eq!(t["reference_ms"].as_array().unwrap().len(), 4);
    assert_eq!(t["reference_int8_ms"].as_array().unwrap().len(), 4);
    let fastest = |runs: &serde_json::Value| {
        runs.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .fold(f64::INFINITY, f64::min)
    };
    assert_eq!(fastest(&t["reference_ms"]), report["reference"]["min_ms"]);
    assert_eq!(
        fastest(&t["reference_int8_ms"]),
        report["reference_int8"]["min_ms"]
    );
    for v in vs {
        let runs = &t["variants"][v["name"].as_str().unwrap()];
        assert_eq!(runs.as_array().unwrap().len(), 4, "{}", v["name"]);
        assert_eq!(fastest(runs), v["latency"]["min_ms"], "{}", v["name"]);
    }

    // timing one frame and scoring the other three on every core changes the timings
    // only: every variant's accuracy and confidences are those of the all-timed pass
    let out1 = tmp.path().join("pareto-timed1");
    pareto(&out1, "1", &[]).unwrap();
    let r1 = json(&out1.join("pareto.json"));
    assert_eq!(
        (r1["frames"].as_u64(), r1["timed_frames"].as_u64()),
        (Some(4), Some(1))
    );
    for (a, b) in vs.iter().zip(r1["variants"].as_array().unwrap()) {
        assert_eq!(a["name"], b["name"]);
        assert_eq!(b["latency"]["runs"], 1, "{}", b["name"]);
        for key in ["map", "f1", "mean_iou", "precision", "recall", "confidence"] {
            assert_eq!(a[key], b[key], "{} {key}", a["name"]);
        }
        // without a device the fronts are drawn on this machine's latencies
        assert!(b["device_ms"].is_null(), "{}", b["name"]);
    }
    assert!(r1["device"].is_null() && r1["slowdowns"].is_null());

    // on a device: every variant's cost scaled by its precision's slowdown, the
    // device's reference over this machine's, and the front drawn on those costs
    let e = pareto(&out1, "1", &["--device-reference-ms", "194.4"]).unwrap_err();
    assert!(e.contains("--device-reference-int8-ms"), "{e}");
    let out2 = tmp.path().join("pareto-device");
    pareto(
        &out2,
        "1",
        &[
            "--device-reference-ms",
            "194.4",
            "--device-reference-int8-ms",
            "140.1",
        ],
    )
    .unwrap();
    let r2 = json(&out2.join("pareto.json"));
    let ms = |v: &serde_json::Value| v.as_f64().unwrap();
    let fp32 = 194.4 / ms(&r2["reference"]["min_ms"]);
    let int8 = 140.1 / ms(&r2["reference_int8"]["min_ms"]);
    assert!((ms(&r2["slowdowns"][0]) - fp32).abs() < 1e-9 * fp32);
    assert!((ms(&r2["slowdowns"][1]) - int8).abs() < 1e-9 * int8);
    assert_eq!(r2["device"]["reference_int8_ms"], 140.1);
    let vs2 = r2["variants"].as_array().unwrap();
    for v in vs2 {
        let is_int8 = rec(v["name"].as_str().unwrap())["int8"].as_bool().unwrap();
        assert_eq!(v["int8"], is_int8);
        let k = if is_int8 { int8 } else { fp32 };
        let want = ms(&v["latency"]["min_ms"]) * k;
        assert!(
            (ms(&v["device_ms"]) - want).abs() < 1e-9 * want,
            "{}",
            v["name"]
        );
        let noise = ms(&v["latency_noise_ms"]) * k;
        assert!((ms(&v["device_noise_ms"]) - noise).abs() < 1e-9 * noise);
    }
    // the map front, fastest first on the device, is what the variants file lists
    let front: Vec<&str> = r2["fronts"]["map"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect();
    let device_ms = |n: &str| ms(&vs2.iter().find(|v| v["name"] == n).unwrap()["device_ms"]);
    assert!(
        front.windows(2).all(|w| device_ms(w[0]) <= device_ms(w[1])),
        "{front:?}"
    );
    let vf2 = json(&out2.join("variants.json"));
    let listed: Vec<&str> = vf2["variants"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["name"].as_str().unwrap())
        .collect();
    assert_eq!(listed, front);
    let csv = std::fs::read_to_string(out2.join("pareto.csv")).unwrap();
    assert!(csv.lines().next().unwrap().ends_with(",int8,device_ms"));
}
