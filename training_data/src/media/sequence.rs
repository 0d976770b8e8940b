//! [`ImageSequence`]: a folder of images read as frames, in natural name order.
use super::{DecodedFrame, MediaInfo, Sampling};
use crate::DataError;
use image::RgbImage;
use image::imageops::FilterType;
use std::cmp::Ordering;
use std::path::{Path, PathBuf};

/// The file extensions read (compared without case).
const EXTENSIONS: [&str; 3] = ["jpg", "jpeg", "png"];

/// Frames of a folder of `.jpg` / `.jpeg` / `.png` images, in natural name order
/// ([`natural_cmp`]: `000002 < 000010`, `img2 < img10`). Hidden files and other files
/// are skipped.
///
/// Frame `i` (its position in that order) is shown at `i / fps` seconds. Images are
/// decoded one at a time, when the iterator reaches them; a corrupt one is an error
/// naming the file, and so is one whose size differs from the first image's unless
/// [`Sampling::size`] resizes them all (bilinear, the aspect ratio not kept).
#[derive(Debug)]
pub struct ImageSequence {
    folder: PathBuf,
    files: Vec<PathBuf>,
    info: MediaInfo,
    sampling: Sampling,
    /// The next position to look at.
    next: usize,
    /// The `fps` slot of the previous frame in the window.
    prev_slot: Option<u64>,
    /// Frames kept by the window and `fps` so far (what `every` counts).
    kept: u64,
    frames_read: u64,
    done: bool,
}

impl ImageSequence {
    /// List the images of `folder`, to be shown at `fps` frames per second.
    ///
    /// Fails, naming the folder, when it cannot be read, holds no image, `fps` is not a
    /// positive number or the sampling is invalid; naming the file when the first image
    /// cannot be read.
    pub fn open(folder: &Path, fps: f64, sampling: &Sampling) -> Result<Self, DataError> {
        sampling.check(folder)?;
        if !(fps.is_finite() && fps > 0.0) {
            return Err(DataError::invalid(
                folder,
                "image sequence",
                format!("the frame rate must be a positive number, not {fps}"),
            ));
        }
        let mut files = Vec::new();
        for entry in std::fs::read_dir(folder).map_err(|e| DataError::io(folder, e))? {
            let path = entry.map_err(|e| DataError::io(folder, e))?.path();
            let name = path.file_name().unwrap_or_default().to_string_lossy();
            let image = !name.starts_with('.')
                && path.extension().is_some_and(|ext| {
                    EXTENSIONS.contains(&ext.to_string_lossy().to_ascii_lowercase().as_str())
                });
            if image && path.is_file() {
                files.push(path);
            }
        }
        if files.is_empty() {
            return Err(DataError::invalid(
                folder,
                "image sequence",
                "no .jpg, .jpeg or .png image in the folder",
            ));
        }
        files.sort_by(|a, b| natural_cmp(&file_name(a), &file_name(b)));
        let (width, height) =
            image::image_dimensions(&files[0]).map_err(|e| DataError::image(&files[0], e))?;
        let mut codecs: Vec<&str> = Vec::new();
        for file in &files {
            let ext = file.extension().unwrap_or_default().to_ascii_lowercase();
            let codec = if ext == "png" { "png" } else { "jpeg" };
            if !codecs.contains(&codec) {
                codecs.push(codec);
            }
        }
        let duration = files.len() as f64 / fps;
        if let Some(start) = sampling.start_s
            && start >= duration
        {
            return Err(DataError::invalid(
                folder,
                "sampling",
                format!("start_s {start} s is at or after the end of the sequence ({duration} s)"),
            ));
        }
        Ok(Self {
            folder: folder.to_path_buf(),
            info: MediaInfo {
                width,
                height,
                fps,
                frames: Some(files.len() as u64),
                duration_s: Some(duration),
                codec: codecs.join(","),
            },
            files,
            sampling: sampling.clone(),
            next: 0,
            prev_slot: None,
            kept: 0,
            frames_read: 0,
            done: false,
        })
    }

    /// The sequence's description: the first image's size, the given rate, the number
    /// of images.
    pub fn info(&self) -> &MediaInfo {
        &self.info
    }

    /// The image files, in frame order.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// How many frames were returned so far.
    pub fn frames_read(&self) -> u64 {
        self.frames_read
    }

