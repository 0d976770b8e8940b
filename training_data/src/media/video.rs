//! [`VideoReader`]: frames of a video file from an `ffmpeg` child process.
//!
//! # The pipe
//!
//! ```text
//! ffmpeg -hide_banner -nostdin -nostats -loglevel level+info [-threads N] -copyts
//!        [-ss START] -i file:PATH -map 0:STREAM
//!        -vf "[trim=end=END,]showinfo@in=checksum=0,[select (fps),][select (every),]
//!             showinfo@out=checksum=0,scale=w=W:h=H:flags=area|bilinear,format=rgb24"
//!        -fps_mode passthrough -f rawvideo -pix_fmt rgb24 pipe:1
//! ```
//!
//! - `-ss` is an input option: ffmpeg seeks to the key frame before `START`, then
//!   decodes and drops the frames before it (`-accurate_seek`, on by default), so the
//!   window starts exactly at the first frame at or after `START` and a late start does
//!   not decode the whole file. The end is a `trim` filter, exact too, after which
//!   ffmpeg stops reading.
//! - `-copyts` keeps the container's timestamps (ffmpeg would otherwise shift them to
//!   start at the window's start), so they can be turned into source indices.
//! - Sampling is done by `select` filters before the scaler, so dropped frames cost
//!   their decoding only. `-fps_mode passthrough` (`-vsync passthrough` before ffmpeg
//!   5.1) stops ffmpeg from duplicating frames to fill the gaps.
//! - The frames are always scaled to the expected size, so a stream whose resolution
//!   changes midway still gives frames of one size and the pipe never loses step.
//! - Each frame is exactly `W × H × 3` bytes on stdout; stderr is drained by a thread.
//!
//! # Timestamps
//!
//! Raw video on a pipe carries no timestamps, so they come from two `showinfo` filters
//! that log one line per frame on stderr (`n: … pts: … pts_time: …`) and, once, their
//! input time base (`config in time_base: 1/15360`): `showinfo@in` sees every decoded
//! frame of the window, `showinfo@out` only the frames the selection kept. A line is
//! logged before its frame is written to stdout and each frame goes through the whole
//! chain before the next one enters it, so the stderr thread counts the `in` lines and,
//! on each `out` line, reports the frame's pts and its rank among the decoded frames;
//! the reader pairs frame *k* on stdout with the *k*-th report. Alternatives were worse:
//! ffprobe's packet list is in decode order and knows nothing of the selection, a
//! container on the pipe (NUT, Matroska) would need a demuxer here, and redoing the
//! selection in Rust from the `in` lines would risk drifting from ffmpeg's arithmetic.
//! The integer `pts` is used, not `pts_time`, which ffmpeg prints with 6 significant
//! digits only. Checksums are off (`checksum=0`): they would cost a pass per frame.
//!
//! From there, with `t = (pts − start_pts) × time_base` (exact, in rationals):
//! - `index` = the rank of the frame among the decoded frames, plus the index of the
//!   first decoded frame: 0 without `start_s`; after a seek, `round(t × fps)` of that
//!   frame when the container declares a constant rate (average rate = base rate),
//!   else the number of packets before it, counted by `ffprobe -read_intervals` up to
//!   the seek point (demuxing only). Counting frames rather than using `round(t × fps)`
//!   everywhere keeps indices right for variable-rate streams that Matroska declares
//!   constant-rate.
//! - `time_s` = `t`, or `round(t × fps) / fps` when the container declares a constant
//!   rate and `t` is within one time-base tick of that grid point (Matroska stores
//!   milliseconds: 33 ms becomes exactly 1/30 s). For MP4 made by ffmpeg both are equal.
//!
//! Logging at info level for `showinfo` means ffmpeg also prints its banner and
//! stream mapping; `-loglevel level+info` tags each line with its level, and only
//! `[error]`, `[fatal]` and `[panic]` lines count as problems.
//!
//! Over 700 lines: the reader, the ffmpeg command it builds and the clock that turns the
//! pipe's `showinfo` lines into each frame's timestamp are one mechanism. Each frame read
//! is checked against the line ffmpeg printed for it, so they stay in one file.
use super::probe::{Probed, Ratio, file_url, probe_with, spawn_error};
use super::{DecodedFrame, MediaInfo, Sampling, TOOLS, Tools};
use crate::DataError;
use image::RgbImage;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread::JoinHandle;

