//! `frugal fly`: closed-loop flights through the shipped easy maze with ground-truth
//! perception at a small camera size, and its clear failures.
use super::{frugal, json, maze, p};

/// `frugal fly` with ground truth at 25 fps on the host and a 160×90 camera, quiet,
/// plus `args`.
pub(crate) fn small_flight<'a>(args: &[&'a str]) -> Vec<&'a str> {
    let mut all = vec![
        "fly",
        "--width",
        "160",
        "--height",
        "90",
        "--device",
        "host",
        "--gt-compute-ms",
        "40",
        "--quiet",
    ];
    all.extend_from_slice(args);
    all
}

#[test]
fn fly_easy_maze_writes_table_files_plots_and_frames() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let out = tmp.path().join("fly");
    frugal(&small_flight(&[
        "--maze",
        p(&maze("easy.maze")),
        "--seeds",
        "2",
        "--frames-every",
        "200",
        "--gif",
        "--gif-every",
        "100",
        "--out",
        p(&out),
    ]))
    .expect("fly");
    let dir = out.join("easy");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).expect("summary"))
            .expect("json");
    assert_eq!(summary["runs"], 2);
    assert_eq!(summary["successes"], 2);
    assert_eq!(summary["collisions"], 0);
    // 40 ms per frame on the host profile: 25 fps.
    let fps = summary["fps"]["mean"].as_f64().expect("fps");
    assert!((fps - 25.0).abs() < 0.01, "{fps}");
    let flights: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("flights.json")).expect("flights"))
            .expect("json");
    let seeds: Vec<_> = flights
        .as_array()
        .expect("array")
        .iter()
        .map(|f| f["seed"].as_u64())
        .collect();
    assert_eq!(seeds, [Some(1), Some(2)]);
    let csv = std::fs::read_to_string(dir.join("flights.csv")).expect("csv");
    assert_eq!(csv.lines().count(), 3);
    assert!(csv.lines().nth(1).expect("row").contains(",success,"));
    for file in [
        "top_view.png",
        "top_view.svg",
        "flight.gif",
        "frames/frame_000000.png",
        "frames/frame_000200.png",
    ] {
        let len = std::fs::metadata(dir.join(file))
            .map(|m| m.len())
            .unwrap_or(0);
        assert!(len > 100, "{file} missing or empty");
    }
    let svg = std::fs::read_to_string(dir.join("top_view.svg")).expect("svg");
    assert!(
        svg.contains("seed 1") && svg.contains("STOP"),
        "legend and sign labels"
    );
    // A GIF89a at half the camera size (logical screen size, little-endian).
    let gif = std::fs::read(dir.join("flight.gif")).expect("gif");
    assert_eq!(&gif[..6], b"GIF89a");
    assert_eq!(
        (
            u16::from_le_bytes([gif[6], gif[7]]),
            u16::from_le_bytes([gif[8], gif[9]])
        ),
        (80, 45)
    );
    assert_eq!(gif.last(), Some(&0x3b), "GIF trailer written");
    assert!(out.join("summary.json").exists());
}

#[test]
fn fly_reports_bad_maze_lines_and_unknown_devices() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let bad = tmp.path().join("bad.maze");
    std::fs::write(
        &bad,
        "start 1 1 east\ngoal 2 1\nsign yield 1 1 n 1.2\nmap\n####\n#..#\n####\nend\n",
    )
    .expect("write");
    let e = frugal(&["fly", "--maze", p(&bad), "--quiet"]).expect_err("bad maze");
    assert!(
        e.contains("bad.maze:3:") && e.contains("unknown sign `yield`"),
        "{e}"
    );
    let e = frugal(&[
        "fly",
        "--maze",
        p(&maze("easy.maze")),
        "--device",
        "pdp11",
        "--quiet",
    ])
    .expect_err("device");
    assert!(e.contains("unknown device profile `pdp11`"), "{e}");
    let e = frugal(&[
        "fly",
        "--maze",
        p(&maze("easy.maze")),
        "--carry",
        "good-enough",
        "--quiet",
    ])
    .expect_err("carry without the adaptive runtime");
    assert!(e.contains("--carry") && e.contains("adaptive"), "{e}");
    for s in ["--slowdown-int8=0", "--slowdown-int8=inf"] {
        let e = frugal(&["fly", "--maze", p(&maze("easy.maze")), s, "--quiet"])
            .expect_err("int8 slowdown");
        assert!(e.contains("--slowdown-int8 must be positive"), "{s}: {e}");
    }
    for fps in ["--camera-fps=0", "--camera-fps=-30", "--camera-fps=NaN"] {
        let e = frugal(&["fly", "--maze", p(&maze("easy.maze")), fps, "--quiet"])
            .expect_err("camera rate");
        assert!(e.contains("--camera-fps must be positive"), "{fps}: {e}");
    }
}

#[test]
fn fly_records_its_frames_as_a_dataset_the_replay_can_read() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let footage = tmp.path().join("footage");
    frugal(&small_flight(&[
        "--maze",
        "train-c",
        "--seeds",
        "1",
        "--record",
        p(&footage),
        "--record-every",
        "20",
        "--out",
        p(&tmp.path().join("fly")),
    ]))
    .expect("fly --record");
    let manifest = json(&footage.join("manifest.json"));
    assert_eq!(manifest["source"]["kind"], "flight");
    assert_eq!(manifest["source"]["every"], 20);
    let videos = manifest["videos"].as_array().expect("videos");
    assert_eq!(videos.len(), 1, "one video per flight");
    assert_eq!(videos[0]["split"], "val");
    let frames = videos[0]["frames"].as_u64().expect("frames");
    let val = json(&footage.join("annotations/val.json"));
    let images = val["images"].as_array().expect("images");
    let signs = val["annotations"].as_array().expect("annotations");
    assert!(frames > 20 && images.len() as u64 == frames, "{frames}");
    // at 160×90 a sign is 8 px tall (the smallest annotated) from about 4 m
    assert!(signs.len() > 20, "{} signs in {frames} frames", signs.len());
    for im in images {
        let file = footage.join(im["file_name"].as_str().expect("file"));
        assert!(file.is_file(), "{}", file.display());
    }
    // the replay's own reader takes it, split by split
    frugal(&["data", "summary", p(&footage)]).expect("summary");
}
