//! docs/safety.md names, for every hazard, the tests that prove its mitigations (and, for
//! every fuzz target, its test). This checks that each named test exists and is a test
//! that runs, so a renamed, moved, ignored or helper-only name cannot leave the safety case
//! pointing at nothing.
//!
//! A reference is a backticked `path/to/file.rs::test_name` or
//! `path/to/file.rs::module::test_name` (a test function in that file, inside that inline
//! module when one is named), `::test_name` or `::module::test_name` (the same file as the
//! previous reference in the same cell) or `path/to/file.rs` (the file). A backticked token
//! that names a `.rs` file with `::` but does not parse is an error, not skipped.
//!
//! "A test" is a function with `#[test]` (or another `...::test]` attribute) or one inside
//! a `proptest!` block, without `#[ignore]`. A test whose body skips unless it runs as
//! root (it, or a helper it names, prints SKIPPED) counts only where the tests run as root,
//! as CI runs them (`.ci/run`); run as another user the check fails instead of counting a
//! test that did not run.

use std::path::Path;

use crate::systemd_support::workspace_root;

/// One checked reference: the file, the inline modules around the test, and the test.
#[derive(Debug, Clone, PartialEq, Eq)]
struct TestRef {
    file: String,
    modules: Vec<String>,
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

/// `a::b::name` as modules `[a, b]` and `name`; `None` unless every segment is a name.
fn item_path(s: &str) -> Option<(Vec<String>, String)> {
    let segments: Vec<&str> = s.split("::").collect();
    if !segments.iter().all(|p| is_ident(p)) {
        return None;
    }
    let (name, modules) = segments.split_last()?;
    Some((
        modules.iter().map(|m| (*m).to_owned()).collect(),
        (*name).to_owned(),
    ))
}

/// The references in one table cell, in order, and the tokens that look like references
/// but do not parse.
fn references(cell: &str) -> (Vec<TestRef>, Vec<String>) {
    let mut out: Vec<TestRef> = Vec::new();
    let mut malformed = Vec::new();
    let mut file: Option<String> = None;
    for (i, token) in cell.split('`').enumerate() {
        if i % 2 == 0 {
            continue; // outside backticks
        }
        let token = token.trim();
        if let Some(rest) = token.strip_prefix("::") {
            match (&file, item_path(rest)) {
                (Some(f), Some((modules, name))) => out.push(TestRef {
                    file: f.clone(),
                    modules,
                    test: Some(name),
                }),
                (None, Some(_)) => malformed.push(format!("`{token}`: no file before it")),
                // `::` alone or Rust syntax quoted in the text.
                (_, None) => {}
            }
        } else if let Some((path, rest)) = token.split_once("::") {
            if !path.ends_with(".rs") {
                continue; // a Rust path in the text, not a reference
            }
            match item_path(rest) {
                Some((modules, name)) if is_path(path) => {
                    file = Some(path.to_owned());
                    out.push(TestRef {
                        file: path.to_owned(),
                        modules,
                        test: Some(name),
                    });
                }
                _ => malformed.push(format!("`{token}`: not file.rs::module::test")),
            }
        } else if is_path(token) {
            file = Some(token.to_owned());
            out.push(TestRef {
                file: token.to_owned(),
                modules: Vec::new(),
                test: None,
            });
        }
    }
    (out, malformed)
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

/// Rust source with comments, strings and character literals blanked out (same length,
/// same line breaks), so that braces and names are only the code's.
fn code_only(source: &str) -> Vec<u8> {
    let s = source.as_bytes();
    let mut out = s.to_vec();
    let blank = |out: &mut Vec<u8>, from: usize, to: usize| {
        for b in &mut out[from..to.min(s.len())] {
            if *b != b'\n' {
                *b = b' ';
            }
        }
    };
    let mut i = 0;
    while i < s.len() {
        match s[i] {
            b'/' if s.get(i + 1) == Some(&b'/') => {
                let end = s[i..]
                    .iter()
                    .position(|&b| b == b'\n')
                    .map_or(s.len(), |p| i + p);
                blank(&mut out, i, end);
                i = end;
            }
            b'/' if s.get(i + 1) == Some(&b'*') => {
                let end = source[i + 2..]
                    .find("*/")
                    .map_or(s.len(), |p| i + 2 + p + 2);
                blank(&mut out, i, end);
                i = end;
            }
            b'r' if matches!(s.get(i + 1), Some(b'"' | b'#'))
                && (i == 0 || !(s[i - 1].is_ascii_alphanumeric() || s[i - 1] == b'_')) =>
            {
                let hashes = s[i + 1..].iter().take_while(|&&b| b == b'#').count();
                if s.get(i + 1 + hashes) != Some(&b'"') {
                    i += 1;
                    continue;
                }
                let close = format!("\"{}", "#".repeat(hashes));
                let body = i + 2 + hashes;
                let end = source[body..]
                    .find(&close)
                    .map_or(s.len(), |p| body + p + close.len());
                blank(&mut out, i, end);
                i = end;
            }
            b'"' => {
                let mut j = i + 1;
                while j < s.len() && s[j] != b'"' {
                    j += if s[j] == b'\\' { 2 } else { 1 };
                }
                blank(&mut out, i, j + 1);
                i = j + 1;
            }
            b'\'' => {
                // A character literal ('x', '\n', '\u{..}') or a lifetime ('a).
                if s.get(i + 1) == Some(&b'\\') {
                    let end = s[i + 2..]
                        .iter()
                        .position(|&b| b == b'\'')
                        .map_or(s.len(), |p| i + 2 + p + 1);
                    blank(&mut out, i, end);
                    i = end;
                } else if s.get(i + 2) == Some(&b'\'') {
                    blank(&mut out, i, i + 3);
                    i += 3;
                } else {
                    i += 1;
                }
            }
            _ => i += 1,
        }
    }
    out
}

/// The end (exclusive) of the brace-delimited block opening at `open` in `code`.
fn block_end(code: &[u8], open: usize) -> usize {
    let mut depth = 0usize;
    for (k, &b) in code.iter().enumerate().skip(open) {
        match b {
            b'{' => depth += 1,
            b'}' => {
                depth = depth.saturating_sub(1);
                if depth == 0 {
                    return k + 1;
                }
            }
            _ => {}
        }
    }
    code.len()
}

fn is_word_byte(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b == b'_'
}

/// Positions in `code[range]` of `keyword name` (whitespace between, `name` a whole word),
/// each with the position just after `name`.
fn find_item(code: &[u8], range: (usize, usize), keyword: &str, name: &str) -> Vec<(usize, usize)> {
    let text = &code[range.0..range.1];
    let kw = keyword.as_bytes();
    let mut hits = Vec::new();
    let mut i = 0;
    while i + kw.len() < text.len() {
        if text[i..].starts_with(kw)
            && (i == 0 || !is_word_byte(text[i - 1]))
            && text[i + kw.len()].is_ascii_whitespace()
        {
            let mut j = i + kw.len();
            while j < text.len() && text[j].is_ascii_whitespace() {
                j += 1;
            }
            let n = name.as_bytes();
            let end = j + n.len();
            if text[j..].starts_with(n) && (end >= text.len() || !is_word_byte(text[end])) {
                hits.push((range.0 + i, range.0 + end));
            }
        }
        i += 1;
    }
    hits
}

/// The attribute lines right above the item starting at `at` (doc comments and blank
/// lines between them skipped; comments are already blank in `code`).
fn attributes_before(source: &str, code: &[u8], at: usize) -> Vec<String> {
    let line_start = code[..at]
        .iter()
        .rposition(|&b| b == b'\n')
        .map_or(0, |p| p + 1);
    let mut attrs = Vec::new();
    for line in source[..line_start].lines().rev() {
        let t = line.trim();
        if t.is_empty() || t.starts_with("//") {
            continue; // doc comments and blank lines between attributes
        }
        // An attribute, or the closing line of one written over several lines.
        if t.starts_with("#[") || t.ends_with(']') {
            attrs.push(t.to_owned());
        } else {
            break;
        }
    }
    attrs
}

/// Whether the item at `at` sits inside a `proptest!` block.
fn in_proptest(code: &[u8], at: usize) -> bool {
    let text = &code[..at];
    let mut from = 0;
    let mut inside = false;
    while let Some(p) = text[from..]
        .windows(b"proptest!".len())
        .position(|w| w == b"proptest!")
    {
        let start = from + p;
        if let Some(open) = code[start..].iter().position(|&b| b == b'{') {
            let open = start + open;
            if open < at && block_end(code, open) > at {
                inside = true;
            }
        }
        from = start + 1;
    }
    inside
}

/// Whether this process runs as root (the safety case's root-only tests then run).
fn running_as_root() -> bool {
    nix::unistd::geteuid().is_root()
}

/// The body of the function whose name ends at `after`.
fn body_of<'a>(source: &'a str, code: &[u8], after: usize) -> &'a str {
    let end = code[after..]
        .iter()
        .position(|&b| b == b'{')
        .map_or(code.len(), |p| block_end(code, after + p));
    &source[after..end]
}