/// Frames of a video file, decoded by an `ffmpeg` child process, one at a time.
///
/// Iterating yields [`DecodedFrame`]s until the end of the stream or the first error;
/// [`read_into`](Self::read_into) reuses one frame's buffer instead. Dropping the
/// reader early kills and reaps the child.
#[derive(Debug)]
pub struct VideoReader {
    path: PathBuf,
    info: MediaInfo,
    clock: Clock,
    width: u32,
    height: u32,
    child: Option<Child>,
    stdout: Option<ChildStdout>,
    events: Receiver<Event>,
    watcher: Option<JoinHandle<()>>,
    frames_read: u64,
    done: bool,
    window: (Option<f64>, Option<f64>),
}

impl VideoReader {
    /// Probe `path` and start decoding it with `sampling`.
    ///
    /// Fails, naming the file, for everything [`probe`](super::probe) rejects, for a
    /// bad [`Sampling`], for a window starting after the end of the video, and when
    /// `ffmpeg` is not installed.
    pub fn open(path: &Path, sampling: &Sampling) -> Result<Self, DataError> {
        Self::open_with(&TOOLS, path, sampling)
    }

    /// [`open`](Self::open) with the given programs.
    pub(crate) fn open_with(
        tools: &Tools,
        path: &Path,
        sampling: &Sampling,
    ) -> Result<Self, DataError> {
        sampling.check(path)?;
        let probed = probe_with(tools, path)?;
        if let (Some(start), Some(duration)) = (sampling.start_s, probed.info.duration_s)
            && start >= duration
        {
            return Err(DataError::invalid(
                path,
                "sampling",
                format!("start_s {start} s is at or after the end of the video ({duration} s)"),
            ));
        }
        let (width, height) = sampling
            .size
            .unwrap_or((probed.info.width, probed.info.height));
        let fps_mode = *tools.fps_mode.get_or_init(|| knows_fps_mode(tools.ffmpeg));
        let mut command = Command::new(tools.ffmpeg);
        command.args(ffmpeg_args(
            path, &probed, sampling, width, height, fps_mode,
        ));
        let mut child = command
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| spawn_error(tools.ffmpeg, path, e))?;
        let stdout = child.stdout.take();
        let stderr = child.stderr.take();
        let (tx, events) = channel();
        let watcher = stderr.map(|stderr| std::thread::spawn(move || watch(stderr, tx)));
        Ok(Self {
            path: path.to_path_buf(),
            clock: Clock {
                stream_tb: probed.time_base,
                filter_tb: probed.time_base,
                start_pts: probed.start_pts,
                rate: probed.rate,
                constant_rate: probed.constant_rate,
                first: if sampling.start_s.is_some() {
                    None
                } else {
                    Some(0)
                },
                ffprobe: tools.ffprobe,
                stream_index: probed.stream_index,
            },
            info: probed.info,
            width,
            height,
            child: Some(child),
            stdout,
            events,
            watcher,
            frames_read: 0,
            done: false,
            window: (sampling.start_s, sampling.end_s),
        })
    }

    /// The source video's description (not changed by sampling).
    pub fn info(&self) -> &MediaInfo {
        &self.info
    }

    /// Width and height of the frames returned.
    pub fn frame_size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// How many frames were returned so far.
    pub fn frames_read(&self) -> u64 {
        self.frames_read
    }

    /// The ffmpeg child's process id while it runs.
    #[cfg(test)]
    pub(crate) fn process_id(&self) -> Option<u32> {
        self.child.as_ref().map(Child::id)
    }

    /// Read the next frame into `frame`, reusing its image's buffer when it has the
    /// capacity. Returns `false` at the end of the stream (and after an error).
    pub fn read_into(&mut self, frame: &mut DecodedFrame) -> Result<bool, DataError> {
        let mut buf = std::mem::replace(&mut frame.image, RgbImage::new(0, 0)).into_raw();
        match self.read_frame(&mut buf)? {
            Some((index, time_s)) => {
                frame.index = index;
                frame.time_s = time_s;
                frame.image = self.image(buf)?;
                Ok(true)
            }
            None => Ok(false),
        }
    }

    /// Wrap one frame's bytes.
    fn image(&self, buf: Vec<u8>) -> Result<RgbImage, DataError> {
        RgbImage::from_raw(self.width, self.height, buf).ok_or_else(|| {
            DataError::invalid(&self.path, "video", "frame buffer of the wrong size")
        })
    }

    /// Bytes of one frame.
    fn frame_bytes(&self) -> usize {
        self.width as usize * self.height as usize * 3
    }

    /// Read one frame into `buf`; its index and time, or `None` at the end. Any error
    /// stops the child and ends the stream.
    fn read_frame(&mut self, buf: &mut Vec<u8>) -> Result<Option<(u64, f64)>, DataError> {
        if self.done {
            return Ok(None);
        }
        let result = self.read_frame_inner(buf);
        if !matches!(result, Ok(Some(_))) {
            self.done = true;
            self.stop();
        }
        result
    }

    fn read_frame_inner(&mut self, buf: &mut Vec<u8>) -> Result<Option<(u64, f64)>, DataError> {
        let want = self.frame_bytes();
        buf.clear();
        buf.reserve_exact(want);
        let Some(stdout) = self.stdout.as_mut() else {
            return Ok(None);
        };
        let got = stdout
            .by_ref()
            .take(want as u64)
            .read_to_end(buf)
            .map_err(|e| DataError::io(&self.path, e))?;
        if got == 0 {
            return self.finish().map(|()| None);
        }
        if got < want {
            self.finish()?;
            return Err(self.corrupt(format!(
                "ffmpeg's output ends inside a frame ({got} of {want} bytes)"
            )));
        }
        let stamp = self.next_stamp()?;
        let (index, time) = self.clock.stamp(&stamp, &self.path)?;
        self.frames_read += 1;
        Ok(Some((index, time)))
    }

    /// Where the frame just read stands, from the `showinfo` lines logged before it.
    fn next_stamp(&mut self) -> Result<Stamp, DataError> {
        loop {
            match self.events.recv() {
                Ok(Event::TimeBase(tb)) => self.clock.filter_tb = tb,
                Ok(Event::Frame(stamp)) => return Ok(stamp),
                Ok(Event::Problem(problem)) => return Err(self.corrupt(problem)),
                Err(_) => {
                    return Err(DataError::invalid(
                        &self.path,
                        "ffmpeg",
                        "a frame came without its showinfo timestamp line",
                    ));
                }
            }
        }
    }

    /// The end of the stream: wait for ffmpeg and check that all went well.
    fn finish(&mut self) -> Result<(), DataError> {
        self.stdout = None;
        let status = match self.child.take() {
            Some(mut child) => Some(child.wait().map_err(|e| DataError::io(&self.path, e))?),
            None => None,
        };
        if let Some(watcher) = self.watcher.take() {
            let _ = watcher.join();
        }
        while let Ok(event) = self.events.try_recv() {
            if let Event::Problem(problem) = event {
                return Err(self.corrupt(problem));
            }
        }
        if let Some(status) = status
            && !status.success()
        {
            return Err(self.corrupt(format!("ffmpeg failed ({status})")));
        }
        if self.frames_read == 0 {
            let problem = match self.window {
                (None, None) => "empty video: ffmpeg decoded no frames".to_string(),
                (start, end) => format!(
                    "no frame in the window from {} s to {}",
                    start.unwrap_or(0.0),
                    end.map_or("the end".to_string(), |e| format!("{e} s"))
                ),
            };
            return Err(DataError::invalid(&self.path, "video", problem));
        }
        Ok(())
    }

    /// A decoding error, counting the frames that came before it.
    fn corrupt(&self, problem: String) -> DataError {
        DataError::invalid(
            &self.path,
            "video",
            format!(
                "decoding failed after {} frame(s) (corrupt or truncated video?): {problem}",
                self.frames_read
            ),
        )
    }

    /// Kill and reap the child (if still there) and join the stderr thread.
    fn stop(&mut self) {
        self.stdout = None;
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
        if let Some(watcher) = self.watcher.take() {
            let _ = watcher.join();
        }
    }
}

