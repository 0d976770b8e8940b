//! How `frugal-pilot` survives its inputs failing: a truncated video, a corrupt image
//! in a folder, SIGINT mid-run, a camera that does not exist, a stream that never
//! sends. Detections are replayed from a file (`--detections`), so no detector is
//! needed; each run ends with the summary line, and a failed input with one line
//! naming it and a failure status.
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn have_ffmpeg() -> bool {
    let ok = Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        eprintln!("skipped: the ffmpeg program is not installed");
    }
    ok
}

/// A detections file with none, and a configuration of a small camera with fast
/// retries, in `dir`; the pilot's leading arguments.
fn setup(dir: &Path, input: &str) -> Vec<String> {
    let detections = dir.join("none.jsonl");
    std::fs::write(&detections, "").unwrap();
    let config = dir.join("pilot.toml");
    std::fs::write(
        &config,
        "[camera]\nwidth = 160\nheight = 90\n\n[input]\nretries = 2\nbackoff_ms = 20\nstall_timeout_ms = 300\n",
    )
    .unwrap();
    [
        "--detections",
        detections.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
        "--input",
        input,
    ]
    .iter()
    .map(|s| (*s).to_owned())
    .collect()
}

/// Run the pilot to its end (killed after a minute, a safety net only): success,
/// stdout, stderr.
fn pilot(args: &[String]) -> (bool, String, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_frugal-pilot"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let read = |mut r: Box<dyn std::io::Read + Send>| {
        std::thread::spawn(move || {
            let mut s = String::new();
            let _ = r.read_to_string(&mut s);
            s
        })
    };
    let out = read(Box::new(child.stdout.take().unwrap()));
    let err = read(Box::new(child.stderr.take().unwrap()));
    let deadline = Instant::now() + Duration::from_secs(60);
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("frugal-pilot did not end: {}", err.join().unwrap());
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    (status.success(), out.join().unwrap(), err.join().unwrap())
}

