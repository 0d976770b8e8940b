//! Decoding speed of [`VideoReader`] next to plain `ffmpeg` on the same file, one
//! decoder thread each: what the pipe, the timestamps and the Rust side cost.
//!
//! Makes a 20 s, 30 fps, 1280×720 H.264 file (`testsrc2`, libx264 default preset) in a
//! temporary folder, then times, in turns so that a busy machine slows all alike, and
//! reports the median of 3 runs of each:
//! - (a) `ffmpeg -threads 1 -i f -f null -`: decoding only;
//! - (b) `ffmpeg -threads 1 -i f -vf scale=480:270 -f rawvideo -pix_fmt rgb24 -`, to
//!   /dev/null: decoding, resizing and RGB conversion, the same work as (c);
//! - (b2) as (b) with the reader's scaler flags (`area`), (b3) with `fast_bilinear`;
//! - (c) `VideoReader` at 480×270, `threads: Some(1)`, iterating over all frames;
//! - (c2) as (c) with `read_into` (one reused buffer);
//! - (d) `VideoReader` at 1280×720.
//!
//! Wall time is what the goal is about; CPU time (of this process and of ffmpeg) is
//! printed too, as it moves less when other work shares the machine.
//!
//! `cargo bench -p frugal-data --bench decode`; set `FRUGAL_BENCH_SECONDS` for a
//! shorter or longer file, or `FRUGAL_BENCH_FILE` to time a video of one's own
//! instead of `testsrc2` (its frames are counted by a first pass of the reader).
use frugal_data::media::{DecodedFrame, Sampling, VideoReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

const RUNS: usize = 3;

/// One way of decoding the file.
enum Run {
    /// Plain ffmpeg, with this `-vf` (none: decode only).
    Plain(Option<&'static str>),
    /// The reader at this size (none: the source's), reusing one buffer or not.
    Reader(Option<(u32, u32)>, bool),
}

fn main() {
    if Command::new("ffmpeg").arg("-version").output().is_err() {
        eprintln!("ffmpeg is not installed (cargo xtask setup); nothing to measure");
        return;
    }
    let seconds: u32 = std::env::var("FRUGAL_BENCH_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20);
    let dir = tempfile::tempdir().expect("temporary folder");
    let (file, frames) = match std::env::var_os("FRUGAL_BENCH_FILE") {
        Some(own) => {
            let file = std::path::PathBuf::from(own);
            let frames = reader(&file, None, false);
            println!(
                "test file: {} ({frames} frames, {:.1} MB)",
                file.display(),
                std::fs::metadata(&file).map_or(0.0, |m| m.len() as f64 / 1e6),
            );
            (file, frames)
        }
        None => {
            let file = dir.path().join("testsrc2-720p.mp4");
            (file.clone(), make_testsrc2(&file, seconds))
        }
    };

    let cases = [
        ("(a)  ffmpeg decode only (-f null)", Run::Plain(None)),
        (
            "(b)  ffmpeg scale=480:270 rgb24 > /dev/null",
            Run::Plain(Some("scale=480:270")),
        ),
        (
            "(b2) same, flags=area (the reader's)",
            Run::Plain(Some("scale=480:270:flags=area")),
        ),
        (
            "(b3) same, flags=fast_bilinear",
            Run::Plain(Some("scale=480:270:flags=fast_bilinear")),
        ),
        (
            "(c)  VideoReader 480x270, iterator",
            Run::Reader(Some((480, 270)), false),
        ),
        (
            "(c2) VideoReader 480x270, read_into",
            Run::Reader(Some((480, 270)), true),
        ),
        (
            "(d)  VideoReader 1280x720, iterator",
            Run::Reader(None, false),
        ),
    ];
    let mut wall = vec![Vec::new(); cases.len()];
    let mut cpu = vec![Vec::new(); cases.len()];
    let mut own_cpu = vec![Vec::new(); cases.len()];
    for _ in 0..RUNS {
        for (case, (name, run)) in cases.iter().enumerate() {
            let (start, cpu_start) = (Instant::now(), cpu_seconds());
            let got = match run {
                Run::Plain(filter) => plain(&file, *filter, frames),
                Run::Reader(size, reuse) => reader(&file, *size, *reuse),
            };
            wall[case].push(start.elapsed().as_secs_f64());
            if let (Some(a), Some(b)) = (cpu_start, cpu_seconds()) {
                own_cpu[case].push(b[0] - a[0]);
                cpu[case].push(b[0] + b[1] - a[0] - a[1]);
            }
            assert_eq!(got, frames, "{name}: frames");
        }
    }
    let median = |runs: &mut Vec<f64>| {
        runs.sort_by(f64::total_cmp);
        runs.get(runs.len() / 2).copied()
    };
    println!(
        "\none decoder thread (-threads 1), median of {RUNS} runs, {} cores; CPU = user + \
         system time of this process and its children (ffmpeg)\n",
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!("| case | wall s | frames/s | CPU s | of which this process | frames per CPU s |");
    println!("|---|---:|---:|---:|---:|---:|");
    let (mut rates, mut cpu_rates) = (Vec::new(), Vec::new());
    for (case, (name, _)) in cases.iter().enumerate() {
        let seconds = median(&mut wall[case]).unwrap_or(f64::NAN);
        let rate = frames as f64 / seconds;
        let (cpu_text, cpu_rate) = match median(&mut cpu[case]) {
            Some(c) => (format!("{c:.2}"), frames as f64 / c),
            None => ("n/a".into(), f64::NAN),
        };
        let own = median(&mut own_cpu[case]).map_or("n/a".into(), |c| format!("{c:.2}"));
        rates.push(rate);
        cpu_rates.push(cpu_rate);
        println!("| {name} | {seconds:.3} | {rate:.0} | {cpu_text} | {own} | {cpu_rate:.0} |");
    }
    println!(
        "\n(c)/(b) = {:.2} by wall time, {:.2} by CPU time;   (c)/(b2) = {:.2}, {:.2};   \
         (d)/(a) = {:.2}, {:.2}",
        rates[4] / rates[1],
        cpu_rates[4] / cpu_rates[1],
        rates[4] / rates[2],
        cpu_rates[4] / cpu_rates[2],
        rates[6] / rates[0],
        cpu_rates[6] / cpu_rates[0],
    );
}

/// User + system CPU seconds of this process and of its reaped children (ffmpeg and
/// ffprobe), from `/proc/self/stat` (Linux; `None` elsewhere), in clock ticks of 1/100 s
/// (`USER_HZ`).
fn cpu_seconds() -> Option<[f64; 2]> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name start at field 3 (state); utime,
    // stime, cutime and cstime are fields 14 to 17.
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let mut ticks = [0.0; 4];
    for (tick, field) in ticks.iter_mut().zip(fields.get(11..15)?) {
        *tick = field.parse::<f64>().ok()? / 100.0;
    }
    Some([ticks[0] + ticks[1], ticks[2] + ticks[3]])
}

/// Plain ffmpeg on one decoder thread: to `-f null` without a filter, else the filter's
/// output as raw RGB to /dev/null. Returns `frames` (ffmpeg does not say).
fn plain(file: &Path, filter: Option<&str>, frames: u64) -> u64 {
    let mut command = Command::new("ffmpeg");
    command
        .args(["-nostdin", "-v", "error", "-threads", "1", "-i"])
        .arg(file);
    match filter {
        None => command.args(["-f", "null", "-"]),
        Some(vf) => command.args(["-vf", vf, "-f", "rawvideo", "-pix_fmt", "rgb24", "-"]),
    };
    let status = command
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .status()
        .expect("ffmpeg runs");
    assert!(status.success());
    frames
}

/// Every frame through the reader on one decoder thread; the number of frames.
fn reader(file: &Path, size: Option<(u32, u32)>, reuse: bool) -> u64 {
    let sampling = Sampling {
        size,
        threads: Some(1),
        ..Sampling::default()
    };
    let mut reader = VideoReader::open(file, &sampling).expect("the reader opens");
    let mut checksum = 0u64;
    if reuse {
        let mut frame = DecodedFrame {
            index: 0,
            time_s: 0.0,
            image: image::RgbImage::new(0, 0),
        };
        while reader.read_into(&mut frame).expect("frame") {
            checksum += u64::from(frame.image.as_raw()[0]);
        }
    } else {
        for frame in &mut reader {
            checksum += u64::from(frame.expect("frame").image.as_raw()[0]);
        }
    }
    std::hint::black_box(checksum);
    reader.frames_read()
}

/// A `seconds`-long 30 fps 1280×720 H.264 `testsrc2` file at `file`; its frame count.
fn make_testsrc2(file: &Path, seconds: u32) -> u64 {
    let made = Instant::now();
    let status = Command::new("ffmpeg")
        .args([
            "-hide_banner",
            "-nostdin",
            "-v",
            "error",
            "-y",
            "-f",
            "lavfi",
            "-i",
        ])
        .arg(format!("testsrc2=size=1280x720:rate=30:duration={seconds}"))
        .args(["-c:v", "libx264", "-pix_fmt", "yuv420p"])
        .arg(file)
        .status()
        .expect("ffmpeg runs");
    assert!(status.success(), "could not make the test file");
    let frames = u64::from(seconds) * 30;
    println!(
        "test file: {frames} frames of 1280x720 H.264 ({:.1} MB), made in {:.1} s",
        std::fs::metadata(file).map_or(0.0, |m| m.len() as f64 / 1e6),
        made.elapsed().as_secs_f64()
    );
    frames
}
