//! Decoding a `candump -L` log with cantools (PyPI, installed by `scripts/setup`) against
//! the project's DBC: the independent decoder the interoperability and bench-log tests
//! check the Rust side against.

use std::fs::File;
use std::path::Path;
use std::process::Command;

use fes_can::MessageKind;

use crate::stack::workspace_root;

/// `python3 -m cantools decode --single-line crates/fes-can/dbc/fes.dbc < log`: one decoded line
/// per frame of the log. Panics (a failed test) when cantools is missing or fails, or when
/// any line is not a complete decode of a message of the DBC.
pub fn decode_log(log: &Path) -> Vec<String> {
    let dbc = workspace_root().join("crates/fes-can/dbc/fes.dbc");
    let out = Command::new("python3")
        .args(["-m", "cantools", "decode", "--single-line"])
        .arg(&dbc)
        .stdin(File::open(log).unwrap_or_else(|e| panic!("{}: {e}", log.display())))
        .output()
        .expect("run cantools");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.contains("No module named cantools"),
        "python3 lacks cantools: python3 -m pip install cantools (scripts/setup does)"
    );
    assert!(out.status.success(), "cantools: {stderr}");
    let names: Vec<&str> = MessageKind::ALL.iter().map(|k| k.name()).collect();
    let lines: Vec<String> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(str::to_owned)
        .collect();
    for l in &lines {
        let (_, msg) = l
            .split_once(" :: ")
            .unwrap_or_else(|| panic!("no decode separator: {l}"));
        let name = msg.split('(').next().unwrap_or("");
        assert!(
            names.contains(&name) && msg.ends_with(')'),
            "cantools could not decode: {l}"
        );
    }
    lines
}
