//! ImageNet VID: snippet folders, inclusive corners, WordNet ids, errors.
use super::*;

const A: &str = "ILSVRC2015_train_00000000";

fn read_vid(path: &Path) -> VideoAnnotations {
    read(AnnotationFormat::ImagenetVid, path, &opts()).expect("read ImageNet VID")
}

#[test]
fn a_folder_of_snippets() {
    let ann = read_vid(&fixture("vid"));
    assert_eq!(ann.format, AnnotationFormat::ImagenetVid);
    assert_eq!(ann.classes, ["n01503061", "n02084071", "n02691156"]);
    let [a, b] = &ann.videos[..] else {
        panic!("two snippets")
    };
    assert_eq!(
        (a.name.as_str(), a.width, a.height, a.length, a.fps),
        (A, 1280, 720, None, None)
    );
    assert_eq!(
        a.frames[&0].file.as_deref(),
        Some("ILSVRC2015_VID_train_0000/ILSVRC2015_train_00000000/000000")
    );
    // Inclusive corners: xmax 1050 is the exclusive edge 1051.
    assert_eq!(
        a.frames[&0].boxes,
        [
            tracked(2, Some(0), bx(263.0, 91.0, 1051.0, 637.0)),
            AnnotatedBox {
                occluded: true,
                ..tracked(1, Some(1), bx(0.0, 0.0, 10.0, 20.0))
            },
        ]
    );
    assert_eq!(
        a.frames[&1].boxes,
        [tracked(2, Some(0), bx(265.0, 92.0, 1052.0, 638.0))]
    );
    assert_eq!(
        (b.name.as_str(), b.width, b.height),
        ("ILSVRC2015_train_00000001", 640, 360)
    );
    assert_eq!(
        b.frames[&0].boxes,
        [tracked(0, Some(0), bx(10.0, 10.0, 21.0, 21.0))]
    );
    assert_eq!(b.frames[&1].boxes, [], "a frame without objects is kept");
    assert_eq!(ann.box_count(), 4);
}

#[test]
fn one_snippet_or_one_file() {
    let ann = read_vid(&fixture(&format!("vid/{A}")));
    assert_eq!(ann.classes, ["n02084071", "n02691156"]);
    assert_eq!(ann.videos.len(), 1);
    assert_eq!(ann.videos[0].name, A);
    assert_eq!(ann.videos[0].frames.len(), 2);
    let ann = read_vid(&fixture(&format!("vid/{A}/000001.xml")));
    assert_eq!(
        ann.videos[0].frames.keys().copied().collect::<Vec<_>>(),
        [1]
    );
    assert_eq!(ann.classes, ["n02691156"]);
}

fn frame(size: (u32, u32), objects: &[(&str, &str, [i32; 4])]) -> String {
    let mut s = format!(
        "<annotation><folder>x</folder><filename>f</filename>\
         <size><width>{}</width><height>{}</height></size>",
        size.0, size.1
    );
    for (track, name, [x1, y1, x2, y2]) in objects {
        s += &format!(
            "<object>{track}<name>{name}</name><bndbox><xmax>{x2}</xmax><xmin>{x1}</xmin>\
             <ymax>{y2}</ymax><ymin>{y1}</ymin></bndbox><occluded>0</occluded></object>"
        );
    }
    s + "</annotation>"
}

#[test]
fn errors_name_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let one = [("<trackid>0</trackid>", "n1", [0, 0, 9, 9])];
    type Case<'a> = (&'a str, Vec<(&'a str, String)>, Vec<&'a str>);
    let cases: Vec<Case> = vec![
        (
            "size",
            vec![
                ("000000.xml", frame((10, 10), &one)),
                ("000001.xml", frame((20, 10), &one)),
            ],
            vec!["000001.xml", "<size>", "20x10", "000000.xml is 10x10"],
        ),
        (
            "name",
            vec![("first.xml", frame((10, 10), &one))],
            vec!["first.xml", "no frame number"],
        ),
        (
            "number",
            vec![
                ("1.xml", frame((10, 10), &one)),
                ("001.xml", frame((10, 10), &one)),
            ],
            vec!["1.xml", "frame 1", "001.xml has the same frame number"],
        ),
        (
            "track",
            vec![(
                "000000.xml",
                frame(
                    (10, 10),
                    &[one[0], ("<trackid>0</trackid>", "n2", [1, 1, 2, 2])],
                ),
            )],
            vec!["000000.xml", "object 2 (n2)", "trackid 0 appears twice"],
        ),
        (
            "notrack",
            vec![("000000.xml", frame((10, 10), &[("", "n1", [0, 0, 9, 9])]))],
            vec!["000000.xml", "object 1 (n1)", "no <trackid>"],
        ),
        (
            "empty",
            vec![(
                "000000.xml",
                frame((10, 10), &[("<trackid>3</trackid>", "n1", [5, 0, 4, 9])]),
            )],
            vec!["000000.xml", "object 1 (n1)", "is empty"],
        ),
        (
            "broken",
            vec![(
                "000000.xml",
                "<annotation><size><width>x</width></size></annotation>".into(),
            )],
            vec!["000000.xml", "malformed XML"],
        ),
    ];
    for (snippet, files, parts) in &cases {
        for (name, text) in files {
            put(d, &format!("{snippet}/{name}"), text);
        }
        let msg = read(AnnotationFormat::ImagenetVid, &d.join(snippet), &opts())
            .expect_err(snippet)
            .to_string();
        assert!(
            !msg.contains('\n') && msg.contains(&d.join(snippet).display().to_string()),
            "{msg}"
        );
        for p in parts {
            assert!(msg.contains(p), "{snippet}: mentions {p:?}: {msg}");
        }
    }
    put(d, "long/000000.xml", &frame((10, 10), &one));
    put(d, "long/000007.xml", &frame((10, 10), &one));
    let short = ReadOptions {
        length: Some(7),
        ..opts()
    };
    let msg = read(AnnotationFormat::ImagenetVid, &d.join("long"), &short)
        .expect_err("past")
        .to_string();
    assert!(
        msg.contains("000007.xml: frame 7: frame 7 is past the video's 7 frames"),
        "{msg}"
    );
    std::fs::create_dir_all(d.join("nothing/sub")).expect("mkdir");
    let msg = read(AnnotationFormat::ImagenetVid, &d.join("nothing"), &opts())
        .expect_err("empty")
        .to_string();
    assert!(
        msg.contains("nothing") && msg.contains("no .xml files"),
        "{msg}"
    );
}
