//! Video in: a reader thread decodes the input continuously and leaves the newest
//! frames in a bounded [`Mailbox`] (`[input] queue` frames, 1 = only the newest); when
//! it is full the oldest frame waiting is dropped (the latest-frame rule: perception is
//! never more than `queue` frames behind the camera) and counted. Inputs
//! ([`Input::parse`]):
//!
//! - a video file, decoded by `frugal_data::media` (the `ffmpeg` program) with each
//!   frame's exact presentation time; paced at those times (`realtime`, the default, as
//!   a camera would deliver them) or read as fast as perception takes them
//!   (`every frame`, no drops);
//! - a folder of images (`.png`, `.jpg`, `.jpeg`, `.ppm`) in natural name order at a
//!   given rate; an image that does not decode is skipped and counted;
//! - a V4L2 camera (`/dev/videoN`) or a network stream (`rtp://`, `udp://`, `rtsp://`,
//!   `srt://`, `tcp://` or an `.sdp` file) through an `ffmpeg` child that writes raw RGB
//!   frames to a pipe; frames are stamped on arrival. A stream that ends, fails or
//!   stalls (no frame for `stall_timeout_ms`) is reported and reopened after a backoff
//!   that doubles on each failure in a row; after `retries` failures in a row the
//!   input gives up. Decoder error lines from ffmpeg (a corrupt packet: the frame is
//!   dropped or concealed by the decoder) are counted as corrupt frames.
use crate::config::InputConfig;
use frugal_data::media::{FrameSource, Sampling, natural_cmp};
use image::RgbImage;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, sync_channel};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// Where frames come from.
#[derive(Clone, Debug, PartialEq)]
pub enum Input {
    /// A video file.
    File(PathBuf),
    /// A folder of images at `fps` frames per second.
    Folder(PathBuf, f64),
    /// A V4L2 device.
    Camera(PathBuf),
    /// A network stream URL or an SDP file, opened by ffmpeg.
    Stream(String),
}

impl Input {
    /// Tell what `spec` names: `/dev/…` is a camera, a URL or an `.sdp` file a stream,
    /// a folder an image sequence (at `fps`), anything else a video file.
    pub fn parse(spec: &str, fps: f64) -> Self {
        let is_url = ["rtp://", "udp://", "rtsp://", "srt://", "tcp://"]
            .iter()
            .any(|p| spec.starts_with(p));
        if is_url || spec.ends_with(".sdp") {
            Input::Stream(spec.to_owned())
        } else if spec.starts_with("/dev/") {
            Input::Camera(PathBuf::from(spec))
        } else if Path::new(spec).is_dir() {
            Input::Folder(PathBuf::from(spec), fps)
        } else {
            Input::File(PathBuf::from(spec))
        }
    }

    /// A live input (camera or stream): retried when it fails.
    pub fn is_live(&self) -> bool {
        matches!(self, Input::Camera(_) | Input::Stream(_))
    }

    /// How the input is named in messages.
    pub fn name(&self) -> String {
        match self {
            Input::File(p) | Input::Folder(p, _) | Input::Camera(p) => p.display().to_string(),
            Input::Stream(s) => s.clone(),
        }
    }
}

/// One decoded frame.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Number of the frame in the input (files and folders: its index in the source;
    /// live inputs: counted from the first frame received).
    pub index: u64,
    /// Presentation time (files, folders) or arrival time since the start (live), s.
    pub time_s: f64,
    /// When the frame was handed over by the reader.
    pub arrived: Instant,
    /// The pixels, at the configured size.
    pub image: RgbImage,
}

/// Counters the reader keeps.
#[derive(Debug, Default)]
pub struct InputStats {
    /// Frames decoded and handed over.
    pub frames: AtomicU64,
    /// Frames skipped as corrupt (undecodable images; decoder errors of a stream).
    pub corrupt: AtomicU64,
    /// Reconnections of a live input.
    pub reconnects: AtomicU64,
}

#[derive(Default)]
struct Slot {
    frames: std::collections::VecDeque<Frame>,
    drops: u64,
    closed: bool,
    error: Option<String>,
}

/// The bounded queue between the reader and perception.
pub struct Mailbox {
    slot: Mutex<Slot>,
    changed: Condvar,
    capacity: usize,
}