impl Drop for VideoReader {
    fn drop(&mut self) {
        self.stop();
    }
}

impl Iterator for VideoReader {
    type Item = Result<DecodedFrame, DataError>;

    fn next(&mut self) -> Option<Self::Item> {
        let mut buf = Vec::new();
        match self.read_frame(&mut buf) {
            Ok(Some((index, time_s))) => Some(self.image(buf).map(|image| DecodedFrame {
                index,
                time_s,
                image,
            })),
            Ok(None) => None,
            Err(e) => Some(Err(e)),
        }
    }
}

impl std::iter::FusedIterator for VideoReader {}

/// ffmpeg's arguments (see the module documentation).
fn ffmpeg_args(
    path: &Path,
    probed: &Probed,
    sampling: &Sampling,
    width: u32,
    height: u32,
    fps_mode: bool,
) -> Vec<std::ffi::OsString> {
    let mut args: Vec<std::ffi::OsString> = Vec::new();
    let mut push = |a: &str| args.push(a.into());
    for a in [
        "-hide_banner",
        "-nostdin",
        "-nostats",
        "-loglevel",
        "level+info",
    ] {
        push(a);
    }
    if let Some(threads) = sampling.threads {
        push("-threads");
        push(&threads.to_string());
    }
    push("-copyts");
    // -ss and -to count from the file's start; the window counts from the stream's.
    let offset = probed.start_time - probed.format_start;
    if let Some(start) = sampling.start_s {
        push("-ss");
        push(&format!("{:.6}", start + offset));
    }
    args.push("-i".into());
    args.push(file_url(path));
    let mut push = |a: &str| args.push(a.into());
    push("-map");
    push(&format!("0:{}", probed.stream_index));
    push("-vf");
    push(&filters(probed, sampling, width, height));
    if fps_mode {
        push("-fps_mode");
    } else {
        push("-vsync");
    }
    push("passthrough");
    for a in ["-f", "rawvideo", "-pix_fmt", "rgb24", "pipe:1"] {
        push(a);
    }
    args
}

