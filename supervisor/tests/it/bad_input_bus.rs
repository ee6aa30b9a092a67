//! Bad input emits nothing on the bus: the virtual stimulator is started
//! for real on a host bus with a tap listening, with a malformed flag each time. It must exit
//! with a clear error naming what is wrong, put no frame on the bus (it would otherwise
//! announce itself with a boot-up heartbeat) and open no station. stim-driver's malformed
//! configurations get the same check in its own sweep
//! (`stim-driver/tests/forward_path.rs::malformed_configurations_are_refused_clearly_without_a_panic`).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::process::Command;

use fes_testkit::assert_refused;
use fes_testkit::bus::SilentBus;
use fes_tests::stack::stack_binaries;

#[test]
fn the_stimulator_with_bad_flags_puts_nothing_on_the_bus() {
    let exe = stack_binaries().join("sim-muscle");
    let bus = SilentBus::new("stim");
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
        let out = Command::new(&exe)
            .args(&args)
            .env("RUST_BACKTRACE", "0")
            .output()
            .unwrap_or_else(|e| panic!("{case}: {e}"));
        // 1: refused by the stimulator's validation; 2: refused by the argument parser.
        assert_refused(case, &out, &[1, 2], needle, 8);
        bus.assert_silent(case);
    }
}
