//! Whole-crate tests on the tiny profile: determinism, splits, reuse, import → export
//! → import round trips and the errors for malformed input.
//!
//! About 1,100 lines of independent tests sharing this file's tiny-profile fixtures.
use crate::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// One tiny dataset shared by the tests (generated once).
fn tiny() -> &'static Dataset {
    static DS: OnceLock<(tempfile::TempDir, Dataset)> = OnceLock::new();
    &DS.get_or_init(|| {
        let dir = tempfile::tempdir().expect("tempdir");
        let ds = generate(&GenConfig::tiny(), &dir.path().join("data"), false).expect("generate");
        (dir, ds)
    })
    .1
}

fn files(root: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![root.to_owned()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("read_dir") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(root).expect("prefix").to_owned();
                out.insert(rel, std::fs::read(&p).expect("read"));
            }
        }
    }
    out
}

fn leftovers(parent: &Path) -> Vec<String> {
    std::fs::read_dir(parent)
        .expect("read_dir")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".partial-"))
        .collect()
}

#[test]
fn same_seed_gives_identical_bytes_on_any_thread_count_and_another_seed_does_not() {
    let dir = tempfile::tempdir().expect("tempdir");
    let config = GenConfig {
        frames_per_video: 2,
        ..GenConfig::tiny()
    };
    let a = dir.path().join("a");
    let b = dir.path().join("b");
    let c = dir.path().join("c");
    generate(&config, &a, false).expect("a");
    // The second run on a single thread: scheduling must not change a byte.
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool")
        .install(|| generate(&config, &b, false))
        .expect("b");
    generate(
        &GenConfig {
            seed: 7,
            ..config.clone()
        },
        &c,
        false,
    )
    .expect("c");
    let (fa, fb, fc) = (files(&a), files(&b), files(&c));
    assert_eq!(
        fa.len(),
        2 + 3 + 18 * 2,
        "manifest, config, 3 COCO files, 36 frames"
    );
    assert_eq!(fa, fb, "same seed and config must give the same bytes");
    assert_eq!(fa.keys().collect::<Vec<_>>(), fc.keys().collect::<Vec<_>>());
    let differing = fa.iter().filter(|(k, v)| fc.get(*k) != Some(*v)).count();
    assert!(
        differing > 30,
        "another seed changes the frames ({differing} files differ)"
    );
    assert!(leftovers(dir.path()).is_empty());
    // The saved config reproduces the dataset.
    let saved = GenConfig::from_file(&a.join("config.toml")).expect("saved config");
    assert_eq!(saved, config);
}

#[test]
fn generated_dataset_loads_back_with_disjoint_splits_and_every_level() {
    let ds = tiny();
    let loaded = Dataset::load(&ds.root).expect("load");
    assert_eq!(&loaded, ds);
    assert_eq!(ds.frames.len(), 54);
    let mut split_of = BTreeMap::new();
    for f in &ds.frames {
        let prev = split_of.insert(f.video, f.split);
        assert!(
            prev.is_none() || prev == Some(f.split),
            "video {} in two splits",
            f.video
        );
        assert_eq!(ds.video(f.video).map(|v| v.split), Some(f.split));
        for o in &f.objects {
            assert!(o.bbox.is_valid() && o.bbox.x1 >= 0.0 && o.bbox.y1 >= 0.0);
            assert!(o.bbox.x2 <= f.width as f32 && o.bbox.y2 <= f.height as f32);
        }
        let rgb = loaded.load_rgb(f).expect("rgb");
        assert_eq!(rgb.dimensions(), (192, 108));
    }
    for split in Split::ALL {
        let levels: std::collections::BTreeSet<_> = ds
            .split(split)
            .filter_map(|f| ds.video(f.video))
            .map(|v| (v.clutter, v.light))
            .collect();
        assert_eq!(levels.len(), 6, "{split} has every scenario combination");
    }
    assert!(ds.frames.iter().map(|f| f.objects.len()).sum::<usize>() > 30);
}

#[test]
fn an_identical_dataset_is_reused_and_a_different_config_regenerates() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("data");
    let config = GenConfig {
        frames_per_video: 1,
        ..GenConfig::tiny()
    };
    let (_, reused) = generate_or_reuse(&config, &out, false).expect("first");
    assert!(!reused);
    let (ds, reused) = generate_or_reuse(&config, &out, false).expect("second");
    assert!(reused);
    assert_eq!(ds.frames.len(), 18);
    let other = GenConfig { seed: 1, ..config };
    let (_, reused) = generate_or_reuse(&other, &out, false).expect("third");
    assert!(!reused);
    assert!(leftovers(dir.path()).is_empty());
}

/// Objects of each frame, in frame order, for comparing datasets.
fn objects(ds: &Dataset) -> Vec<Vec<(ClassId, [i32; 4])>> {
    ds.frames
        .iter()
        .map(|f| {
            f.objects
                .iter()
                .map(|o| {
                    let b = o.bbox;
                    (
                        o.class,
                        [b.x1, b.y1, b.x2, b.y2].map(|v| (v * 100.0).round() as i32),
                    )
                })
                .collect()
        })
        .collect()
}

