//! Tests of the video annotation readers and writers, on the small hand-written files
//! under `tests/fixtures/annotations/` and on error inputs written to temporary files.
use super::*;
use crate::DataError;
use std::path::{Path, PathBuf};

mod coco_video;
mod cvat;
mod imagenet_vid;
mod mot;

/// A fixture file or folder.
fn fixture(rel: &str) -> PathBuf {
    Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/annotations"
    ))
    .join(rel)
}

fn bx(x1: f32, y1: f32, x2: f32, y2: f32) -> BBox {
    BBox::new(x1, y1, x2, y2)
}

/// A box with track and flags, for comparisons.
fn tracked(class: usize, track: Option<u64>, bbox: BBox) -> AnnotatedBox {
    AnnotatedBox {
        track,
        ..AnnotatedBox::new(class, bbox)
    }
}

/// Write `text` into `dir/rel` (creating folders) and return its path.
fn put(dir: &Path, rel: &str, text: &str) -> PathBuf {
    let p = dir.join(rel);
    std::fs::create_dir_all(p.parent().expect("parent")).expect("mkdir");
    std::fs::write(&p, text).expect("write");
    p
}

/// The one-line message of a failed read; asserts it names the file and every `parts`.
fn read_err(format: AnnotationFormat, path: &Path, opts: &ReadOptions, parts: &[&str]) -> String {
    let err: DataError = read(format, path, opts).expect_err("the read must fail");
    let msg = err.to_string();
    assert!(!msg.contains('\n'), "one line: {msg}");
    assert!(
        msg.contains(&path.display().to_string()),
        "names the file {}: {msg}",
        path.display()
    );
    for p in parts {
        assert!(msg.contains(p), "mentions {p:?}: {msg}");
    }
    msg
}

fn opts() -> ReadOptions {
    ReadOptions::default()
}

#[test]
fn format_names_round_trip() {
    for f in AnnotationFormat::ALL {
        assert_eq!(AnnotationFormat::from_name(f.name()), Some(f));
        assert_eq!(f.to_string(), f.name());
    }
    assert_eq!(
        AnnotationFormat::from_name("COCO-Video"),
        Some(AnnotationFormat::CocoVideo)
    );
    assert_eq!(AnnotationFormat::from_name("voc"), None);
}

#[test]
fn detects_every_fixture() {
    use AnnotationFormat::*;
    let cases = [
        ("mot7/gt/gt.txt", Some(Mot)),
        ("mot9/gt/gt.txt", Some(Mot)),
        ("mot10/gt.txt", Some(Mot)),
        ("cvat_video.xml", Some(Cvat)),
        ("cvat_images.xml", Some(Cvat)),
        ("tao.json", Some(CocoVideo)),
        ("ytvis.json", Some(CocoVideo)),
        ("vid", Some(ImagenetVid)),
        ("vid/ILSVRC2015_train_00000000", Some(ImagenetVid)),
        (
            "vid/ILSVRC2015_train_00000000/000000.xml",
            Some(ImagenetVid),
        ),
        ("mot7/seqinfo.ini", None),
    ];
    for (rel, want) in cases {
        assert_eq!(detect_format(&fixture(rel)), want, "{rel}");
    }
    assert_eq!(detect_format(&fixture("missing.txt")), None);
}

#[test]
fn detect_rejects_look_alikes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let voc = put(
        dir.path(),
        "voc.xml",
        "<annotation><filename>a.jpg</filename><object><name>car</name></object></annotation>",
    );
    let coco = put(
        dir.path(),
        "coco.json",
        r#"{"images": [], "annotations": []}"#,
    );
    let csv = put(dir.path(), "words.csv", "a,b,c,d,e,f,g\n");
    for p in [voc, coco, csv] {
        assert_eq!(detect_format(&p), None, "{}", p.display());
    }
}

