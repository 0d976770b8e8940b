//! Tests of the media readers on tiny clips made here with the `ffmpeg` program from
//! frames drawn here: a block moving by a known amount and a grey patch coding the
//! frame number, so that each decoded frame can be matched to the frame it came from.
//!
//! About 1,000 lines of independent tests sharing this file's clip makers.
use super::probe::{Ratio, probe_with};
use super::video::{Line, parse_line, version_has_fps_mode};
use super::*;
use image::{Rgb, RgbImage};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

const W: u32 = 64;
const H: u32 = 48;

/// Whether `ffmpeg` and `ffprobe` are installed; says so on stderr when not.
fn have_ffmpeg() -> bool {
    let runs = |program: &str| {
        Command::new(program)
            .arg("-version")
            .output()
            .is_ok_and(|out| out.status.success())
    };
    let found = runs("ffmpeg") && runs("ffprobe");
    if !found {
        eprintln!("note: ffmpeg / ffprobe not installed, video test skipped");
    }
    found
}

/// Skip a video test when ffmpeg is missing.
macro_rules! need_ffmpeg {
    () => {
        if !have_ffmpeg() {
            return;
        }
    };
}

/// Frame `i` of the test clips: a blue-grey background, an orange 16×16 block moving
/// 4 px right and 2 px down per frame (wrapping), and an 8×8 grey patch whose level codes
/// `i`. Everything on even pixels, so 4:2:0 chroma loses nothing.
fn drawn(i: u32) -> RgbImage {
    let mut img = RgbImage::from_pixel(W, H, Rgb([40, 80, 120]));
    let (bx, by) = (8 + (4 * i) % 40, 8 + (2 * i) % 24);
    for y in by..by + 16 {
        for x in bx..bx + 16 {
            img.put_pixel(x, y, Rgb([220, 60, 30]));
        }
    }
    let code = (30 + (i * 23) % 200) as u8;
    for y in 0..8 {
        for x in 0..8 {
            img.put_pixel(x, y, Rgb([code, code, code]));
        }
    }
    img
}

/// Mean absolute difference per channel.
fn mad(a: &RgbImage, b: &RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let sum: u64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(&x, &y)| u64::from(x.abs_diff(y)))
        .sum();
    sum as f64 / a.as_raw().len() as f64
}

const H264: &[&str] = &["-c:v", "libx264", "-qp", "0", "-pix_fmt", "yuv420p"];
const MJPEG: &[&str] = &["-c:v", "mjpeg", "-q:v", "2", "-pix_fmt", "yuvj420p"];

