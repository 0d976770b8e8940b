//! Video annotation formats (MOT Challenge, CVAT for video, COCO with videos,
//! ImageNet VID) read into one neutral in-memory form, and written back as MOT or
//! COCO-video.
//!
//! The neutral form is [`VideoAnnotations`]: a class list and videos, each video a map
//! from **0-based** frame index to the boxes of that frame. Boxes are [`BBox`]es in
//! pixels with exclusive right / bottom edges (`x2 = x + w`), whatever the source's
//! corner convention. Each format's conventions are documented in its module:
//!
//! | format | input | module |
//! | --- | --- | --- |
//! | MOT Challenge `gt.txt` (7, 9 or 10 columns, 1-based frames) | the `gt.txt` file | [`mot`] |
//! | CVAT for video 1.1 XML (keyframes, interpolation, `outside`) | the XML file | [`cvat`] |
//! | COCO with videos (TAO and YouTube-VIS styles) | the JSON file | [`coco_video`] |
//! | ImageNet VID XML (one file per frame, inclusive corners) | a snippet folder, or a folder of them | [`imagenet_vid`] |
//!
//! [`read`] checks first that the input looks like the format asked for
//! ([`detect_format`]), so a CVAT file read as MOT fails with a message saying it is
//! CVAT. Every error is one line naming the file and the line, frame, track or id.
//!
//! ```no_run
//! use frugal_data::annotations::{self, AnnotationFormat, ReadOptions};
//! # fn main() -> Result<(), frugal_data::DataError> {
//! let path = std::path::Path::new("MOT17-02/gt/gt.txt");
//! let format = annotations::detect_format(path).unwrap_or(AnnotationFormat::Mot);
//! let ann = annotations::read(format, path, &ReadOptions::default())?;
//! for video in &ann.videos {
//!     for (frame, b) in video.boxes() {
//!         println!("{frame} {} {:?} ignore={}", ann.classes[b.class], b.bbox, b.ignore);
//!     }
//! }
//! annotations::write_coco_video(&ann, "out/mot17-02.json".as_ref())?;
//! # Ok(())
//! # }
//! ```
use crate::{BBox, DataError};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

pub mod coco_video;
pub mod cvat;
pub mod imagenet_vid;
pub mod mot;
mod write;

pub use mot::{MOT_CLASSES, MOT_DISTRACTORS};
pub use write::{write_coco_video, write_mot};

#[cfg(test)]
mod tests;

/// A video annotation format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AnnotationFormat {
    /// MOT Challenge ground truth `gt.txt` (see [`mot`]).
    Mot,
    /// CVAT for video 1.1 XML (see [`cvat`]).
    Cvat,
    /// COCO JSON with a `videos` list, TAO or YouTube-VIS style (see [`coco_video`]).
    CocoVideo,
    /// ImageNet VID (ILSVRC 2015) per-frame XML files (see [`imagenet_vid`]).
    ImagenetVid,
}

impl AnnotationFormat {
    /// Every format, in the order of [`AnnotationFormat::name`]'s documentation.
    pub const ALL: [AnnotationFormat; 4] = [
        AnnotationFormat::Mot,
        AnnotationFormat::Cvat,
        AnnotationFormat::CocoVideo,
        AnnotationFormat::ImagenetVid,
    ];

    /// `mot`, `cvat`, `coco-video` or `imagenet-vid`.
    pub fn name(self) -> &'static str {
        match self {
            AnnotationFormat::Mot => "mot",
            AnnotationFormat::Cvat => "cvat",
            AnnotationFormat::CocoVideo => "coco-video",
            AnnotationFormat::ImagenetVid => "imagenet-vid",
        }
    }

    /// The format of a [`name`](AnnotationFormat::name) (case-insensitive).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|f| f.name().eq_ignore_ascii_case(name.trim()))
    }

    /// What a file of this format is, for messages (`a MOT Challenge gt.txt`).
    pub fn describe(self) -> &'static str {
        match self {
            AnnotationFormat::Mot => "a MOT Challenge gt.txt",
            AnnotationFormat::Cvat => "a CVAT for video XML file",
            AnnotationFormat::CocoVideo => "a COCO-with-videos JSON file",
            AnnotationFormat::ImagenetVid => "ImageNet VID XML",
        }
    }
}

