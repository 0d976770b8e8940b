//! MOT Challenge `gt.txt`: the three layouts, seqinfo.ini, labels.txt, errors, writer.
use super::*;

fn mot_names() -> Vec<String> {
    MOT_CLASSES.iter().map(|s| (*s).to_owned()).collect()
}

fn read_mot(path: &Path, opts: &ReadOptions) -> VideoAnnotations {
    read(AnnotationFormat::Mot, path, opts).expect("read MOT")
}

#[test]
fn seven_columns_with_seqinfo() {
    let ann = read_mot(&fixture("mot7/gt/gt.txt"), &opts());
    assert_eq!(ann.format, AnnotationFormat::Mot);
    assert_eq!(ann.classes, mot_names());
    let v = &ann.videos[0];
    assert_eq!(
        (v.name.as_str(), v.width, v.height),
        ("campus-mini", 640, 480)
    );
    assert_eq!((v.length, v.fps), (Some(5), Some(25.0)));
    assert_eq!(v.frames.keys().copied().collect::<Vec<_>>(), [0, 1, 2, 4]);
    assert_eq!(v.frames[&0].file.as_deref(), Some("img1/000001.jpg"));
    assert_eq!(v.frames[&4].file.as_deref(), Some("img1/000005.jpg"));
    assert_eq!(
        v.frames[&0].boxes,
        [
            tracked(0, Some(1), bx(399.0, 182.0, 520.0, 411.0)),
            tracked(0, Some(2), bx(282.0, 201.0, 374.0, 385.0)),
        ]
    );
    assert_eq!(
        v.frames[&1].boxes,
        [tracked(0, Some(1), bx(400.5, 183.0, 520.5, 411.0))]
    );
    assert_eq!(
        v.frames[&2].boxes,
        [tracked(0, None, bx(10.0, 20.0, 40.0, 60.0))]
    );
    assert_eq!(
        v.frames[&4].boxes,
        [tracked(0, Some(2), bx(290.0, 205.0, 380.0, 385.0))]
    );
}

#[test]
fn nine_columns_classes_ignore_and_visibility() {
    let ann = read_mot(&fixture("mot9/gt/gt.txt"), &opts());
    assert_eq!(ann.classes, mot_names());
    let v = &ann.videos[0];
    assert_eq!(
        (v.name.as_str(), v.width, v.height, v.length),
        ("MOT17-mini", 1920, 1080, Some(4))
    );
    assert_eq!(v.fps, None);
    assert!(v.frames.values().all(|f| f.file.is_none()));
    let b = |frame: u32, i: usize| v.frames[&frame].boxes[i];
    // static_person (7) with flag 0: ignored, keeps its class.
    assert_eq!(
        b(0, 0),
        AnnotatedBox {
            ignore: true,
            visibility: Some(1.0),
            ..tracked(6, Some(1), bx(912.0, 484.0, 1009.0, 593.0))
        }
    );
    assert_eq!(
        b(0, 1),
        AnnotatedBox {
            visibility: Some(0.86),
            ..tracked(0, Some(2), bx(1338.0, 418.0, 1505.0, 797.0))
        }
    );
    assert!(!b(0, 2).ignore, "visibility 0.2 with the default minimum 0");
    assert_eq!(
        b(1, 0),
        AnnotatedBox {
            visibility: Some(0.875),
            ..tracked(0, Some(2), bx(1340.5, 419.25, 1507.5, 798.25))
        }
    );
    assert_eq!(ann.classes[b(1, 1).class], "car");
    assert_eq!(
        (b(1, 1).ignore, b(1, 1).bbox),
        (false, bx(0.0, 0.0, 50.5, 20.0))
    );
    // reflection (12) is a distractor even with flag 1.
    assert_eq!(
        (ann.classes[b(2, 0).class].as_str(), b(2, 0).ignore),
        ("reflection", true)
    );
    // flag 0 pedestrian, visibility -1 = unknown.
    assert_eq!(
        (b(3, 0).class, b(3, 0).ignore, b(3, 0).visibility),
        (0, true, None)
    );

    let strict = ReadOptions {
        min_visibility: 0.25,
        ..opts()
    };
    let ann = read_mot(&fixture("mot9/gt/gt.txt"), &strict);
    let f0 = &ann.videos[0].frames[&0].boxes;
    assert_eq!(
        f0.iter().map(|b| b.ignore).collect::<Vec<_>>(),
        [true, false, true]
    );
}

#[test]
fn ten_columns_without_seqinfo() {
    let ann = read_mot(&fixture("mot10/gt.txt"), &opts());
    let v = &ann.videos[0];
    assert_eq!(
        (v.name.as_str(), v.width, v.height, v.length, v.fps),
        ("gt", 0, 0, None, None)
    );
    assert_eq!(v.box_count(), 3);
    assert_eq!(
        v.frames[&1].boxes,
        [
            tracked(0, Some(1), bx(12.0, 22.0, 42.0, 62.0)),
            tracked(0, Some(2), bx(100.0, 110.0, 115.5, 140.25)),
        ]
    );
}