impl Mailbox {
    /// A mailbox holding at most `capacity` frames (at least 1).
    pub fn new(capacity: usize) -> Self {
        Self {
            slot: Mutex::default(),
            changed: Condvar::new(),
            capacity: capacity.max(1),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Slot> {
        self.slot
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Leave `frame` as the newest, dropping the oldest waiting frame when the queue
    /// is full. `wait`: block until there is room instead of dropping (every-frame
    /// mode) — or until `stop` is raised.
    pub fn put(&self, frame: Frame, wait: bool, stop: &AtomicBool) {
        let mut slot = self.lock();
        while wait && slot.frames.len() >= self.capacity && !stop.load(Ordering::Relaxed) {
            slot = self
                .changed
                .wait_timeout(slot, Duration::from_millis(50))
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
        if wait && slot.frames.len() >= self.capacity {
            // stopping: the frame is not handed over, and no frame was dropped for it
            return;
        }
        while slot.frames.len() >= self.capacity {
            slot.frames.pop_front();
            slot.drops += 1;
        }
        slot.frames.push_back(frame);
        self.changed.notify_all();
    }

    /// No more frames; `error` says why, when the input failed.
    pub fn close(&self, error: Option<String>) {
        let mut slot = self.lock();
        slot.closed = true;
        slot.error = error;
        self.changed.notify_all();
    }

    /// The oldest frame waiting, waiting for one; `None` once the input is closed and
    /// empty or `stop` is raised.
    pub fn take(&self, stop: &AtomicBool) -> Option<Frame> {
        let mut slot = self.lock();
        loop {
            if let Some(frame) = slot.frames.pop_front() {
                self.changed.notify_all();
                return Some(frame);
            }
            if slot.closed || stop.load(Ordering::Relaxed) {
                return None;
            }
            slot = self
                .changed
                .wait_timeout(slot, Duration::from_millis(50))
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
    }

    /// Frames overwritten before perception took them.
    pub fn drops(&self) -> u64 {
        self.lock().drops
    }

    /// Why the input ended, when it failed.
    pub fn error(&self) -> Option<String> {
        self.lock().error.clone()
    }
}

/// What the reader thread needs.
pub struct Reader {
    /// The input.
    pub input: Input,
    /// Frame size, pixels.
    pub size: (u32, u32),
    /// Pace files and folders at their timestamps (frames may drop) rather than
    /// handing over every frame.
    pub realtime: bool,
    /// Retry policy of live inputs.
    pub retry: InputConfig,
    /// Where problems are reported (one line each).
    pub report: fn(&str),
}

impl Reader {
    /// Read until the input ends, fails for good, or `stop` is raised; then close
    /// the mailbox.
    pub fn run(&self, mailbox: &Mailbox, stats: &Arc<InputStats>, stop: &AtomicBool) {
        let result = match &self.input {
            Input::File(path) => self.file(path, mailbox, stats, stop),
            Input::Folder(dir, fps) => self.folder(dir, *fps, mailbox, stats, stop),
            Input::Camera(_) | Input::Stream(_) => self.live(mailbox, stats, stop),
        };
        mailbox.close(result.err());
    }

    fn hand_over(&self, frame: Frame, mailbox: &Mailbox, stats: &InputStats, stop: &AtomicBool) {
        stats.frames.fetch_add(1, Ordering::Relaxed);
        mailbox.put(frame, !self.realtime, stop);
    }

    /// Sleep until `at`, waking for `stop`.
    fn pace(at: Instant, stop: &AtomicBool) {
        while !stop.load(Ordering::Relaxed) {
            let now = Instant::now();
            if now >= at {
                return;
            }
            std::thread::sleep((at - now).min(Duration::from_millis(20)));
        }
    }

    fn file(
        &self,
        path: &Path,
        mailbox: &Mailbox,
        stats: &InputStats,
        stop: &AtomicBool,
    ) -> Result<(), String> {
        let sampling = Sampling {
            size: Some(self.size),
            ..Sampling::default()
        };
        let source = FrameSource::open(path, None, &sampling).map_err(|e| e.to_string())?;
        let start = Instant::now();
        let mut first = None;
        for frame in source {
            if stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            let frame = frame.map_err(|e| e.to_string())?;
            if self.realtime {
                let t0 = *first.get_or_insert(frame.time_s);
                Self::pace(
                    start + Duration::from_secs_f64((frame.time_s - t0).max(0.0)),
                    stop,
                );
            }
            let frame = Frame {
                index: frame.index,
                time_s: frame.time_s,
                arrived: Instant::now(),
                image: frame.image,
            };
            self.hand_over(frame, mailbox, stats, stop);
        }
        Ok(())
    }

    fn folder(
        &self,
        dir: &Path,
        fps: f64,
        mailbox: &Mailbox,
        stats: &InputStats,
        stop: &AtomicBool,
    ) -> Result<(), String> {
        let entries = std::fs::read_dir(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let mut files: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.extension().is_some_and(|x| {
                    let x = x.to_string_lossy().to_ascii_lowercase();
                    ["png", "jpg", "jpeg", "ppm"].contains(&x.as_str())
                })
            })
            .collect();
        files.sort_by(|a, b| {
            natural_cmp(
                &a.file_name().unwrap_or_default().to_string_lossy(),
                &b.file_name().unwrap_or_default().to_string_lossy(),
            )
        });
        if files.is_empty() {
            return Err(format!(
                "{}: no images (.png, .jpg, .jpeg, .ppm)",
                dir.display()
            ));
        }
        let start = Instant::now();
        for (i, file) in files.iter().enumerate() {
            if stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            let time_s = i as f64 / fps;
            if self.realtime {
                Self::pace(start + Duration::from_secs_f64(time_s), stop);
            }
            let image = match image::open(file) {
                Ok(img) => img.into_rgb8(),
                Err(e) => {
                    stats.corrupt.fetch_add(1, Ordering::Relaxed);
                    (self.report)(&format!(
                        "{}: skipped, does not decode: {e}",
                        file.display()
                    ));
                    continue;
                }
            };
            let image = if image.dimensions() == self.size {
                image
            } else {
                image::imageops::resize(
                    &image,
                    self.size.0,
                    self.size.1,
                    image::imageops::FilterType::Triangle,
                )
            };
            let frame = Frame {
                index: i as u64,
                time_s,
                arrived: Instant::now(),
                image,
            };
            self.hand_over(frame, mailbox, stats, stop);
        }
        Ok(())
    }

    /// ffmpeg's arguments for a live input.
    fn ffmpeg_args(&self) -> Vec<String> {
        let mut args: Vec<String> = [
            "-hide_banner",
            "-nostdin",
            "-nostats",
            "-loglevel",
            "error",
            "-fflags",
            "nobuffer",
            "-flags",
            "low_delay",
        ]
        .iter()
        .map(|s| (*s).to_owned())
        .collect();
        match &self.input {
            Input::Camera(dev) => {
                args.extend(["-f".into(), "v4l2".into(), "-i".into()]);
                args.push(dev.display().to_string());
            }
            Input::Stream(url) => {
                if url.ends_with(".sdp") {
                    args.extend(["-protocol_whitelist".into(), "file,udp,rtp".into()]);
                }
                args.extend(["-i".into(), url.clone()]);
            }
            Input::File(_) | Input::Folder(..) => {}
        }
        let (w, h) = self.size;
        for a in [
            "-an".to_owned(),
            "-vf".to_owned(),
            format!("scale=w={w}:h={h}:flags=area"),
            "-f".to_owned(),
            "rawvideo".to_owned(),
            "-pix_fmt".to_owned(),
            "rgb24".to_owned(),
            "pipe:1".to_owned(),
        ] {
            args.push(a);
        }
        args
    }

    fn live(
        &self,
        mailbox: &Mailbox,
        stats: &Arc<InputStats>,
        stop: &AtomicBool,
    ) -> Result<(), String> {
        let name = self.input.name();
        let start = Instant::now();
        let mut index = 0u64;
        let mut failures = 0u32;
        let stall = Duration::from_millis(self.retry.stall_timeout_ms);
        loop {
            if stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            let before = index;
            let problem = match Stream::spawn(&self.ffmpeg_args(), self.size, stats) {
                Err(e) => e,
                Ok(mut stream) => loop {
                    if stop.load(Ordering::Relaxed) {
                        stream.stop();
                        return Ok(());
                    }
                    match stream
                        .frames
                        .recv_timeout(stall.min(Duration::from_millis(100)))
                    {
                        Ok(buf) => {
                            stream.last = Instant::now();
                            let Some(image) = RgbImage::from_raw(self.size.0, self.size.1, buf)
                            else {
                                break "a frame of the wrong size".to_owned();
                            };
                            let frame = Frame {
                                index,
                                time_s: start.elapsed().as_secs_f64(),
                                arrived: Instant::now(),
                                image,
                            };
                            index += 1;
                            self.hand_over(frame, mailbox, stats, stop);
                        }
                        Err(RecvTimeoutError::Timeout) => {
                            if stream.last.elapsed() >= stall {
                                stream.stop();
                                break format!("stalled: no frame for {} ms", stall.as_millis());
                            }
                        }
                        Err(RecvTimeoutError::Disconnected) => {
                            break stream.finish();
                        }
                    }
                },
            };
            if index > before {
                failures = 0;
            }
            failures += 1;
            if failures > self.retry.retries {
                return Err(format!(
                    "{name}: {problem}; gave up after {} attempt(s) in a row",
                    failures
                ));
            }
            let wait = Duration::from_millis(
                self.retry
                    .backoff_ms
                    .saturating_mul(1 << (failures - 1).min(10))
                    .min(8000),
            );
            (self.report)(&format!(
                "{name}: {problem}; reconnecting in {} ms (attempt {failures} of {})",
                wait.as_millis(),
                self.retry.retries
            ));
            stats.reconnects.fetch_add(1, Ordering::Relaxed);
            Self::pace(Instant::now() + wait, stop);
        }
    }
}

/// One ffmpeg child writing raw frames.
struct Stream {
    child: Child,
    frames: Receiver<Vec<u8>>,
    errors: Arc<Mutex<Option<String>>>,
    last: Instant,
}

impl Stream {
    fn spawn(args: &[String], size: (u32, u32), stats: &Arc<InputStats>) -> Result<Self, String> {
        let mut child = Command::new("ffmpeg")
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| {
                format!("cannot start ffmpeg ({e}); install ffmpeg, e.g. `cargo xtask setup`")
            })?;
        let bytes = size.0 as usize * size.1 as usize * 3;
        let (tx, frames) = sync_channel(2);
        if let Some(mut out) = child.stdout.take() {
            std::thread::spawn(move || {
                loop {
                    let mut buf = vec![0u8; bytes];
                    if out.read_exact(&mut buf).is_err() || tx.send(buf).is_err() {
                        return;
                    }
                }
            });
        }
        let errors = Arc::new(Mutex::new(None));
        if let Some(err) = child.stderr.take() {
            let last = Arc::clone(&errors);
            // decoder complaints count as corrupt frames; the last line says why a
            // stream ended
            let stats = Arc::clone(stats);
            std::thread::spawn(move || {
                for line in BufReader::new(err).lines().map_while(Result::ok) {
                    let l = line.to_ascii_lowercase();
                    if l.contains("decod") || l.contains("corrupt") || l.contains("concealing") {
                        stats.corrupt.fetch_add(1, Ordering::Relaxed);
                    }
                    *last
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(line);
                }
            });
        }
        Ok(Self {
            child,
            frames,
            errors,
            last: Instant::now(),
        })
    }

    fn stop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// The stream ended: why.
    fn finish(&mut self) -> String {
        let status = self.child.wait();
        // give the stderr thread a moment to read the last line
        std::thread::sleep(Duration::from_millis(50));
        let last = self
            .errors
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone();
        match (status, last) {
            (Ok(s), Some(line)) => format!("ended ({s}): {line}"),
            (Ok(s), None) => format!("ended ({s})"),
            (Err(e), _) => format!("ended: {e}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(index: u64) -> Frame {
        Frame {
            index,
            time_s: index as f64 / 60.0,
            arrived: Instant::now(),
            image: RgbImage::new(2, 2),
        }
    }

    #[test]
    fn a_full_mailbox_drops_its_oldest_frame_and_counts_it() {
        let stop = AtomicBool::new(false);
        for capacity in [1, 3] {
            let mailbox = Mailbox::new(capacity);
            for i in 0..5 {
                mailbox.put(frame(i), false, &stop);
            }
            mailbox.close(None);
            let kept: Vec<u64> = std::iter::from_fn(|| mailbox.take(&stop))
                .map(|f| f.index)
                .collect();
            // the newest `capacity` frames, oldest first; the rest dropped
            let newest: Vec<u64> = (5 - capacity as u64..5).collect();
            assert_eq!(kept, newest, "capacity {capacity}");
            assert_eq!(mailbox.drops(), 5 - capacity as u64);
        }
    }

    #[test]
    fn every_frame_mode_waits_for_room_instead_of_dropping() {
        let stop = Arc::new(AtomicBool::new(false));
        let mailbox = Arc::new(Mailbox::new(2));
        let writer = {
            let (mailbox, stop) = (Arc::clone(&mailbox), Arc::clone(&stop));
            std::thread::spawn(move || {
                for i in 0..20 {
                    mailbox.put(frame(i), true, &stop);
                }
                mailbox.close(None);
            })
        };
        let mut got = Vec::new();
        while let Some(f) = mailbox.take(&stop) {
            got.push(f.index);
            std::thread::sleep(Duration::from_millis(1));
        }
        writer.join().unwrap();
        assert_eq!(got, (0..20).collect::<Vec<_>>());
        assert_eq!(mailbox.drops(), 0);
        // a reader stopped while the queue is full hands nothing over and drops nothing
        let full = Mailbox::new(1);
        full.put(frame(0), true, &stop);
        stop.store(true, Ordering::Relaxed);
        full.put(frame(1), true, &stop);
        assert_eq!(full.drops(), 0);
        assert_eq!(full.take(&AtomicBool::new(false)).map(|f| f.index), Some(0));
    }
}
