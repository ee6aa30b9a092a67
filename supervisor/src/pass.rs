//! The daemon's decisions in one pass of its loop, without I/O (time and the process
//! probe are passed in), so that the daemon and the tests run the same rules: an operator
//! command (a re-arm first clears only the processes that are live again) and the health
//! check (a fault stops stimulation at once: the first names the stop, later ones are
//! noted).

use crate::core::{CommandError, Fault, SupervisorCore};
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
