//! Video files and image-sequence folders read as streams of RGB frames with timestamps.
//!
//! # Why the `ffmpeg` program rather than libav bindings
//!
//! Videos are decoded by spawning the `ffmpeg` program and reading raw `rgb24` frames
//! from its stdout pipe, not by linking libavcodec through Rust bindings:
//! - nothing at build time: no libav headers, no version of the bindings to match to the
//!   installed libraries, no C toolchain for them; the crate builds wherever Rust does;
//! - the decoder is the same `ffmpeg` users already have and can try their files with on
//!   the command line, with every codec and container of their distribution's build;
//! - a decoder that crashes or misbehaves on a broken file takes down its own process
//!   only: the reader turns that into an error naming the file instead of aborting a
//!   training or import run.
//!
//! The price is a process start per video (milliseconds) and one copy of each frame
//! through a pipe, small next to decoding (`benches/decode.rs` measures both side by
//! side with plain `ffmpeg`).
//!
//! # What is read
//!
//! - [`probe`]: size, frame rate, frame count, duration and codec of a file's first
//!   video stream, from `ffprobe -of json`.
//! - [`VideoReader`]: frames of a video file, optionally sampled ([`Sampling`]): a time
//!   window, a maximum frame rate, one frame in `every`, a resize. Sampling is done by
//!   ffmpeg filters so that skipped frames are never converted or piped.
//! - [`ImageSequence`]: a folder of `.jpg` / `.jpeg` / `.png` images in natural name
//!   order, at a frame rate given by the caller, with the same sampling.
//! - [`FrameSource`]: either of them, chosen by whether the path is a folder.
//!
//! Every frame is a [`DecodedFrame`]: its index in the source (before sampling), its
//! presentation time in seconds from the start of the stream, and the RGB image. Memory
//! stays bounded: one frame at a time is read from the pipe (ffmpeg blocks when the
//! reader does not keep up) and images of a sequence are decoded one at a time.
//!
//! # Errors
//!
//! Every failure is a [`DataError`] whose message is one line naming the file: a missing
//! file, a file that is empty, not a video, has no video stream or no frames, a stream
//! that is truncated or corrupt (ffmpeg's exit status, any error line it prints, or a
//! partial frame at the end of the pipe), a corrupt image in a sequence, and `ffmpeg` /
//! `ffprobe` not installed. Nothing here panics on bad input. After an error the
//! iterator ends.
//!
//! ```no_run
//! use frugal_data::media::{FrameSource, Sampling};
//! # fn main() -> Result<(), frugal_data::DataError> {
//! let sampling = Sampling { fps: Some(5.0), size: Some((480, 270)), ..Sampling::default() };
//! for frame in FrameSource::open("flight.mp4".as_ref(), None, &sampling)? {
//!     let frame = frame?;
//!     println!("frame {} at {:.3} s: {}x{}", frame.index, frame.time_s, frame.image.width(), frame.image.height());
//! }
//! # Ok(())
//! # }
//! ```
mod probe;
mod sequence;
mod video;

pub use probe::probe;
pub use sequence::{ImageSequence, natural_cmp};
pub use video::VideoReader;

use crate::DataError;
use std::path::Path;

/// What `ffmpeg` and `ffprobe` say when they are missing.
const INSTALL_HINT: &str = "install ffmpeg, e.g. `cargo xtask setup`";

/// The programs used, by name on the `PATH` (tests swap in missing ones).
#[derive(Debug)]
pub(crate) struct Tools {
    /// The `ffmpeg` program.
    pub ffmpeg: &'static str,
    /// The `ffprobe` program.
    pub ffprobe: &'static str,
    /// Whether this `ffmpeg` knows `-fps_mode` (5.1 and later), asked once.
    pub fps_mode: std::sync::OnceLock<bool>,
}

/// The installed `ffmpeg` and `ffprobe`.
pub(crate) static TOOLS: Tools = Tools {
    ffmpeg: "ffmpeg",
    ffprobe: "ffprobe",
    fps_mode: std::sync::OnceLock::new(),
};

/// A stream's description, from `ffprobe` (video) or from the first image (sequence).
#[derive(Clone, Debug, PartialEq)]
pub struct MediaInfo {
    /// Width of the decoded frames in pixels (after the container's rotation, if any).
    pub width: u32,
    /// Height of the decoded frames in pixels (after the container's rotation, if any).
    pub height: u32,
    /// Frames per second: the stream's average rate, or the rate given for a sequence.
    pub fps: f64,
    /// Number of frames when the container says (MP4, MOV, AVI do; MKV does not), or the
    /// number of images of a sequence.
    pub frames: Option<u64>,
    /// Duration in seconds when known.
    pub duration_s: Option<f64>,
    /// Codec name as ffprobe spells it (`h264`, `mjpeg`, …); `png` / `jpeg` (or both,
    /// comma-separated) for a sequence.
    pub codec: String,
}

