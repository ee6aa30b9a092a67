//! Self-tests of the vcan harness: a test body really gets a working CAN interface; a
//! failure inside the environment fails the test; misconfiguration fails loudly (never
//! skips); `vcan-run` propagates exit status and output.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::process::Command;
use std::time::Duration;

use fes_testkit::vcan::{Backend, with_vcan};
use socketcan::{CanFrame, CanSocket, EmbeddedFrame, Frame as _, Socket, StandardId};

#[test]
fn body_gets_a_can_interface_that_carries_frames() {
    with_vcan(|can| {
        let ty = std::fs::read_to_string(format!("/sys/class/net/{}/type", can.iface))
            .expect("interface in sysfs");
        assert_eq!(
            ty.trim(),
            "280",
            "{} is a CAN interface (ARPHRD_CAN)",
            can.iface
        );
        if can.backend == Backend::Uml {
            assert_eq!(can.iface, "vcan0");
            // The guest has a private /dev/shm and iceoryx2 root.
            assert!(std::path::Path::new("/dev/shm").is_dir());
            assert!(std::env::var("FES_IOX2_ROOT").is_ok());
        }
        // A frame written on one socket is read, unchanged, on another.
        let rx = CanSocket::open(&can.iface).expect("open rx");
        rx.set_read_timeout(Duration::from_secs(2)).unwrap();
        let tx = CanSocket::open(&can.iface).expect("open tx");
        let id = StandardId::new(0x123).unwrap();
        tx.write_frame(&CanFrame::new(id, &[0xDE, 0xAD, 0xBE, 0xEF]).unwrap())
            .unwrap();
        let got = rx.read_frame().expect("frame received");
        assert_eq!(
            (got.raw_id(), got.data()),
            (0x123, &[0xDE, 0xAD, 0xBE, 0xEF][..])
        );
    });
}

/// Run by `a_failing_body_fails_the_test` in a child process; fails on purpose.
#[test]
#[ignore = "fails on purpose; run by a_failing_body_fails_the_test"]
fn deliberately_failing_body() {
    with_vcan(|_| panic!("deliberate failure inside the CAN environment"));
}

/// Run by `misconfiguration_fails_loudly` in a child process.
#[test]
#[ignore = "run by misconfiguration_fails_loudly with a broken environment"]
fn needs_can() {
    with_vcan(|_| {});
}

fn run_self(test: &str, env: &[(&str, &str)]) -> (i32, String) {
    let exe = std::env::current_exe().unwrap();
    let mut c = Command::new(exe);
    // This binary's test names carry their module path.
    let test = format!("harness::{test}");
    c.args([
        test.as_str(),
        "--exact",
        "--include-ignored",
        "--nocapture",
        "--test-threads=1",
    ]);
    for (k, v) in env {
        c.env(k, v);
    }
    let out = c.output().expect("run the test binary");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.code().unwrap_or(-1), text)
}

#[test]
fn a_failing_body_fails_the_test() {
    let (code, text) = run_self("deliberately_failing_body", &[]);
    assert_ne!(code, 0, "the failing body must fail the test:\n{text}");
    assert!(
        text.contains("deliberate failure inside the CAN environment"),
        "{text}"
    );
}

#[test]
fn misconfiguration_fails_loudly() {
    let (code, text) = run_self(
        "needs_can",
        &[("FES_VCAN_BACKEND", "native"), ("CAN_IFACE", "nosuchcan7")],
    );
    assert_ne!(code, 0, "{text}");
    assert!(
        text.contains("CAN_IFACE=nosuchcan7: interface nosuchcan7 does not exist"),
        "{text}"
    );

    let (code, text) = run_self(
        "needs_can",
        &[
            ("FES_VCAN_BACKEND", "uml"),
            ("FES_UML_KERNEL", "/nonexistent/linux.uml"),
        ],
    );
    assert_ne!(code, 0, "{text}");
    assert!(
        text.contains("no CAN interface for the CAN tests"),
        "{text}"
    );
    assert!(
        text.contains("UML kernel /nonexistent/linux.uml does not exist"),
        "{text}"
    );

    let (code, text) = run_self("needs_can", &[("FES_VCAN_BACKEND", "sometimes")]);
    assert_ne!(code, 0, "{text}");
    assert!(text.contains("auto, native or uml"), "{text}");
}

#[test]
fn vcan_run_propagates_status_and_output() {
    let out = Command::new(env!("CARGO_BIN_EXE_vcan-run"))
        .args([
            "-c",
            "echo \"iface=$CAN_IFACE\"; test -e /sys/class/net/$CAN_IFACE && echo present; exit 3",
        ])
        .output()
        .expect("run vcan-run");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(3),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("iface=") && stdout.contains("present"),
        "{stdout}"
    );

    let out = Command::new(env!("CARGO_BIN_EXE_vcan-run"))
        .output()
        .expect("run vcan-run");
    assert_eq!(out.status.code(), Some(2), "no command is a usage error");
}