/// The filter chain: selection, `showinfo`, scaling to `width × height` in RGB.
fn filters(probed: &Probed, sampling: &Sampling, width: u32, height: u32) -> String {
    let mut chain = Vec::new();
    if let Some(end) = sampling.end_s {
        // Not `-to`, whose end ffmpeg counts from the first frame kept rather than from
        // the seek point (`-ss 0.01 -to 0.02` would keep the frame at 0.033 s). `trim`
        // drops frames from this pts on (absolute: -copyts) and then ends the stream,
        // which stops ffmpeg reading further.
        chain.push(format!("trim=end={:.6}", end + probed.start_time));
    }
    chain.push("showinfo@in=checksum=0".to_string());
    if let Some(fps) = sampling.fps {
        // A frame is kept when it is the first of its 1/fps slot. With a constant rate,
        // slots are counted on the source's frame grid (as for image sequences), so
        // rounded container timestamps do not move a frame across a boundary.
        let t0 = probed.start_time;
        let (n, d) = (probed.rate.num, probed.rate.den);
        let slot = |t: &str| {
            if probed.constant_rate {
                format!("floor(round(({t}-({t0}))*{n}/{d})*{fps}*{d}/{n}+1e-9)")
            } else {
                format!("floor(({t}-({t0}))*{fps}+1e-6)")
            }
        };
        chain.push(format!(
            "select='if(isnan(prev_t),1,gt({},{}))'",
            slot("t"),
            slot("prev_t")
        ));
    }
    let step = sampling.step();
    if step > 1 {
        chain.push(format!("select='not(mod(n,{step}))'"));
    }
    chain.push("showinfo@out=checksum=0".into());
    let shrink = width <= probed.info.width && height <= probed.info.height;
    let flags = if shrink { "area" } else { "bilinear" };
    chain.push(format!("scale=w={width}:h={height}:flags={flags}"));
    chain.push("format=rgb24".into());
    chain.join(",")
}

/// Whether `ffmpeg -version` is 5.1 or later (`-fps_mode` replaced `-vsync`). Assumes so
/// when the version cannot be read (git builds print `N-…`).
fn knows_fps_mode(ffmpeg: &str) -> bool {
    Command::new(ffmpeg)
        .arg("-version")
        .stdin(Stdio::null())
        .stderr(Stdio::null())
        .output()
        .map_or(true, |out| {
            version_has_fps_mode(
                String::from_utf8_lossy(&out.stdout)
                    .lines()
                    .next()
                    .unwrap_or(""),
            )
        })
}

/// [`knows_fps_mode`] on the first line of `ffmpeg -version`.
pub(crate) fn version_has_fps_mode(first_line: &str) -> bool {
    let Some(version) = first_line.split_whitespace().nth(2) else {
        return true;
    };
    let mut parts = version
        .trim_start_matches('n')
        .split(|c: char| !c.is_ascii_digit())
        .map(|p| p.parse::<u32>().ok());
    match (parts.next().flatten(), parts.next().flatten()) {
        (Some(major), minor) => (major, minor.unwrap_or(0)) >= (5, 1),
        _ => true,
    }
}