    /// The next position kept by the sampling, or `None` at the end.
    fn next_position(&mut self) -> Option<usize> {
        let fps = self.info.fps;
        while self.next < self.files.len() {
            let i = self.next;
            self.next += 1;
            let t = i as f64 / fps;
            if self.sampling.start_s.is_some_and(|start| t < start - 1e-9) {
                continue;
            }
            if self.sampling.end_s.is_some_and(|end| t >= end - 1e-9) {
                break;
            }
            if let Some(rate) = self.sampling.fps {
                let slot = slot(i as u64, rate, fps);
                let first = self.prev_slot != Some(slot);
                self.prev_slot = Some(slot);
                if !first {
                    continue;
                }
            }
            self.kept += 1;
            if (self.kept - 1).is_multiple_of(self.sampling.step()) {
                return Some(i);
            }
        }
        self.next = self.files.len();
        None
    }

    /// Decode the image at position `i`, resized as asked.
    fn load(&self, i: usize) -> Result<RgbImage, DataError> {
        let file = &self.files[i];
        let image = image::ImageReader::open(file)
            .and_then(|reader| reader.with_guessed_format())
            .map_err(|e| DataError::io(file, e))?
            .decode()
            .map_err(|e| DataError::image(file, e))?
            .into_rgb8();
        match self.sampling.size {
            Some((w, h)) if image.dimensions() != (w, h) => {
                Ok(image::imageops::resize(&image, w, h, FilterType::Triangle))
            }
            Some(_) => Ok(image),
            None if image.dimensions() != (self.info.width, self.info.height) => {
                Err(DataError::invalid(
                    file,
                    "image sequence",
                    format!(
                        "the image is {}x{} but the sequence's first image is {}x{} \
                         (give a size to resize them all)",
                        image.width(),
                        image.height(),
                        self.info.width,
                        self.info.height
                    ),
                ))
            }
            None => Ok(image),
        }
    }
}

impl Iterator for ImageSequence {
    type Item = Result<DecodedFrame, DataError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let Some(i) = self.next_position() else {
            self.done = true;
            if self.frames_read == 0 {
                let (start, end) = (self.sampling.start_s, self.sampling.end_s);
                return Some(Err(DataError::invalid(
                    &self.folder,
                    "sampling",
                    format!(
                        "no frame in the window from {} s to {}",
                        start.unwrap_or(0.0),
                        end.map_or("the end".to_string(), |e| format!("{e} s"))
                    ),
                )));
            }
            return None;
        };
        match self.load(i) {
            Ok(image) => {
                self.frames_read += 1;
                Some(Ok(DecodedFrame {
                    index: i as u64,
                    time_s: i as f64 / self.info.fps,
                    image,
                }))
            }
            Err(e) => {
                self.done = true;
                Some(Err(e))
            }
        }
    }
}

impl std::iter::FusedIterator for ImageSequence {}

/// A path's file name as text.
fn file_name(path: &Path) -> std::borrow::Cow<'_, str> {
    path.file_name().unwrap_or_default().to_string_lossy()
}

/// The `1 / fps` slot of the frame at `index` of a source running at `source_fps`. A
/// frame is kept when it opens a new slot: the first frame at or after each multiple of
/// `1 / fps` seconds, counted on the source's frame grid.
fn slot(index: u64, fps: f64, source_fps: f64) -> u64 {
    (index as f64 * fps / source_fps + 1e-9).floor() as u64
}

/// Natural order of file names: runs of digits compare as numbers (`img2 < img10`,
/// `000002 < 000010`), other characters without case; names equal that way (`img01`,
/// `img1`) fall back to plain string order, so the order is total.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut x, mut y) = (a, b);
    loop {
        let (Some(c), Some(d)) = (x.chars().next(), y.chars().next()) else {
            return x
                .is_empty()
                .cmp(&y.is_empty())
                .reverse()
                .then_with(|| a.cmp(b));
        };
        if c.is_ascii_digit() && d.is_ascii_digit() {
            let (nx, rx) = x.split_at(x.find(|ch: char| !ch.is_ascii_digit()).unwrap_or(x.len()));
            let (ny, ry) = y.split_at(y.find(|ch: char| !ch.is_ascii_digit()).unwrap_or(y.len()));
            let (nx, ny) = (nx.trim_start_matches('0'), ny.trim_start_matches('0'));
            let order = nx.len().cmp(&ny.len()).then_with(|| nx.cmp(ny));
            if order != Ordering::Equal {
                return order;
            }
            (x, y) = (rx, ry);
        } else {
            let order = c.to_lowercase().cmp(d.to_lowercase());
            if order != Ordering::Equal {
                return order;
            }
            (x, y) = (&x[c.len_utf8()..], &y[d.len_utf8()..]);
        }
    }
}