#[test]
fn default_class_and_labels_txt() {
    let person = ReadOptions {
        default_class: "person".into(),
        ..opts()
    };
    let ann = read_mot(&fixture("mot10/gt.txt"), &person);
    assert_eq!(ann.classes, ["person"]);
    assert!(ann.videos[0].boxes().all(|(_, b)| b.class == 0));

    let dir = tempfile::tempdir().expect("tempdir");
    let gt = put(dir.path(), "seq/gt/gt.txt", "1.0,3.000,1,2,3,4,1,2,0.5\n");
    put(dir.path(), "seq/gt/labels.txt", "sign\nstatic_person\n\n");
    let ann = read_mot(&gt, &opts());
    assert_eq!(ann.classes, ["sign", "static_person"]);
    assert_eq!(ann.videos[0].name, "seq");
    let b = ann.videos[0].frames[&0].boxes[0];
    assert_eq!((b.class, b.track, b.ignore), (1, Some(3), true));
}

#[test]
fn errors_name_the_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let cases: [(&str, &str, &[&str]); 9] = [
        ("cols.txt", "1,1,2,3,4,5,1,1\n", &["line 1", "8 columns"]),
        (
            "mixed.txt",
            "1,1,2,3,4,5,-1\n\n2,1,2,3,4,5,1,1,1\n",
            &["line 3", "9 columns, but line 1 has 7"],
        ),
        (
            "dup.txt",
            "1,1,2,3,4,5,-1\n1,2,2,3,4,5,-1\n1,1,9,9,4,5,-1\n",
            &["line 3", "frame 1 track 1 is already on line 1"],
        ),
        (
            "negw.txt",
            "1,1,2,3,-4,5,-1\n",
            &["line 1", "negative width or height"],
        ),
        (
            "neg_h.txt",
            "1,1,2,3,4,5,-1\n2,1,2,3,4,-0.5,-1\n",
            &["line 2", "negative width or height"],
        ),
        (
            "frame0.txt",
            "0,1,2,3,4,5,-1\n",
            &["line 1", "frame 0", "1-based"],
        ),
        (
            "nan.txt",
            "1,1,x,3,4,5,-1\n",
            &["line 1", "column x is not a number"],
        ),
        ("class.txt", "1,1,2,3,4,5,1,13,1\n", &["line 1", "class 13"]),
        ("track.txt", "1,-2,2,3,4,5,-1\n", &["line 1", "track id -2"]),
    ];
    for (name, text, parts) in cases {
        read_err(AnnotationFormat::Mot, &put(d, name, text), &opts(), parts);
    }
    // Past seqinfo.ini's seqLength (5 frames), and past the caller's length.
    let gt = put(d, "seq/gt/gt.txt", "5,1,2,3,4,5,-1\n6,1,2,3,4,5,-1\n");
    put(d, "seq/seqinfo.ini", "[Sequence]\nseqLength=5\n");
    read_err(
        AnnotationFormat::Mot,
        &gt,
        &opts(),
        &[
            "line 2",
            "frame 6 is past the video's 5 frames",
            "seqLength",
        ],
    );
    let short = ReadOptions {
        length: Some(4),
        ..opts()
    };
    read_err(
        AnnotationFormat::Mot,
        &gt,
        &short,
        &[
            "line 1",
            "frame 5 is past the video's 4 frames",
            "length option",
        ],
    );
    put(d, "bad/seqinfo.ini", "[Sequence]\nimWidth=wide\n");
    let gt = put(d, "bad/gt/gt.txt", "1,1,2,3,4,5,-1\n");
    let msg = read(AnnotationFormat::Mot, &gt, &opts())
        .expect_err("bad seqinfo")
        .to_string();
    let ini = d.join("bad/seqinfo.ini").display().to_string();
    assert!(msg.starts_with(&format!("{ini}: line 2: imWidth")), "{msg}");
}

/// Read `path` as MOT after writing `video` there.
fn write_read(video: &AnnotatedVideo, classes: &[String], path: &Path) -> VideoAnnotations {
    write_mot(video, classes, path).expect("write MOT");
    read_mot(path, &opts())
}

