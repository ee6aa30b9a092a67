//! The figures are drawn: every file of `figures` exists and is a PNG (Fig. E.1 also an
//! SVG).

#[test]
fn every_figure_is_drawn() {
    let dir = fes_testkit::Scratch::new("heat-transfer-fig");
    heat_transfer::study_with_figures(1, Some(dir.path())).unwrap();
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    for n in &names {
        let bytes = std::fs::read(dir.join(n)).unwrap();
        if n.ends_with(".svg") {
            assert!(bytes.starts_with(b"<svg"), "{n}");
        } else {
            assert!(bytes.starts_with(b"\x89PNG"), "{n}");
        }
    }
    assert_eq!(names.len(), 14, "{names:?}");
    assert!(names.contains(&"fig-e1.svg".to_string()), "{names:?}");
}

#[test]
fn fig_e1_labels_every_part_of_the_rig() {
    let dir = fes_testkit::Scratch::new("heat-transfer-e1");
    heat_transfer::rig::fig_e1(&dir).unwrap();
    let png = std::fs::read(dir.join("fig-e1.png")).unwrap();
    assert!(png.starts_with(b"\x89PNG"));
    // Width and height from the IHDR chunk.
    let be = |b: &[u8]| u32::from_be_bytes([b[0], b[1], b[2], b[3]]);
    assert_eq!(
        (be(&png[16..20]), be(&png[20..24])),
        heat_transfer::rig::SIZE
    );
    let svg = std::fs::read_to_string(dir.join("fig-e1.svg")).unwrap();
    // Every text element's content.
    let texts: Vec<&str> = svg
        .split("<text")
        .skip(1)
        .filter_map(|t| t.split_once('>')?.1.split_once("</text>"))
        .map(|(content, _)| content.trim())
        .collect();
    for label in [
        "fan",
        "throttle valve",
        "α",
        "tube",
        "heating resistor, voltage u (0 … 10 V)",
        "u",
        "thermocouple: outlet temperature y",
        "y",
        "air in",
        "air out",
    ] {
        assert!(
            texts.contains(&label),
            "Fig. E.1 lacks `{label}`: {texts:?}"
        );
    }
}