#[test]
fn a_file_given_as_the_wrong_format_says_what_it_looks_like() {
    let msg = read_err(
        AnnotationFormat::Mot,
        &fixture("cvat_video.xml"),
        &opts(),
        &[
            "root element <annotations>",
            "looks like a CVAT for video XML file",
            "not a MOT Challenge gt.txt",
            "\"cvat\"",
        ],
    );
    assert!(msg.contains("cvat_video.xml"), "{msg}");
    read_err(
        AnnotationFormat::Cvat,
        &fixture("tao.json"),
        &opts(),
        &[
            "\"videos\"",
            "looks like a COCO-with-videos JSON file",
            "not a CVAT for video XML file",
            "\"coco-video\"",
        ],
    );
    read_err(
        AnnotationFormat::CocoVideo,
        &fixture("mot9/gt/gt.txt"),
        &opts(),
        &["line 1", "looks like a MOT Challenge gt.txt", "\"mot\""],
    );
    read_err(
        AnnotationFormat::Mot,
        &fixture("vid"),
        &opts(),
        &["folder of XML files", "ImageNet VID", "\"imagenet-vid\""],
    );
}

#[test]
fn tud_campus_reads_completely() {
    let path = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/tud-campus/gt/gt.txt"
    ));
    if !path.is_file() {
        eprintln!("skipped: {} is absent", path.display());
        return;
    }
    assert_eq!(detect_format(path), Some(AnnotationFormat::Mot));
    let ann = read(AnnotationFormat::Mot, path, &opts()).expect("read TUD-Campus");
    assert_eq!(ann.videos.len(), 1);
    let v = &ann.videos[0];
    assert_eq!(v.name, "tud-campus");
    assert_eq!(v.frames.len(), 71);
    assert_eq!(
        v.frames.keys().copied().collect::<Vec<_>>(),
        (0..71).collect::<Vec<_>>()
    );
    assert_eq!(v.box_count(), 359);
    assert_eq!(v.track_ids(), (1..=8).collect());
    assert_eq!(ann.classes[0], "pedestrian");
    assert!(
        v.boxes()
            .all(|(_, b)| b.class == 0 && !b.ignore && b.visibility.is_none())
    );
    // `1,1,399,182,121,229,-1`
    assert_eq!(
        v.frames[&0].boxes[0],
        tracked(0, Some(1), bx(399.0, 182.0, 520.0, 411.0))
    );
}

#[test]
fn hostile_inputs_never_panic() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let dir = tempfile::tempdir().expect("tempdir");
    let inputs = [
        (AnnotationFormat::Mot, "mot9/gt/gt.txt"),
        (AnnotationFormat::Mot, "mot7/gt/gt.txt"),
        (AnnotationFormat::Cvat, "cvat_video.xml"),
        (AnnotationFormat::CocoVideo, "tao.json"),
        (AnnotationFormat::CocoVideo, "ytvis.json"),
        (
            AnnotationFormat::ImagenetVid,
            "vid/ILSVRC2015_train_00000000/000000.xml",
        ),
    ];
    let alphabet = b"0123456789-.,<>/=\"[]{}: naex\n";
    for (format, rel) in inputs {
        let original = std::fs::read(fixture(rel)).expect("fixture");
        let path = dir.path().join(rel);
        for _ in 0..150 {
            let mut bytes = original.clone();
            for _ in 0..rng.random_range(1..4) {
                if bytes.is_empty() {
                    break;
                }
                let at = rng.random_range(0..bytes.len());
                if rng.random_range(0..8) == 0 {
                    bytes.truncate(at);
                } else {
                    bytes[at] = alphabet[rng.random_range(0..alphabet.len())];
                }
            }
            std::fs::create_dir_all(path.parent().expect("parent")).expect("mkdir");
            std::fs::write(&path, &bytes).expect("write");
            if let Err(e) = read(format, &path, &opts()) {
                assert!(!e.to_string().contains('\n'), "one line: {e}");
            }
        }
    }
    // Frame numbers at the end of the u32 range.
    let job = "<?xml version=\"1.0\"?><annotations><version>1.1</version><meta><job>\
               <stop_frame>4294967295</stop_frame></job></meta><track id=\"0\" label=\"a\">\
               <box frame=\"4294967295\" xtl=\"0\" ytl=\"0\" xbr=\"1\" ybr=\"1\"/></track></annotations>";
    let p = put(dir.path(), "max.xml", job);
    let ann = read(AnnotationFormat::Cvat, &p, &opts()).expect("read");
    assert_eq!(ann.videos[0].box_count(), 1);
    assert_eq!(ann.videos[0].length, None, "stop_frame + 1 does not fit");
    let p = put(dir.path(), "max.txt", "4294967296,1,0,0,1,1,-1\n");
    read_err(
        AnnotationFormat::Mot,
        &p,
        &opts(),
        &["line 1", "out of range"],
    );
}