/// Run ffmpeg (quietly) and insist that it worked.
fn ffmpeg(args: &[&str], cwd: &Path) {
    let out = Command::new("ffmpeg")
        .args(["-hide_banner", "-nostdin", "-v", "error", "-y"])
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("ffmpeg runs");
    assert!(
        out.status.success(),
        "ffmpeg {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Encode frames `drawn(0..n)` at `fps` into `dir/name` with `codec` arguments.
fn clip(dir: &Path, name: &str, n: u32, fps: u32, codec: &[&str]) -> PathBuf {
    let frames = dir.join(format!("{name}.frames"));
    std::fs::create_dir_all(&frames).unwrap();
    for i in 0..n {
        drawn(i).save(frames.join(format!("f{i:04}.png"))).unwrap();
    }
    let fps = fps.to_string();
    let input = format!("{name}.frames/f%04d.png");
    let mut args = vec!["-framerate", &fps, "-i", &input];
    args.extend_from_slice(codec);
    args.push(name);
    ffmpeg(&args, dir);
    dir.join(name)
}

/// Every frame of a source, or the first error.
fn read_all(
    frames: impl Iterator<Item = Result<DecodedFrame, DataError>>,
) -> Result<Vec<DecodedFrame>, DataError> {
    frames.collect()
}

fn open(path: &Path, sampling: &Sampling) -> Vec<DecodedFrame> {
    read_all(VideoReader::open(path, sampling).unwrap()).unwrap()
}

fn indices(frames: &[DecodedFrame]) -> Vec<u64> {
    frames.iter().map(|f| f.index).collect()
}

/// The error's message, checked to be one line naming `path`.
fn message(error: DataError, path: &Path) -> String {
    let text = error.to_string();
    assert!(!text.contains('\n'), "one line: {text}");
    assert!(
        text.contains(&path.display().to_string()),
        "names {}: {text}",
        path.display()
    );
    text
}

/// Check the frames of a clip of `drawn` frames: index, exact time, size and pixels,
/// and that the closest of all drawn frames is the one of that index.
fn check_frames(frames: &[DecodedFrame], fps: f64, tolerance: f64, what: &str) {
    for f in frames {
        assert_eq!(
            f.time_s,
            f.index as f64 / fps,
            "{what}: time of frame {}",
            f.index
        );
        assert_eq!(f.image.dimensions(), (W, H), "{what}");
        let error = mad(&f.image, &drawn(f.index as u32));
        assert!(
            error < tolerance,
            "{what}: frame {} differs by {error}",
            f.index
        );
        let closest = (0..40)
            .min_by(|&a, &b| mad(&f.image, &drawn(a)).total_cmp(&mad(&f.image, &drawn(b))))
            .unwrap();
        assert_eq!(
            u64::from(closest),
            f.index,
            "{what}: frame {} looks like {closest}",
            f.index
        );
    }
}

/// The error of a result that must have failed.
fn error_of<T>(result: Result<T, DataError>) -> DataError {
    match result {
        Ok(_) => panic!("expected an error"),
        Err(e) => e,
    }
}

#[test]
fn probe_describes_the_first_video_stream() {
    need_ffmpeg!();
    let dir = tempfile::tempdir().unwrap();
    let mp4 = clip(dir.path(), "a.mp4", 20, 30, H264);
    let info = probe(&mp4).unwrap();
    assert_eq!(
        info,
        MediaInfo {
            width: W,
            height: H,
            fps: 30.0,
            frames: Some(20),
            duration_s: info.duration_s,
            codec: "h264".into(),
        }
    );
    assert!((info.duration_s.unwrap() - 20.0 / 30.0).abs() < 1e-3);
    let mkv = clip(dir.path(), "a.mkv", 10, 25, H264);
    let info = probe(&mkv).unwrap();
    assert_eq!((info.width, info.height, info.fps), (W, H, 25.0));
    assert_eq!(info.frames, None, "Matroska does not count frames");
}

#[test]
fn every_frame_has_its_index_exact_time_and_pixels_in_each_container() {
    need_ffmpeg!();
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, u32, &[&str], f64); 5] = [
        ("a.mp4", 30, H264, 3.0),
        ("b.mp4", 25, H264, 3.0),
        ("c.avi", 30, MJPEG, 6.0),
        ("d.mkv", 30, H264, 3.0),
        ("e.mov", 25, H264, 3.0),
    ];
    for (name, fps, codec, tolerance) in cases {
        let path = clip(dir.path(), name, 20, fps, codec);
        let reader = VideoReader::open(&path, &Sampling::default()).unwrap();
        assert_eq!(reader.info().fps, f64::from(fps), "{name}");
        assert_eq!(reader.frame_size(), (W, H));
        let frames = read_all(reader).unwrap();
        assert_eq!(indices(&frames), (0..20).collect::<Vec<_>>(), "{name}");
        check_frames(&frames, f64::from(fps), tolerance, name);
    }
}

/// Samplings and the source frames (of 30 at 30 fps) they keep, worked out by hand.
fn sampling_cases() -> Vec<(Sampling, Vec<u64>)> {
    let s = Sampling::default;
    vec![
        (Sampling { every: 3, ..s() }, (0..30).step_by(3).collect()),
        (Sampling { every: 1, ..s() }, (0..30).collect()),
        (
            Sampling {
                fps: Some(10.0),
                ..s()
            },
            (0..30).step_by(3).collect(),
        ),
        (
            Sampling {
                fps: Some(12.0),
                ..s()
            },
            vec![0, 3, 5, 8, 10, 13, 15, 18, 20, 23, 25, 28],
        ),
        (
            Sampling {
                fps: Some(60.0),
                ..s()
            },
            (0..30).collect(),
        ),
        (
            Sampling {
                fps: Some(10.0),
                every: 2,
                ..s()
            },
            vec![0, 6, 12, 18, 24],
        ),
        (
            Sampling {
                start_s: Some(0.5),
                end_s: Some(0.8),
                ..s()
            },
            (15..24).collect(),
        ),
        (
            Sampling {
                start_s: Some(0.9),
                ..s()
            },
            vec![27, 28, 29],
        ),
        (
            Sampling {
                end_s: Some(0.1),
                ..s()
            },
            vec![0, 1, 2],
        ),
        (
            Sampling {
                start_s: Some(0.5),
                end_s: Some(0.8),
                every: 2,
                ..s()
            },
            vec![15, 17, 19, 21, 23],
        ),
        (
            Sampling {
                start_s: Some(0.55),
                fps: Some(10.0),
                ..s()
            },
            vec![17, 18, 21, 24, 27],
        ),
    ]
}

