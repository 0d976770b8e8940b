//! `ffprobe -of json` of a file's first video stream, and the few program-running helpers
//! shared with the reader.
use super::{INSTALL_HINT, MediaInfo, TOOLS, Tools};
use crate::DataError;
use serde_json::Value;
use std::ffi::OsString;
use std::path::Path;
use std::process::{Command, Output, Stdio};

/// A positive rational number (`num / den`), as ffprobe prints time bases and rates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Ratio {
    /// Numerator (> 0).
    pub num: i64,
    /// Denominator (> 0).
    pub den: i64,
}

impl Ratio {
    /// Parse `"30000/1001"` (or a plain integer); `None` unless both parts are > 0.
    pub fn parse(text: &str) -> Option<Self> {
        let (num, den) = text.trim().split_once('/').unwrap_or((text.trim(), "1"));
        let (num, den) = (num.trim().parse().ok()?, den.trim().parse().ok()?);
        (num > 0 && den > 0).then_some(Self { num, den })
    }

    /// The value as a float.
    pub fn to_f64(self) -> f64 {
        self.num as f64 / self.den as f64
    }

    /// The same value (compared exactly).
    pub fn same(self, other: Self) -> bool {
        i128::from(self.num) * i128::from(other.den) == i128::from(other.num) * i128::from(self.den)
    }
}

/// What the reader needs beyond [`MediaInfo`].
#[derive(Clone, Debug)]
pub(crate) struct Probed {
    /// The public part.
    pub info: MediaInfo,
    /// Index of the video stream in the file (for `-map 0:N`).
    pub stream_index: u64,
    /// The stream's time base.
    pub time_base: Ratio,
    /// The stream's first pts, in its time base.
    pub start_pts: i64,
    /// The stream's first pts in seconds.
    pub start_time: f64,
    /// The file's start time in seconds (what ffmpeg's `-ss` counts from).
    pub format_start: f64,
    /// The frame rate as an exact ratio.
    pub rate: Ratio,
    /// Whether the container declares a constant frame rate (average rate = base rate).
    pub constant_rate: bool,
}

/// The `file:` URL ffmpeg and ffprobe are given, so that no file name is read as an
/// option or a protocol (`-x.mp4`, `a:b.mp4`).
pub(crate) fn file_url(path: &Path) -> OsString {
    let mut url = OsString::from("file:");
    url.push(path.as_os_str());
    url
}

/// Run a program to completion, mapping "not installed" to a clear error.
pub(crate) fn run(program: &str, command: &mut Command, path: &Path) -> Result<Output, DataError> {
    command
        .stdin(Stdio::null())
        .output()
        .map_err(|e| spawn_error(program, path, e))
}

/// Run `ffprobe` (the program `program`) with `args` on `path`'s URL; its standard
/// output, or an error that starts with `failure` and carries ffprobe's message.
pub(crate) fn ffprobe(
    program: &str,
    path: &Path,
    args: &[&str],
    failure: &str,
) -> Result<Vec<u8>, DataError> {
    let url = file_url(path);
    let out = run(program, Command::new(program).args(args).arg(&url), path)?;
    if !out.status.success() {
        return Err(DataError::invalid(
            path,
            "video",
            format!("{failure}: {}", one_line(&out.stderr, &url)),
        ));
    }
    Ok(out.stdout)
}

/// The error for a program that could not be started.
pub(crate) fn spawn_error(program: &str, path: &Path, e: std::io::Error) -> DataError {
    if e.kind() == std::io::ErrorKind::NotFound {
        DataError::invalid(
            path,
            program,
            format!("the `{program}` program was not found; {INSTALL_HINT}"),
        )
    } else {
        DataError::invalid(path, program, format!("could not start `{program}`: {e}"))
    }
}

/// ffmpeg's or ffprobe's error output as one line: the messages without their
/// `[demuxer @ 0x…]` prefixes and without the file name they repeat, joined by `; `.
pub(crate) fn one_line(stderr: &[u8], url: &OsString) -> String {
    let url = url.to_string_lossy();
    let mut parts: Vec<String> = Vec::new();
    for line in String::from_utf8_lossy(stderr).lines() {
        let mut text = line.trim();
        while text.starts_with('[')
            && let Some(end) = text.find("] ")
        {
            text = text[end + 2..].trim_start();
        }
        if let Some(rest) = text.strip_prefix(url.as_ref()) {
            text = rest.trim_start_matches(':').trim_start();
        }
        if !text.is_empty() && !parts.iter().any(|p| p == text) {
            parts.push(text.to_string());
        }
    }
    if parts.is_empty() {
        "no message".into()
    } else {
        parts.join("; ")
    }
}

