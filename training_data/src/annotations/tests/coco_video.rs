//! COCO with videos: TAO and YouTube-VIS styles, pycocotools quirks, errors, writer.
use super::*;

fn read_coco(path: &Path) -> VideoAnnotations {
    read(AnnotationFormat::CocoVideo, path, &opts()).expect("read COCO-video")
}

#[test]
fn tao_style() {
    let ann = read_coco(&fixture("tao.json"));
    assert_eq!(ann.format, AnnotationFormat::CocoVideo);
    // Categories in id order 0, 2, 5; id 0 is an ordinary category.
    assert_eq!(ann.classes, ["person", "car", "bicycle"]);
    let [a, b] = &ann.videos[..] else {
        panic!("two videos")
    };
    assert_eq!(
        (a.name.as_str(), a.width, a.height, a.length, a.fps),
        ("train/YFCC100M/v_abc", 640, 480, None, None)
    );
    assert_eq!(a.frames.keys().copied().collect::<Vec<_>>(), [0, 30]);
    assert_eq!(
        a.frames[&30].file.as_deref(),
        Some("train/YFCC100M/v_abc/frame0031.jpg")
    );
    assert_eq!(
        a.frames[&0].boxes,
        [
            tracked(0, Some(100), bx(10.0, 20.0, 40.0, 60.0)),
            AnnotatedBox {
                ignore: true,
                ..tracked(2, Some(101), bx(0.5, 1.5, 2.75, 4.5))
            },
        ]
    );
    assert_eq!(
        a.frames[&30].boxes,
        [AnnotatedBox {
            ignore: true,
            ..tracked(0, Some(100), bx(12.0, 22.0, 42.0, 62.0))
        }]
    );
    assert_eq!(
        (b.name.as_str(), b.width, b.height, b.length, b.fps),
        ("val/b", 320, 240, Some(30), Some(29.97))
    );
    // The polygon-only annotation gets the polygons' bounding box.
    assert_eq!(
        b.frames[&5].boxes,
        [
            tracked(2, Some(200), bx(5.0, 5.0, 25.0, 30.0)),
            tracked(1, None, bx(1.0, 1.0, 6.0, 6.0))
        ]
    );
    assert_eq!(
        b.frames[&6],
        AnnotatedFrame {
            file: Some("val/b/00006.jpg".into()),
            boxes: vec![]
        }
    );
}

#[test]
fn youtube_vis_style() {
    let ann = read_coco(&fixture("ytvis.json"));
    assert_eq!(ann.classes, ["person", "airplane"]);
    let v = &ann.videos[0];
    assert_eq!(
        (v.name.as_str(), v.width, v.height, v.length),
        ("0043f083b5", 1280, 720, Some(3))
    );
    let files: Vec<_> = v
        .frames
        .values()
        .map(|f| f.file.clone().unwrap_or_default())
        .collect();
    assert_eq!(
        files,
        [
            "0043f083b5/00000.jpg",
            "0043f083b5/00005.jpg",
            "0043f083b5/00010.jpg"
        ]
    );
    assert_eq!(
        v.frames[&0].boxes,
        [tracked(0, Some(1), bx(10.0, 20.0, 40.0, 60.0))]
    );
    assert_eq!(
        v.frames[&1].boxes,
        [AnnotatedBox {
            ignore: true,
            ..tracked(1, Some(2), bx(0.0, 0.0, 5.0, 5.0))
        }]
    );
    assert_eq!(
        v.frames[&2].boxes,
        [tracked(0, Some(1), bx(12.0, 22.0, 42.0, 62.0))]
    );
}

/// A COCO-video file with one 3-frame video, images 1 and 2, categories 0 and 1, and
/// the given annotations (and extra top-level text).
fn coco(annotations: &str, extra: &str) -> String {
    format!(
        r#"{{"videos": [{{"id": 1, "name": "v", "length": 3}}],
  "images": [{{"id": 1, "video_id": 1, "frame_id": 0}}, {{"id": 2, "video_id": 1, "frame_id": 1}}{extra}],
  "annotations": [{annotations}],
  "categories": [{{"id": 0, "name": "a"}}, {{"id": 1, "name": "b"}}]}}"#
    )
}