#[test]
fn sampling_keeps_the_frames_it_says_in_video_and_sequence_alike() {
    need_ffmpeg!();
    let dir = tempfile::tempdir().unwrap();
    let mp4 = clip(dir.path(), "a.mp4", 30, 30, H264);
    let mkv = clip(dir.path(), "a.mkv", 30, 30, H264);
    let folder = dir.path().join("a.mp4.frames");
    for (sampling, expected) in sampling_cases() {
        for path in [&mp4, &mkv] {
            let frames = open(path, &sampling);
            assert_eq!(
                indices(&frames),
                expected,
                "{} {sampling:?}",
                path.display()
            );
            check_frames(&frames, 30.0, 3.0, "sampled");
        }
        let frames = read_all(ImageSequence::open(&folder, 30.0, &sampling).unwrap()).unwrap();
        assert_eq!(indices(&frames), expected, "sequence {sampling:?}");
        check_frames(&frames, 30.0, 0.5, "sequence");
    }
}

#[test]
fn threads_do_not_change_the_frames() {
    need_ffmpeg!();
    let dir = tempfile::tempdir().unwrap();
    let mp4 = clip(dir.path(), "a.mp4", 12, 30, H264);
    let one = open(
        &mp4,
        &Sampling {
            threads: Some(1),
            ..Sampling::default()
        },
    );
    let two = open(
        &mp4,
        &Sampling {
            threads: Some(2),
            ..Sampling::default()
        },
    );
    assert_eq!(indices(&one), (0..12).collect::<Vec<_>>());
    for (a, b) in one.iter().zip(&two) {
        assert_eq!((a.index, a.time_s, &a.image), (b.index, b.time_s, &b.image));
    }
}

#[test]
fn size_resizes_to_exactly_that_size() {
    need_ffmpeg!();
    let dir = tempfile::tempdir().unwrap();
    let mp4 = clip(dir.path(), "a.mp4", 6, 30, H264);
    let folder = dir.path().join("a.mp4.frames");
    for (w, h) in [(32, 24), (128, 96), (50, 30)] {
        let sampling = Sampling {
            size: Some((w, h)),
            ..Sampling::default()
        };
        let video = open(&mp4, &sampling);
        let sequence = read_all(ImageSequence::open(&folder, 30.0, &sampling).unwrap()).unwrap();
        assert_eq!(video.len(), 6);
        assert_eq!(sequence.len(), 6);
        for (v, s) in video.iter().zip(&sequence) {
            assert_eq!(v.image.dimensions(), (w, h));
            assert_eq!(s.image.dimensions(), (w, h));
            let expected = image::imageops::resize(
                &drawn(v.index as u32),
                w,
                h,
                image::imageops::FilterType::Triangle,
            );
            let (dv, ds) = (mad(&v.image, &expected), mad(&s.image, &expected));
            assert!(dv < 8.0, "{w}x{h}: video frame {} differs by {dv}", v.index);
            assert!(
                ds < 1.0,
                "{w}x{h}: sequence frame {} differs by {ds}",
                s.index
            );
        }
    }
    // Halving averages 2×2 blocks: on the block-aligned frames that is exact up to the
    // codec's rounding.
    let half = open(
        &mp4,
        &Sampling {
            size: Some((32, 24)),
            ..Sampling::default()
        },
    );
    let box2 = |img: &RgbImage| {
        RgbImage::from_fn(32, 24, |x, y| {
            let mut sum = [0u32; 3];
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let p = img.get_pixel(2 * x + dx, 2 * y + dy);
                for c in 0..3 {
                    sum[c] += u32::from(p[c]);
                }
            }
            Rgb(sum.map(|s| ((s + 2) / 4) as u8))
        })
    };
    for f in &half {
        let error = mad(&f.image, &box2(&drawn(f.index as u32)));
        assert!(
            error < 3.0,
            "area-halved frame {} differs by {error}",
            f.index
        );
    }
}