fn assert_same_pixels(a: &Dataset, b: &Dataset) {
    assert_eq!(a.frames.len(), b.frames.len());
    for (fa, fb) in a.frames.iter().zip(&b.frames) {
        assert_eq!(a.load_rgb(fa).expect("a"), b.load_rgb(fb).expect("b"));
    }
}

#[test]
fn coco_export_then_import_round_trips() {
    let ds = tiny();
    let dir = tempfile::tempdir().expect("tempdir");
    let json = export_coco(ds, None, &dir.path().join("coco")).expect("export");
    let back = import(
        &ImportOptions::new(Format::Coco, &json),
        &dir.path().join("back"),
    )
    .expect("import");
    assert_eq!(objects(&back), objects(ds));
    assert_eq!(back.videos.len(), ds.videos.len());
    for (a, b) in ds.videos.iter().zip(&back.videos) {
        assert_eq!(
            (a.id, a.clutter, a.light, a.split, a.frames),
            (b.id, b.clutter, b.light, b.split, b.frames)
        );
    }
    for (a, b) in ds.frames.iter().zip(&back.frames) {
        assert_eq!(
            (a.id, a.video, a.index, a.split, &a.file),
            (b.id, b.video, b.index, b.split, &b.file)
        );
    }
    assert_same_pixels(ds, &back);
    // And once more: export of the import equals the first export.
    let json2 = export_coco(&back, None, &dir.path().join("coco2")).expect("export");
    assert_eq!(
        std::fs::read(&json).expect("1"),
        std::fs::read(&json2).expect("2")
    );
}

/// Write the train frames of `ds` as Pascal VOC files into `dir`.
fn write_voc(ds: &Dataset, dir: &Path) {
    std::fs::create_dir_all(dir).expect("mkdir");
    for f in ds.split(Split::Train) {
        let mut xml = format!(
            "<annotation>\n  <folder>x</folder>\n  <filename>{}</filename>\n  <size><width>{}</width><height>{}</height><depth>3</depth></size>\n",
            f.file.display(),
            f.width,
            f.height
        );
        for o in &f.objects {
            let b = o.bbox;
            xml += &format!(
                "  <object><name>{}</name><pose>Unspecified</pose><difficult>0</difficult><bndbox><xmin>{}</xmin><ymin>{}</ymin><xmax>{}</xmax><ymax>{}</ymax></bndbox></object>\n",
                ds.classes[usize::from(o.class)].code,
                b.x1 + 1.0,
                b.y1 + 1.0,
                b.x2,
                b.y2
            );
        }
        xml += "</annotation>\n";
        std::fs::write(dir.join(format!("{:05}.xml", f.id)), xml).expect("write");
    }
}

/// Write the train frames of `ds` as a GTSDB CSV with numeric classes `100 + id`.
fn write_gtsdb(ds: &Dataset, path: &Path) {
    let mut csv = String::new();
    for f in ds.split(Split::Train) {
        for o in &f.objects {
            let b = o.bbox;
            csv += &format!(
                "{};{};{};{};{};{}\n",
                f.file.display(),
                b.x1,
                b.y1,
                b.x2 - 1.0,
                b.y2 - 1.0,
                100 + o.class
            );
        }
    }
    std::fs::write(path, csv).expect("write");
}

fn train_only(ds: &Dataset) -> Vec<Vec<(ClassId, [i32; 4])>> {
    let mut t = ds.clone();
    t.frames.retain(|f| f.split == Split::Train);
    objects(&t)
}

fn reimport_via_coco(first: &Dataset, dir: &Path) -> Dataset {
    let json = export_coco(first, None, &dir.join("exported")).expect("export");
    let second = import(
        &ImportOptions::new(Format::Coco, &json),
        &dir.join("second"),
    )
    .expect("import coco");
    assert_eq!(objects(&second), objects(first));
    for (a, b) in first.frames.iter().zip(&second.frames) {
        assert_eq!((a.video, a.index, a.split), (b.video, b.index, b.split));
    }
    assert_same_pixels(first, &second);
    second
}

#[test]
fn voc_import_then_coco_export_then_import_round_trips() {
    let ds = tiny();
    let dir = tempfile::tempdir().expect("tempdir");
    let voc = dir.path().join("voc");
    write_voc(ds, &voc);
    let mut opts = ImportOptions::new(Format::Voc, &voc);
    opts.images = Some(ds.root.clone());
    opts.classes = ClassList::Signs;
    let first = import(&opts, &dir.path().join("first")).expect("import voc");
    assert_eq!(objects(&first), train_only(ds));
    assert_eq!(
        first.videos.len(),
        first.frames.len(),
        "one video per image"
    );
    reimport_via_coco(&first, dir.path());
}

