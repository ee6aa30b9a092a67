//! The host bus (crates/fes-hostbus): the CAN frames as `struct can_frame` bytes over Unix
//! datagrams between three stations. Its tests live here, in the system tests' binary, so
//! that the crate adds no test binary of its own (docs/architecture.md, "Tests").

use std::io;
use std::path::{Path, PathBuf};
use std::time::Duration;

use fes_hostbus::*;
use fes_testkit::Scratch;

/// A bus directory not made yet (the first station makes it, private), in a scratch
/// directory that goes with the test.
fn dir(name: &str) -> (Scratch, PathBuf) {
    let scratch = Scratch::new(&format!("hostbus-{name}"));
    let d = scratch.join("bus");
    (scratch, d)
}

#[test]
fn frames_round_trip_as_struct_can_frame() {
    let f = RawFrame::data(0x110, &[1, 2, 3]).unwrap();
    let b = f.to_bytes();
    assert_eq!(b.len(), FRAME_LEN);
    assert_eq!(RawFrame::from_bytes(&b), Some(f));
    assert_eq!(f.payload(), &[1, 2, 3]);
    assert_eq!(f.standard_id(), Some(0x110));
    let e = RawFrame::error(0x40, &[0, 0x10]);
    assert!(e.is_error());
    assert_eq!(e.standard_id(), None);
    assert_eq!(RawFrame::from_bytes(&b[..15]), None);
    let mut long = b;
    long[4] = 9;
    assert_eq!(RawFrame::from_bytes(&long), None);
    assert!(RawFrame::data(0x800, &[]).is_none());
    assert!(RawFrame::data(0x10, &[0; 9]).is_none());
    assert_eq!(bus_dir("hostbus:/run/x"), Some(Path::new("/run/x")));
    assert_eq!(bus_dir("vcan0"), None);
    assert!(validate_dir(Path::new("relative")).is_err());
    assert!(validate_dir(&Path::new("/").join("x".repeat(MAX_DIR_LEN))).is_err());
}

#[test]
fn a_frame_reaches_every_other_station_with_a_timestamp() {
    let (_scratch, d) = dir("bcast");
    let driver = HostBus::open(&d, Station::Driver, None).unwrap();
    let stim = HostBus::open(&d, Station::Stimulator, None).unwrap();
    let tap = HostBus::open(&d, Station::Tap, Some(Duration::from_millis(50))).unwrap();
    let f = RawFrame::data(0x110, &[7; 8]).unwrap();
    driver.send(&f).unwrap();
    let got = stim.recv().unwrap().unwrap();
    assert_eq!(got.frame, f);
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64;
    let t = got.rx_realtime_ns.expect("a receive timestamp");
    assert!(t <= now && now - t < 5_000_000_000, "{t} vs {now}");
    assert_eq!(tap.recv().unwrap().unwrap().frame, f);
    // The sender does not hear itself; nothing else is queued.
    assert_eq!(driver.recv().unwrap(), None);
    assert_eq!(stim.recv().unwrap(), None);
    // The tap's read times out.
    let t0 = std::time::Instant::now();
    assert_eq!(tap.recv().unwrap(), None);
    assert!(t0.elapsed() >= Duration::from_millis(40));
    // The tap injects to both.
    let e = RawFrame::error(0x40, &[]);
    tap.send(&e).unwrap();
    assert_eq!(driver.recv().unwrap().unwrap().frame, e);
    assert_eq!(stim.recv().unwrap().unwrap().frame, e);
    assert_eq!(driver.missed(), 0);
}