/// Whether a test `body` skips when not root: it prints SKIPPED itself, or names (calls or
/// passes on) a function of the same file that does (the fault-injection tests' attempts).
fn skips_unless_root(source: &str, code: &[u8], body: &str) -> bool {
    if body.contains("SKIPPED") {
        return true;
    }
    let text = std::str::from_utf8(code).unwrap_or("");
    let mut from = 0;
    while let Some(p) = text[from..].find("fn ") {
        let at = from + p;
        from = at + 3;
        let name: String = text[from..]
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        if name.is_empty() || (at > 0 && is_word_byte(code[at - 1])) {
            continue;
        }
        let helper = body_of(source, code, from + name.len());
        let named = body.match_indices(name.as_str()).any(|(i, _)| {
            let b = body.as_bytes();
            (i == 0 || !is_word_byte(b[i - 1]))
                && b.get(i + name.len()).is_none_or(|&c| !is_word_byte(c))
        });
        if named && helper.contains("SKIPPED") {
            return true;
        }
    }
    false
}

/// What is wrong with `name` (inside `modules`) as a test of `source`, if anything.
fn check_test(source: &str, modules: &[String], name: &str, as_root: bool) -> Option<String> {
    let code = code_only(source);
    let mut range = (0, code.len());
    for m in modules {
        let Some(&(_, after)) = find_item(&code, range, "mod", m).first() else {
            return Some(format!("no module `{m}`"));
        };
        let rest = &code[after..range.1];
        match rest
            .iter()
            .position(|b| !b.is_ascii_whitespace())
            .map(|p| rest[p])
        {
            Some(b'{') => {
                let open = after + rest.iter().position(|&b| b == b'{').unwrap_or(0);
                range = (open, block_end(&code, open));
            }
            _ => {
                return Some(format!(
                    "module `{m}` is in its own file: name that file instead"
                ));
            }
        }
    }
    let fns = find_item(&code, range, "fn", name);
    if fns.is_empty() {
        return Some("no such function".into());
    }
    let mut why = String::from("not a test (no #[test], not in proptest!)");
    for (at, after) in fns {
        let attrs = attributes_before(source, &code, at);
        if attrs.iter().any(|a| a.contains("ignore")) {
            why = "an #[ignore]d test: it does not run".into();
            continue;
        }
        let is_test = attrs
            .iter()
            .any(|a| a == "#[test]" || a.ends_with("::test]") || a.contains("::test("))
            || in_proptest(&code, at);
        if !is_test {
            continue;
        }
        let body = body_of(source, &code, after);
        if !as_root && skips_unless_root(source, &code, body) {
            why = "skips unless root: it counts only where the tests run as root (CI)".into();
            continue;
        }
        return None;
    }
    Some(why)
}