impl std::fmt::Display for AnnotationFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Annotations of one or more videos, in the neutral form.
#[derive(Clone, Debug, PartialEq)]
pub struct VideoAnnotations {
    /// The format they were read from.
    pub format: AnnotationFormat,
    /// Class names; [`AnnotatedBox::class`] indexes this list.
    pub classes: Vec<String>,
    /// The videos, in the source's order.
    pub videos: Vec<AnnotatedVideo>,
}

impl VideoAnnotations {
    /// Number of boxes over all videos.
    pub fn box_count(&self) -> usize {
        self.videos.iter().map(AnnotatedVideo::box_count).sum()
    }
}

/// The annotations of one video.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AnnotatedVideo {
    /// Sequence, video or task name.
    pub name: String,
    /// Frame width in pixels (0 when the file does not say).
    pub width: u32,
    /// Frame height in pixels (0 when the file does not say).
    pub height: u32,
    /// Declared number of frames, when the format says (CVAT `<size>`, COCO-video
    /// `length`, MOT `seqinfo.ini` `seqLength`).
    pub length: Option<u32>,
    /// Frame rate, when declared (MOT `seqinfo.ini` `frameRate`, COCO-video `fps`).
    pub fps: Option<f64>,
    /// Frames by **0-based** index. Formats that list frames (COCO-video images,
    /// ImageNet VID files) keep frames without boxes; MOT and CVAT list boxes only.
    pub frames: BTreeMap<u32, AnnotatedFrame>,
}

impl AnnotatedVideo {
    /// An empty video called `name`.
    pub fn new(name: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            ..Self::default()
        }
    }

    /// Every box with its 0-based frame index, in frame order.
    pub fn boxes(&self) -> impl Iterator<Item = (u32, &AnnotatedBox)> {
        self.frames
            .iter()
            .flat_map(|(&k, f)| f.boxes.iter().map(move |b| (k, b)))
    }

    /// Number of boxes.
    pub fn box_count(&self) -> usize {
        self.frames.values().map(|f| f.boxes.len()).sum()
    }

    /// The distinct track ids.
    pub fn track_ids(&self) -> BTreeSet<u64> {
        self.boxes().filter_map(|(_, b)| b.track).collect()
    }
}

/// One annotated frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AnnotatedFrame {
    /// The image path as the source names it (relative, as written), when it does.
    pub file: Option<String>,
    /// The boxes, in the source's order.
    pub boxes: Vec<AnnotatedBox>,
}

/// One box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnnotatedBox {
    /// Index into [`VideoAnnotations::classes`].
    pub class: usize,
    /// Track (object identity) id, when the source has one.
    pub track: Option<u64>,
    /// The box, in pixels, exclusive right / bottom edges.
    pub bbox: BBox,
    /// An ignore region: neither a miss when undetected nor a false positive when
    /// detected (MOT flag 0 or distractor class, COCO `iscrowd` / `ignore`).
    pub ignore: bool,
    /// Visible fraction in `[0, 1]`, when the source says (MOT 9-column layout).
    pub visibility: Option<f32>,
    /// Marked occluded by the annotator (CVAT, ImageNet VID).
    pub occluded: bool,
}

impl AnnotatedBox {
    /// A box of `class` without track, not ignored, visibility unknown, not occluded.
    pub fn new(class: usize, bbox: BBox) -> Self {
        Self {
            class,
            track: None,
            bbox,
            ignore: false,
            visibility: None,
            occluded: false,
        }
    }
}

/// How to read.
#[derive(Clone, Debug, PartialEq)]
pub struct ReadOptions {
    /// The class of MOT files without a class column (7 and 10 columns): `pedestrian`.
    pub default_class: String,
    /// MOT: boxes whose visibility is below this become ignore regions (default 0).
    pub min_visibility: f32,
    /// Frames in the video, when the caller knows it: a box at or past this 0-based
    /// frame index is an error.
    pub length: Option<u32>,
}

impl Default for ReadOptions {
    fn default() -> Self {
        Self {
            default_class: "pedestrian".to_owned(),
            min_visibility: 0.0,
            length: None,
        }
    }
}