/// Send SIGINT to process `pid`.
fn interrupt(pid: u32) {
    let ok = Command::new("kill")
        .args(["-INT", &pid.to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill -INT {pid} failed");
}

/// A test video of `seconds` at 160×90, 30 fps, with its index up front.
fn video(path: &Path, seconds: u32) {
    let ok = Command::new("ffmpeg")
        .args([
            "-hide_banner",
            "-loglevel",
            "error",
            "-y",
            "-f",
            "lavfi",
            "-i",
        ])
        .arg("testsrc2=size=160x90:rate=30")
        .args(["-t", &seconds.to_string(), "-c:v", "mpeg4", "-q:v", "5"])
        .args(["-movflags", "+faststart"])
        .arg(path)
        .status()
        .unwrap()
        .success();
    assert!(ok, "ffmpeg could not write {}", path.display());
}

/// The numbers of the summary line: processed, decoded, dropped, corrupt, reconnects.
fn counts(line: &str) -> [u64; 5] {
    let words: Vec<&str> = line.split([' ', '(', ')', ',']).collect();
    let after = |w: &str| -> u64 {
        let i = words
            .iter()
            .position(|x| *x == w)
            .unwrap_or_else(|| panic!("{line}"));
        words[i - 1].parse().unwrap_or_else(|_| panic!("{line}"))
    };
    [
        after("frames"),
        after("decoded"),
        after("dropped"),
        after("corrupt"),
        after("reconnects"),
    ]
}

fn summary_line(err: &str) -> &str {
    let last = err.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("frugal-pilot: ") && last.contains("frames processed"),
        "the last line is not the summary: {err}"
    );
    last
}

#[test]
fn a_truncated_video_ends_the_run_after_the_frames_before_the_damage() {
    if !have_ffmpeg() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let full = tmp.path().join("full.mp4");
    video(&full, 2);
    let bytes = std::fs::read(&full).unwrap();
    let cut = tmp.path().join("cut.mp4");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let mut args = setup(tmp.path(), cut.to_str().unwrap());
    args.extend(["--every-frame".into(), "--json".into(), "none".into()]);
    let (ok, _, err) = pilot(&args);
    assert!(!ok, "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let problems: Vec<&str> = err.lines().filter(|l| l.contains("cut.mp4")).collect();
    assert_eq!(problems.len(), 1, "{err}");
    let [frames, decoded, drops, _, _] = counts(summary_line(&err));
    assert!((1..60).contains(&frames), "{err}");
    assert_eq!((frames, drops), (decoded, 0), "{err}");
    // the whole file plays to its end
    let mut args = setup(tmp.path(), full.to_str().unwrap());
    args.extend(["--every-frame".into(), "--json".into(), "none".into()]);
    let (ok, _, err) = pilot(&args);
    assert!(ok, "{err}");
    assert_eq!(counts(summary_line(&err))[..3], [60, 60, 0], "{err}");
}

#[test]
fn a_corrupt_image_of_a_folder_is_skipped_and_counted() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = tmp.path().join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    for i in 0..4 {
        let image = image::RgbImage::from_pixel(32, 18, image::Rgb([i * 40, 90, 200]));
        image.save(frames.join(format!("f{i}.png"))).unwrap();
    }
    std::fs::write(frames.join("f2.png"), b"\x89PNG\r\n\x1a\nnot an image").unwrap();
    let mut args = setup(tmp.path(), frames.to_str().unwrap());
    args.push("--every-frame".into());
    let (ok, out, err) = pilot(&args);
    assert!(ok, "{err}");
    let named: Vec<&str> = err.lines().filter(|l| l.contains("f2.png")).collect();
    assert_eq!(named.len(), 1, "{err}");
    assert_eq!(counts(summary_line(&err)), [3, 3, 0, 1, 0], "{err}");
    // the frames after it were processed, f2 was not
    let numbers: Vec<u64> = out
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter_map(|v| v.get("frame").and_then(serde_json::Value::as_u64))
        .collect();
    assert_eq!(numbers, [0, 1, 3], "{out}");
    let last: serde_json::Value = serde_json::from_str(out.lines().last().unwrap()).unwrap();
    assert_eq!(last["summary"]["corrupt"], 1, "{out}");
}

#[test]
fn sigint_mid_run_stops_cleanly_with_the_summary() {
    if !have_ffmpeg() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let long = tmp.path().join("long.mp4");
    video(&long, 40);
    let args = setup(tmp.path(), long.to_str().unwrap());
    let mut child = Command::new(env!("CARGO_BIN_EXE_frugal-pilot"))
        .args(&args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut first = String::new();
    out.read_line(&mut first).unwrap();
    let first: serde_json::Value = serde_json::from_str(&first).unwrap();
    assert!(first.get("frame").is_some(), "{first}");
    let started = Instant::now();
    interrupt(pid);
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut out, &mut rest).unwrap();
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    let status = child.wait().unwrap();
    // a safety bound, not a measurement: 40 s of footage did not play out
    assert!(started.elapsed() < Duration::from_secs(30));
    assert!(status.success(), "{status}: {err}");
    let last = summary_line(&err);
    assert!(last.starts_with("frugal-pilot: stopped: "), "{err}");
    assert!(
        last.contains("dropped") && last.contains("0 commands []"),
        "{err}"
    );
    let [frames, decoded, ..] = counts(last);
    assert!((1..1200).contains(&frames) && decoded >= frames, "{err}");
    let summary: serde_json::Value = serde_json::from_str(rest.lines().last().unwrap()).unwrap();
    assert_eq!(summary["summary"]["interrupted"], true, "{rest}");
    assert_eq!(summary["summary"]["frames"], frames, "{rest}");
}

#[test]
fn a_missing_camera_is_retried_with_backoff_then_given_up() {
    if !have_ffmpeg() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let args = setup(tmp.path(), "/dev/video99");
    let (ok, _, err) = pilot(&args);
    assert!(!ok, "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let lines: Vec<&str> = err.lines().collect();
    assert!(
        lines[0].contains("/dev/video99")
            && lines[0].contains("reconnecting in 20 ms (attempt 1 of 2)"),
        "{err}"
    );
    assert!(
        lines[1].contains("/dev/video99")
            && lines[1].contains("reconnecting in 40 ms (attempt 2 of 2)"),
        "{err}"
    );
    assert!(
        lines[2].contains("/dev/video99") && lines[2].contains("gave up after 3 attempt(s)"),
        "{err}"
    );
    assert_eq!(lines.len(), 4, "{err}");
    assert_eq!(counts(summary_line(&err)), [0, 0, 0, 0, 2], "{err}");
}

#[test]
fn a_stream_that_never_sends_is_reported_stalled_and_given_up() {
    if !have_ffmpeg() {
        return;
    }
    let port = std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let url = format!("udp://127.0.0.1:{port}");
    let tmp = tempfile::tempdir().unwrap();
    let args = setup(tmp.path(), &url);
    let (ok, _, err) = pilot(&args);
    assert!(!ok, "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let stalls = err
        .lines()
        .filter(|l| l.contains(&url) && l.contains("stalled: no frame for 300 ms"))
        .count();
    assert_eq!(stalls, 3, "{err}");
    assert!(err.contains("gave up after 3 attempt(s)"), "{err}");
    assert_eq!(counts(summary_line(&err)), [0, 0, 0, 0, 2], "{err}");
}