#[test]
fn a_rotated_video_reads_upright_as_ffmpeg_shows_it() {
    need_ffmpeg!();
    let dir = tempfile::tempdir().unwrap();
    clip(dir.path(), "a.mp4", 3, 30, H264);
    // Phones store portrait video as landscape frames and a rotation to apply.
    ffmpeg(
        &[
            "-i",
            "a.mp4",
            "-c",
            "copy",
            "-metadata:s:v:0",
            "rotate=90",
            "r.mp4",
        ],
        dir.path(),
    );
    ffmpeg(&["-i", "r.mp4", "-frames:v", "1", "first.png"], dir.path());
    let rotated = dir.path().join("r.mp4");
    let info = probe(&rotated).unwrap();
    assert_eq!((info.width, info.height), (H, W));
    let frames = open(&rotated, &Sampling::default());
    assert_eq!(indices(&frames), [0, 1, 2]);
    let shown = image::open(dir.path().join("first.png"))
        .unwrap()
        .into_rgb8();
    assert_eq!(frames[0].image.dimensions(), (H, W));
    assert!(mad(&frames[0].image, &shown) < 0.5);
    let turned = [
        image::imageops::rotate90(&drawn(0)),
        image::imageops::rotate270(&drawn(0)),
    ];
    assert!(turned.iter().any(|t| mad(&frames[0].image, t) < 3.0));
}

/// A variable-rate clip: `drawn(0..7)` shown for 80, 40, 200, 120, 160, 40 and 40 ms.
fn variable_rate_clip(dir: &Path, name: &str) -> PathBuf {
    let frames = dir.join(format!("{name}.frames"));
    std::fs::create_dir_all(&frames).unwrap();
    let mut list = String::new();
    for (i, ms) in [80, 40, 200, 120, 160, 40, 40].into_iter().enumerate() {
        let file = frames.join(format!("f{i}.png"));
        drawn(i as u32).save(&file).unwrap();
        list += &format!(
            "file '{}'\nduration {}\n",
            file.display(),
            f64::from(ms) / 1000.0
        );
    }
    // The concat demuxer takes the last file's duration only from a repeated entry.
    list += &format!("file '{}'\n", frames.join("f6.png").display());
    std::fs::write(dir.join(format!("{name}.txt")), list).unwrap();
    let listed = format!("{name}.txt");
    let mut args = vec![
        "-f",
        "concat",
        "-safe",
        "0",
        "-i",
        &listed,
        "-fps_mode",
        "vfr",
    ];
    args.extend_from_slice(H264);
    args.push(name);
    ffmpeg(&args, dir);
    dir.join(name)
}

#[test]
fn variable_rate_frames_keep_their_times_and_ranks() {
    need_ffmpeg!();
    let dir = tempfile::tempdir().unwrap();
    let times = [0.0, 0.08, 0.12, 0.32, 0.44, 0.6, 0.64];
    for name in ["v.mp4", "v.mkv"] {
        let path = variable_rate_clip(dir.path(), name);
        let frames = open(&path, &Sampling::default());
        // The concat demuxer repeats the last picture once more.
        let shown = &frames[..7];
        assert_eq!(indices(shown), (0..7).collect::<Vec<_>>(), "{name}");
        for (f, t) in shown.iter().zip(times) {
            assert_eq!(f.time_s, t, "{name}: frame {}", f.index);
            assert!(mad(&f.image, &drawn(f.index as u32)) < 3.0, "{name}");
        }
        let frames = open(
            &path,
            &Sampling {
                fps: Some(5.0),
                ..Sampling::default()
            },
        );
        assert_eq!(
            indices(&frames)[..4],
            [0, 3, 4, 5],
            "{name}: one per 200 ms slot"
        );
    }
    // After a seek, the index of a variable-rate stream comes from counting packets.
    let path = dir.path().join("v.mp4");
    assert_ne!(probe(&path).unwrap().fps, 25.0, "declared variable-rate");
    let frames = open(
        &path,
        &Sampling {
            start_s: Some(0.3),
            ..Sampling::default()
        },
    );
    assert_eq!(indices(&frames)[..4], [3, 4, 5, 6]);
    assert_eq!(frames[0].time_s, 0.32);
    assert!(mad(&frames[0].image, &drawn(3)) < 3.0);
}

#[test]
fn read_into_reuses_one_buffer() {
    need_ffmpeg!();
    let dir = tempfile::tempdir().unwrap();
    let mp4 = clip(dir.path(), "a.mp4", 5, 30, H264);
    let mut reader = VideoReader::open(&mp4, &Sampling::default()).unwrap();
    let mut frame = DecodedFrame {
        index: 0,
        time_s: 0.0,
        image: RgbImage::new(0, 0),
    };
    assert!(reader.read_into(&mut frame).unwrap());
    let buffer = frame.image.as_raw().as_ptr();
    let mut seen = vec![frame.index];
    while reader.read_into(&mut frame).unwrap() {
        assert_eq!(frame.image.as_raw().as_ptr(), buffer, "same allocation");
        assert!(mad(&frame.image, &drawn(frame.index as u32)) < 3.0);
        seen.push(frame.index);
    }
    assert_eq!(seen, vec![0, 1, 2, 3, 4]);
    assert_eq!(reader.frames_read(), 5);
    assert!(!reader.read_into(&mut frame).unwrap(), "stays at the end");
}

