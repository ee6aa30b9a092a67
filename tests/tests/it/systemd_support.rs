//! Shared pieces of the systemd tests: building the stack's binaries, staging an install
//! with `scripts/install --destdir`, and reading unit files.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The workspace root (the parent of this package's directory).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("fes-tests lives inside the workspace")
        .to_path_buf()
}

/// The cargo target directory the tests were built in.
pub fn target_dir() -> PathBuf {
    fes_testkit::target_dir(&workspace_root())
}

/// The stack's binaries (the workspace's test build; a no-op when it is fresh) and their
/// directory.
pub use fes_tests::stack::stack_binaries;

/// A scratch directory inside the target directory (not /tmp: a UML guest hides the host's
/// /tmp behind its own), from the testkit: removed when the test passes, kept when it fails
/// or `FES_TEST_KEEP` is set.
pub fn scratch(tag: &str) -> Scratch {
    Scratch::new_in(&target_dir().join("test-scratch"), tag)
}

pub use fes_testkit::Scratch;

/// Runs `scripts/install` with `args`; returns (success, stdout + stderr).
pub fn run_install(args: &[&str]) -> (bool, String) {
    let out = Command::new(workspace_root().join("scripts/install"))
        .args(args)
        .output()
        .expect("run scripts/install");
    let mut text = String::from_utf8_lossy(&out.stdout).into_owned();
    text.push_str(&String::from_utf8_lossy(&out.stderr));
    (out.status.success(), text)
}

/// Stages an install (`--rig` or `--bench`) under `dest` from the binaries in `bins`.
pub fn stage(mode: &str, dest: &Path, bins: &Path, extra: &[&str]) -> String {
    let dest = dest.to_str().expect("UTF-8 path");
    let bins = bins.to_str().expect("UTF-8 path");
    let mut args = vec![mode, "--destdir", dest, "--from", bins];
    args.extend_from_slice(extra);
    let (ok, text) = run_install(&args);
    assert!(ok, "scripts/install {args:?} failed:\n{text}");
    text
}

/// A parsed systemd unit file: every assignment, in order, per section.
#[derive(Debug, Clone)]
pub struct UnitFile {
    /// File name, e.g. `fes-rt-core.service`.
    pub name: String,
    sections: BTreeMap<String, Vec<(String, String)>>,
}

impl UnitFile {
    /// Parses unit-file syntax (systemd.syntax(7)): `[Section]` headers, `Key=Value`
    /// assignments, `#`/`;` comments, lines continued with a trailing backslash.
    pub fn parse(name: &str, text: &str) -> Result<Self, String> {
        let mut sections: BTreeMap<String, Vec<(String, String)>> = BTreeMap::new();
        let mut current: Option<String> = None;
        let mut pending = String::new();
        for (n, raw) in text.lines().enumerate() {
            let line = raw.trim();
            if pending.is_empty() && (line.is_empty() || line.starts_with(['#', ';'])) {
                continue;
            }
            if let Some(cont) = line.strip_suffix('\\') {
                pending.push_str(cont);
                pending.push(' ');
                continue;
            }
            let mut full = std::mem::take(&mut pending);
            full.push_str(line);
            if let Some(section) = full.strip_prefix('[').and_then(|s| s.strip_suffix(']')) {
                current = Some(section.to_owned());
                sections.entry(section.to_owned()).or_default();
                continue;
            }
            let Some((key, value)) = full.split_once('=') else {
                return Err(format!("{name}:{}: not an assignment: {raw:?}", n + 1));
            };
            let Some(section) = &current else {
                return Err(format!("{name}:{}: assignment outside a section", n + 1));
            };
            sections
                .entry(section.clone())
                .or_default()
                .push((key.trim().to_owned(), value.trim().to_owned()));
        }
        Ok(Self {
            name: name.to_owned(),
            sections,
        })
    }

    /// Reads and parses `path`.
    pub fn load(path: &Path) -> Self {
        let text = std::fs::read_to_string(path)
            .unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        Self::parse(&name, &text).unwrap_or_else(|e| panic!("{e}"))
    }

    /// The effective values of a list setting: every assignment after the last empty one
    /// (an empty assignment resets a list in systemd).
    pub fn values(&self, section: &str, key: &str) -> Vec<String> {
        let mut out = Vec::new();
        for (k, v) in self.sections.get(section).into_iter().flatten() {
            if k == key {
                if v.is_empty() {
                    out.clear();
                } else {
                    out.push(v.clone());
                }
            }
        }
        out
    }

    /// The whitespace-separated words of a list setting (dependencies, paths).
    pub fn words(&self, section: &str, key: &str) -> Vec<String> {
        self.values(section, key)
            .iter()
            .flat_map(|v| v.split_whitespace().map(str::to_owned))
            .collect()
    }

    /// The last assignment of a single-valued setting, if any (an empty one counts).
    pub fn get(&self, section: &str, key: &str) -> Option<String> {
        self.sections
            .get(section)?
            .iter()
            .rev()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.clone())
    }

    /// True when `key` in `section` is assigned exactly `value` (its last assignment).
    pub fn is(&self, section: &str, key: &str, value: &str) -> bool {
        self.get(section, key).as_deref() == Some(value)
    }

    /// True when the list setting contains `word`.
    pub fn has_word(&self, section: &str, key: &str, word: &str) -> bool {
        self.words(section, key).iter().any(|w| w == word)
    }
}

/// The CPUs of a `CPUAffinity=` value (`0 1`, `0-2`, `1,3`).
pub fn cpu_set(value: &str) -> Vec<usize> {
    let mut cpus = Vec::new();
    for item in value.split([' ', ',']).filter(|s| !s.is_empty()) {
        match item.split_once('-') {
            Some((a, b)) => {
                let (a, b): (usize, usize) = (
                    a.parse().expect("CPU number"),
                    b.parse().expect("CPU number"),
                );
                cpus.extend(a..=b);
            }
            None => cpus.push(item.parse().expect("CPU number")),
        }
    }
    cpus.sort_unstable();
    cpus.dedup();
    cpus
}

#[test]
fn unit_parser_follows_systemd_syntax() {
    let u = UnitFile::parse(
        "x.service",
        "# comment\n[Unit]\nAfter=a.service\nAfter=b.service \\\n  c.service\n; other\n\
         [Service]\nReadWritePaths=/x\nReadWritePaths=\nReadWritePaths=/y /z\nType=notify\n",
    )
    .unwrap();
    assert_eq!(
        u.words("Unit", "After"),
        ["a.service", "b.service", "c.service"]
    );
    assert_eq!(u.words("Service", "ReadWritePaths"), ["/y", "/z"]);
    assert!(u.is("Service", "Type", "notify"));
    assert_eq!(u.get("Service", "Missing"), None);
    assert!(UnitFile::parse("y", "Key=1\n").is_err());
    assert!(UnitFile::parse("y", "[A]\nnot an assignment\n").is_err());
    assert_eq!(cpu_set("0-2,5 7"), [0, 1, 2, 5, 7]);
}