#[test]
fn gtsdb_import_with_class_map_then_coco_round_trips() {
    let ds = tiny();
    let dir = tempfile::tempdir().expect("tempdir");
    let csv = dir.path().join("gt.txt");
    write_gtsdb(ds, &csv);
    let map_path = dir.path().join("map.json");
    let map: BTreeMap<String, String> = Sign::ALL
        .iter()
        .map(|s| ((100 + s.id()).to_string(), s.name().to_owned()))
        .collect();
    std::fs::write(&map_path, serde_json::to_string(&map).expect("json")).expect("write");
    let mut opts = ImportOptions::new(Format::Gtsdb, &csv);
    opts.images = Some(ds.root.clone());
    opts.class_map = ClassMap::from_file(&map_path).expect("map");
    opts.classes = ClassList::Signs;
    let first = import(&opts, &dir.path().join("first")).expect("import gtsdb");
    // GTSDB lists only images with signs.
    let mut expected = train_only(ds);
    expected.retain(|o| !o.is_empty());
    assert_eq!(objects(&first), expected);
    reimport_via_coco(&first, dir.path());

    // Without the map, onto the ten signs, the numeric classes are unknown; with
    // --drop-unmapped they go.
    opts.class_map = ClassMap::default();
    opts.classes = ClassList::Signs;
    let err = import(&opts, &dir.path().join("x")).expect_err("unknown");
    let msg = err.to_string();
    assert!(
        msg.contains("gt.txt") && msg.contains("line 1") && msg.contains("unknown class"),
        "{msg}"
    );
    opts.drop_unmapped = true;
    let dropped = import(&opts, &dir.path().join("dropped")).expect("dropped");
    assert!(dropped.frames.iter().all(|f| f.objects.is_empty()));
}

fn import_err(format: Format, input: &Path, images: &Path) -> String {
    let mut opts = ImportOptions::new(format, input);
    opts.images = Some(images.to_owned());
    opts.classes = ClassList::Signs;
    opts.strict = true;
    let out = input.with_extension("out");
    let err = import(&opts, &out).expect_err("must fail").to_string();
    assert!(!out.exists(), "nothing is written on error");
    err
}

#[test]
fn malformed_inputs_name_the_file_and_the_record() {
    let ds = tiny();
    let root = &ds.root;
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let frame = ds.frames[0].file.display().to_string();

    // GTSDB: missing image (strict), box outside, negative box, unknown class, bad
    // number, wrong field count; a box reaching past the image is clipped instead.
    let cases = [
        (
            "missing.csv",
            "nope/none.png;1;1;5;5;stop\n",
            vec!["missing.csv", "line 1", "none.png", "not found"],
        ),
        (
            "outside.csv",
            &*format!("{frame};1;1;5;5;stop\n{frame};500;90;520;100;stop\n"),
            vec!["outside.csv", "line 2", "outside"],
        ),
        (
            "negative.csv",
            &*format!("{frame};1;1;5;5;stop\n{frame};20;20;10;30;stop\n"),
            vec!["negative.csv", "line 2", "negative"],
        ),
        (
            "unknown.csv",
            &*format!("{frame};1;1;5;5;stop\n{frame};1;1;5;5;yield\n"),
            vec!["unknown.csv", "line 2", "yield"],
        ),
        (
            "number.csv",
            &*format!("{frame};1;1;5;5;stop\n\n{frame};1;x;5;5;stop\n"),
            vec!["number.csv", "line 3", "y1"],
        ),
        (
            "fields.csv",
            &*format!("{frame};1;1;5;5;stop\n{frame};1;1;5;stop\n"),
            vec!["fields.csv", "line 2", "6 fields"],
        ),
        ("empty.csv", "", vec!["empty.csv", "empty dataset"]),
    ];
    for (name, text, needles) in cases {
        let p = d.join(name);
        std::fs::write(&p, text).expect("write");
        let msg = import_err(Format::Gtsdb, &p, root);
        for n in needles {
            assert!(msg.contains(n), "{name}: {msg:?} lacks {n:?}");
        }
    }

    // COCO: malformed JSON (line number), dangling image id, unknown category.
    let bad_json = d.join("bad.json");
    std::fs::write(
        &bad_json,
        "{\n  \"images\": [\n    {\"id\": 1,, }\n  ]\n}\n",
    )
    .expect("write");
    let msg = import_err(Format::Coco, &bad_json, root);
    assert!(msg.contains("bad.json") && msg.contains("line 3"), "{msg}");
    let dangling = d.join("dangling.json");
    std::fs::write(
        &dangling,
        format!(
            r#"{{"images": [{{"id": 1, "file_name": "{frame}", "width": 192, "height": 108}}],
               "annotations": [{{"id": 9, "image_id": 2, "category_id": 1, "bbox": [1, 1, 4, 4]}}],
               "categories": [{{"id": 1, "name": "stop"}}]}}"#
        ),
    )
    .expect("write");
    let msg = import_err(Format::Coco, &dangling, root);
    assert!(
        msg.contains("dangling.json")
            && msg.contains("annotation id 9")
            && msg.contains("image id 2"),
        "{msg}"
    );
    let empty = d.join("empty.json");
    std::fs::write(
        &empty,
        r#"{"images": [], "annotations": [], "categories": []}"#,
    )
    .expect("write");
    assert!(import_err(Format::Coco, &empty, root).contains("empty dataset"));
    let size = d.join("size.json");
    std::fs::write(
        &size,
        format!(r#"{{"images": [{{"id": 4, "file_name": "{frame}", "width": 100, "height": 108}}], "categories": []}}"#),
    )
    .expect("write");
    let msg = import_err(Format::Coco, &size, root);
    assert!(
        msg.contains("size.json") && msg.contains("image id 4") && msg.contains("192x108"),
        "{msg}"
    );

    // VOC: malformed XML, unknown class.
    let voc = d.join("voc");
    std::fs::create_dir_all(&voc).expect("mkdir");
    let bad_xml = voc.join("a.xml");
    std::fs::write(
        &bad_xml,
        "<annotation><filename>x.png</filename><object><name>stop</name></annotation>",
    )
    .expect("write");
    let msg = import_err(Format::Voc, &bad_xml, root);
    assert!(msg.contains("a.xml") && msg.contains("XML"), "{msg}");
    let unknown = voc.join("b.xml");
    std::fs::write(
        &unknown,
        format!("<annotation><filename>{frame}</filename><object><name>stop</name><bndbox><xmin>2</xmin><ymin>2</ymin><xmax>9</xmax><ymax>9</ymax></bndbox></object><object><name>zebra</name><bndbox><xmin>2</xmin><ymin>2</ymin><xmax>9</xmax><ymax>9</ymax></bndbox></object></annotation>"),
    )
    .expect("write");
    let msg = import_err(Format::Voc, &unknown, root);
    assert!(
        msg.contains("b.xml") && msg.contains("object 2") && msg.contains("zebra"),
        "{msg}"
    );
}