#[cfg(target_os = "linux")]
#[test]
fn dropping_a_reader_early_kills_and_reaps_ffmpeg() {
    need_ffmpeg!();
    let dir = tempfile::tempdir().unwrap();
    // 40 frames of 9 kB: more than a pipe holds, so ffmpeg is still writing.
    let mp4 = clip(dir.path(), "a.mp4", 40, 30, H264);
    let mut reader = VideoReader::open(&mp4, &Sampling::default()).unwrap();
    let first = reader.next().unwrap().unwrap();
    assert_eq!(first.index, 0);
    let pid = reader.process_id().expect("ffmpeg runs");
    let proc = PathBuf::from(format!("/proc/{pid}"));
    assert!(proc.exists());
    drop(reader);
    // A zombie would keep its /proc entry until reaped.
    assert!(!proc.exists(), "ffmpeg {pid} is gone and reaped");
}

#[test]
fn missing_empty_and_non_video_files_are_errors_naming_them() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.mp4");
    let text = message(error_of(probe(&missing)), &missing);
    assert!(text.contains("No such file"), "{text}");
    let text = message(
        error_of(VideoReader::open(&missing, &Sampling::default())),
        &missing,
    );
    assert!(text.contains("No such file"), "{text}");

    let empty = dir.path().join("empty.mp4");
    std::fs::write(&empty, b"").unwrap();
    let text = message(error_of(probe(&empty)), &empty);
    assert!(text.contains("empty file"), "{text}");

    need_ffmpeg!();
    let fake = dir.path().join("notes.mp4");
    std::fs::write(&fake, "these are notes, not a video\n".repeat(20)).unwrap();
    let text = message(error_of(probe(&fake)), &fake);
    assert!(text.contains("not a video"), "{text}");
    let text = message(
        error_of(FrameSource::open(&fake, None, &Sampling::default())),
        &fake,
    );
    assert!(text.contains("not a video"), "{text}");

    ffmpeg(
        &["-f", "lavfi", "-i", "sine=duration=0.5", "tone.wav"],
        dir.path(),
    );
    let wav = dir.path().join("tone.wav");
    let text = message(error_of(probe(&wav)), &wav);
    assert!(text.contains("no video stream (only audio)"), "{text}");
}

#[test]
fn a_video_without_frames_is_empty() {
    need_ffmpeg!();
    let dir = tempfile::tempdir().unwrap();
    let mut args = vec![
        "-f",
        "lavfi",
        "-i",
        "testsrc2=size=64x48:rate=30",
        "-frames:v",
        "0",
    ];
    args.extend_from_slice(MJPEG);
    args.push("none.avi");
    ffmpeg(&args, dir.path());
    let avi = dir.path().join("none.avi");
    let text = message(error_of(probe(&avi)), &avi);
    assert!(text.contains("empty video"), "{text}");
    let text = message(
        error_of(VideoReader::open(&avi, &Sampling::default())),
        &avi,
    );
    assert!(text.contains("empty video"), "{text}");
}

#[test]
fn truncated_videos_are_errors() {
    need_ffmpeg!();
    let dir = tempfile::tempdir().unwrap();
    let half = |path: &Path| {
        let bytes = std::fs::read(path).unwrap();
        let cut = path.with_extension(format!(
            "half.{}",
            path.extension().unwrap().to_string_lossy()
        ));
        std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
        cut
    };
    // MP4 writes its index last: half a file has none.
    let mp4 = half(&clip(dir.path(), "a.mp4", 30, 30, H264));
    let text = message(error_of(probe(&mp4)), &mp4);
    assert!(text.contains("not a video ffprobe can read"), "{text}");
    assert!(text.contains("moov atom not found"), "{text}");

    // With the index first (faststart), and in Matroska, the frames stop midway.
    let mut faststart = H264.to_vec();
    faststart.extend_from_slice(&["-movflags", "+faststart"]);
    let fast = half(&clip(dir.path(), "b.mp4", 30, 30, &faststart));
    let mkv = half(&clip(dir.path(), "c.mkv", 30, 30, H264));
    for path in [fast, mkv] {
        let mut reader = VideoReader::open(&path, &Sampling::default()).unwrap();
        let mut good = 0;
        let error = loop {
            match reader.next() {
                Some(Ok(frame)) => {
                    assert_eq!(frame.index, good);
                    good += 1;
                }
                Some(Err(e)) => break e,
                None => panic!("{}: no error after {good} frames", path.display()),
            }
        };
        assert!(good < 30, "{}: {good} frames", path.display());
        let text = message(error, &path);
        assert!(text.contains("decoding failed"), "{text}");
        assert!(reader.next().is_none(), "the stream ends after an error");
    }
}