#[test]
fn errors_name_the_id() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let a = |id: u64, rest: &str| format!(r#"{{"id": {id}, "category_id": 0, {rest}}}"#);
    let ok = a(5, r#""image_id": 1, "bbox": [1, 2, 3, 4]"#);
    let cases: Vec<(&str, String, Vec<&str>)> = vec![
        (
            "dup_ann.json",
            coco(&format!("{ok}, {ok}"), ""),
            vec!["annotation id 5", "appears twice"],
        ),
        (
            "dup_img.json",
            coco("", r#", {"id": 2, "video_id": 1, "frame_id": 2}"#),
            vec!["image id 2", "appears twice"],
        ),
        (
            "no_img.json",
            coco(&a(6, r#""image_id": 9, "bbox": [1, 2, 3, 4]"#), ""),
            vec!["annotation id 6", "image id 9 does not exist"],
        ),
        (
            "no_cat.json",
            coco(
                r#"{"id": 7, "image_id": 1, "category_id": 4, "bbox": [1, 2, 3, 4]}"#,
                "",
            ),
            vec!["annotation id 7", "category id 4 does not exist"],
        ),
        (
            "rle.json",
            coco(
                &a(
                    8,
                    r#""image_id": 1, "segmentation": {"size": [4, 4], "counts": "x"}"#,
                ),
                "",
            ),
            vec!["annotation id 8", "RLE segmentation without bbox"],
        ),
        (
            "neg.json",
            coco(&a(9, r#""image_id": 1, "bbox": [1, 2, -3, 4]"#), ""),
            vec!["annotation id 9", "negative width"],
        ),
        (
            "short.json",
            coco(&a(10, r#""image_id": 1, "bbox": [1, 2, 3]"#), ""),
            vec!["annotation id 10", "not [x, y, w, h]"],
        ),
        (
            "past.json",
            coco("", r#", {"id": 3, "video_id": 1, "frame_id": 3}"#),
            vec!["image id 3", "frame 3 is past the video's 3 frames"],
        ),
        (
            "same_frame.json",
            coco("", r#", {"id": 3, "video_id": 1, "frame_index": 1}"#),
            vec!["image id 3", "frame 1 of video id 1 is also image id 2"],
        ),
        (
            "no_video.json",
            coco("", r#", {"id": 3, "video_id": 4, "frame_id": 2}"#),
            vec!["image id 3", "video id 4 does not exist"],
        ),
        (
            "bboxes.json",
            coco(
                &a(11, r#""video_id": 1, "bboxes": [[1, 2, 3, 4], null]"#),
                "",
            ),
            vec!["annotation id 11", "2 per-frame boxes", "3 frames"],
        ),
        (
            "plain.json",
            r#"{"images": [], "annotations": [], "categories": []}"#.into(),
            vec!["top level", "plain COCO"],
        ),
        (
            "dup_cat.json",
            r#"{"videos": [], "categories": [{"id": 3, "name": "a"}, {"id": 3, "name": "b"}]}"#
                .into(),
            vec!["category id 3", "appears twice"],
        ),
        (
            "syntax.json",
            "{\"videos\": [\n  {\"id\": 1,}\n]}".into(),
            vec!["malformed JSON", "line 2"],
        ),
    ];
    for (name, text, parts) in &cases {
        read_err(
            AnnotationFormat::CocoVideo,
            &put(d, name, text),
            &opts(),
            parts,
        );
    }
    let p = put(
        d,
        "long.json",
        &coco("", r#", {"id": 3, "video_id": 1, "frame_id": 2}"#),
    );
    let two = ReadOptions {
        length: Some(2),
        ..opts()
    };
    read_err(
        AnnotationFormat::CocoVideo,
        &p,
        &two,
        &[
            "image id 3",
            "frame 2 is past the video's 2 frames",
            "length option",
        ],
    );
}

#[test]
fn writer_round_trips_every_reader() {
    let dir = tempfile::tempdir().expect("tempdir");
    let inputs = [
        (AnnotationFormat::CocoVideo, "tao.json"),
        (AnnotationFormat::CocoVideo, "ytvis.json"),
        (AnnotationFormat::Mot, "mot9/gt/gt.txt"),
        (AnnotationFormat::Mot, "mot7/gt/gt.txt"),
        (AnnotationFormat::Cvat, "cvat_video.xml"),
        (AnnotationFormat::ImagenetVid, "vid"),
    ];
    for (n, (format, rel)) in inputs.into_iter().enumerate() {
        let mut ann = read(format, &fixture(rel), &opts()).expect("read fixture");
        let out = dir.path().join(format!("{n}.json"));
        write_coco_video(&ann, &out).expect("write");
        ann.format = AnnotationFormat::CocoVideo;
        assert_eq!(read_coco(&out), ann, "{rel}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("0.json")).expect("read"))
            .expect("json");
    assert_eq!(json["images"][1]["frame_index"], 30);
    assert_eq!(
        json["annotations"][0]["bbox"],
        serde_json::json!([10.0, 20.0, 30.0, 40.0])
    );
    assert_eq!(json["annotations"][1]["iscrowd"], 1);
    assert_eq!(json["annotations"][1]["track_id"], 101);
    assert_eq!(
        json["categories"][0],
        serde_json::json!({"id": 1, "name": "person"})
    );
}

#[test]
fn writer_refuses_unknown_classes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut video = AnnotatedVideo::new("v");
    video
        .frames
        .entry(3)
        .or_default()
        .boxes
        .push(AnnotatedBox::new(2, bx(0.0, 0.0, 1.0, 1.0)));
    let ann = VideoAnnotations {
        format: AnnotationFormat::Mot,
        classes: vec!["a".into()],
        videos: vec![video],
    };
    let path = dir.path().join("x.json");
    let msg = write_coco_video(&ann, &path)
        .expect_err("class 2 of 1")
        .to_string();
    assert!(
        msg.contains("video \"v\" frame index 3 box 0") && msg.contains("class 2"),
        "{msg}"
    );
    assert!(!path.exists());
}