/// Read `path` as `format` into the neutral form. The input must not look like another
/// format (see [`detect_format`]); the error says which one it looks like.
pub fn read(
    format: AnnotationFormat,
    path: &Path,
    opts: &ReadOptions,
) -> Result<VideoAnnotations, DataError> {
    // JSON can only be COCO-video: no need to parse a large file twice to know it.
    let deep_json = format != AnnotationFormat::CocoVideo;
    if let Some((found, evidence)) = sniff(path, deep_json)
        && found != format
    {
        return Err(DataError::invalid(
            path,
            evidence,
            format!(
                "this looks like {}, not {} (read it as format {:?})",
                found.describe(),
                format.describe(),
                found.name()
            ),
        ));
    }
    match format {
        AnnotationFormat::Mot => mot::read(path, opts),
        AnnotationFormat::Cvat => cvat::read(path, opts),
        AnnotationFormat::CocoVideo => coco_video::read(path, opts),
        AnnotationFormat::ImagenetVid => imagenet_vid::read(path, opts),
    }
    .map_err(one_line)
}

/// The error with line breaks quoted (`\n`): parser messages can quote the input.
fn one_line(e: DataError) -> DataError {
    let flat = |s: String| {
        if s.contains(['\n', '\r']) {
            s.replace('\r', "\\r").replace('\n', "\\n")
        } else {
            s
        }
    };
    match e {
        DataError::Xml { path, message } => DataError::Xml {
            path,
            message: flat(message),
        },
        DataError::Csv {
            path,
            record,
            message,
        } => DataError::Csv {
            path,
            record: flat(record),
            message: flat(message),
        },
        DataError::Invalid {
            path,
            record,
            problem,
        } => DataError::Invalid {
            path,
            record: flat(record),
            problem: flat(problem),
        },
        DataError::Json { path, source } if source.to_string().contains(['\n', '\r']) => {
            DataError::invalid(
                path,
                format!("line {} column {}", source.line(), source.column()),
                format!("malformed JSON: {}", flat(source.to_string())),
            )
        }
        other => other,
    }
}

/// The format of `path`, by content: an XML root `<annotations>` with `<track>` or
/// `<version>` is CVAT; an XML root `<annotation>` with `<trackid>` (or a folder of
/// such files, or of snippet folders of them) is ImageNet VID; a JSON object with
/// `videos` is COCO-video; lines of at least 6 comma-separated numbers are MOT.
/// `None` when it is none of these (or cannot be read).
pub fn detect_format(path: &Path) -> Option<AnnotationFormat> {
    sniff(path, true).map(|(f, _)| f)
}

/// The format of `path` and what gave it away (for messages). A JSON file is parsed
/// (for `videos`) only when `deep_json`; otherwise it is `None`.
fn sniff(path: &Path, deep_json: bool) -> Option<(AnnotationFormat, String)> {
    if path.is_dir() {
        return xml_files(path)
            .ok()?
            .into_iter()
            .take(50)
            .find_map(|f| sniff_file(&f, deep_json))
            .map(|(f, e)| (f, format!("folder of XML files with {e}")));
    }
    sniff_file(path, deep_json)
}

fn sniff_file(path: &Path, deep_json: bool) -> Option<(AnnotationFormat, String)> {
    use std::io::Read;
    let mut head = Vec::new();
    std::fs::File::open(path)
        .ok()?
        .take(64 * 1024)
        .read_to_end(&mut head)
        .ok()?;
    let text = String::from_utf8_lossy(&head);
    let text = text.trim_start_matches('\u{feff}').trim_start();
    if text.starts_with('<') {
        return sniff_xml(text);
    }
    if text.starts_with('{') {
        if !deep_json {
            return None;
        }
        #[derive(serde::Deserialize)]
        struct Probe {
            videos: Option<serde::de::IgnoredAny>,
        }
        let file = std::fs::File::open(path).ok()?;
        let probe: Probe = serde_json::from_reader(std::io::BufReader::new(file)).ok()?;
        return probe.videos.map(|_| {
            (
                AnnotationFormat::CocoVideo,
                "JSON object with \"videos\"".to_owned(),
            )
        });
    }
    let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
    let numeric = |l: &str| {
        let fields: Vec<&str> = l.split(',').collect();
        fields.len() >= 6 && fields.iter().all(|f| f.trim().parse::<f64>().is_ok())
    };
    let first = lines.next()?;
    (numeric(first) && lines.take(4).all(numeric)).then(|| {
        (
            AnnotationFormat::Mot,
            "line 1: comma-separated numbers".to_owned(),
        )
    })
}