#[test]
fn missing_programs_say_how_to_install_them() {
    static NO_FFPROBE: Tools = Tools {
        ffmpeg: "ffmpeg",
        ffprobe: "frugal-test-no-such-ffprobe",
        fps_mode: OnceLock::new(),
    };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a.mp4");
    std::fs::write(&file, b"not empty").unwrap();
    let text = message(error_of(probe_with(&NO_FFPROBE, &file)), &file);
    assert!(
        text.contains("`frugal-test-no-such-ffprobe` program was not found"),
        "{text}"
    );
    assert!(
        text.contains("install ffmpeg, e.g. `cargo xtask setup`"),
        "{text}"
    );

    need_ffmpeg!();
    static NO_FFMPEG: Tools = Tools {
        ffmpeg: "frugal-test-no-such-ffmpeg",
        ffprobe: "ffprobe",
        fps_mode: OnceLock::new(),
    };
    let mp4 = clip(dir.path(), "b.mp4", 3, 30, H264);
    let error = error_of(VideoReader::open_with(
        &NO_FFMPEG,
        &mp4,
        &Sampling::default(),
    ));
    let text = message(error, &mp4);
    assert!(
        text.contains("install ffmpeg, e.g. `cargo xtask setup`"),
        "{text}"
    );
}

#[test]
fn bad_sampling_and_empty_windows_are_errors() {
    need_ffmpeg!();
    let dir = tempfile::tempdir().unwrap();
    let mp4 = clip(dir.path(), "a.mp4", 10, 30, H264);
    let s = Sampling::default;
    for (sampling, says) in [
        (
            Sampling {
                fps: Some(0.0),
                ..s()
            },
            "fps must be",
        ),
        (
            Sampling {
                fps: Some(f64::NAN),
                ..s()
            },
            "fps must be",
        ),
        (
            Sampling {
                start_s: Some(-1.0),
                ..s()
            },
            "start_s must be",
        ),
        (
            Sampling {
                start_s: Some(0.2),
                end_s: Some(0.1),
                ..s()
            },
            "must come after",
        ),
        (
            Sampling {
                size: Some((0, 10)),
                ..s()
            },
            "size must not be empty",
        ),
        (
            Sampling {
                threads: Some(0),
                ..s()
            },
            "threads must be",
        ),
        (
            Sampling {
                start_s: Some(5.0),
                ..s()
            },
            "at or after the end",
        ),
    ] {
        let text = message(error_of(VideoReader::open(&mp4, &sampling)), &mp4);
        assert!(text.contains(says), "{sampling:?}: {text}");
    }
    // A window between two frames holds none.
    let window = Sampling {
        start_s: Some(0.01),
        end_s: Some(0.02),
        ..s()
    };
    let error = error_of(read_all(VideoReader::open(&mp4, &window).unwrap()));
    let text = message(error, &mp4);
    assert!(
        text.contains("no frame in the window from 0.01 s to 0.02 s"),
        "{text}"
    );
    let folder = dir.path().join("a.mp4.frames");
    let error = error_of(read_all(
        ImageSequence::open(&folder, 30.0, &window).unwrap(),
    ));
    let text = message(error, &folder);
    assert!(text.contains("no frame in the window"), "{text}");
}

#[test]
fn natural_order_compares_numbers_as_numbers() {
    use std::cmp::Ordering::*;
    for (a, b, order) in [
        ("000002.png", "000010.png", Less),
        ("img2.jpg", "img10.jpg", Less),
        ("img10.jpg", "img9.jpg", Greater),
        ("a2b10", "a2b9", Greater),
        ("IMG3", "img20", Less),
        ("img01", "img1", Less),
        ("img1", "img1", Equal),
        ("img", "img1", Less),
        (
            "frame_99999999999999999999",
            "frame_100000000000000000000",
            Less,
        ),
    ] {
        assert_eq!(natural_cmp(a, b), order, "{a} vs {b}");
        assert_eq!(natural_cmp(b, a), order.reverse(), "{b} vs {a}");
    }
    let mut names = vec![
        "f10.png", "f9.png", "f1.png", "F2.png", "f010.png", "f100.png",
    ];
    names.sort_by(|a, b| natural_cmp(a, b));
    assert_eq!(
        names,
        [
            "f1.png", "F2.png", "f9.png", "f010.png", "f10.png", "f100.png"
        ]
    );
}