/// How many packets of a variable-rate stream come before `pts` (in the stream's time
/// base): the index of the frame shown at `pts`. Reads the file from its start to a
/// little past `pts` only.
fn packets_before(
    ffprobe: &str,
    path: &Path,
    stream_index: u64,
    pts: i64,
    seconds: f64,
) -> Result<u64, DataError> {
    // Packets are in decode order: read 2 s more so that none shown before `pts` is
    // missed.
    let (stream, interval) = (stream_index.to_string(), format!("%{:.6}", seconds + 2.0));
    let stdout = super::probe::ffprobe(
        ffprobe,
        path,
        &[
            "-v",
            "error",
            "-select_streams",
            &stream,
            "-read_intervals",
            &interval,
            "-show_entries",
            "packet=pts,flags",
            "-of",
            "csv=p=0",
        ],
        "ffprobe could not list the packets",
    )?;
    let count = String::from_utf8_lossy(&stdout)
        .lines()
        .filter(|line| {
            let (packet_pts, flags) = line.split_once(',').unwrap_or((line, ""));
            // Packets flagged D (before an edit list's start) are decoded, never shown.
            !flags.contains('D') && packet_pts.trim().parse::<i64>().is_ok_and(|p| p < pts)
        })
        .count();
    Ok(count as u64)
}

/// What the stderr thread knows of a frame that came out of the filters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Stamp {
    /// Its pts in the filters' time base (`None`: the frame had none).
    pub pts: Option<i64>,
    /// Its rank among the frames decoded in the window (0 = the first).
    pub rank: u64,
    /// The pts of the first frame decoded in the window.
    pub first_pts: Option<i64>,
}

/// Turns [`Stamp`]s into source indices and times.
#[derive(Debug)]
struct Clock {
    /// The stream's time base (of `start_pts` and of packets).
    stream_tb: Ratio,
    /// The time base of the pts `showinfo` prints (the stream's, unless it says).
    filter_tb: Ratio,
    /// The stream's first pts.
    start_pts: i64,
    /// The stream's frame rate.
    rate: Ratio,
    /// Whether the container declares a constant frame rate.
    constant_rate: bool,
    /// The source index of the first frame decoded in the window, once known.
    first: Option<u64>,
    /// The `ffprobe` program (to count packets before a seek point).
    ffprobe: &'static str,
    /// The video stream's index in the file.
    stream_index: u64,
}

impl Clock {
    /// `pts − start_pts` in seconds, as an exact ratio `(num, den)`.
    fn since_start(&self, pts: i64) -> (i128, i128) {
        let (f, s) = (self.filter_tb, self.stream_tb);
        let num = i128::from(pts) * i128::from(f.num) * i128::from(s.den)
            - i128::from(self.start_pts) * i128::from(s.num) * i128::from(f.den);
        (num, i128::from(f.den) * i128::from(s.den))
    }

    /// `round(t × fps)` for a time `t = num / den`.
    fn grid_index(&self, (num, den): (i128, i128)) -> i128 {
        round_div(
            num * i128::from(self.rate.num),
            den * i128::from(self.rate.den),
        )
    }

    /// Source index and time of a frame.
    fn stamp(&mut self, stamp: &Stamp, path: &Path) -> Result<(u64, f64), DataError> {
        let first = match self.first {
            Some(first) => first,
            None => {
                let first = match stamp.first_pts {
                    None => 0,
                    Some(pts) if self.constant_rate => {
                        self.grid_index(self.since_start(pts)).max(0) as u64
                    }
                    Some(pts) => {
                        let (f, s) = (self.filter_tb, self.stream_tb);
                        let in_stream = round_div(
                            i128::from(pts) * i128::from(f.num) * i128::from(s.den),
                            i128::from(f.den) * i128::from(s.num),
                        ) as i64;
                        let seconds = pts as f64 * f.to_f64();
                        packets_before(self.ffprobe, path, self.stream_index, in_stream, seconds)?
                    }
                };
                self.first = Some(first);
                first
            }
        };
        let index = first + stamp.rank;
        let rate = self.rate;
        let Some(pts) = stamp.pts else {
            return Ok((
                index,
                exact(
                    i128::from(index) * i128::from(rate.den),
                    i128::from(rate.num),
                ),
            ));
        };
        let t = self.since_start(pts);
        let real = exact(t.0, t.1);
        if self.constant_rate {
            let grid = exact(
                self.grid_index(t) * i128::from(rate.den),
                i128::from(rate.num),
            );
            if (real - grid).abs() <= self.filter_tb.to_f64() {
                return Ok((index, grid));
            }
        }
        Ok((index, real))
    }
}