#[test]
fn a_failed_import_leaves_the_previous_dataset_untouched() {
    let ds = tiny();
    let dir = tempfile::tempdir().expect("tempdir");
    let json = export_coco(ds, Some(Split::Val), &dir.path().join("coco")).expect("export");
    let out = dir.path().join("data");
    import(&ImportOptions::new(Format::Coco, &json), &out).expect("good import");
    let before = files(&out);
    // Cut the last image short: conversion fails after others were written.
    let last = ds.split(Split::Val).last().expect("val frame").file.clone();
    let path = dir.path().join("coco").join(&last);
    let bytes = std::fs::read(&path).expect("read");
    // (the export hard-links frames: replace the file, never write through the link)
    std::fs::remove_file(&path).expect("unlink");
    std::fs::write(&path, &bytes[..bytes.len() / 2]).expect("truncate");
    let err = import(&ImportOptions::new(Format::Coco, &json), &out).expect_err("corrupt image");
    assert!(
        err.to_string().contains(&last.display().to_string()),
        "{err}"
    );
    assert_eq!(files(&out), before);
    assert!(
        leftovers(dir.path()).is_empty(),
        "{:?}",
        leftovers(dir.path())
    );
}

#[test]
fn corrupt_own_annotations_are_reported_on_load() {
    let ds = tiny();
    let dir = tempfile::tempdir().expect("tempdir");
    let copy = dir.path().join("copy");
    for (rel, bytes) in files(&ds.root) {
        let p = copy.join(rel);
        std::fs::create_dir_all(p.parent().expect("parent")).expect("mkdir");
        std::fs::write(p, bytes).expect("write");
    }
    let val = copy.join("annotations/val.json");
    let text = std::fs::read_to_string(&val).expect("read");
    let mut coco: serde_json::Value = serde_json::from_str(&text).expect("json");
    coco["annotations"][0]["bbox"] = serde_json::json!([180.0, 100.0, 30.0, 30.0]);
    let id = coco["annotations"][0]["id"].clone();
    std::fs::write(&val, serde_json::to_string(&coco).expect("json")).expect("write");
    let msg = Dataset::load(&copy).expect_err("box outside").to_string();
    assert!(
        msg.contains("val.json") && msg.contains(&format!("annotation id {id}")),
        "{msg}"
    );
    std::fs::write(copy.join("manifest.json"), "{").expect("write");
    let msg = Dataset::load(&copy).expect_err("bad manifest").to_string();
    assert!(
        msg.contains("manifest.json") && msg.contains("line 1"),
        "{msg}"
    );
}

#[test]
fn missing_images_are_skipped_and_counted_unless_strict() {
    let ds = tiny();
    let dir = tempfile::tempdir().expect("tempdir");
    let json = export_coco(ds, Some(Split::Val), &dir.path().join("coco")).expect("export");
    let listed = ds.split(Split::Val).count();
    let first = ds.split(Split::Val).next().expect("val frame").file.clone();
    std::fs::remove_file(dir.path().join("coco").join(&first)).expect("rm");
    let out = dir.path().join("data");
    let got = import(&ImportOptions::new(Format::Coco, &json), &out).expect("import");
    assert_eq!(got.frames.len(), listed - 1);
    let manifest = crate::dataset::read_manifest(&out).expect("manifest");
    let Source::Imported { counts, .. } = manifest.source else {
        panic!("not an import: {:?}", manifest.source);
    };
    assert_eq!(counts.missing_images, 1);

    let mut strict = ImportOptions::new(Format::Coco, &json);
    strict.strict = true;
    let err = import(&strict, &dir.path().join("strict")).expect_err("strict");
    assert!(
        err.to_string().contains("not found") && err.to_string().contains("annotations.json"),
        "{err}"
    );
    assert!(!dir.path().join("strict").exists());
}

