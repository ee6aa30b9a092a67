//! The driver binary on the ScienceMode 2 transport against the virtual RehaStim 2 on a
//! pty (`support/on_serial.rs`): it comes up, arms and delivers pulses end to end, every
//! pulse acknowledged is reconciled; and the serial twins of the CAN path's fault cases.

use std::time::Duration;

use fes_rt::msg::{DeviceState, DriverCommandKind, DriverStatus};

use crate::on_bus::Publisher;
use crate::on_serial::{Rig, decisions_delivered, run_armed, signal_driver};

/// 5 s at 50 Hz, armed, until the publisher's final tick: every decision the driver let
/// through is delivered by the device once, in order, with its current; the device's
/// acknowledgements (the delivered count of the driver's last STATUS, which STATUS
/// reconciliation compares, in its final line) equal the device's own log; the run ends on the final tick, never on a
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
        rig.stop_driver_applied(),
        Some(pulses.len() as u64),
        "acknowledged = delivered\n{}",
        crate::on_bus::tail(&rig.log)
    );
    println!("ScienceMode: 125 decisions, {sent} delivered in order, {refused} refused as late");
}

/// A MOTOmed attached (§3.5, §2.3): the device sends ActualValues every 20 ms on its own
/// packet counter, unasked. The driver skips them: it arms, delivers, and the run ends on
/// the final tick, never on a link fault.
#[test]
fn sciencemode_motomed_actual_values_are_skipped_not_a_link_fault() {
    let mut rig = Rig::start_with_motomed("motomed");
    let (decisions, before, s, _) = run_armed(&mut rig, "mA,p20:1000");
    let sent = s.pulses_sent - before.pulses_sent;
    assert_eq!(decisions.len(), 50);
    // run_armed asserts the run ended on the final tick (no LinkDown, no other fault).
    assert!(sent >= 40, "{sent} of 50 delivered: {s:?}");
    let log = std::fs::read_to_string(&rig.device.log).unwrap();
    assert!(!log.contains("bad_packet"), "{log}");
}

/// The device at the real RehaStim 2's worst-case latency (24 ms to execute a command,
/// Hasomed's figure): every acknowledgement and liveness answer 24 ms late. The driver
/// waits for each answer (stop-and-wait), so pulses 30 ms apart all go out; the in-flight
/// allowance of STATUS reconciliation (the pulses written within `stimulator_timeout_ms`,
/// required >= 24 ms + 2 liveness queries) covers the latency: the run ends on the final
/// tick, not on a delivery mismatch, and every pulse let through is delivered and
/// acknowledged.
#[test]
fn sciencemode_device_latency_is_within_the_in_flight_allowance() {
    let mut rig = Rig::start_with("latency", None, 24);
    let (decisions, before, s, pulses_before) = run_armed(&mut rig, "mA,p30:3000");
    std::thread::sleep(Duration::from_millis(300));
    let pulses = rig.device.pulses();
    let sent = s.pulses_sent - before.pulses_sent;
    let refused = s.pulses_rejected - before.pulses_rejected;
    assert_eq!((pulses.len() - pulses_before) as u64, sent);
    // A pulse decided while a liveness query awaits its answer waits for it; 24 ms is
    // beyond the lateness bound, so it is dropped and reported. (A shared host refuses a
    // late tick now and then too: reported, never sent late.)
    let late = rig.reported_late(&decisions);
    assert_eq!(sent + refused + late, 100, "{s:?}");
    assert!(sent >= 80, "{sent} of 100 delivered, {late} late: {s:?}");
    assert_eq!(
        rig.stop_driver_applied(),
        Some(pulses.len() as u64),
        "acknowledged = delivered\n{}",
        crate::on_bus::tail(&rig.log)
    );
}

/// The device as HASOMED documents it (§2.3, §5.1): each command processed for 5-15 ms
/// (3 % of them 100 ms, the MaxResponseTime), and -8 busy to any command meanwhile. The
/// driver waits for each answer: it never provokes -8 or -3 (counted by the device),
/// every pulse it wrote is delivered and acknowledged, a pulse the device could not take
/// within the lateness bound is reported late (never sent as a burst), and the run ends
/// on the final tick. How many are late depends on the host's timing as well as on the
/// device: that figure is [`timing::a_busy_device_loses_pulses_only_behind_its_slow_answers_on_a_quiet_host`].
#[test]
fn sciencemode_busy_device_is_never_provoked_and_late_pulses_are_reported() {
    let run = busy_device_run("busy");
    println!(
        "ScienceMode, busy device: 100 decisions at 33 Hz, {} delivered, {} dropped late, \
         {} refused, {} slow answers; no -8 or -3 provoked",
        run.sent, run.late, run.refused, run.slow
    );
}

