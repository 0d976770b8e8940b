//! CVAT for video: interpolation, outside, persistence to the end, errors.
use super::*;

fn third(a: f64, b: f64, t: f64) -> f32 {
    (a + (b - a) * t) as f32
}

#[test]
fn tracks_expand_as_cvat_does() {
    let ann = read(AnnotationFormat::Cvat, &fixture("cvat_video.xml"), &opts()).expect("read CVAT");
    assert_eq!(ann.format, AnnotationFormat::Cvat);
    assert_eq!(ann.classes, ["car", "person", "bus"]);
    assert_eq!(ann.videos.len(), 1);
    let v = &ann.videos[0];
    assert_eq!(
        (v.name.as_str(), v.width, v.height, v.length, v.fps),
        ("drone & cars", 1280, 720, Some(10), None)
    );
    let track = |id: u64| -> Vec<(u32, AnnotatedBox)> {
        v.boxes()
            .filter(|(_, b)| b.track == Some(id))
            .map(|(k, b)| (k, *b))
            .collect()
    };
    let car = |k: u32, b: BBox| (k, tracked(0, Some(0), b));
    let occluded = |k: u32, b: BBox| {
        (
            k,
            AnnotatedBox {
                occluded: true,
                ..tracked(0, Some(0), b)
            },
        )
    };
    // Keyframes 0 and 4, interpolated 1-3 in quarters; 5 interpolated towards the
    // outside box at 6; hidden 6-7; keyframe 8 (occluded) persists to frame 9 = size - 1.
    assert_eq!(
        track(0),
        [
            car(0, bx(10.0, 20.0, 50.0, 60.0)),
            car(1, bx(15.0, 25.0, 55.0, 70.0)),
            car(2, bx(20.0, 30.0, 60.0, 80.0)),
            car(3, bx(25.0, 35.0, 65.0, 90.0)),
            car(4, bx(30.0, 40.0, 70.0, 100.0)),
            car(5, bx(40.0, 45.0, 80.0, 110.0)),
            occluded(8, bx(0.5, 1.5, 20.25, 30.75)),
            occluded(9, bx(0.5, 1.5, 20.25, 30.75)),
        ]
    );
    // The non-keyframe box at 3 is used as given (not 101.33 from keyframes 2 and 5);
    // 4 lies halfway between 3 and 5; 6 halfway towards the outside box at 7.
    let person = |k: u32, x1: f32| (k, tracked(1, Some(1), bx(x1, 100.0, x1 + 10.0, 120.0)));
    assert_eq!(
        track(1),
        [
            person(2, 100.0),
            person(3, 101.0),
            person(4, 102.5),
            person(5, 104.0),
            person(6, 105.0)
        ]
    );
    // Listed out of order; thirds computed in f64 like CVAT; persists from 3 to 9.
    let mut want = vec![
        car(0, bx(0.0, 0.0, 10.0, 10.0)),
        car(
            1,
            bx(
                third(0.0, 1.0, 1.0 / 3.0),
                third(0.0, 2.0, 1.0 / 3.0),
                third(10.0, 11.0, 1.0 / 3.0),
                third(10.0, 12.0, 1.0 / 3.0),
            ),
        ),
        car(
            2,
            bx(
                third(0.0, 1.0, 2.0 / 3.0),
                third(0.0, 2.0, 2.0 / 3.0),
                third(10.0, 11.0, 2.0 / 3.0),
                third(10.0, 12.0, 2.0 / 3.0),
            ),
        ),
    ];
    want.extend((3..=9).map(|k| car(k, bx(1.0, 2.0, 11.0, 12.0))));
    for w in &mut want {
        w.1.track = Some(2);
    }
    assert_eq!(track(2), want);
    assert_eq!(track(3), [], "polygon tracks are not boxes");
    assert_eq!(v.box_count(), 8 + 5 + 10);
    let order: Vec<Option<u64>> = v.frames[&2].boxes.iter().map(|b| b.track).collect();
    assert_eq!(order, [Some(0), Some(1), Some(2)]);
    assert!(v.frames.values().all(|f| f.file.is_none()));
}

/// A CVAT document with `meta` inside `<meta>` and `tracks` after it.
fn doc(meta: &str, tracks: &str) -> String {
    format!(
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<annotations>\n<version>1.1</version>\n\
         <meta>{meta}</meta>\n{tracks}\n</annotations>\n"
    )
}

const TASK: &str =
    "<task><name>t</name><size>5</size><labels><label><name>car</name></label></labels></task>";

