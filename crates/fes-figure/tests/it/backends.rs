//! [`fes_figure::by_extension!`]: PNG or SVG by the file's extension, nothing for another.

use std::path::Path;

use fes_figure::Format;
use plotters::prelude::*;

#[test]
fn the_format_is_the_extensions_in_any_case() {
    for (name, want) in [
        ("a.png", Some(Format::Png)),
        ("dir.svg/a.PNG", Some(Format::Png)),
        ("a.svg", Some(Format::Svg)),
        ("a.Svg", Some(Format::Svg)),
        ("a.jpg", None),
        ("a.png.txt", None),
        ("png", None),
        ("a", None),
    ] {
        assert_eq!(Format::of(Path::new(name)), want, "{name}");
    }
}

/// Draws a small figure at `path`: `Some(Ok)` when drawn, `None` when the name is neither.
fn draw(path: &Path) -> Option<Result<(), String>> {
    fes_figure::by_extension!(path, (200, 100), |root| {
        root.fill(&WHITE)
            .and_then(|()| root.present())
            .map_err(|e| e.to_string())
    })
}

#[test]
fn png_and_svg_files_by_their_extension() {
    let dir = fes_testkit::Scratch::new("fes-figure-backends");
    for (name, magic) in [
        ("f.png", &b"\x89PNG"[..]),
        ("f.PNG", &b"\x89PNG"[..]),
        ("f.svg", &b"<svg"[..]),
    ] {
        let path = dir.join(name);
        draw(&path).unwrap().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert!(bytes.starts_with(magic), "{name}");
    }
}

#[test]
fn another_name_runs_nothing() {
    let dir = fes_testkit::Scratch::new("fes-figure-other");
    let path = dir.join("f.jpg");
    assert!(draw(&path).is_none());
    assert!(!path.exists());
}

#[test]
fn a_drawing_error_is_the_bodys() {
    let dir = fes_testkit::Scratch::new("fes-figure-error");
    let path = dir.join("missing").join("f.png");
    assert!(draw(&path).unwrap().is_err());
}