#[test]
fn a_source_class_list_is_kept_and_actions_attach_by_name() {
    let ds = tiny();
    let dir = tempfile::tempdir().expect("tempdir");
    let csv = dir.path().join("gt.txt");
    write_gtsdb(ds, &csv);
    // three user classes from the numeric GTSDB ids; the rest dropped
    let map = ClassMap::from_pairs([("100", "left"), ("101", "right"), ("102", "halt")]);
    let mut opts = ImportOptions::new(Format::Gtsdb, &csv);
    opts.images = Some(ds.root.clone());
    opts.class_map = map;
    opts.drop_unmapped = true;
    opts.actions = [("halt".to_owned(), NavAction::Stop)].into_iter().collect();
    let got = import(&opts, &dir.path().join("three")).expect("import");
    let mut names: Vec<&str> = got.classes.iter().map(|c| c.name.as_str()).collect();
    names.sort_unstable();
    assert_eq!(names, ["halt", "left", "right"]);
    let halt = got.classes.iter().find(|c| c.name == "halt").expect("halt");
    assert_eq!(halt.action, Some(NavAction::Stop));
    assert!(
        got.classes
            .iter()
            .filter(|c| c.name != "halt")
            .all(|c| c.action.is_none())
    );
    let kept = |c: u16| {
        [Sign::TurnLeft, Sign::TurnRight, Sign::Stop]
            .iter()
            .any(|s| s.id() == c)
    };
    let expected: usize = ds
        .split(Split::Train)
        .flat_map(|f| &f.objects)
        .filter(|o| kept(o.class))
        .count();
    let objects: usize = got.frames.iter().map(|f| f.objects.len()).sum();
    assert_eq!(objects, expected);
    assert!(
        got.frames
            .iter()
            .flat_map(|f| &f.objects)
            .all(|o| o.class < 3)
    );
    // and the set loads back with its own classes
    let again = Dataset::load(&got.root).expect("load");
    assert_eq!(again.classes, got.classes);

    // an action for a class the set does not have is an error naming it
    opts.actions = [("pedestrian".to_owned(), NavAction::Wait)]
        .into_iter()
        .collect();
    let err = import(&opts, &dir.path().join("bad")).expect_err("unknown action class");
    assert!(err.to_string().contains("pedestrian"), "{err}");
}

#[test]
fn a_box_reaching_past_the_image_is_clipped_and_counted() {
    let ds = tiny();
    let dir = tempfile::tempdir().expect("tempdir");
    let f = &ds.frames[0];
    let csv = dir.path().join("gt.txt");
    let (w, h) = (f.width as f32, f.height as f32);
    let text = format!(
        "{0};2;3;9;9;stop\n{0};{1};{2};{3};{4};stop\n",
        f.file.display(),
        w - 10.0,
        h - 10.0,
        w + 20.0,
        h + 5.0
    );
    std::fs::write(&csv, text).expect("write");
    let mut opts = ImportOptions::new(Format::Gtsdb, &csv);
    opts.images = Some(ds.root.clone());
    let got = import(&opts, &dir.path().join("out")).expect("import");
    let boxes: Vec<BBox> = got.frames[0].objects.iter().map(|o| o.bbox).collect();
    assert_eq!(
        boxes,
        [
            BBox::new(2.0, 3.0, 10.0, 10.0),
            BBox::new(w - 10.0, h - 10.0, w, h)
        ]
    );
    let manifest = crate::dataset::read_manifest(&got.root).expect("manifest");
    let Source::Imported { counts, .. } = manifest.source else {
        panic!("not an import");
    };
    assert_eq!(counts.clipped_boxes, 1);
    assert_eq!(got.classes.len(), 1, "the source's one class");
}

/// `../shared/data/tud-campus`, the real MOT fixture (not in the repository), if present.
fn tud_campus() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/tud-campus");
    if p.join("gt/gt.txt").is_file() {
        Some(p)
    } else {
        eprintln!("skipped: {} is absent", p.display());
        None
    }
}

#[test]
fn tud_campus_imports_with_its_71_frames_and_359_boxes_split_by_time() {
    let Some(tud) = tud_campus() else { return };
    let dir = tempfile::tempdir().expect("tempdir");
    let mut opts = ImportOptions::new(
        Format::Video(crate::annotations::AnnotationFormat::Mot),
        tud.join("gt/gt.txt"),
    );
    opts.fps = Some(25.0);
    opts.actions = [("pedestrian".to_owned(), NavAction::Wait)]
        .into_iter()
        .collect();
    let ds = import(&opts, &dir.path().join("tud")).expect("import");
    assert_eq!(ds.frames.len(), 71);
    assert_eq!(
        ds.frames.iter().map(|f| f.objects.len()).sum::<usize>(),
        359
    );
    assert_eq!(ds.classes.len(), 1);
    assert_eq!(ds.classes[0].name, "pedestrian");
    assert_eq!(ds.classes[0].action, Some(NavAction::Wait));
    assert!(ds.frames.iter().all(|f| (f.width, f.height) == (640, 480)));
    // first 70 % train, next 15 % val, last 15 % test, in time order
    let per: Vec<usize> = Split::ALL.iter().map(|&s| ds.split(s).count()).collect();
    assert_eq!(per, [50, 11, 10]);
    assert_eq!(ds.videos.len(), 3);
    let names: Vec<&str> = ds.videos.iter().filter_map(|v| v.name.as_deref()).collect();
    assert_eq!(names.len(), 3);
    assert!(
        names[0].ends_with("#0-49") && names[2].ends_with("#61-70"),
        "{names:?}"
    );
    // real time: 25 fps, from each part's start
    let test: Vec<&FrameRecord> = ds.split(Split::Test).collect();
    assert_eq!(test[0].time_s, Some(0.0));
    assert!((ds.frame_time(test[9]) - 9.0 / 25.0).abs() < 1e-9);
    assert!(ds.videos.iter().all(|v| v.fps == Some(25.0)));
    // the first frame's boxes are gt.txt's frame-1 lines (x, y, w, h), clipped to 640×480
    let first = &ds.frames[0];
    assert!(
        first
            .objects
            .iter()
            .any(|o| o.bbox == BBox::new(399.0, 182.0, 520.0, 411.0))
    );
    // and it loads back
    let again = Dataset::load(&ds.root).expect("load");
    for (a, b) in again.frames.iter().zip(&ds.frames) {
        assert_eq!(a, b);
    }
}