/// Which frames to read, at what size, and with how many decoder threads.
///
/// The steps apply in this order: the window `[start_s, end_s)`, then `fps`, then
/// `every`, then `size`. The default reads every frame at its own size.
#[derive(Clone, Debug, Default)]
pub struct Sampling {
    /// Keep one frame in `every` (the first, then every `every`-th, counted among the
    /// frames that the window and `fps` kept); 0 or 1 keep all.
    pub every: u32,
    /// Keep at most this many frames per second: the first frame at or after each
    /// multiple of `1 / fps` seconds. Frames are never duplicated, so a rate above the
    /// source's keeps every frame; timestamps stay the source's.
    pub fps: Option<f64>,
    /// Start of the window in seconds from the stream start (inclusive).
    pub start_s: Option<f64>,
    /// End of the window in seconds from the stream start (exclusive).
    pub end_s: Option<f64>,
    /// Resize every frame to exactly this width and height (area averaging when
    /// shrinking, bilinear when enlarging; the aspect ratio is not kept).
    pub size: Option<(u32, u32)>,
    /// Decoder threads for videos (`ffmpeg -threads`); `None` lets ffmpeg choose.
    pub threads: Option<u32>,
}

impl Sampling {
    /// Check the values: `fps > 0`, `0 ≤ start_s < end_s`, a non-empty `size`,
    /// `threads ≥ 1`. `path` is the file the error names.
    pub fn check(&self, path: &Path) -> Result<(), DataError> {
        let bad = |problem: String| Err(DataError::invalid(path, "sampling", problem));
        if let Some(fps) = self.fps
            && !(fps.is_finite() && fps > 0.0)
        {
            return bad(format!("fps must be a positive number, not {fps}"));
        }
        if let Some(start) = self.start_s
            && !(start.is_finite() && start >= 0.0)
        {
            return bad(format!("start_s must be ≥ 0 s, not {start}"));
        }
        if let Some(end) = self.end_s {
            let start = self.start_s.unwrap_or(0.0);
            if !(end.is_finite() && end > start) {
                return bad(format!(
                    "end_s ({end} s) must come after start_s ({start} s)"
                ));
            }
        }
        if let Some((w, h)) = self.size
            && (w == 0 || h == 0)
        {
            return bad(format!("size must not be empty, not {w}x{h}"));
        }
        if self.threads == Some(0) {
            return bad("threads must be ≥ 1 (or unset to let ffmpeg choose)".into());
        }
        Ok(())
    }

    /// `every` with 0 read as 1.
    fn step(&self) -> u64 {
        u64::from(self.every.max(1))
    }
}

/// One frame read from a video or an image sequence.
#[derive(Clone)]
pub struct DecodedFrame {
    /// The frame's index in the source (0-based, counting every frame before sampling).
    pub index: u64,
    /// Presentation time in seconds from the start of the stream.
    pub time_s: f64,
    /// The frame, resized if [`Sampling::size`] asked.
    pub image: image::RgbImage,
}

impl std::fmt::Debug for DecodedFrame {
    /// Index, time and size (not the pixels).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DecodedFrame")
            .field("index", &self.index)
            .field("time_s", &self.time_s)
            .field("size", &self.image.dimensions())
            .finish()
    }
}

/// Frames of either a video file or a folder of images.
#[derive(Debug)]
pub enum FrameSource {
    /// A video file, decoded by ffmpeg.
    Video(VideoReader),
    /// A folder of images.
    Sequence(ImageSequence),
}

impl FrameSource {
    /// Open `path`: a folder is read as an image sequence at `fps_for_sequences` frames
    /// per second (required then), anything else as a video file.
    pub fn open(
        path: &Path,
        fps_for_sequences: Option<f64>,
        sampling: &Sampling,
    ) -> Result<Self, DataError> {
        if path.is_dir() {
            let Some(fps) = fps_for_sequences else {
                return Err(DataError::invalid(
                    path,
                    "image sequence",
                    "a folder of images has no frame rate of its own; give one",
                ));
            };
            Ok(Self::Sequence(ImageSequence::open(path, fps, sampling)?))
        } else {
            Ok(Self::Video(VideoReader::open(path, sampling)?))
        }
    }

    /// The source's description.
    pub fn info(&self) -> &MediaInfo {
        match self {
            Self::Video(v) => v.info(),
            Self::Sequence(s) => s.info(),
        }
    }

    /// How many frames were returned so far.
    pub fn frames_read(&self) -> u64 {
        match self {
            Self::Video(v) => v.frames_read(),
            Self::Sequence(s) => s.frames_read(),
        }
    }
}

impl Iterator for FrameSource {
    type Item = Result<DecodedFrame, DataError>;

    fn next(&mut self) -> Option<Self::Item> {
        match self {
            Self::Video(v) => v.next(),
            Self::Sequence(s) => s.next(),
        }
    }
}

#[cfg(test)]
mod tests;
