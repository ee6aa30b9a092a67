//! The daemon's decisions in one pass of its loop, without I/O (time and the process
//! probe are passed in), so that the daemon and the tests run the same rules: an operator
//! command (a re-arm first clears only the processes that are live again) and the health
//! check (a fault stops stimulation at once: the first names the stop, later ones are
//! noted).

use crate::command_link::LinkEvent;
use crate::core::{CommandError, DriverOrder, DriverProblem, Fault, FaultCause, SupervisorCore};
use crate::health::{HealthEvent, HealthMonitor, ProcState, Severity};
use crate::protocol::Command;

/// Serves one operator `command` at `now_ns`. An Arm first clears the faults of the
/// processes that are live again ([`HealthMonitor::clear_recovered`], asking `probe`
/// about process ids); then the core decides against the health verdict. Returns what
/// was done, or why nothing was.
pub fn serve_command(
    core: &mut SupervisorCore,
    health: &mut HealthMonitor,
    command: &Command,
    now_ns: u64,
    probe: &dyn Fn(u32) -> ProcState,
) -> Result<String, CommandError> {
    if matches!(command, Command::Arm) {
        health.clear_recovered(now_ns, probe);
    }
    core.command(command, now_ns, health.ready())
}

/// Checks health at `now_ns` ([`HealthMonitor::check`]) and hands what it found to the
/// core: a fault stops stimulation ([`SupervisorCore::fault`]: zero reference with the
/// stop flag, a safe stop for the driver) or, when already stopped, is noted; a warning
/// is noted. Returns the events, for the log.
pub fn check_health(
    core: &mut SupervisorCore,
    health: &mut HealthMonitor,
    now_ns: u64,
    probe: &dyn Fn(u32) -> ProcState,
) -> Vec<HealthEvent> {
    health.check(now_ns, probe);
    let events = health.take_events();
    for e in &events {
        match e.severity {
            Severity::Fault => {
                if !core.fault(Fault::from_event(e)) {
                    core.note(format!("also: {}", e.message));
                }
            }
            Severity::Warning => core.note(format!("warning: {}", e.message)),
        }
    }
    events
}

/// Acts on what the driver's statuses said about the orders ([`crate::command_link`]): a
/// refused or unacknowledged Arm and a driver not armed after confirming one are faults;
/// a driver still armed after confirming a stop gets another safe stop; an unacknowledged
/// or refused stop is an alarm (the link keeps re-sending it). Returns the alarm or fault
/// text for the log at `err`, or `None` for a plain confirmation.
pub fn on_link_event(core: &mut SupervisorCore, event: LinkEvent) -> Option<String> {
    let driver_fault =
        |problem, message: String| Fault::new(FaultCause::Driver { problem }, message);
    match event {
        LinkEvent::Confirmed(order) => {
            if order == DriverOrder::Arm {
                core.note("stim-driver confirmed the arm".into());
            }
            None
        }
        LinkEvent::Refused {
            order: DriverOrder::Arm,
            reason,
        } => {
            let m = format!("stim-driver refused the arm: {}", reason.name());
            core.fault(driver_fault(DriverProblem::ArmRefused, m.clone()));
            Some(m)
        }
        LinkEvent::Refused { order, reason } => {
            let m = format!(
                "ALARM: stim-driver refused the {order:?}: {}; re-sending",
                reason.name()
            );
            core.note(m.clone());
            Some(m)
        }
        LinkEvent::Unacknowledged {
            order: DriverOrder::Arm,
            waited_ns,
        } => {
            let m = format!(
                "stim-driver did not acknowledge the arm within {} ms",
                waited_ns / 1_000_000
            );
            core.fault(driver_fault(DriverProblem::Unacknowledged, m.clone()));
            Some(m)
        }
        LinkEvent::Unacknowledged { order, waited_ns } => {
            // Whether the driver stopped is unknown: a fault the status and `watch` show
            // (the stop goes on being re-sent, now as the fault's safe stop).
            let m = format!(
                "ALARM: stim-driver has not acknowledged the {order:?} for {} ms; re-sending",
                waited_ns / 1_000_000
            );
            if !core.fault(driver_fault(DriverProblem::StopUnacknowledged, m.clone())) {
                core.note(m.clone());
            }
            Some(m)
        }
        LinkEvent::NotArmed { state } => {
            let m = format!("stim-driver reports {state:?} after confirming the arm");
            core.fault(driver_fault(DriverProblem::StateMismatch, m.clone()));
            Some(m)
        }
        LinkEvent::StillArmed { state } => {
            let m = format!("ALARM: stim-driver reports {state:?} after confirming a stop");
            if !core.fault(driver_fault(DriverProblem::StateMismatch, m.clone())) {
                core.note(m.clone());
                core.reissue_safe_stop();
            }
            Some(m)
        }
    }
}