#[test]
fn absent_or_full_stations_miss_frames_and_the_sender_carries_on() {
    let (_scratch, d) = dir("missing");
    let driver = HostBus::open(&d, Station::Driver, None).unwrap();
    let f = RawFrame::data(0x110, &[1]).unwrap();
    driver.send(&f).unwrap();
    assert_eq!(driver.missed(), 2);
    let stim = HostBus::open(&d, Station::Stimulator, None).unwrap();
    // The tap stays absent (one miss per send); send until the stimulator's queue has
    // refused 10 frames.
    let mut sent = 0u64;
    while driver.missed() - 2 - sent < 10 {
        driver.send(&f).unwrap();
        sent += 1;
        assert!(sent < 1_000_000, "the stimulator's queue never filled");
    }
    // A station that never reads does not silence the sender towards the others: a
    // tap appears and receives while the stimulator's queue stays full.
    let tap = HostBus::open(&d, Station::Tap, None).unwrap();
    driver.send(&f).unwrap();
    assert_eq!(tap.recv().unwrap().map(|r| r.frame), Some(f));
    let mut got = 0;
    while stim.recv().unwrap().is_some() {
        got += 1;
    }
    assert!(got > 0 && got < sent, "{got} of {sent}");
    // With the raised limit the queue holds far more than Linux's default 10 (the
    // sending socket's buffer then bounds it: about 280 frames with the default
    // wmem; a quarter of a second of the driver's traffic).
    if stim.queue_limit() >= Some(MIN_DGRAM_QLEN) {
        assert!(got >= 200, "{got}");
    }
}

#[test]
fn a_stale_socket_is_replaced_a_live_one_refused_and_bad_datagrams_rejected() {
    let (_scratch, d) = dir("stale");
    let first = HostBus::open(&d, Station::Stimulator, None).unwrap();
    let e = HostBus::open(&d, Station::Stimulator, None).unwrap_err();
    assert_eq!(e.kind(), io::ErrorKind::AddrInUse, "{e}");
    // A crashed station leaves its file behind (no Drop): the next one takes over.
    let fd = first.raw_fd();
    std::mem::forget(first);
    // SAFETY: the forgotten HostBus no longer closes `fd`; nothing else uses it.
    unsafe { libc::close(fd) };
    assert!(d.join("stimulator.sock").exists());
    let stim = HostBus::open(&d, Station::Stimulator, None).unwrap();
    // A datagram that is not a CAN frame is an error value, not a panic.
    let raw = std::os::unix::net::UnixDatagram::unbound().unwrap();
    raw.send_to(&[1, 2, 3], d.join("stimulator.sock")).unwrap();
    let e = stim.recv().unwrap_err();
    assert_eq!(e.kind(), io::ErrorKind::InvalidData);
    // A sender reaches the stations without being one.
    let s = HostBus::sender(&d, None).unwrap();
    s.send(&RawFrame::data(0, &[2, 1]).unwrap()).unwrap();
    assert_eq!(stim.recv().unwrap().unwrap().frame.payload(), &[2, 1]);
    drop(stim);
    assert!(!d.join("stimulator.sock").exists());
}

/// As on SocketCAN (`CAN_RAW_RECV_OWN_MSGS` off), a station never hears its own frames,
/// from its bound socket or from a second, send-only socket of the same station (the
/// driver writes through one, stim-driver/src/tx.rs); every other sender reaches it. So on
/// the host bus each frame on the driver's own identifiers that reaches its station is
/// someone else's (the intrusion detection, stim-driver/src/intrusion.rs).
#[test]
fn a_station_never_hears_itself_and_hears_every_other_sender() {
    let (_scratch, d) = dir("own");
    let driver = HostBus::open(&d, Station::Driver, None).unwrap();
    let stim = HostBus::open(&d, Station::Stimulator, None).unwrap();
    let tap = HostBus::open(&d, Station::Tap, None).unwrap();
    let own_sender = HostBus::sender(&d, Some(Station::Driver)).unwrap();
    let nmt_start = RawFrame::data(0x000, &[0x01, 0x10]).unwrap();
    driver.send(&nmt_start).unwrap();
    own_sender.send(&nmt_start).unwrap();
    for _ in 0..2 {
        assert_eq!(stim.recv().unwrap().unwrap().frame, nmt_start);
        assert_eq!(tap.recv().unwrap().unwrap().frame, nmt_start);
    }
    assert_eq!(driver.recv().unwrap(), None, "the driver heard itself");
    // The same frame from anyone else reaches the driver: from the tap, from a sender in
    // no station's name, from a sender in the stimulator's.
    let anyone = HostBus::sender(&d, None).unwrap();
    let as_stim = HostBus::sender(&d, Some(Station::Stimulator)).unwrap();
    for s in [&tap, &anyone, &as_stim] {
        s.send(&nmt_start).unwrap();
        assert_eq!(driver.recv().unwrap().unwrap().frame, nmt_start);
    }
    assert_eq!(driver.recv().unwrap(), None);
}