fn missing(root: &Path, refs: &[TestRef], as_root: bool) -> Vec<String> {
    let mut out = Vec::new();
    for r in refs {
        let path = root.join(&r.file);
        let Ok(source) = std::fs::read_to_string(&path) else {
            out.push(format!("{}: no such file", r.file));
            continue;
        };
        if let Some(t) = &r.test
            && let Some(why) = check_test(&source, &r.modules, t, as_root)
        {
            let mut name = r.modules.join("::");
            if !name.is_empty() {
                name.push_str("::");
            }
            out.push(format!("{}::{name}{t}: {why}", r.file));
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
    let as_root = running_as_root();
    let mut problems = Vec::new();
    let mut checked = 0;
    for (row, cell) in &cells {
        let (refs, malformed) = references(cell);
        if refs.is_empty() {
            problems.push(format!("{row}: names no test"));
        }
        problems.extend(malformed.into_iter().map(|m| format!("{row}: {m}")));
        checked += refs.len();
        problems.extend(
            missing(&root, &refs, as_root)
                .into_iter()
                .map(|m| format!("{row}: {m}")),
        );
    }
    eprintln!("{checked} references in {} rows checked", cells.len());
    assert!(
        problems.is_empty(),
        "docs/safety.md names tests that do not exist or do not run:\n{}",
        problems.join("\n")
    );
}

/// The checker itself: it finds the references and tells a test from a missing, ignored,
/// helper, misplaced or root-only one (so the test above cannot pass by finding nothing).
#[test]
fn the_checker_reads_references_and_finds_missing_tests() {
    let cell = "`a/b.rs::one`, `::two`, `::tests::three`; see `c/d.rs` and \
                `supervisor/src` control; `e.rs::tests::` `f.rs::a-b`";
    let (refs, malformed) = references(cell);
    let r = |file: &str, modules: &[&str], test: Option<&str>| TestRef {
        file: file.into(),
        modules: modules.iter().map(|m| (*m).to_owned()).collect(),
        test: test.map(Into::into),
    };
    assert_eq!(
        refs,
        vec![
            r("a/b.rs", &[], Some("one")),
            r("a/b.rs", &[], Some("two")),
            r("a/b.rs", &["tests"], Some("three")),
            r("c/d.rs", &[], None),
        ]
    );
    assert_eq!(malformed.len(), 2, "{malformed:?}");
    let src = r#"
#[test]
fn one() { let s = "fn ignored_in_a_string() {"; }
fn helper_one() {}
proptest! { #[test] fn two(x in 0..1) {} }
proptest! {
    /// Docs.
    fn three(x in 0..1) {}
}
#[test]
#[ignore = "slow"]
fn four() {}
mod tests {
    #[test]
    fn five() { if !root { eprintln!("SKIPPED: not root"); return; } }
    #[cfg(test)]
    #[test]
    fn six() { let c = '{'; }
}
#[test]
fn seven() {}
fn attempt() { eprintln!("SKIPPED: cannot mount"); }
#[test]
fn eight() { repeat("case", attempt); }
"#;
    let ok = |m: &[&str], n: &str| {
        let m: Vec<String> = m.iter().map(|s| (*s).to_owned()).collect();
        check_test(src, &m, n, false)
    };
    assert_eq!(ok(&[], "one"), None);
    assert_eq!(ok(&[], "two"), None);
    assert_eq!(ok(&[], "three"), None);
    assert_eq!(ok(&["tests"], "six"), None);
    assert_eq!(ok(&[], "six"), None, "a bare name is found in any module");
    assert_eq!(ok(&[], "seven"), None, "after the module's braces");
    assert!(ok(&[], "helper_one").unwrap().contains("not a test"));
    assert!(ok(&[], "ignored_in_a_string").unwrap().contains("no such"));
    assert!(ok(&[], "four").unwrap().contains("ignore"));
    assert!(ok(&["tests"], "five").unwrap().contains("root"));
    assert_eq!(check_test(src, &["tests".into()], "five", true), None);
    assert!(
        ok(&[], "eight").unwrap().contains("root"),
        "through its helper"
    );
    assert!(ok(&["tests"], "one").unwrap().contains("no such"));
    assert!(ok(&["nope"], "one").unwrap().contains("no module"));
    let root = workspace_root();
    let refs = [
        r(
            "tests/tests/it/safety_traceability.rs",
            &[],
            Some("every_test_the_safety_case_names_exists"),
        ),
        r(
            "tests/tests/it/safety_traceability.rs",
            &[],
            Some("no_such_test_here"),
        ),
        r("no/such/file.rs", &[], None),
    ];
    assert_eq!(missing(&root, &refs, false).len(), 2);
}