fn sniff_xml(text: &str) -> Option<(AnnotationFormat, String)> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::Reader::from_str(text);
    let root = loop {
        match reader.read_event().ok()? {
            Event::Start(e) | Event::Empty(e) => {
                break String::from_utf8_lossy(e.local_name().as_ref()).into_owned();
            }
            Event::Eof => return None,
            _ => {}
        }
    };
    match root.as_str() {
        "annotations" if text.contains("<track") || text.contains("<version") => Some((
            AnnotationFormat::Cvat,
            "root element <annotations> with <track> / <version>".to_owned(),
        )),
        "annotation" if text.contains("<trackid") => Some((
            AnnotationFormat::ImagenetVid,
            "root element <annotation> with <trackid>".to_owned(),
        )),
        _ => None,
    }
}

/// The `.xml` files of `dir` in name order; if it has none, those of its first
/// subfolder (in name order) that has some.
fn xml_files(dir: &Path) -> Result<Vec<PathBuf>, DataError> {
    let own = list_dir(dir, is_xml)?;
    if !own.is_empty() {
        return Ok(own);
    }
    for sub in list_dir(dir, Path::is_dir)? {
        let files = list_dir(&sub, is_xml)?;
        if !files.is_empty() {
            return Ok(files);
        }
    }
    Ok(Vec::new())
}

/// A file ending in `.xml` (any case).
pub(crate) fn is_xml(p: &Path) -> bool {
    p.is_file() && p.extension().is_some_and(|x| x.eq_ignore_ascii_case("xml"))
}

/// The entries of `dir` that pass `keep`, in name order.
pub(crate) fn list_dir(dir: &Path, keep: fn(&Path) -> bool) -> Result<Vec<PathBuf>, DataError> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| DataError::io(dir, e))? {
        let p = entry.map_err(|e| DataError::io(dir, e))?.path();
        if keep(&p) {
            out.push(p);
        }
    }
    out.sort();
    Ok(out)
}

/// The frame limit a reader checks boxes against, and where it comes from.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Limit {
    /// Frames in the video: 0-based indices must be below.
    pub frames: u32,
    /// Where the number comes from (`the length option`, `seqinfo.ini seqLength`).
    pub source: &'static str,
}

impl Limit {
    /// The caller's length, else the declared one.
    pub fn new(opts: &ReadOptions, declared: Option<u32>, source: &'static str) -> Option<Self> {
        opts.length
            .map(|frames| Limit {
                frames,
                source: "the length option",
            })
            .or(declared.map(|frames| Limit { frames, source }))
    }

    /// An error if 0-based `frame` is past the limit; `shown` is the frame as the
    /// file numbers it.
    pub fn check(
        limit: Option<Self>,
        path: &Path,
        record: &str,
        frame: u32,
        shown: u64,
    ) -> Result<(), DataError> {
        match limit {
            Some(l) if frame >= l.frames => Err(DataError::invalid(
                path,
                record,
                format!(
                    "frame {shown} is past the video's {} frames ({})",
                    l.frames, l.source
                ),
            )),
            _ => Ok(()),
        }
    }
}

/// Line numbers of byte offsets met in increasing order, counted incrementally.
#[derive(Debug)]
pub(crate) struct LineCounter<'a> {
    text: &'a [u8],
    at: usize,
    line: usize,
}

impl<'a> LineCounter<'a> {
    /// A counter at the start of `text` (line 1).
    pub fn new(text: &'a [u8]) -> Self {
        Self {
            text,
            at: 0,
            line: 1,
        }
    }

    /// The line (1-based) of byte offset `to` (not before the previous offset).
    pub fn line(&mut self, to: usize) -> usize {
        let to = to.clamp(self.at, self.text.len());
        self.line += self.text[self.at..to]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        self.at = to;
        self.line
    }
}

/// Read a whole text file.
pub(crate) fn read_text(path: &Path) -> Result<String, DataError> {
    std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))
}