/// Write `drawn(i)` as `path`, JPEG at quality 95 or PNG by extension.
fn save(image: &RgbImage, path: &Path) {
    if path.extension().is_some_and(|e| e == "jpg") {
        let file = std::fs::File::create(path).unwrap();
        image::codecs::jpeg::JpegEncoder::new_with_quality(file, 95)
            .encode_image(image)
            .unwrap();
    } else {
        image.save(path).unwrap();
    }
}

#[test]
fn a_sequence_reads_png_and_jpeg_in_natural_order() {
    let dir = tempfile::tempdir().unwrap();
    for i in 0..12u32 {
        let ext = if i % 2 == 0 { "png" } else { "jpg" };
        save(&drawn(i), &dir.path().join(format!("img{}.{ext}", i + 1)));
    }
    std::fs::write(dir.path().join("notes.txt"), "not an image").unwrap();
    std::fs::write(dir.path().join(".hidden.png"), "not an image either").unwrap();
    let sequence = ImageSequence::open(dir.path(), 25.0, &Sampling::default()).unwrap();
    assert_eq!(
        sequence.info(),
        &MediaInfo {
            width: W,
            height: H,
            fps: 25.0,
            frames: Some(12),
            duration_s: Some(12.0 / 25.0),
            codec: "png,jpeg".into(),
        }
    );
    assert_eq!(sequence.files()[9].file_name().unwrap(), "img10.jpg");
    let frames = read_all(sequence).unwrap();
    assert_eq!(indices(&frames), (0..12).collect::<Vec<_>>());
    for f in &frames {
        assert_eq!(f.time_s, f.index as f64 / 25.0);
        let error = mad(&f.image, &drawn(f.index as u32));
        let tolerance = if f.index % 2 == 0 { 0.0 } else { 4.0 };
        assert!(error <= tolerance, "frame {} differs by {error}", f.index);
    }
}

#[test]
fn a_corrupt_or_odd_sized_image_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    for i in 0..5u32 {
        save(&drawn(i), &dir.path().join(format!("{i:06}.png")));
    }
    let bad = dir.path().join("000003.png");
    std::fs::write(&bad, b"\x89PNG\r\n\x1a\n but then nothing valid").unwrap();
    let mut sequence = ImageSequence::open(dir.path(), 30.0, &Sampling::default()).unwrap();
    for i in 0..3 {
        assert_eq!(sequence.next().unwrap().unwrap().index, i);
    }
    let text = message(error_of(sequence.next().unwrap()), &bad);
    assert!(text.contains("image"), "{text}");
    assert!(sequence.next().is_none(), "the stream ends after an error");

    let odd = dir.path().join("000003.png");
    RgbImage::new(10, 10).save(&odd).unwrap();
    let error = error_of(read_all(
        ImageSequence::open(dir.path(), 30.0, &Sampling::default()).unwrap(),
    ));
    let text = message(error, &odd);
    assert!(
        text.contains("10x10 but the sequence's first image is 64x48"),
        "{text}"
    );
    let resized = Sampling {
        size: Some((W, H)),
        ..Sampling::default()
    };
    let frames = read_all(ImageSequence::open(dir.path(), 30.0, &resized).unwrap()).unwrap();
    assert_eq!(frames.len(), 5);

    let empty = tempfile::tempdir().unwrap();
    let text = message(
        error_of(ImageSequence::open(
            empty.path(),
            30.0,
            &Sampling::default(),
        )),
        empty.path(),
    );
    assert!(text.contains("no .jpg, .jpeg or .png image"), "{text}");
    let text = message(
        error_of(ImageSequence::open(dir.path(), 0.0, &Sampling::default())),
        dir.path(),
    );
    assert!(
        text.contains("frame rate must be a positive number"),
        "{text}"
    );
}