/// Whether the `ffmpeg` program is installed (the set-up installs it).
fn have_ffmpeg() -> bool {
    let ok = std::process::Command::new("ffmpeg")
        .arg("-version")
        .stdout(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        eprintln!("skipped: ffmpeg is not installed (cargo xtask setup installs it)");
    }
    ok
}

/// One synthetic video of `ds` as an H.264 MP4 at 30 fps (near-lossless) plus a MOT
/// `gt.txt` of its boxes; returns (mp4, gt.txt, its frames).
fn synthetic_mp4(ds: &Dataset, dir: &Path) -> (PathBuf, PathBuf, Vec<FrameRecord>) {
    let video = ds
        .videos
        .iter()
        .max_by_key(|v| (v.frames, v.id))
        .expect("a video")
        .id;
    let frames: Vec<FrameRecord> = ds
        .frames
        .iter()
        .filter(|f| f.video == video)
        .cloned()
        .collect();
    let pngs = dir.join("png");
    std::fs::create_dir_all(&pngs).expect("mkdir");
    let mut gt = String::new();
    for f in &frames {
        std::fs::copy(ds.frame_path(f), pngs.join(format!("{:06}.png", f.index))).expect("copy");
        for (k, o) in f.objects.iter().enumerate() {
            let b = o.bbox;
            gt += &format!(
                "{},{},{},{},{},{},1\n",
                f.index + 1,
                k + 1,
                b.x1,
                b.y1,
                b.x2 - b.x1,
                b.y2 - b.y1
            );
        }
    }
    let mp4 = dir.join("clip.mp4");
    let status = std::process::Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-framerate", "30", "-i"])
        .arg(pngs.join("%06d.png"))
        .args(["-c:v", "libx264", "-qp", "0", "-pix_fmt", "yuv444p"])
        .arg(&mp4)
        .status()
        .expect("ffmpeg");
    assert!(status.success());
    let gt_path = dir.join("gt.txt");
    std::fs::write(&gt_path, gt).expect("gt");
    (mp4, gt_path, frames)
}

#[test]
fn an_mp4_with_a_mot_file_imports_its_frames_boxes_and_timestamps() {
    if !have_ffmpeg() {
        return;
    }
    let ds = tiny();
    let dir = tempfile::tempdir().expect("tempdir");
    let (mp4, gt, frames) = synthetic_mp4(ds, dir.path());
    let mut opts = ImportOptions::new(Format::from_name("mot").expect("mot"), &gt);
    opts.video = Some(mp4.clone());
    opts.split = Some(Split::Test);
    opts.default_class = "sign".into();
    let got = import(&opts, &dir.path().join("out")).expect("import");
    assert_eq!(got.frames.len(), frames.len());
    assert_eq!(got.classes.len(), 1);
    for (a, b) in got.frames.iter().zip(&frames) {
        let boxes = |f: &FrameRecord| f.objects.iter().map(|o| o.bbox).collect::<Vec<_>>();
        assert_eq!(boxes(a), boxes(b), "frame {}", b.index);
        // 30 fps, exactly
        assert!((got.frame_time(a) - f64::from(b.index) / 30.0).abs() < 1e-6);
        // the same pixels within codec error
        let diff = mean_abs_diff(
            &got.load_rgb(a).expect("rgb"),
            &ds.load_rgb(b).expect("rgb"),
        );
        // (H.264 at qp 0 in 4:4:4, then the dataset's JPEG at quality 95)
        assert!(diff < 4.0, "frame {}: mean abs difference {diff}", b.index);
    }
    assert_eq!(got.videos[0].fps, Some(30.0));

    // every second frame: the kept frames keep their source times
    opts.sampling.every = 2;
    let half = import(&opts, &dir.path().join("half")).expect("import every 2");
    assert_eq!(half.frames.len(), frames.len().div_ceil(2));
    assert!((half.frame_time(&half.frames[1]) - 2.0 / 30.0).abs() < 1e-6);
}

