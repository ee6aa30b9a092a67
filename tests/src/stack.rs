//! Helpers for tests that run the four processes of the stack (`fes_bench::bench::Stack`):
//! building their binaries and reading the virtual stimulator's per-tick record.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("fes-tests lives inside the workspace")
        .to_path_buf()
}

/// The four binaries of the stack, as the workspace's test build made them, on the host
/// side (`cargo test --workspace --no-run`: a no-op under the README's test command, which
/// has just built exactly that), and their directory (inside a UML guest,
/// `FES_VCAN_IFACE` set, the host's build is reused).
///
/// Not `cargo build -p rt-core -p stim-driver ...`: features are unified over the packages
/// a build selects, and the test build's (dev-dependencies included: `libc/extra_traits`,
/// `bitflags/std`, ...) differ from those four's, so that build recompiled nix, iceoryx2
/// and everything on them a second time, minutes of a cold CI run (docs/architecture.md,
/// "Tests").
pub fn stack_binaries() -> PathBuf {
    let target = fes_testkit::target_dir(&workspace_root());
    if std::env::var_os("FES_VCAN_IFACE").is_none() {
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
        let ok = Command::new(cargo)
            .current_dir(workspace_root())
            .args(["test", "--workspace", "--no-run", "--quiet"])
            .status()
            .is_ok_and(|s| s.success());
        assert!(
            ok,
            "cargo test --workspace --no-run (the stack's binaries) failed"
        );
    }
    let dir = target.join("debug");
    for b in STACK_BINARIES {
        assert!(
            dir.join(b).is_file(),
            "{} was not built",
            dir.join(b).display()
        );
    }
    dir
}

/// The stack's binaries, in `scripts/install`'s order.
pub const STACK_BINARIES: [&str; 4] = ["rt-core", "stim-driver", "supervisor", "sim-muscle"];

/// One row of the virtual stimulator's record (`sim-muscle stimulator --record`).
#[derive(Debug, Clone, PartialEq)]
pub struct StimRow {
    /// Tick index.
    pub tick: u64,
    /// The tick's time, CLOCK_MONOTONIC ns.
    pub t_ns: u64,
    /// Stimulator state (`stimulating`, `armed`, `stopped`, `fault`, ...).
    pub state: String,
    /// The pulse applied at the tick: (seq, amplitude mA, width us).
    pub pulse: Option<(u64, f64, f64)>,
}

/// Reads the stimulator's record (rows in file order).
pub fn stimulator_rows(path: &Path) -> Vec<StimRow> {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("stimulator record {}: {e}", path.display()));
    text.lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            if f.len() != 8 {
                return None;
            }
            let pulse = (!f[5].is_empty()).then(|| {
                (
                    f[5].parse().unwrap_or(0),
                    f[6].parse().unwrap_or(f64::NAN),
                    f[7].parse().unwrap_or(f64::NAN),
                )
            });
            Some(StimRow {
                tick: f[0].parse().ok()?,
                t_ns: f[1].parse().ok()?,
                state: f[3].to_string(),
                pulse,
            })
        })
        .collect()
}