/// Check that `path` is a non-empty file before handing it to a program.
pub(crate) fn check_file(path: &Path) -> Result<(), DataError> {
    let meta = std::fs::metadata(path).map_err(|e| DataError::io(path, e))?;
    if meta.is_dir() {
        return Err(DataError::invalid(
            path,
            "video",
            "is a folder, not a video file",
        ));
    }
    if meta.len() == 0 {
        return Err(DataError::invalid(path, "video", "empty file (0 bytes)"));
    }
    Ok(())
}

/// Describe the first video stream of `path` (cover pictures are not video streams).
///
/// Fails, naming the file, when it is missing or empty, when ffprobe cannot read it
/// (not a video, truncated before its index), when it has no video stream or no frames,
/// and when `ffprobe` is not installed.
pub fn probe(path: &Path) -> Result<MediaInfo, DataError> {
    Ok(probe_with(&TOOLS, path)?.info)
}

/// [`probe`] with the given programs, keeping what the reader needs.
pub(crate) fn probe_with(tools: &Tools, path: &Path) -> Result<Probed, DataError> {
    check_file(path)?;
    let stdout = ffprobe(
        tools.ffprobe,
        path,
        &[
            "-v",
            "error",
            "-of",
            "json",
            "-show_format",
            "-show_streams",
        ],
        "not a video ffprobe can read",
    )?;
    let json: Value = serde_json::from_slice(&stdout).map_err(|e| {
        DataError::invalid(path, "ffprobe", format!("unexpected ffprobe output: {e}"))
    })?;
    parse(path, &json)
}

/// A field that ffprobe prints either as a number or as a string.
fn number(value: &Value) -> Option<f64> {
    match value {
        Value::Number(n) => n.as_f64(),
        Value::String(s) => s.trim().parse().ok(),
        _ => None,
    }
}

/// Read ffprobe's JSON.
fn parse(path: &Path, json: &Value) -> Result<Probed, DataError> {
    let bad = |problem: String| DataError::invalid(path, "video", problem);
    let empty = Vec::new();
    let streams = json["streams"].as_array().unwrap_or(&empty);
    let Some(stream) = streams.iter().find(|s| {
        s["codec_type"] == "video" && s["disposition"]["attached_pic"].as_i64() != Some(1)
    }) else {
        let kinds: Vec<&str> = streams
            .iter()
            .filter_map(|s| s["codec_type"].as_str())
            .collect();
        return Err(bad(if kinds.is_empty() {
            "no video stream (the file holds no streams)".into()
        } else {
            format!("no video stream (only {})", kinds.join(", "))
        }));
    };
    let codec = stream["codec_name"]
        .as_str()
        .unwrap_or("unknown")
        .to_string();
    let (width, height) = match (stream["width"].as_u64(), stream["height"].as_u64()) {
        (Some(w), Some(h)) if w > 0 && h > 0 => (w as u32, h as u32),
        _ => return Err(bad(format!("the {codec} video stream has no frame size"))),
    };
    // Phones store portrait video as landscape plus a rotation that ffmpeg applies.
    let rotation = stream["side_data_list"]
        .as_array()
        .and_then(|list| list.iter().find_map(|d| number(&d["rotation"])))
        .or_else(|| number(&stream["tags"]["rotate"]))
        .unwrap_or(0.0);
    let (width, height) = if (rotation.round() as i64).rem_euclid(180) == 90 {
        (height, width)
    } else {
        (width, height)
    };
    let avg = stream["avg_frame_rate"].as_str().and_then(Ratio::parse);
    let base = stream["r_frame_rate"].as_str().and_then(Ratio::parse);
    let Some(rate) = avg.or(base) else {
        return Err(bad(format!("the {codec} video stream has no frame rate")));
    };
    let constant_rate = matches!((avg, base), (Some(a), Some(b)) if a.same(b));
    let frames = stream["nb_frames"]
        .as_str()
        .and_then(|s| s.parse::<u64>().ok());
    let duration_s = number(&stream["duration"])
        .or_else(|| number(&json["format"]["duration"]))
        .filter(|d| d.is_finite() && *d >= 0.0);
    if frames == Some(0) || (frames.is_none() && duration_s == Some(0.0)) {
        return Err(bad(format!(
            "empty video: the {codec} stream has no frames"
        )));
    }
    let time_base = stream["time_base"]
        .as_str()
        .and_then(Ratio::parse)
        .ok_or_else(|| bad(format!("the {codec} video stream has no time base")))?;
    Ok(Probed {
        info: MediaInfo {
            width,
            height,
            fps: rate.to_f64(),
            frames,
            duration_s,
            codec,
        },
        stream_index: stream["index"].as_u64().unwrap_or(0),
        time_base,
        start_pts: stream["start_pts"].as_i64().unwrap_or(0),
        start_time: number(&stream["start_time"]).unwrap_or(0.0),
        format_start: number(&json["format"]["start_time"]).unwrap_or(0.0),
        rate,
        constant_rate,
    })
}