#[test]
fn bad_video_imports_name_the_file_and_write_nothing() {
    if !have_ffmpeg() {
        return;
    }
    let ds = tiny();
    let dir = tempfile::tempdir().expect("tempdir");
    let (mp4, gt, frames) = synthetic_mp4(ds, dir.path());
    let try_import = |gt: &Path, video: &Path, name: &str| -> String {
        let mut opts = ImportOptions::new(Format::from_name("mot").expect("mot"), gt);
        opts.video = Some(video.to_owned());
        let out = dir.path().join(name);
        let err = import(&opts, &out).expect_err(name).to_string();
        assert!(!out.exists(), "{name}: nothing is written");
        assert_eq!(err.lines().count(), 1, "{name}: one line: {err}");
        err
    };
    // an annotation past the video's end
    let past = dir.path().join("past.txt");
    let n = frames.len();
    std::fs::write(&past, format!("1,1,2,2,5,5,1\n{},1,2,2,5,5,1\n", n + 3)).expect("write");
    let err = try_import(&past, &mp4, "past");
    assert!(
        err.contains("past.txt") && err.contains(&format!("frame {}", n + 3)),
        "{err}"
    );
    // a truncated video
    let bytes = std::fs::read(&mp4).expect("read");
    let cut = dir.path().join("cut.mp4");
    std::fs::write(&cut, &bytes[..bytes.len() / 3]).expect("write");
    let err = try_import(&gt, &cut, "cut");
    assert!(err.contains("cut.mp4"), "{err}");
    // an empty video file
    let empty = dir.path().join("empty.mp4");
    std::fs::write(&empty, b"").expect("write");
    let err = try_import(&gt, &empty, "empty");
    assert!(err.contains("empty.mp4"), "{err}");
    // a negative box
    let neg = dir.path().join("neg.txt");
    std::fs::write(&neg, "1,1,2,2,-5,5,1\n").expect("write");
    let err = try_import(&neg, &mp4, "neg");
    assert!(err.contains("neg.txt") && err.contains("line 1"), "{err}");
}

#[test]
fn crowds_difficult_objects_and_mot_ignore_boxes_become_ignore_regions() {
    let ds = tiny();
    let dir = tempfile::tempdir().expect("tempdir");
    let f = ds
        .frames
        .iter()
        .find(|f| !f.objects.is_empty())
        .expect("a frame with a sign");
    let o = f.objects[0];
    let b = o.bbox;

    // COCO: the frame's sign plus a crowd of its class
    let coco = serde_json::json!({
        "images": [{"id": 7, "file_name": f.file, "width": f.width, "height": f.height}],
        "annotations": [
            {"id": 1, "image_id": 7, "category_id": 3, "bbox": [b.x1, b.y1, b.width(), b.height()], "iscrowd": 0},
            {"id": 2, "image_id": 7, "category_id": 3, "bbox": [1.0, 2.0, 40.0, 30.0], "iscrowd": 1}
        ],
        "categories": [{"id": 3, "name": "sign"}]
    });
    let json = dir.path().join("crowd.json");
    std::fs::write(&json, coco.to_string()).expect("write");
    let mut opts = ImportOptions::new(Format::Coco, &json);
    opts.images = Some(ds.root.clone());
    let got = import(&opts, &dir.path().join("coco")).expect("import coco");
    let frame = &got.frames[0];
    assert_eq!(frame.objects.len(), 1);
    assert_eq!(
        frame.ignore,
        [IgnoreRegion {
            class: Some(0),
            bbox: BBox::new(1.0, 2.0, 41.0, 32.0)
        }]
    );
    let manifest = crate::dataset::read_manifest(&got.root).expect("manifest");
    let Source::Imported { counts, .. } = manifest.source else {
        panic!("not an import");
    };
    assert_eq!(counts.ignored_boxes, 1);
    // the dataset's own files and an export keep the region
    let back = import(
        &ImportOptions::new(
            Format::Coco,
            export_coco(&got, None, &dir.path().join("exp")).expect("export"),
        ),
        &dir.path().join("back"),
    )
    .expect("reimport");
    assert_eq!(back.frames[0].ignore, frame.ignore);
    assert_eq!(
        Dataset::load(&got.root).expect("load").frames[0].ignore,
        frame.ignore
    );

    // VOC: a difficult object
    let voc = dir.path().join("voc");
    std::fs::create_dir_all(&voc).expect("mkdir");
    std::fs::write(
        voc.join("a.xml"),
        format!(
            "<annotation><filename>{}</filename><size><width>{}</width><height>{}</height></size>\
             <object><name>sign</name><difficult>1</difficult><bndbox><xmin>11</xmin><ymin>21</ymin><xmax>30</xmax><ymax>40</ymax></bndbox></object>\
             <object><name>sign</name><difficult>0</difficult><bndbox><xmin>{}</xmin><ymin>{}</ymin><xmax>{}</xmax><ymax>{}</ymax></bndbox></object>\
             </annotation>",
            f.file.display(),
            f.width,
            f.height,
            b.x1 + 1.0,
            b.y1 + 1.0,
            b.x2,
            b.y2
        ),
    )
    .expect("write");
    let mut opts = ImportOptions::new(Format::Voc, &voc);
    opts.images = Some(ds.root.clone());
    let got = import(&opts, &dir.path().join("voc-out")).expect("import voc");
    assert_eq!(got.frames[0].objects.len(), 1);
    assert_eq!(
        got.frames[0].ignore,
        [IgnoreRegion {
            class: Some(0),
            bbox: BBox::new(10.0, 20.0, 30.0, 40.0)
        }]
    );

    // MOT (9 columns): a pedestrian with flag 0 excuses pedestrians; a distractor,
    // a class the data do not keep, excuses any class
    if !have_ffmpeg() {
        return;
    }
    let (mp4, _, frames) = synthetic_mp4(ds, dir.path());
    let mut gt = String::new();
    for fr in &frames {
        let n = fr.index + 1;
        gt +=
            &format!("{n},1,10,10,20,30,1,1,1\n{n},2,50,10,20,30,0,1,1\n{n},3,90,10,20,30,1,8,1\n");
    }
    let gt_path = dir.path().join("gt9.txt");
    std::fs::write(&gt_path, gt).expect("gt");
    let mut opts = ImportOptions::new(Format::from_name("mot").expect("mot"), &gt_path);
    opts.video = Some(mp4);
    opts.split = Some(Split::Test);
    let got = import(&opts, &dir.path().join("mot")).expect("import mot");
    assert_eq!(
        got.classes
            .iter()
            .map(|c| c.name.as_str())
            .collect::<Vec<_>>(),
        ["pedestrian"]
    );
    for fr in &got.frames {
        assert_eq!(fr.objects.len(), 1);
        assert_eq!(
            fr.ignore,
            [
                IgnoreRegion {
                    class: Some(0),
                    bbox: BBox::new(50.0, 10.0, 70.0, 40.0)
                },
                IgnoreRegion {
                    class: None,
                    bbox: BBox::new(90.0, 10.0, 110.0, 40.0)
                }
            ]
        );
    }
    // a region of any class is one crowd per class in COCO
    let coco = got.to_coco(None);
    assert_eq!(
        coco.annotations.iter().filter(|a| a.iscrowd == 1).count(),
        2 * got.frames.len()
    );
}