/// What one busy-device run delivered and what the device did.
struct BusyRun {
    /// Pulses written and delivered.
    sent: u64,
    /// Decisions dropped late (reported with their tick).
    late: u64,
    /// Decisions refused by the interlocks.
    refused: u64,
    /// Commands the device took [`fes_virtual_stimulator::rehastim2::SLOW_PROCESSING_MS`]
    /// to answer, over the whole run (arming and stopping included).
    slow: u64,
}

/// One run of [`sciencemode_busy_device_is_never_provoked_and_late_pulses_are_reported`]:
/// its functional assertions, and what it delivered.
fn busy_device_run(name: &str) -> BusyRun {
    let mut rig = Rig::start_with_processing(name, 10);
    let (decisions, before, s, pulses_before) = run_armed(&mut rig, "mA,p30:3000");
    std::thread::sleep(Duration::from_millis(300));
    let pulses = rig.device.pulses();
    let sent = s.pulses_sent - before.pulses_sent;
    let refused = s.pulses_rejected - before.pulses_rejected;
    let delivered = (pulses.len() - pulses_before) as u64;
    assert_eq!(decisions.len(), 100);
    assert_eq!(delivered, sent, "the device delivered every pulse written");
    let js = decisions_delivered(&pulses[pulses_before..], &decisions);
    assert!(js.windows(2).all(|w| w[0] < w[1]), "in order: {js:?}");
    assert_eq!(
        rig.stop_driver_applied(),
        Some(pulses.len() as u64),
        "acknowledged = delivered\n{}",
        crate::on_bus::tail(&rig.log)
    );
    // Every decision not delivered is reported: refused by the interlocks (a late tick
    // on a shared host) or dropped late, each with a log line naming its tick.
    let late = rig.reported_late(&decisions);
    assert_eq!(
        sent + refused + late,
        100,
        "{s:?}\n{}",
        crate::on_bus::tail(&rig.log)
    );
    let device = rig.device.stop().expect("the device's summary");
    assert_eq!(
        (device.busy_sent, device.wrong_mode_sent),
        (0, 0),
        "the driver provoked busy or wrong-mode answers"
    );
    BusyRun {
        sent,
        late,
        refused,
        slow: device.slow_commands,
    }
}

