//! The bad-input sweeps' check.

use std::process::Output;

/// Asserts that a run refused its input clearly: an exit code in `codes`, no panic,
/// `needle` (the offending key, field or file) in stderr, and at most `max_lines` lines of
/// it. Returns stderr.
///
/// # Panics
/// When any of that does not hold: this is a test assertion.
pub fn assert_refused(
    case: &str,
    out: &Output,
    codes: &[i32],
    needle: &str,
    max_lines: usize,
) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    eprintln!("{case}: {}", stderr.trim().lines().last().unwrap_or(""));
    assert!(
        out.status.code().is_some_and(|c| codes.contains(&c)),
        "{case}: exit {:?}, expected one of {codes:?}\n{stderr}",
        out.status.code()
    );
    assert!(!stderr.contains("panicked"), "{case}: {stderr}");
    assert!(
        stderr.contains(needle),
        "{case}: expected {needle:?} in {stderr}"
    );
    assert!(
        stderr.lines().count() <= max_lines,
        "{case}: not short: {stderr}"
    );
    stderr
}