#[test]
fn job_exports_persist_to_stop_frame() {
    let dir = tempfile::tempdir().expect("tempdir");
    let job = "<job><id>3</id><size>5</size><start_frame>5</start_frame><stop_frame>9</stop_frame>\
               <labels><label><name>car</name></label></labels></job>";
    let track = r#"<track id="4" label="car"><box frame="7" xtl="1" ytl="1" xbr="2" ybr="2" outside="0" occluded="0" keyframe="1"/></track>"#;
    let p = put(dir.path(), "job.xml", &doc(job, track));
    let ann = read(AnnotationFormat::Cvat, &p, &opts()).expect("read job");
    let v = &ann.videos[0];
    assert_eq!(v.frames.keys().copied().collect::<Vec<_>>(), [7, 8, 9]);
    assert_eq!((v.length, v.name.as_str()), (Some(10), "job"));

    // Without <size> or <stop_frame>, the caller's length ends the track.
    let bare = "<task><labels><label><name>car</name></label></labels></task>";
    let p = put(dir.path(), "bare.xml", &doc(bare, track));
    read_err(
        AnnotationFormat::Cvat,
        &p,
        &opts(),
        &["line 5: track 4 frame 7", "pass the video length"],
    );
    let ten = ReadOptions {
        length: Some(9),
        ..opts()
    };
    let ann = read(AnnotationFormat::Cvat, &p, &ten).expect("read with length");
    assert_eq!(
        ann.videos[0].frames.keys().copied().collect::<Vec<_>>(),
        [7, 8]
    );

    // No <labels>: classes from the tracks.
    let p = put(
        dir.path(),
        "nolabels.xml",
        &doc("<task><size>8</size></task>", track),
    );
    assert_eq!(
        read(AnnotationFormat::Cvat, &p, &opts())
            .expect("read")
            .classes,
        ["car"]
    );
}

#[test]
fn errors_name_the_track_and_frame() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let b = |f: u32, extra: &str| {
        format!(
            r#"<box frame="{f}" xtl="1" ytl="1" xbr="2" ybr="2" outside="0" occluded="0" keyframe="1"{extra}/>"#
        )
    };
    let cases: Vec<(&str, String, Vec<&str>)> = vec![
        (
            "label.xml",
            doc(
                TASK,
                &format!(r#"<track id="7" label="truck">{}</track>"#, b(0, "")),
            ),
            vec!["line 5: track 7", "unknown track class \"truck\"", "car"],
        ),
        (
            "past.xml",
            doc(
                TASK,
                &format!(r#"<track id="1" label="car">{}</track>"#, b(5, "")),
            ),
            vec!["track 1 frame 5", "past the last frame 4", "<size>"],
        ),
        (
            "twice.xml",
            doc(
                TASK,
                &format!(
                    "<track id=\"1\" label=\"car\">\n{}\n{}</track>",
                    b(2, ""),
                    b(2, "")
                ),
            ),
            vec!["line 7: track 1 frame 2", "first is on line 6"],
        ),
        (
            "rotated.xml",
            doc(
                TASK,
                &format!(
                    r#"<track id="2" label="car">{}</track>"#,
                    b(0, r#" rotation="30""#)
                ),
            ),
            vec!["track 2 frame 0", "rotated"],
        ),
        (
            "coords.xml",
            doc(
                TASK,
                r#"<track id="2" label="car"><box frame="1" xtl="a" ytl="1" xbr="2" ybr="2"/></track>"#,
            ),
            vec!["line 5: track 2 frame 1", "xtl=\"a\""],
        ),
        (
            "inverted.xml",
            doc(
                TASK,
                r#"<track id="2" label="car"><box frame="1" xtl="5" ytl="1" xbr="2" ybr="2"/></track>"#,
            ),
            vec!["track 2 frame 1", "before xtl"],
        ),
        (
            "dupid.xml",
            doc(
                TASK,
                &format!(
                    "<track id=\"1\" label=\"car\">{}</track>\n<track id=\"1\" label=\"car\"></track>",
                    b(0, "")
                ),
            ),
            vec!["line 6: track 1", "already used on line 5"],
        ),
        (
            "broken.xml",
            doc(
                TASK,
                r#"<track id="1" label="car"><box frame="0" xtl="1" ytl="1" xbr="2" ybr="2"></track>"#,
            ),
            vec!["malformed XML", "line 5"],
        ),
    ];
    for (name, text, parts) in &cases {
        read_err(AnnotationFormat::Cvat, &put(d, name, text), &opts(), parts);
    }
    let short = ReadOptions {
        length: Some(3),
        ..opts()
    };
    let p = put(
        d,
        "long.xml",
        &doc(
            TASK,
            &format!(r#"<track id="1" label="car">{}</track>"#, b(1, "")),
        ),
    );
    read_err(
        AnnotationFormat::Cvat,
        &p,
        &short,
        &[
            "track 1 frame 3",
            "past the video's 3 frames",
            "length option",
        ],
    );
    read_err(
        AnnotationFormat::Cvat,
        &fixture("cvat_images.xml"),
        &opts(),
        &["<image>", "CVAT for images", "not CVAT for video"],
    );
    let p = put(
        d,
        "voc.xml",
        "<annotation><filename>a.jpg</filename></annotation>",
    );
    read_err(
        AnnotationFormat::Cvat,
        &p,
        &opts(),
        &[
            "line 1",
            "root element <annotation>, expected <annotations>",
        ],
    );
}
