//! Bad input emits nothing on the bus (issue 10, item 3): the processes that write to the
//! bus (stim-driver and the virtual stimulator) are started for real — not `--check` — on a
//! host bus with a tap station listening, with a malformed configuration file or flag. Each
//! must exit with a clear one-line error naming what is wrong, put no frame on the bus, and
//! create no station socket.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use fes_can::hostbus::{HostBus, Station};
use fes_tests::stack::stack_binaries;

struct Bus {
    dir: PathBuf,
    tap: HostBus,
}

impl Bus {
    fn new(tag: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("fes-badbus-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let tap = HostBus::open(&dir, Station::Tap, None).expect("tap");
        Self { dir, tap }
    }

    fn iface(&self) -> String {
        format!("hostbus:{}", self.dir.display())
    }

    /// Runs `exe args`, which must fail (exit 1 or clap's 2) with `needle` in a short
    /// stderr, and leave the bus silent and without other stations.
    fn refused(&self, case: &str, exe: &Path, args: &[String], needle: &str) {
        let out = Command::new(exe)
            .args(args)
            .env("RUST_BACKTRACE", "0")
            .output()
            .unwrap_or_else(|e| panic!("{case}: {e}"));
        let stderr = String::from_utf8_lossy(&out.stderr);
        eprintln!("{case}: {}", stderr.trim().lines().last().unwrap_or(""));
        assert!(
            matches!(out.status.code(), Some(1 | 2)),
            "{case}: exit {:?}\n{stderr}",
            out.status.code()
        );
        assert!(!stderr.contains("panicked"), "{case}: {stderr}");
        assert!(
            stderr.contains(needle),
            "{case}: expected {needle:?} in {stderr}"
        );
        assert!(stderr.lines().count() <= 8, "{case}: not short: {stderr}");
        std::thread::sleep(Duration::from_millis(20));
        if let Some(r) = self.tap.recv().expect("tap read") {
            panic!("{case}: a frame reached the bus: {:?}", r.frame);
        }
        for s in [Station::Driver, Station::Stimulator] {
            assert!(
                !self.dir.join(s.file_name()).exists(),
                "{case}: the {s:?} station was opened"
            );
        }
    }
}

impl Drop for Bus {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// stim-driver `run` with a malformed configuration: refused before the bus is touched.
#[test]
fn stim_driver_with_a_bad_configuration_puts_nothing_on_the_bus() {
    let exe = stack_binaries().join("stim-driver");
    let bus = Bus::new("driver");
    let example = Command::new(&exe).arg("example-config").output().unwrap();
    assert!(example.status.success());
    let good = String::from_utf8(example.stdout).unwrap();
    let edit = |from: &str, to: &str| {
        assert!(good.contains(from), "example has no {from:?}");
        good.replacen(from, to, 1).into_bytes()
    };
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("nan force", edit("max_n = 40.0", "max_n = nan"), "max_n"),
        (
            "negative time",
            edit("watchdog_ms = 100", "watchdog_ms = -100"),
            "watchdog_ms",
        ),
        (
            "huge amplitude",
            edit("max_amplitude_ua = 100000", "max_amplitude_ua = 4000000000"),
            "max_amplitude_ua",
        ),
        (
            "wrong schema",
            edit("fes-stim-driver/1", "fes-stim-driver/2"),
            "fes-stim-driver/2",
        ),
        ("unknown key", edit("[force]", "[force]\ntypo = 1"), "typo"),
        (
            "truncated",
            good.as_bytes()[..good.len() / 2].to_vec(),
            "configuration",
        ),
        (
            "non-UTF-8",
            [&[0xFF, 0xFE][..], good.as_bytes()].concat(),
            "UTF-8",
        ),
    ];
    let cfg = bus.dir.with_extension("toml");
    for (case, bytes, needle) in cases {
        std::fs::write(&cfg, &bytes).unwrap();
        let args = vec![
            "run".into(),
            "--config".into(),
            cfg.display().to_string(),
            "--iface".into(),
            bus.iface(),
        ];
        bus.refused(case, &exe, &args, needle);
    }
    // A bad interface name with a good file: refused by name.
    std::fs::write(&cfg, &good).unwrap();
    let args = vec![
        "run".into(),
        "--config".into(),
        cfg.display().to_string(),
        "--iface".into(),
        "hostbus:relative/dir".into(),
    ];
    bus.refused("relative host bus", &exe, &args, "can.iface");
    let _ = std::fs::remove_file(&cfg);
}

/// The virtual stimulator with malformed flags: refused before it joins the bus (it would
/// otherwise announce itself with a boot-up heartbeat).
#[test]
fn the_stimulator_with_bad_flags_puts_nothing_on_the_bus() {
    let exe = stack_binaries().join("sim-muscle");
    let bus = Bus::new("stim");
    let cases: [(&str, &[&str], &str); 8] = [
        (
            "amplitude",
            &["--max-amplitude-ma", "200"],
            "max_amplitude = 200 mA",
        ),
        (
            "amplitude NaN",
            &["--max-amplitude-ma", "NaN"],
            "--max-amplitude-ma NaN",
        ),
        ("width", &["--max-width-us", "5000"], "max_width = 5000 us"),
        ("node id", &["--node-id", "0x80"], "--node-id"),
        (
            "same node ids",
            &["--node-id", "0x01"],
            "both use node id 0x01",
        ),
        ("watchdog", &["--watchdog-ms", "0"], "watchdog = 0 ms"),
        ("negative time", &["--duration-s", "-1"], "--duration-s -1"),
        ("unknown preset", &["--preset", "nope"], "--preset"),
    ];
    for (case, extra, needle) in cases {
        let mut args: Vec<String> = vec!["stimulator".into(), "--iface".into(), bus.iface()];
        if !extra.contains(&"--preset") {
            args.extend(["--preset".into(), "fast".into()]);
        }
        args.extend(extra.iter().map(|s| s.to_string()));
        bus.refused(case, &exe, &args, needle);
    }
}
