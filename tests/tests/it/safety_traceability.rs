//! docs/safety.md names, for every hazard, the tests that prove its mitigations (and, for
//! every fuzz target, its test). This checks that each named test exists, so a renamed or
//! moved test cannot leave the safety case pointing at nothing (issue 19, item 8).
//!
//! A reference is a backticked `path/to/file.rs::test_name` (a test function in that
//! file), `::test_name` (the same file as the previous reference in the same cell) or
//! `path/to/file.rs` (the file).

use std::path::Path;

use crate::systemd_support::workspace_root;

/// One checked reference: the file and, when named, the test.
#[derive(Debug, Clone, PartialEq, Eq)]
struct TestRef {
    file: String,
    test: Option<String>,
}

/// A Rust file's path (a name without its directory counts too, and then fails the check
/// as a file that does not exist: the table gives paths from the workspace root).
fn is_path(s: &str) -> bool {
    s.ends_with(".rs")
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "/_-.".contains(c))
}

fn is_ident(s: &str) -> bool {
    !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// The references in one table cell, in order.
fn references(cell: &str) -> Vec<TestRef> {
    let mut out: Vec<TestRef> = Vec::new();
    let mut file: Option<String> = None;
    for (i, token) in cell.split('`').enumerate() {
        if i % 2 == 0 {
            continue; // outside backticks
        }
        let token = token.trim();
        if let Some(name) = token.strip_prefix("::") {
            if let (Some(f), true) = (&file, is_ident(name)) {
                out.push(TestRef {
                    file: f.clone(),
                    test: Some(name.to_owned()),
                });
            }
        } else if let Some((path, name)) = token.split_once("::") {
            if is_path(path) && is_ident(name) {
                file = Some(path.to_owned());
                out.push(TestRef {
                    file: path.to_owned(),
                    test: Some(name.to_owned()),
                });
            }
        } else if is_path(token) {
            file = Some(token.to_owned());
            out.push(TestRef {
                file: token.to_owned(),
                test: None,
            });
        }
    }
    out
}

/// The proving-test cells of the hazard table (its last column) and the test cells of the
/// fuzz-target table (its second column).
fn test_cells(text: &str) -> Vec<(String, String)> {
    let mut cells = Vec::new();
    for line in text.lines() {
        let cols: Vec<&str> = line.split('|').map(str::trim).collect();
        // `| a | b | ... |` splits into ["", a, b, ..., ""].
        if cols.len() < 4 || !line.starts_with('|') {
            continue;
        }
        let row = cols[1];
        if row.starts_with('H') && row[1..].chars().all(|c| c.is_ascii_digit()) {
            cells.push((row.to_owned(), cols[cols.len() - 2].to_owned()));
        } else if cols.len() == 6 && cols[2].contains(".rs") {
            cells.push((format!("fuzz target {row}"), cols[2].to_owned()));
        }
    }
    cells
}

/// Whether `source` defines a function `name` (a `#[test]`, a proptest, or a helper the
/// table names as a test's body).
fn defines(source: &str, name: &str) -> bool {
    source.match_indices(name).any(|(i, _)| {
        let before = source[..i].trim_end();
        let after = &source[i + name.len()..];
        before.ends_with("fn") && (after.starts_with('(') || after.starts_with('<'))
    })
}

fn missing(root: &Path, refs: &[TestRef]) -> Vec<String> {
    let mut out = Vec::new();
    for r in refs {
        let path = root.join(&r.file);
        let Ok(source) = std::fs::read_to_string(&path) else {
            out.push(format!("{}: no such file", r.file));
            continue;
        };
        if let Some(t) = &r.test
            && !defines(&source, t)
        {
            out.push(format!("{}::{t}: no such test", r.file));
        }
    }
    out
}

#[test]
fn every_test_the_safety_case_names_exists() {
    let root = workspace_root();
    let text = std::fs::read_to_string(root.join("docs/safety.md")).expect("docs/safety.md");
    let cells = test_cells(&text);
    let hazards = cells.iter().filter(|(r, _)| r.starts_with('H')).count();
    assert!(
        hazards >= 5,
        "only {hazards} hazard rows found: the table's layout changed?"
    );
    let mut problems = Vec::new();
    let mut checked = 0;
    for (row, cell) in &cells {
        let refs = references(cell);
        if refs.is_empty() {
            problems.push(format!("{row}: names no test"));
        }
        checked += refs.len();
        problems.extend(
            missing(&root, &refs)
                .into_iter()
                .map(|m| format!("{row}: {m}")),
        );
    }
    eprintln!("{checked} references in {} rows checked", cells.len());
    assert!(
        problems.is_empty(),
        "docs/safety.md names tests that do not exist:\n{}",
        problems.join("\n")
    );
}

/// The checker itself: it finds the references and tells a missing test from a present
/// one (so the test above cannot pass by finding nothing).
#[test]
fn the_checker_reads_references_and_finds_missing_tests() {
    let cell = "`a/b.rs::one`, `::two`; see `c/d.rs` and `supervisor/src` control";
    assert_eq!(
        references(cell),
        vec![
            TestRef {
                file: "a/b.rs".into(),
                test: Some("one".into())
            },
            TestRef {
                file: "a/b.rs".into(),
                test: Some("two".into())
            },
            TestRef {
                file: "c/d.rs".into(),
                test: None
            },
        ]
    );
    let src = "#[test]\nfn one() {}\nfn helper_one() {}\nproptest! { fn two(x in 0..1) {} }";
    assert!(defines(src, "one") && defines(src, "two"));
    assert!(!defines(src, "three") && !defines(src, "helper"));
    let root = workspace_root();
    let refs = [
        TestRef {
            file: "tests/tests/it/safety_traceability.rs".into(),
            test: Some("every_test_the_safety_case_names_exists".into()),
        },
        TestRef {
            file: "tests/tests/it/safety_traceability.rs".into(),
            test: Some("no_such_test_here".into()),
        },
        TestRef {
            file: "no/such/file.rs".into(),
            test: None,
        },
    ];
    assert_eq!(missing(&root, &refs).len(), 2);
}