/// Mean absolute pixel difference of two same-sized images (imported video frames are
/// stored as JPEG at quality 95).
fn mean_abs_diff(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let sum: f64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(p, q)| f64::from(p.abs_diff(*q)))
        .sum();
    sum / a.as_raw().len() as f64
}

/// Objects per frame by class name, boxes to 1/100 px.
fn named_objects(ds: &Dataset, frames: &[&FrameRecord]) -> Vec<Vec<(String, [i32; 4])>> {
    frames
        .iter()
        .map(|f| {
            f.objects
                .iter()
                .map(|o| {
                    let b = o.bbox;
                    (
                        ds.classes[usize::from(o.class)].name.clone(),
                        [b.x1, b.y1, b.x2, b.y2].map(|v| (v * 100.0).round() as i32),
                    )
                })
                .collect()
        })
        .collect()
}

#[test]
fn mot_and_coco_video_exports_import_back_with_the_same_frames_and_boxes() {
    let ds = tiny();
    let dir = tempfile::tempdir().expect("tempdir");
    let test: Vec<&FrameRecord> = ds.split(Split::Test).collect();
    let videos: std::collections::BTreeSet<u32> = test.iter().map(|f| f.video).collect();

    // COCO-video: every test video in one file
    let json = export_video(
        ds,
        Some(Split::Test),
        annotations::AnnotationFormat::CocoVideo,
        &dir.path().join("cv"),
    )
    .expect("export coco-video");
    let mut opts = ImportOptions::new(Format::from_name("coco-video").expect("format"), &json);
    opts.split = Some(Split::Test);
    let back = import(&opts, &dir.path().join("cv-back")).expect("import coco-video");
    assert_eq!(back.videos.len(), videos.len());
    let back_frames: Vec<&FrameRecord> = back.frames.iter().collect();
    assert_eq!(named_objects(&back, &back_frames), named_objects(ds, &test));
    for (a, b) in back_frames.iter().zip(&test) {
        let d = mean_abs_diff(&back.load_rgb(a).expect("a"), &ds.load_rgb(b).expect("b"));
        assert!(d < 4.0, "frame {}: mean abs difference {d}", b.index);
    }

    // MOT: one sequence per video, each imported on its own
    let seqs = export_video(
        ds,
        Some(Split::Test),
        annotations::AnnotationFormat::Mot,
        &dir.path().join("mot"),
    )
    .expect("export mot");
    for (k, v) in videos.iter().enumerate() {
        let gt = seqs.join(format!("video{v:04}")).join("gt").join("gt.txt");
        let mut opts = ImportOptions::new(Format::from_name("mot").expect("mot"), &gt);
        opts.split = Some(Split::Test);
        let back = import(&opts, &dir.path().join(format!("mot-back{k}"))).expect("import mot");
        let want: Vec<&FrameRecord> = test.iter().copied().filter(|f| f.video == *v).collect();
        let got: Vec<&FrameRecord> = back.frames.iter().collect();
        assert_eq!(
            named_objects(&back, &got),
            named_objects(ds, &want),
            "video {v}"
        );
        // (imported times are kept to the microsecond)
        assert!((back.frame_time(got[1]) - ds.frame_time(want[1])).abs() <= 1e-6);
        let d = mean_abs_diff(
            &back.load_rgb(got[1]).expect("a"),
            &ds.load_rgb(want[1]).expect("b"),
        );
        assert!(d < 4.0, "video {v}: mean abs difference {d}");
    }

    // a format that cannot be written, and an empty selection, are clear errors
    let err = export_video(
        ds,
        None,
        annotations::AnnotationFormat::Cvat,
        &dir.path().join("cvat"),
    )
    .expect_err("cvat");
    assert!(err.to_string().contains("cannot be written"), "{err}");
    assert!(!dir.path().join("cvat").exists());
}
