//! The figures are drawn: every file of `figures` exists and is a PNG.

#[test]
fn every_figure_is_drawn() {
    let dir = std::env::temp_dir().join(format!("heat-transfer-fig-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    heat_transfer::study_with_figures(1, Some(&dir)).unwrap();
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    for n in &names {
        let bytes = std::fs::read(dir.join(n)).unwrap();
        assert!(bytes.starts_with(b"\x89PNG"), "{n}");
    }
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(names.len(), 12, "{names:?}");
}