/// `num / den` rounded to the nearest integer (halves away from zero), `den > 0`.
fn round_div(num: i128, den: i128) -> i128 {
    if num >= 0 {
        (2 * num + den) / (2 * den)
    } else {
        -((-2 * num + den) / (2 * den))
    }
}

/// `num / den` as the nearest float: reduced first, so that e.g. 512·i / 15360 gives
/// exactly the same float as i / 30.
fn exact(num: i128, den: i128) -> f64 {
    let g = gcd(num.unsigned_abs(), den.unsigned_abs()).max(1) as i128;
    (num / g) as f64 / (den / g) as f64
}

fn gcd(mut a: u128, mut b: u128) -> u128 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// What the stderr thread reports.
#[derive(Debug, PartialEq)]
pub(crate) enum Event {
    /// `showinfo`'s input time base.
    TimeBase(Ratio),
    /// A frame came out of the filters.
    Frame(Stamp),
    /// An error line (one line, without the context's address).
    Problem(String),
}

/// One line of ffmpeg's stderr, as far as the reader cares.
#[derive(Debug, PartialEq)]
pub(crate) enum Line {
    /// `showinfo` reported its input time base.
    TimeBase(Ratio),
    /// `showinfo@in` saw a decoded frame with this pts.
    Decoded(Option<i64>),
    /// `showinfo@out` saw a kept frame with this pts.
    Kept(Option<i64>),
    /// An error, fatal or panic line.
    Problem(String),
}

/// Drain ffmpeg's stderr until it closes, turning `showinfo` lines into [`Stamp`]s and
/// error lines into problems. Keeps reading after the reader is gone so that ffmpeg
/// never blocks on a full pipe. Only kept frames are sent, so the channel holds at
/// most the frames ffmpeg is ahead by (a pipe's worth).
fn watch(stderr: impl Read, events: Sender<Event>) {
    let mut reader = BufReader::new(stderr);
    let mut line = Vec::new();
    let (mut decoded, mut first_pts) = (0u64, None);
    loop {
        line.clear();
        match reader.read_until(b'\n', &mut line) {
            Ok(0) | Err(_) => break,
            Ok(_) => {}
        }
        let event = match parse_line(String::from_utf8_lossy(&line).trim_end()) {
            Some(Line::TimeBase(tb)) => Event::TimeBase(tb),
            Some(Line::Decoded(pts)) => {
                if decoded == 0 {
                    first_pts = pts;
                }
                decoded += 1;
                continue;
            }
            Some(Line::Kept(pts)) => Event::Frame(Stamp {
                pts,
                rank: decoded.saturating_sub(1),
                first_pts,
            }),
            Some(Line::Problem(problem)) => Event::Problem(problem),
            None => continue,
        };
        let _ = events.send(event);
    }
}

/// One line of `-loglevel level+info` output: `[context @ 0x…] [level] message`, the
/// context being optional.
pub(crate) fn parse_line(line: &str) -> Option<Line> {
    let (context, rest) = match line.strip_prefix('[') {
        Some(inner) if inner.split(']').next()?.contains(" @ ") => {
            let (context, rest) = inner.split_once("] ")?;
            (context.split(" @ ").next().unwrap_or(context), rest)
        }
        _ => ("", line),
    };
    let (level, message) = rest.strip_prefix('[')?.split_once(']')?;
    let message = message.trim_start();
    match level {
        // `NULL` is how a parser without a name shows.
        "error" | "fatal" | "panic" => {
            Some(Line::Problem(if context.is_empty() || context == "NULL" {
                format!("ffmpeg: {message}")
            } else {
                format!("ffmpeg: {context}: {message}")
            }))
        }
        "info" if context == "showinfo@in" || context == "showinfo@out" => {
            if let Some(tb) = message.strip_prefix("config in time_base:") {
                Ratio::parse(tb.split(',').next()?).map(Line::TimeBase)
            } else if message.starts_with("n:") {
                let pts = message.split_once(" pts:")?.1.split_whitespace().next()?;
                let pts = pts.parse().ok();
                Some(if context == "showinfo@in" {
                    Line::Decoded(pts)
                } else {
                    Line::Kept(pts)
                })
            } else {
                None
            }
        }
        _ => None,
    }
}