#[test]
fn frame_source_reads_a_folder_as_a_sequence_and_a_file_as_a_video() {
    need_ffmpeg!();
    let dir = tempfile::tempdir().unwrap();
    let mp4 = clip(dir.path(), "a.mp4", 4, 25, H264);
    let folder = dir.path().join("a.mp4.frames");
    let text = message(
        error_of(FrameSource::open(&folder, None, &Sampling::default())),
        &folder,
    );
    assert!(text.contains("no frame rate"), "{text}");
    let mut sequence = FrameSource::open(&folder, Some(25.0), &Sampling::default()).unwrap();
    assert!(matches!(sequence, FrameSource::Sequence(_)));
    let mut video = FrameSource::open(&mp4, Some(99.0), &Sampling::default()).unwrap();
    assert!(matches!(video, FrameSource::Video(_)));
    assert_eq!(video.info().fps, 25.0, "a video keeps its own rate");
    assert_eq!(sequence.info().frames, Some(4));
    for i in 0..4 {
        let (s, v) = (
            sequence.next().unwrap().unwrap(),
            video.next().unwrap().unwrap(),
        );
        assert_eq!((s.index, s.time_s), (i, i as f64 / 25.0));
        assert_eq!((v.index, v.time_s), (i, i as f64 / 25.0));
        assert!(mad(&s.image, &v.image) < 3.0);
    }
    assert!(sequence.next().is_none() && video.next().is_none());
    assert_eq!((sequence.frames_read(), video.frames_read()), (4, 4));
}

#[test]
fn stderr_lines_are_read_by_context_and_level() {
    let line = "[showinfo@out @ 0x55e5c1e8b3c0] [info] n:   2 pts:  10240 pts_time:0.666667 \
                pos:    24149 fmt:yuv420p sar:1/1 s:320x240 i:P iskey:0 type:P ";
    assert_eq!(parse_line(line), Some(Line::Kept(Some(10240))));
    let line = "[showinfo@in @ 0x5] [info] n:   0 pts:NOPTS pts_time:NOPTS";
    assert_eq!(parse_line(line), Some(Line::Decoded(None)));
    let line = "[showinfo@in @ 0x5] [info] config in time_base: 1/15360, frame_rate: 30/1";
    assert_eq!(
        parse_line(line),
        Some(Line::TimeBase(Ratio { num: 1, den: 15360 }))
    );
    let line = "[showinfo@in @ 0x5] [info] config out time_base: 0/0, frame_rate: 0/0";
    assert_eq!(parse_line(line), None);
    let line = "[h264 @ 0x562b67bd3280] [error] Invalid NAL unit size (1629 > 1580).";
    assert_eq!(
        parse_line(line),
        Some(Line::Problem(
            "ffmpeg: h264: Invalid NAL unit size (1629 > 1580).".into()
        ))
    );
    let line = "[error] Error while decoding stream #0:0: Invalid data found when processing input";
    assert!(
        matches!(parse_line(line), Some(Line::Problem(p)) if p.starts_with("ffmpeg: Error while"))
    );
    for ignored in [
        "[info] Input #0, mov,mp4,m4a,3gp,3g2,mj2, from 'a.mp4':",
        "[swscaler @ 0x1] [warning] deprecated pixel format used",
        "[Parsed_showinfo_1 @ 0x1] [info] n:   0 pts:      0 pts_time:0",
        "[showinfo@in @ 0x5] [info] UUID=dc45e9bd-e6d9-48b7-962c-d820d923eeef",
        "",
    ] {
        assert_eq!(parse_line(ignored), None, "{ignored}");
    }
}

#[test]
fn fps_mode_is_used_from_ffmpeg_5_1_on() {
    for (line, new) in [
        (
            "ffmpeg version 5.1.9-0+deb12u1 Copyright (c) 2000-2026",
            true,
        ),
        ("ffmpeg version 4.4.2-0ubuntu0.22.04.1 Copyright", false),
        ("ffmpeg version 5.0.1 Copyright", false),
        ("ffmpeg version n6.1 Copyright", true),
        ("ffmpeg version 7.1.1-1ubuntu1 Copyright", true),
        ("ffmpeg version N-113015-g1234abcd Copyright", true),
        ("", true),
    ] {
        assert_eq!(version_has_fps_mode(line), new, "{line}");
    }
}

#[test]
fn ratios_parse_like_ffprobe_prints_them() {
    assert_eq!(
        Ratio::parse("30000/1001"),
        Some(Ratio {
            num: 30000,
            den: 1001
        })
    );
    assert_eq!(Ratio::parse("25"), Some(Ratio { num: 25, den: 1 }));
    assert_eq!(Ratio::parse("0/0"), None);
    assert!(
        Ratio::parse("60/2")
            .unwrap()
            .same(Ratio { num: 30, den: 1 })
    );
}
