//! The driver binary on the ScienceMode 2 transport against the virtual RehaStim 2 on a
//! pty (`support/on_serial.rs`): it comes up, arms and delivers pulses end to end, every
//! pulse acknowledged is reconciled; and the serial twins of the CAN path's fault cases.

use std::time::Duration;

use fes_rt::msg::{DeviceState, DriverCommandKind, DriverStatus};

use crate::on_bus::Publisher;
use crate::on_serial::{Rig, decisions_delivered, run_armed};

/// 5 s at 50 Hz, armed, until the publisher's final tick: every decision the driver let
/// through is delivered by the device once, in order, with its current; the device's
/// acknowledgements (the driver's "pulses applied", STATUS reconciliation's delivered
/// count) equal the device's own log; the run ends on the final tick, never on a
/// delivery mismatch.
#[test]
fn sciencemode_arms_and_delivers_and_every_acknowledged_pulse_is_reconciled() {
    let mut rig = Rig::start("e2e");
    let (decisions, before, s, pulses_before) = run_armed(&mut rig, "mA,p20:2500");
    // The device's last acknowledgements and the STATUS after the stop.
    std::thread::sleep(Duration::from_millis(300));
    let pulses = rig.device.pulses();
    let delivered = &pulses[pulses_before..];
    let sent = s.pulses_sent - before.pulses_sent;
    let refused = s.pulses_rejected - before.pulses_rejected;
    assert_eq!(decisions.len(), 125);
    assert_eq!(sent + refused, 125, "sent or reported: {s:?}");
    assert_eq!(
        delivered.len() as u64,
        sent,
        "the device delivered every pulse sent"
    );
    let js = decisions_delivered(delivered, &decisions);
    assert!(js.windows(2).all(|w| w[0] < w[1]), "in order: {js:?}");
    // A shared host refuses a late tick now and then (reported, never sent late).
    assert!(sent >= 100, "{sent} of 125 delivered: {s:?}");
    assert_eq!(
        rig.applied_logged(),
        Some(pulses.len() as u64),
        "acknowledged = delivered\n{}",
        crate::on_bus::tail(&rig.log)
    );
    println!("ScienceMode: 125 decisions, {sent} delivered in order, {refused} refused as late");
}

/// The device switched off mid-stimulation (its pty closes: the driver's port reads and
/// writes EIO): the driver trips with the link-down fault, and stays in its safe state,
/// refusing an Arm, while the port is gone.
#[test]
fn sciencemode_link_lost_trips_link_down_and_never_rearms() {
    let mut rig = Rig::start("link");
    let mut p = Publisher::start(&rig.prefix, "mA,p20:30000");
    rig.op.arm(Duration::from_secs(5), &rig.log);
    p.go();
    std::thread::sleep(Duration::from_millis(500));
    let on = rig.device.pulses().len();
    assert!(on > 5, "pulses before the loss: {on}");
    rig.device.stop();
    let s = rig.wait_fault(Duration::from_secs(2));
    assert_eq!(
        s.fault_code,
        DriverStatus::FAULT_LINK_DOWN,
        "{s:?}\n{}",
        crate::on_bus::tail(&rig.log)
    );
    rig.op.send(DriverCommandKind::Arm);
    std::thread::sleep(Duration::from_millis(1000));
    let s = rig.op.status().unwrap();
    assert_eq!(s.state(), Ok(DeviceState::Fault), "{s:?}");
    assert_eq!(s.fault_code, DriverStatus::FAULT_LINK_DOWN);
    p.kill();
}