/// Checks that depend on the host's timing (scripts/test runs them one at a time).
mod timing {
    /// On a quiet host, the pulses lost to the busy device are those behind its slow
    /// answers: a 100 ms answer holds the line over at most 4 decisions 30 ms apart (each
    /// dropped past the lateness bound), so the losses stay within 4 per slow answer,
    /// plus 3 for the host and the query that confirms the arming. How many slow answers
    /// a run meets is the device's draw (3 % of commands): counting against it keeps the
    /// check about the driver. 93-94 of 100 were delivered with 2 slow answers on an idle
    /// host (2026-12-05). With the 20 ms polling of the other scenarios instead of the
    /// shipped 150 ms, a query landing just before a pulse cost 6-26 pulses on the same
    /// host, which this check fails.
    #[test]
    fn a_busy_device_loses_pulses_only_behind_its_slow_answers_on_a_quiet_host() {
        let run = super::busy_device_run("busy-timing");
        let lost = run.late + run.refused;
        assert!(
            lost <= 4 * run.slow + 3,
            "{} of 100 delivered, {} dropped late, {} refused, {} slow answers",
            run.sent,
            run.late,
            run.refused,
            run.slow
        );
    }
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

/// Starts a 50 Hz train on `rig` (armed) and waits until the device has delivered some.
fn stimulating(rig: &mut Rig) -> Publisher {
    let mut p = Publisher::start(&rig.prefix, "mA,p20:30000");
    rig.op.arm(Duration::from_secs(5), &rig.log);
    p.go();
    std::thread::sleep(Duration::from_millis(500));
    assert!(rig.device.pulses().len() > 5, "stimulating");
    p
}

/// The pulses the device delivers from `after` on, over `window`.
fn delivered_over(rig: &Rig, window: Duration) -> (usize, usize) {
    let at = rig.device.pulses().len();
    std::thread::sleep(window);
    (at, rig.device.pulses().len())
}

/// The driver SIGKILLed mid-train (the CAN twin: the driver killed, the stimulator's
/// watchdog stops it): on this transport a pulse is a command, so the device delivers
/// nothing once the commands in flight are done: none from 100 ms after the kill to 1.5 s
/// after it (beyond the device's 1 s watchdog).
#[test]
fn sciencemode_driver_killed_delivers_no_pulse_after() {
    let mut rig = Rig::start("kill");
    let p = stimulating(&mut rig);
    signal_driver(&rig, libc::SIGKILL);
    std::thread::sleep(Duration::from_millis(100));
    let (at, later) = delivered_over(&rig, Duration::from_millis(1400));
    assert_eq!(at, later, "pulses delivered after the driver died");
    p.kill();
}

/// The driver SIGSTOPped 1.5 s mid-train, then continued (the CAN twin: a stalled
/// driver): nothing is delivered while it is stopped; continued, it trips (its StimTicks
/// are stale, the device's STATUS is old) without a burst, and stays in its safe state.
#[test]
fn sciencemode_driver_stalled_fails_safe_and_never_rearms() {
    let mut rig = Rig::start("stall");
    let p = stimulating(&mut rig);
    signal_driver(&rig, libc::SIGSTOP);
    std::thread::sleep(Duration::from_millis(100));
    let (at, later) = delivered_over(&rig, Duration::from_millis(1400));
    assert_eq!(at, later, "pulses delivered while the driver was stopped");
    signal_driver(&rig, libc::SIGCONT);
    let s = rig.wait_fault(Duration::from_secs(3));
    // 1.5 s of silence is beyond the device's 1200 ms watchdog (§2.3): it has reset every
    // mode and announces Init again (§5.2), which the resumed driver may see first as the
    // device's restart.
    assert!(
        [
            DriverStatus::FAULT_STALE_TICK,
            DriverStatus::FAULT_TICK_TIMEOUT,
            DriverStatus::FAULT_STIMULATOR_SILENT,
            DriverStatus::FAULT_STIMULATOR_RESET,
        ]
        .contains(&s.fault_code),
        "{s:?}\n{}",
        crate::on_bus::tail(&rig.log)
    );
    let (at_resume, after) = delivered_over(&rig, Duration::from_millis(1000));
    assert!(
        after - later <= 1,
        "a burst after the stall: {} pulses ({later} before, {at_resume} at the trip)",
        after - later
    );
    let s = rig.op.status().unwrap();
    assert_eq!(s.state(), Ok(DeviceState::Fault), "never re-armed: {s:?}");
    p.kill();
}

/// A device fault at the 21st pulse (`sim-muscle rehastim2 --test-fault`): the driver
/// trips with `code`, its log names the ScienceMode command and code (`detail`), the device
/// delivers nothing more and the driver stays in its safe state.
fn device_fault_trips(name: &str, fault: &str, code: u16, detail: Option<u16>) {
    let mut rig = Rig::start_with(name, Some(fault.parse().unwrap()), 0);
    let mut p = Publisher::start(&rig.prefix, "mA,p20:30000");
    rig.op.arm(Duration::from_secs(5), &rig.log);
    p.go();
    let s = rig.wait_fault(Duration::from_secs(5));
    assert_eq!(
        s.fault_code,
        code,
        "{fault}: {s:?}\n{}",
        crate::on_bus::tail(&rig.log)
    );
    if let Some(detail) = detail {
        let text = rig.log_text();
        assert!(
            text.contains(&format!("detail {detail}")),
            "{fault}: the log names the command and code\n{}",
            crate::on_bus::tail(&rig.log)
        );
    }
    let (at, later) = delivered_over(&rig, Duration::from_millis(700));
    assert_eq!(at, 20, "{fault}: the 20 pulses before the fault");
    assert_eq!(at, later, "{fault}: nothing after the trip");
    assert_eq!(rig.op.status().unwrap().state(), Ok(DeviceState::Fault));
    p.kill();
}

/// StimulationError (-2, electrode) instead of the 21st pulse: EMCY generic, detail
/// 0x26FE (command 38, code -2).
#[test]
fn sciencemode_stimulation_error_trips_naming_it() {
    device_fault_trips("electrode", "electrode:20", 0x1000, Some(0x26FE));
}

/// The 21st pulse acknowledged with a parameter error (-2): EMCY value_out_of_range,
/// detail 0x25FE (SinglePulseAck, -2).
#[test]
fn sciencemode_error_acknowledgement_trips_naming_it() {
    device_fault_trips("paramerr", "parameter-error:20", 0xFF0B, Some(0x25FE));
}

/// The device falls silent at the 21st pulse (the twin of a lost stimulator heartbeat):
/// no answer to the liveness query for `stimulator_timeout_ms`, the driver trips
/// stimulator-silent.
#[test]
fn sciencemode_silent_device_trips_stimulator_silent() {
    device_fault_trips(
        "silent",
        "silent:20",
        DriverStatus::FAULT_STIMULATOR_SILENT,
        None,
    );
}
