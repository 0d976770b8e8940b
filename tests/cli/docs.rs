//! The README's figures, and those of the guide page it sends readers to for the
//! budget policy's standing, are the published run's: `frugal figures check` passes on
//! the repository as committed, and fails, naming the line, on a figure typed by hand.
use super::{frugal, p};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate sits in the workspace")
        .to_path_buf()
}

#[test]
fn every_figure_the_readme_quotes_is_the_published_runs() {
    let root = root();
    let figures = root.join("docs/results/figures.json");
    let readme = root.join("README.md");
    let standing = root.join("docs/guide/where-the-policy-stands.md");
    frugal(&[
        "figures",
        "check",
        "--figures",
        p(&figures),
        p(&readme),
        p(&standing),
    ])
    .unwrap_or_else(|e| panic!("{e}"));
    // the check reads every quoted figure: the README quotes some
    let text = std::fs::read_to_string(&readme).unwrap();
    assert!(
        text.matches("figures.json#").count() >= 20,
        "the README quotes fewer than 20 figures"
    );
    let text = std::fs::read_to_string(&standing).unwrap();
    assert!(
        text.matches("figures.json#").count() >= 10,
        "the standing guide quotes fewer than 10 figures"
    );
}

#[test]
fn a_figure_typed_by_hand_fails_the_check() {
    let root = root();
    let figures = root.join("docs/results/figures.json");
    let text = std::fs::read_to_string(root.join("README.md")).unwrap();
    let (at, _) = text
        .match_indices("](docs/results/figures.json#detector.map)")
        .next()
        .expect("the README quotes the detector's mAP");
    let open = text[..at].rfind('[').unwrap();
    let mut typed = text.clone();
    typed.replace_range(open + 1..at, "0.999");
    let tmp = tempfile::tempdir().unwrap();
    let doc = tmp.path().join("README.md");
    std::fs::write(&doc, typed).unwrap();
    let e = frugal(&["figures", "check", "--figures", p(&figures), p(&doc)]).unwrap_err();
    let line = text[..at].matches('\n').count() + 1;
    assert!(
        e.contains(&format!("README.md:{line}: `detector.map` shows 0.999")),
        "{e}"
    );
}