#[test]
fn writer_round_trips_the_fixtures() {
    let dir = tempfile::tempdir().expect("tempdir");
    for rel in ["mot7/gt/gt.txt", "mot9/gt/gt.txt", "mot10/gt.txt"] {
        let ann = read_mot(&fixture(rel), &opts());
        let mut video = ann.videos[0].clone();
        video.name = format!("copy-{}", rel.replace('/', "-"));
        let out = dir.path().join(&video.name).join("gt/gt.txt");
        let back = write_read(&video, &ann.classes, &out);
        assert_eq!(back.classes, ann.classes, "{rel}");
        assert_eq!(back.videos, [video], "{rel}");
    }
    let text =
        std::fs::read_to_string(dir.path().join("copy-mot9-gt-gt.txt/gt/gt.txt")).expect("read");
    assert!(
        text.starts_with("1,1,912,484,97,109,0,7,1\n1,2,1338,418,167,379,1,1,0.86\n"),
        "{text}"
    );
    assert!(text.ends_with("4,6,200,200,30,60,0,1,-1\n"), "{text}");
    let ini =
        std::fs::read_to_string(dir.path().join("copy-mot7-gt-gt.txt/seqinfo.ini")).expect("ini");
    assert!(
        ini.contains("imDir=img1\n")
            && ini.contains("imExt=.jpg\n")
            && ini.contains("frameRate=25\n"),
        "{ini}"
    );
}

#[test]
fn writer_keeps_classes_that_are_not_mot_names() {
    let dir = tempfile::tempdir().expect("tempdir");
    let classes: Vec<String> = ["sign", "car"].map(String::from).to_vec();
    let mut video = AnnotatedVideo::new("custom");
    video.frames.entry(0).or_default().boxes = vec![
        tracked(0, Some(4), bx(1.0, 2.0, 3.0, 4.0)),
        AnnotatedBox {
            ignore: true,
            visibility: Some(0.3),
            ..tracked(1, None, bx(5.0, 6.0, 7.5, 8.25))
        },
    ];
    let out = dir.path().join("custom/gt/gt.txt");
    let back = write_read(&video, &classes, &out);
    assert_eq!(back.classes, classes);
    assert_eq!(back.videos, [video.clone()]);
    let labels = std::fs::read_to_string(dir.path().join("custom/gt/labels.txt")).expect("labels");
    assert_eq!(labels, "sign\ncar\n");

    // All MOT names, but not MOT's list: MOT ids, names kept, indices into the MOT list.
    let classes: Vec<String> = ["car", "pedestrian"].map(String::from).to_vec();
    let back = write_read(&video, &classes, &dir.path().join("mot/gt.txt"));
    assert_eq!(back.classes, mot_names());
    let text = std::fs::read_to_string(dir.path().join("mot/gt.txt")).expect("gt");
    assert_eq!(text, "1,4,1,2,2,2,1,3,-1\n1,-1,5,6,2.5,2.25,0,1,0.3\n");
    let names: Vec<&str> = back.videos[0]
        .boxes()
        .map(|(_, b)| back.classes[b.class].as_str())
        .collect();
    assert_eq!(names, ["car", "pedestrian"]);
}

#[test]
fn writer_round_trips_awkward_floats() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut video = AnnotatedVideo::new("floats");
    for k in 0..400u32 {
        let scale = [1.0f32, 0.01, 1000.0, 1.0e6][k as usize % 4];
        let x1: f32 = rng.random_range(-1.0..1.0) * scale;
        let y1: f32 = rng.random_range(0.0..1.0) * scale;
        let (w, h): (f32, f32) = (
            rng.random_range(0.0..2.0) * scale,
            rng.random_range(0.0..0.001),
        );
        let mut b = tracked(0, Some(u64::from(k)), bx(x1, y1, x1 + w, y1 + h));
        b.visibility = Some(rng.random_range(0.0..1.0));
        video.frames.entry(k / 3).or_default().boxes.push(b);
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let back = write_read(&video, &mot_names(), &dir.path().join("floats.txt"));
    assert_eq!(back.videos[0].frames, video.frames);
}

#[test]
fn writer_refuses_what_mot_cannot_hold() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("gt.txt");
    let mut video = AnnotatedVideo::new("bad");
    video.frames.entry(2).or_default().boxes = vec![tracked(3, None, bx(0.0, 0.0, 1.0, 1.0))];
    let msg = write_mot(&video, &mot_names()[..2], &path)
        .expect_err("class 3 of 2")
        .to_string();
    assert!(
        msg.contains("frame index 2 box 0") && msg.contains("class 3"),
        "{msg}"
    );
    video.frames.entry(2).or_default().boxes = vec![
        tracked(0, Some(1), bx(0.0, 0.0, 1.0, 1.0)),
        tracked(0, Some(1), bx(2.0, 0.0, 3.0, 1.0)),
    ];
    let msg = write_mot(&video, &mot_names(), &path)
        .expect_err("same track twice")
        .to_string();
    assert!(
        msg.contains("frame index 2 box 1") && msg.contains("track 1"),
        "{msg}"
    );
    video.frames.entry(2).or_default().boxes = vec![tracked(0, None, bx(5.0, 0.0, 1.0, 1.0))];
    let msg = write_mot(&video, &mot_names(), &path)
        .expect_err("negative width")
        .to_string();
    assert!(msg.contains("negative width"), "{msg}");
    assert!(!path.exists());
}
