//! Health of the stimulation chain: which process is alive, stalled or dead, and why.
//!
//! Watched: **rt-core** (its StimTick stream, every 1 ms, and its iceoryx2 node),
//! **stim-driver** (its DriverStatus stream and node) and **sim-muscle**, the stimulator
//! (the FORCE samples the driver forwards as ForceSample, the stimulator state in
//! DriverStatus, and, when its process id is known, the process itself). Liveness combines
//! message freshness with the state of the process: a process whose messages stop is
//! `dead` when its process is gone (or a zombie), `stopped` when it was stopped by a
//! signal, `stalled` otherwise; a process that published its final message and removed
//! its node `exited`. Reported faults (DriverStatus FAULT, a watchdog trip, an EMCY code,
//! a stimulator in FAULT, a generator fault, an invalid message) are faults of the
//! process that reported them. Causes are attributed upstream first: when rt-core stops
//! ticking, the driver's watchdog trip that follows is reported as its consequence.
//!
//! Pure: time and the process probe are passed in.

use std::collections::BTreeMap;

use fes_rt::msg::{
    Contract, DeviceState, DriverStatus, ForceSample, StimTick, TimingReport, TimingSource,
};
use fes_rt::rt::liveness::NodeObservation;
use serde::{Deserialize, Serialize};

use crate::protocol::{ProcessState, ProcessStatus};
use crate::range::{self, Interval, RangeError};

/// The processes of the chain.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Process {
    /// The pattern generator.
    RtCore,
    /// The stimulator driver.
    StimDriver,
    /// The (virtual) stimulator and muscle.
    SimMuscle,
}

impl Process {
    /// All, upstream first.
    pub const ALL: [Process; 3] = [Process::RtCore, Process::StimDriver, Process::SimMuscle];

    /// Process name as the operator knows it.
    pub fn name(self) -> &'static str {
        match self {
            Process::RtCore => "rt-core",
            Process::StimDriver => "stim-driver",
            Process::SimMuscle => "sim-muscle",
        }
    }

    fn index(self) -> usize {
        self as usize
    }
}

/// What the operating system says about a process id.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProcState {
    /// No such process.
    Gone,
    /// Terminated, not yet reaped by its parent.
    Zombie,
    /// Stopped by a signal (SIGSTOP, a debugger).
    Stopped,
    /// Running or sleeping.
    Running,
}

/// Reads `/proc/<pid>/stat` to tell a dead process from a stopped or a running one.
pub fn proc_state(pid: u32) -> ProcState {
    let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
        return ProcState::Gone;
    };
    // The state letter follows the command name, which is in parentheses and may itself
    // contain parentheses: take the last ')'.
    let state = stat
        .rfind(')')
        .and_then(|i| stat[i + 1..].split_whitespace().next());
    match state {
        Some("Z") | Some("X") | Some("x") => ProcState::Zombie,
        Some("T") | Some("t") => ProcState::Stopped,
        Some(_) => ProcState::Running,
        None => ProcState::Gone,
    }
}

/// Health settings. Defaults suit a native bench; the UML bench relaxes them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HealthSettings {
    /// rt-core is stalled when no StimTick came for this long, ms. Default 50.
    pub stim_tick_timeout_ms: u64,
    /// stim-driver is stalled when no DriverStatus came for this long, ms. Default 500.
    pub driver_status_timeout_ms: u64,
    /// The stimulator is silent when no ForceSample came for this long, ms. Default 100.
    pub force_timeout_ms: u64,
    /// Period of the iceoryx2 node listing, ms. Default 250.
    pub node_scan_period_ms: u64,
    /// Watch rt-core. Default true.
    pub watch_rt_core: bool,
    /// Watch stim-driver. Default true.
    pub watch_stim_driver: bool,
    /// Watch the stimulator (sim-muscle on a bench, the real stimulator on a rig) through
    /// the forwarded force and the driver's view of it. Default true.
    pub watch_stimulator: bool,
    /// Process id of the stimulator process, when known (the bench sets it).
    pub stimulator_pid: Option<u32>,
    /// A test configuration: only then may a `watch_*` be false (a daemon under test
    /// without the process it would watch). A rig's or a bench's configuration turning a
    /// watch off is refused: without the driver's watch, no stop or arm is acknowledged.
    /// Default false.
    pub test_configuration: bool,
    /// The supervisor itself is stalled when two passes of its loop are further apart
    /// than this, ms (it was stopped by a signal, or starved): while armed, that is a
    /// fault, so stimulation does not resume on its own when it runs again. Default 500
    /// (rt-core ramps a reference older than its `stale_after_ms` to zero meanwhile).
    pub self_stall_ms: u64,
}

impl Default for HealthSettings {
    fn default() -> Self {
        Self {
            stim_tick_timeout_ms: 50,
            driver_status_timeout_ms: 500,
            force_timeout_ms: 100,
            node_scan_period_ms: 250,
            watch_rt_core: true,
            watch_stim_driver: true,
            watch_stimulator: true,
            stimulator_pid: None,
            test_configuration: false,
            self_stall_ms: 500,
        }
    }
}

impl HealthSettings {
    /// Checks the ranges; the error names the key.
    pub fn validate(&self) -> Result<(), RangeError> {
        for (k, v, lo) in [
            ("stim_tick_timeout_ms", self.stim_tick_timeout_ms, 2.0),
            (
                "driver_status_timeout_ms",
                self.driver_status_timeout_ms,
                2.0,
            ),
            ("force_timeout_ms", self.force_timeout_ms, 2.0),
            ("node_scan_period_ms", self.node_scan_period_ms, 10.0),
            ("self_stall_ms", self.self_stall_ms, 20.0),
        ] {
            range::check(k, v as f64, Interval::closed(lo, 60_000.0))?;
        }
        Ok(())
    }

    /// The supervisor's own stall, when the gap `gap_ns` between two passes of its loop
    /// exceeds `self_stall_ms`: the fault message.
    pub fn self_stall(&self, gap_ns: u64) -> Option<String> {
        (gap_ns > self.self_stall_ms * 1_000_000).then(|| {
            format!(
                "supervisor stalled: {:.0} ms between two passes of its loop (limit {} ms); \
                 its view of the chain is stale",
                ms(gap_ns),
                self.self_stall_ms
            )
        })
    }

    fn watched(&self, p: Process) -> bool {
        match p {
            Process::RtCore => self.watch_rt_core,
            Process::StimDriver => self.watch_stim_driver,
            Process::SimMuscle => self.watch_stimulator,
        }
    }

    fn timeout_ns(&self, p: Process) -> u64 {
        1_000_000
            * match p {
                Process::RtCore => self.stim_tick_timeout_ms,
                Process::StimDriver => self.driver_status_timeout_ms,
                Process::SimMuscle => self.force_timeout_ms,
            }
    }
}

/// The iceoryx2 node ids of the publishers of this stack's services (its prefix): how
/// the monitor tells its own rt-core and stim-driver from those of another stack on the
/// same machine, whose nodes have the same names.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ServiceOwners {
    /// Publishers of StimTick (rt-core).
    pub stim_tick: Vec<u128>,
    /// Publishers of DriverStatus (stim-driver).
    pub driver_status: Vec<u128>,
}

/// How serious an event is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Severity {
    /// Stimulation must stop.
    Fault,
    /// Worth reporting; stimulation goes on.
    Warning,
}

/// Something the monitor noticed.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct HealthEvent {
    /// Which process it concerns.
    pub process: Process,
    /// Fault or warning.
    pub severity: Severity,
    /// What happened, typed: what a program acts on.
    pub cause: Cause,
    /// The process id, when known.
    pub pid: Option<u32>,
    /// What happened, in words (starts with the process name): what a person reads.
    pub message: String,
}

/// What happened to a watched process: the typed cause of a [`HealthEvent`], carried into
/// the supervisor's fault ([`crate::core::FaultCause`]) and the status (`fault_cause`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum Cause {
    /// The process is gone, a zombie, or its iceoryx2 node is dead.
    Died,
    /// Alive (or stopped by a signal) but silent beyond its timeout.
    Stalled,
    /// Its node is gone after it ended (a final message, or the node removed).
    Exited,
    /// The stimulator sends no force while the driver is alive.
    Silent,
    /// The driver's watchdog tripped (ticks or the stimulator silent).
    WatchdogTripped,
    /// A message that failed validation.
    InvalidMessage,
    /// The pattern generator produced a non-finite value.
    NonFinite,
    /// rt-core sent its final tick.
    Finished,
    /// An EMCY from the driver or the stimulator.
    Emcy {
        /// The EMCY code (fes-can `ErrorCode` or a driver fault code).
        code: u16,
    },
    /// The driver or the stimulator reports its FAULT state.
    DeviceFault {
        /// The last fault code.
        code: u16,
    },
    /// Messages lost before the supervisor read them (warning).
    LostMessages,
    /// rt-core runs without real-time guarantees (warning).
    BestEffort,
    /// The driver refused pulses (warning).
    PulsesRejected,
    /// CAN transmit errors (warning).
    TransmitErrors,
    /// Heap allocations on a hot path (warning).
    HeapAllocation,
    /// rt-core rejected a Reference the supervisor published.
    ReferenceRejected,
    /// rt-core's reference went stale: the supervisor's References stopped reaching it.
    ReferenceStale,
}

impl Cause {
    /// A trip judged against time (a stall, a silence, a watchdog): on a loaded host it
    /// may be the host's noise, not the chain's fault.
    pub fn is_timing(self) -> bool {
        matches!(
            self,
            Cause::Stalled | Cause::Silent | Cause::WatchdogTripped | Cause::ReferenceStale
        )
    }
}

/// Why stimulation may not be armed yet ([`HealthMonitor::ready`]): every watched process
/// that is not ready, upstream first. Reads as their reasons joined by `; `.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct NotReady {
    /// The processes that are not ready, upstream first (never empty).
    pub problems: Vec<Unready>,
}

impl std::fmt::Display for NotReady {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (i, problem) in self.problems.iter().enumerate() {
            if i > 0 {
                f.write_str("; ")?;
            }
            write!(f, "{problem}")?;
        }
        Ok(())
    }
}

/// One watched process that is not ready to arm.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Unready {
    /// Not heard from since the supervisor started.
    #[error("{}: not heard from yet", .process.name())]
    Waiting {
        /// The process.
        process: Process,
    },
    /// Its fault is in force.
    #[error("{reason}")]
    Faulted {
        /// The process.
        process: Process,
        /// The fault's message (starts with the process's name).
        reason: String,
    },
    /// It enforces another prescription than the supervisor (or than the other process).
    #[error(
        "{}: enforces prescription {found} (first 12 hex digits of its SHA-256) where the \
         stack's is {expected} (the supervisor's, or the other process's when the \
         supervisor reads none): after a prescription change restart every process",
        .process.name()
    )]
    Prescription {
        /// The process.
        process: Process,
        /// Its fingerprint, hex.
        found: String,
        /// The one expected, hex.
        expected: String,
    },
}

/// What a stream of messages says about a process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Condition {
    Waiting,
    Ok,
    Faulted,
}

#[derive(Debug, Clone)]
struct Watch {
    last_ns: Option<u64>,
    node: Option<NodeObservation>,
    node_gone: bool,
    condition: Condition,
    reason: String,
    cause: Option<Cause>,
    finished: bool,
    /// `last_ns` when the fault was raised: a fault clears only after a newer message.
    last_at_fault: Option<u64>,
    /// The pid of the process this watch saw die: that process never clears its fault
    /// (a frame it sent before its death may still arrive after it), only a new one.
    died_pid: Option<u32>,
}

impl Watch {
    fn new() -> Self {
        Self {
            last_ns: None,
            node: None,
            node_gone: false,
            condition: Condition::Waiting,
            reason: String::new(),
            cause: None,
            finished: false,
            last_at_fault: None,
            died_pid: None,
        }
    }
}

/// The health monitor.
#[derive(Debug, Clone)]
pub struct HealthMonitor {
    settings: HealthSettings,
    watch: [Watch; 3],
    driver: Option<DriverStatus>,
    timing: BTreeMap<u8, TimingReport>,
    warned_degraded: bool,
    /// The reference flags (rejected, stale) of the last StimTick: a fault is raised when
    /// one appears, not on every tick that carries it.
    last_reference_flags: u16,
    last_tick_seq: u64,
    /// rt-core's speech by its own clock: the newest StimTick's grid time and the last
    /// silence between two StimTicks, for blaming a driver watchdog trip.
    ticks: TickGaps,
    events: Vec<HealthEvent>,
    /// The supervisor's own prescription fingerprint, if it read one.
    prescription: Option<[u8; 6]>,
}

/// The StimTick stream by the ticks' own grid times (CLOCK_MONOTONIC, shared by every
/// process), not by when the supervisor read them: after a stall of the supervisor's own
/// loop, the ticks from before a silence of rt-core and the driver's trip can be read in
/// one pass, and the receive times would then show no silence at all.
#[derive(Debug, Clone, Copy, Default)]
struct TickGaps {
    /// Grid time of the newest tick, ns.
    newest_ns: Option<u64>,
    /// The last silence longer than [`TickGaps::SILENCE_NS`]: (last tick before it, first
    /// tick after it), ns.
    last_gap: Option<(u64, u64)>,
}

impl TickGaps {
    /// Two ticks' grid times this far apart are a silence of rt-core: more than two missed
    /// 1 ms periods, what the driver's StimTick watchdog (3 ticks on the shipped
    /// configurations) trips on.
    const SILENCE_NS: u64 = 2_500_000;

    fn on_tick(&mut self, t_ns: u64) {
        if let Some(prev) = self.newest_ns
            && t_ns > prev + Self::SILENCE_NS
        {
            self.last_gap = Some((prev, t_ns));
        }
        self.newest_ns = Some(self.newest_ns.map_or(t_ns, |p| p.max(t_ns)));
    }

    /// How long rt-core was silent at some time in `[from_ns, to_ns]` (by the ticks' grid
    /// times), ns, when it was: the newest tick is older than that window's end by more
    /// than a silence, or the last silence overlaps the window.
    fn silence_within(&self, from_ns: u64, to_ns: u64) -> Option<u64> {
        let quiet_now = self
            .newest_ns
            .filter(|&t| to_ns > t + Self::SILENCE_NS)
            .map(|t| to_ns - t);
        let gap = self
            .last_gap
            .filter(|&(start, end)| start <= to_ns && end >= from_ns)
            .map(|(start, end)| end - start);
        quiet_now.or(gap)
    }
}

/// A watched process found silent beyond its timeout, or dead ([`HealthMonitor::check`]).
struct Silence {
    process: Process,
    pid: Option<u32>,
    /// What the probe says about `pid`.
    pstate: Option<ProcState>,
    /// Its process is gone or a zombie, or its node is dead.
    dead_now: bool,
    /// Its node is gone, or it sent its final message.
    ended: bool,
    /// Since its last message, ns.
    age: u64,
    /// Its timeout, ns.
    limit: u64,
}

impl Silence {
    /// The cause, and the message that names the process and says why.
    fn verdict(&self) -> (Cause, String) {
        let p = self.process;
        let name = p.name();
        let what = match p {
            Process::RtCore => "StimTick",
            Process::StimDriver => "DriverStatus",
            Process::SimMuscle => "FORCE sample",
        };
        let pid_txt = self
            .pid
            .map_or(String::new(), |pid| format!(" (pid {pid})"));
        let (age, limit) = (ms(self.age), ms(self.limit));
        match (self.pstate, self.dead_now) {
            (Some(ProcState::Gone), _) => (
                Cause::Died,
                format!("{name}{pid_txt} died: the process is gone; last {what} {age:.0} ms ago"),
            ),
            (Some(ProcState::Zombie), _) => (
                Cause::Died,
                format!(
                    "{name}{pid_txt} died: the process has exited (zombie); last {what} {age:.0} ms ago"
                ),
            ),
            (_, true) => (
                Cause::Died,
                format!(
                    "{name}{pid_txt} died: its iceoryx2 node is dead; last {what} {age:.0} ms ago"
                ),
            ),
            (Some(ProcState::Stopped), _) => (
                Cause::Stalled,
                format!(
                    "{name}{pid_txt} stalled: stopped by a signal; no {what} for {age:.0} ms (limit {limit:.0} ms)"
                ),
            ),
            _ if self.ended => (
                Cause::Exited,
                format!("{name}{pid_txt} exited: its node is gone; no {what} for {age:.0} ms"),
            ),
            _ if p == Process::SimMuscle => (
                Cause::Silent,
                format!(
                    "sim-muscle (stimulator){pid_txt} silent: no {what} forwarded for {age:.0} ms (limit {limit:.0} ms) while stim-driver is alive"
                ),
            ),
            _ => (
                Cause::Stalled,
                format!(
                    "{name}{pid_txt} stalled: process alive but no {what} for {age:.0} ms (limit {limit:.0} ms)"
                ),
            ),
        }
    }
}

fn ms(ns: u64) -> f64 {
    ns as f64 * 1e-6
}

fn state_name(s: Result<DeviceState, fes_rt::msg::ValidationError>) -> String {
    match s {
        Ok(s) => format!("{s:?}"),
        Err(_) => "invalid".into(),
    }
}

/// Name of a CANopen EMCY code of the stimulator protocol.
pub fn emcy_name(code: u16) -> String {
    match (
        fes_can::ErrorCode::from_raw(code.into()),
        DriverStatus::driver_fault_name(code),
    ) {
        (Some(c), _) => format!("0x{code:04X} {}", c.name()),
        (None, Some(n)) => format!("0x{code:04X} {n}"),
        (None, None) => format!("0x{code:04X}"),
    }
}

impl HealthMonitor {
    /// A monitor that has heard from nobody yet.
    pub fn new(settings: HealthSettings) -> Self {
        Self {
            settings,
            watch: [Watch::new(), Watch::new(), Watch::new()],
            driver: None,
            timing: BTreeMap::new(),
            warned_degraded: false,
            last_reference_flags: 0,
            last_tick_seq: 0,
            ticks: TickGaps::default(),
            events: Vec::new(),
            prescription: None,
        }
    }

    /// The prescription the supervisor records under (its fingerprint): rt-core and
    /// stim-driver must enforce the same one to be armed ([`Self::ready`]).
    pub fn set_prescription(&mut self, fingerprint: [u8; 6]) {
        self.prescription = Some(fingerprint);
    }

    /// The watched pattern generator and driver whose last TimingReport names another
    /// prescription than the supervisor's (or, without one, than each other's). A process
    /// reporting zeros enforces none (rt-core's prescription is optional) and is not
    /// compared; one not reported yet is not known to differ.
    fn prescription_mismatches(&self) -> Vec<Unready> {
        let reported: Vec<(Process, [u8; 6])> = [
            (Process::RtCore, TimingSource::RtCore),
            (Process::StimDriver, TimingSource::StimDriver),
        ]
        .into_iter()
        .filter(|(p, _)| self.settings.watched(*p))
        .filter_map(|(p, s)| self.timing.get(&(s as u8)).map(|r| (p, r.prescription)))
        .filter(|(_, f)| *f != [0; 6])
        .collect();
        let Some(expected) = self
            .prescription
            .or_else(|| reported.first().map(|(_, f)| *f))
        else {
            return Vec::new();
        };
        reported
            .into_iter()
            .filter(|(_, f)| *f != expected)
            .map(|(process, f)| Unready::Prescription {
                process,
                found: fes_prescription::fingerprint_hex(&f),
                expected: fes_prescription::fingerprint_hex(&expected),
            })
            .collect()
    }

    /// The settings.
    pub fn settings(&self) -> &HealthSettings {
        &self.settings
    }

    /// The pid of `p`, when known (its iceoryx2 node; the stimulator's from the settings).
    fn pid_of(&self, p: Process) -> Option<u32> {
        match p {
            Process::SimMuscle => self.settings.stimulator_pid,
            _ => self.watch[p.index()].node.as_ref().map(|n| n.pid),
        }
    }

    fn raise(&mut self, p: Process, severity: Severity, cause: Cause, message: String) {
        let pid = self.pid_of(p);
        if severity == Severity::Fault {
            let w = &mut self.watch[p.index()];
            if w.condition == Condition::Faulted {
                return;
            }
            w.condition = Condition::Faulted;
            w.reason = message.clone();
            w.cause = Some(cause);
            w.last_at_fault = w.last_ns;
        }
        self.events.push(HealthEvent {
            process: p,
            severity,
            cause,
            pid,
            message,
        });
    }

    fn heard(&mut self, p: Process, now_ns: u64) {
        let w = &mut self.watch[p.index()];
        w.last_ns = Some(now_ns);
        if w.condition == Condition::Waiting {
            w.condition = Condition::Ok;
        }
    }

    /// Takes the events raised since the last call.
    pub fn take_events(&mut self) -> Vec<HealthEvent> {
        std::mem::take(&mut self.events)
    }

    /// A StimTick received at `now_ns`.
    pub fn on_stim_tick(&mut self, tick: &StimTick, now_ns: u64) {
        if let Err(e) = tick.validate() {
            self.raise(
                Process::RtCore,
                Severity::Fault,
                Cause::InvalidMessage,
                format!("rt-core sent an invalid StimTick (seq {}): {e}", tick.seq),
            );
            return;
        }
        self.heard(Process::RtCore, now_ns);
        self.ticks.on_tick(tick.t_ns);
        if self.last_tick_seq != 0 && tick.seq > self.last_tick_seq + 1 {
            let lost = tick.seq - self.last_tick_seq - 1;
            self.raise(
                Process::RtCore,
                Severity::Warning,
                Cause::LostMessages,
                format!(
                    "supervisor lost {lost} StimTick(s) before seq {} (slow receiver)",
                    tick.seq
                ),
            );
        }
        self.last_tick_seq = tick.seq;
        if tick.has(StimTick::FLAG_SOURCE_FAULT) {
            self.raise(
                Process::RtCore,
                Severity::Fault,
                Cause::NonFinite,
                format!(
                    "rt-core: the pattern generator produced a non-finite value (tick {})",
                    tick.seq
                ),
            );
        }
        if tick.has(StimTick::FLAG_FINAL) {
            self.watch[Process::RtCore.index()].finished = true;
            self.raise(
                Process::RtCore,
                Severity::Fault,
                Cause::Finished,
                format!("rt-core stopped: final tick {} received", tick.seq),
            );
        }
        self.on_reference_flags(tick);
        if tick.has(StimTick::FLAG_DEGRADED) && !self.warned_degraded {
            self.warned_degraded = true;
            self.raise(
                Process::RtCore,
                Severity::Warning,
                Cause::BestEffort,
                "rt-core runs best-effort (no real-time guarantee)".into(),
            );
        }
    }

    /// rt-core's verdict on the supervisor's References: a rejected one (the supervisor
    /// published what rt-core would not take) or a stale one (they stopped reaching it) is
    /// a fault, raised when the flag appears.
    fn on_reference_flags(&mut self, tick: &StimTick) {
        let flags =
            tick.flags & (StimTick::FLAG_REFERENCE_REJECTED | StimTick::FLAG_STALE_REFERENCE);
        let new = flags & !self.last_reference_flags;
        self.last_reference_flags = flags;
        if new & StimTick::FLAG_REFERENCE_REJECTED != 0 {
            self.raise(
                Process::RtCore,
                Severity::Fault,
                Cause::ReferenceRejected,
                format!(
                    "rt-core rejected a Reference of the supervisor (tick {}, reference seq {})",
                    tick.seq, tick.ref_seq
                ),
            );
        }
        if new & StimTick::FLAG_STALE_REFERENCE != 0 {
            self.raise(
                Process::RtCore,
                Severity::Fault,
                Cause::ReferenceStale,
                format!(
                    "rt-core: the supervisor's reference went stale (tick {}): References are not reaching it",
                    tick.seq
                ),
            );
        }
    }

    /// A ForceSample received at `now_ns`.
    pub fn on_force_sample(&mut self, sample: &ForceSample, now_ns: u64) {
        if let Err(e) = sample.validate() {
            self.raise(
                Process::StimDriver,
                Severity::Fault,
                Cause::InvalidMessage,
                format!(
                    "stim-driver forwarded an invalid ForceSample (seq {}): {e}",
                    sample.seq
                ),
            );
            return;
        }
        self.heard(Process::SimMuscle, now_ns);
    }

    /// A DriverStatus received at `now_ns`.
    pub fn on_driver_status(&mut self, s: &DriverStatus, now_ns: u64) {
        if let Err(e) = s.validate() {
            self.raise(
                Process::StimDriver,
                Severity::Fault,
                Cause::InvalidMessage,
                format!(
                    "stim-driver sent an invalid DriverStatus (seq {}): {e}",
                    s.seq
                ),
            );
            return;
        }
        self.heard(Process::StimDriver, now_ns);
        let prev = self.driver.replace(*s);
        if s.watchdog_trips > prev.map_or(0, |p| p.watchdog_trips) {
            self.blame_watchdog_trip(s, prev);
        }
        self.on_device_faults(s, prev.map_or(0, |p| p.fault_code));
        self.on_driver_counters(s, prev);
    }

    /// The driver's watchdog tripped between `prev` and `s`: a fault of the process it
    /// lost (rt-core or the stimulator), else of the driver.
    fn blame_watchdog_trip(&mut self, s: &DriverStatus, prev: Option<DriverStatus>) {
        // The driver's StimTick watchdog (no tick in time, a tick too old) fires when
        // rt-core stops: blame rt-core when it had gone quiet itself between the driver's
        // previous status and this one, judged by the ticks' and the statuses' own
        // CLOCK_MONOTONIC stamps (not by when this loop read them).
        let since_ns = prev.map_or(0, |p| p.t_ns);
        let rt_silence = self
            .ticks
            .silence_within(since_ns, s.t_ns)
            .filter(|_| self.settings.watch_rt_core && DriverStatus::is_tick_loss(s.fault_code));
        if let Some(silence_ns) = rt_silence {
            let age = ms(silence_ns);
            self.raise(
                Process::RtCore,
                Severity::Fault,
                Cause::WatchdogTripped,
                format!("rt-core: no StimTick for {age:.0} ms (stim-driver's watchdog tripped)"),
            );
        } else if DriverStatus::is_stimulator_loss(s.fault_code) && self.settings.watch_stimulator {
            // The driver lost the stimulator: the stimulator is the cause.
            self.raise(
                Process::SimMuscle,
                Severity::Fault,
                Cause::WatchdogTripped,
                format!(
                    "sim-muscle (stimulator): {} (stim-driver's watchdog tripped)",
                    emcy_name(s.fault_code)
                ),
            );
        } else {
            self.raise(
                Process::StimDriver,
                Severity::Fault,
                Cause::WatchdogTripped,
                format!(
                    "stim-driver: watchdog tripped: {} ({} in all)",
                    emcy_name(s.fault_code),
                    s.watchdog_trips
                ),
            );
        }
    }

    /// The fault code and the device states of `s` (`prev_code`: the previous status's
    /// fault code): a new EMCY, the stimulator or the driver in FAULT.
    fn on_device_faults(&mut self, s: &DriverStatus, prev_code: u16) {
        // A safe state the supervisor itself ordered (SafeStop) is the answer to a fault
        // already raised, not a new one.
        let ordered_stop = s.fault_code == DriverStatus::FAULT_CODE_SAFE_STOP_ORDERED;
        if s.fault_code != 0 && s.fault_code != prev_code && !ordered_stop {
            let severity = if s.state() == Ok(DeviceState::Fault)
                || s.stimulator_state() == Ok(DeviceState::Fault)
            {
                Severity::Fault
            } else {
                Severity::Warning
            };
            let who = if s.stimulator_state() == Ok(DeviceState::Fault) {
                Process::SimMuscle
            } else {
                Process::StimDriver
            };
            self.raise(
                who,
                severity,
                Cause::Emcy { code: s.fault_code },
                format!("{}: EMCY {}", who.name(), emcy_name(s.fault_code)),
            );
        }
        if s.stimulator_state() == Ok(DeviceState::Fault) {
            self.raise(
                Process::SimMuscle,
                Severity::Fault,
                Cause::DeviceFault { code: s.fault_code },
                format!(
                    "sim-muscle (stimulator) in FAULT, last EMCY {}",
                    emcy_name(s.fault_code)
                ),
            );
        }
        if s.state() == Ok(DeviceState::Fault) && !ordered_stop {
            self.raise(
                Process::StimDriver,
                Severity::Fault,
                Cause::DeviceFault { code: s.fault_code },
                format!(
                    "stim-driver in FAULT (fault code {})",
                    emcy_name(s.fault_code)
                ),
            );
        }
    }

    /// The driver's counters since `prev`: pulses it refused, CAN transmit errors
    /// (warnings).
    fn on_driver_counters(&mut self, s: &DriverStatus, prev: Option<DriverStatus>) {
        let prev_rejected = prev.map_or(0, |p| p.pulses_rejected);
        let prev_tx = prev.map_or(0, |p| p.can_tx_errors);
        if s.pulses_rejected > prev_rejected {
            self.raise(
                Process::StimDriver,
                Severity::Warning,
                Cause::PulsesRejected,
                format!(
                    "stim-driver: {} pulse(s) rejected ({} in all)",
                    s.pulses_rejected - prev_rejected,
                    s.pulses_rejected
                ),
            );
        }
        if s.can_tx_errors > prev_tx {
            self.raise(
                Process::StimDriver,
                Severity::Warning,
                Cause::TransmitErrors,
                format!(
                    "stim-driver: {} CAN transmit error(s)",
                    s.can_tx_errors - prev_tx
                ),
            );
        }
    }

    /// A TimingReport received.
    pub fn on_timing(&mut self, r: &TimingReport) {
        if r.validate().is_err() {
            return;
        }
        let prev = self.timing.insert(r.source, *r);
        let name = match r.source() {
            Ok(TimingSource::RtCore) => "rt-core",
            Ok(TimingSource::StimDriver) => "stim-driver",
            Ok(TimingSource::SimMuscle) => "sim-muscle",
            _ => return,
        };
        let p = match r.source() {
            Ok(TimingSource::StimDriver) => Process::StimDriver,
            Ok(TimingSource::SimMuscle) => Process::SimMuscle,
            _ => Process::RtCore,
        };
        let prev_alloc = prev.map_or(0, |p| p.hot_path_allocations);
        if r.hot_path_allocations > prev_alloc {
            self.raise(
                p,
                Severity::Warning,
                Cause::HeapAllocation,
                format!(
                    "{name}: {} heap allocation(s) on the hot path",
                    r.hot_path_allocations - prev_alloc
                ),
            );
        }
    }

    /// The latest TimingReport of each source.
    pub fn timing_reports(&self) -> impl Iterator<Item = &TimingReport> {
        self.timing.values()
    }

    /// The latest DriverStatus.
    pub fn driver_status(&self) -> Option<&DriverStatus> {
        self.driver.as_ref()
    }

    /// A node listing taken at `now_ns`.
    pub fn on_nodes(&mut self, nodes: &[NodeObservation], owners: &ServiceOwners) {
        for p in [Process::RtCore, Process::StimDriver] {
            let ids = match p {
                Process::RtCore => &owners.stim_tick,
                _ => &owners.driver_status,
            };
            let w = &mut self.watch[p.index()];
            match &w.node {
                None => {
                    // Adopt the live node that publishes our service (by its id: other
                    // stacks on this machine have nodes of the same names).
                    if let Some(n) = nodes
                        .iter()
                        .filter(|n| !n.dead && ids.contains(&n.id))
                        .max_by_key(|n| n.pid)
                    {
                        w.node = Some(n.clone());
                        w.node_gone = false;
                    }
                }
                Some(known) => match nodes.iter().find(|n| n.id == known.id) {
                    Some(n) if !n.dead => w.node = Some(n.clone()),
                    found => {
                        // Our process is dead or gone: a live node that now publishes
                        // our service is its restart (systemd's); adopt it, so that a
                        // re-arm can clear the fault once it is heard from.
                        let successor = nodes
                            .iter()
                            .filter(|n| !n.dead && n.id != known.id && ids.contains(&n.id))
                            .max_by_key(|n| n.pid);
                        match (successor, found) {
                            (Some(n), _) => {
                                w.node = Some(n.clone());
                                w.node_gone = false;
                            }
                            (None, Some(n)) => w.node = Some(n.clone()),
                            (None, None) => w.node_gone = true,
                        }
                    }
                },
            }
        }
    }

    /// Checks freshness at `now_ns`, asking `probe` about process ids.
    pub fn check(&mut self, now_ns: u64, probe: &dyn Fn(u32) -> ProcState) {
        for p in Process::ALL {
            if self.settings.watched(p) {
                self.check_process(p, now_ns, probe);
            }
        }
    }

    /// Checks the freshness of `p` at `now_ns`: a process that is silent beyond its
    /// timeout, or dead, is a fault (of its upstream process when that explains it).
    fn check_process(&mut self, p: Process, now_ns: u64, probe: &dyn Fn(u32) -> ProcState) {
        let w = &self.watch[p.index()];
        if w.condition != Condition::Ok {
            return;
        }
        let Some(last) = w.last_ns else { return };
        let age = now_ns.saturating_sub(last);
        let limit = self.settings.timeout_ns(p);
        // The process's own state, when we know its pid.
        let pid = self.pid_of(p);
        let pstate = pid.map(probe);
        let dead_now = matches!(pstate, Some(ProcState::Gone | ProcState::Zombie))
            || w.node.as_ref().is_some_and(|n| n.dead);
        if age <= limit && !dead_now {
            return;
        }
        let ended = w.node_gone || w.finished;
        // Upstream causes first: the force reaches us through the driver, so a silent
        // stimulator behind a dead, stopped or faulted driver is the driver's fault.
        if p == Process::SimMuscle
            && !dead_now
            && self.settings.watch_stim_driver
            && self.blame_driver_for_silence(age, probe)
        {
            return;
        }
        let silence = Silence {
            process: p,
            pid,
            pstate,
            dead_now,
            ended,
            age,
            limit,
        };
        let (cause, message) = silence.verdict();
        if dead_now {
            self.watch[p.index()].died_pid = pid;
        }
        self.raise(p, Severity::Fault, cause, message);
    }

    /// The stimulator has been silent for `age`: when the driver, through which its force
    /// reaches us, is dead or stopped, that is the driver's fault, raised here. True when
    /// the driver accounts for the silence (its fault raised now or before).
    fn blame_driver_for_silence(&mut self, age: u64, probe: &dyn Fn(u32) -> ProcState) -> bool {
        let drv = &self.watch[Process::StimDriver.index()];
        if drv.condition == Condition::Faulted {
            return true;
        }
        let drv_pid = drv.node.as_ref().map(|n| n.pid);
        let drv_dead = drv.node.as_ref().is_some_and(|n| n.dead);
        let drv_state = drv_pid.map(probe);
        let pid_txt = drv_pid.map_or(String::new(), |pid| format!(" (pid {pid})"));
        let reason = match drv_state {
            Some(ProcState::Gone | ProcState::Zombie) => {
                Some((Cause::Died, "died: the process is gone"))
            }
            _ if drv_dead => Some((Cause::Died, "died: its iceoryx2 node is dead")),
            Some(ProcState::Stopped) => Some((Cause::Stalled, "stalled: stopped by a signal")),
            _ => None,
        };
        let Some((cause, reason)) = reason else {
            return false;
        };
        if cause == Cause::Died {
            self.watch[Process::StimDriver.index()].died_pid = drv_pid;
        }
        let message = format!(
            "stim-driver{pid_txt} {reason}; no force sample forwarded for {:.0} ms",
            ms(age)
        );
        self.raise(Process::StimDriver, Severity::Fault, cause, message);
        true
    }

    /// Whether stimulation may be armed: every watched process heard from and not
    /// faulted. The error lists what is missing.
    pub fn ready(&self) -> Result<(), NotReady> {
        let mut problems = Vec::new();
        for process in Process::ALL {
            if !self.settings.watched(process) {
                continue;
            }
            let w = &self.watch[process.index()];
            match w.condition {
                Condition::Waiting => problems.push(Unready::Waiting { process }),
                Condition::Faulted => problems.push(Unready::Faulted {
                    process,
                    reason: w.reason.clone(),
                }),
                Condition::Ok => {}
            }
        }
        problems.extend(self.prescription_mismatches());
        if problems.is_empty() {
            Ok(())
        } else {
            Err(NotReady { problems })
        }
    }

    /// Clears the fault latches of processes that are live again: heard from after the
    /// fault was raised, recently (within their timeout at `now_ns`), not seen dead, not
    /// found gone by `probe` now, and not the very process that was seen to die; called on
    /// an operator re-arm. (A message from before the fault, however recent, says nothing
    /// about a process that died after sending it; nor does a frame it sent before its
    /// death that the driver forwarded after it.)
    pub fn clear_recovered(&mut self, now_ns: u64, probe: &dyn Fn(u32) -> ProcState) {
        for p in Process::ALL {
            let limit = self.settings.timeout_ns(p);
            let pid = match p {
                Process::SimMuscle => self.settings.stimulator_pid,
                _ => self.watch[p.index()].node.as_ref().map(|n| n.pid),
            };
            let w = &mut self.watch[p.index()];
            let heard_since = w.last_ns > w.last_at_fault;
            let fresh = w.last_ns.is_some_and(|t| now_ns.saturating_sub(t) <= limit);
            let dead = w.node.as_ref().is_some_and(|n| n.dead)
                || (pid.is_some() && pid == w.died_pid)
                || pid.is_some_and(|pid| matches!(probe(pid), ProcState::Gone | ProcState::Zombie));
            if w.condition == Condition::Faulted && heard_since && fresh && !dead && !w.finished {
                w.condition = Condition::Ok;
                w.reason.clear();
                w.cause = None;
            }
        }
    }

    /// Per-process status at `now_ns`.
    pub fn statuses(&self, now_ns: u64) -> Vec<ProcessStatus> {
        Process::ALL
            .iter()
            .filter(|p| self.settings.watched(**p))
            .map(|&p| {
                let w = &self.watch[p.index()];
                let state = match (w.condition, w.cause) {
                    (Condition::Waiting, _) => ProcessState::Waiting,
                    (Condition::Ok, _) => ProcessState::Ok,
                    (Condition::Faulted, Some(Cause::Died)) => ProcessState::Dead,
                    (Condition::Faulted, Some(Cause::Stalled)) => ProcessState::Stalled,
                    (Condition::Faulted, Some(Cause::Exited)) => ProcessState::Exited,
                    (Condition::Faulted, _) => ProcessState::Fault,
                };
                ProcessStatus {
                    name: p.name().into(),
                    state,
                    pid: match p {
                        Process::SimMuscle => self.settings.stimulator_pid,
                        _ => w.node.as_ref().map(|n| n.pid),
                    },
                    last_message_age_ms: w.last_ns.map(|t| ms(now_ns.saturating_sub(t))),
                    detail: w.reason.clone(),
                }
            })
            .collect()
    }

    /// Driver and stimulator states, as words.
    pub fn device_states(&self) -> (Option<String>, Option<String>) {
        match &self.driver {
            Some(s) => (
                Some(state_name(s.state())),
                Some(state_name(s.stimulator_state())),
            ),
            None => (None, None),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn tick(seq: u64, t: u64) -> StimTick {
        StimTick::quiet(seq, t)
    }

    fn status(seq: u64) -> DriverStatus {
        DriverStatus {
            seq,
            t_ns: 1,
            ticks_received: 10,
            ticks_lost: 0,
            pulses_sent: 0,
            pulses_rejected: 0,
            can_tx_errors: 0,
            watchdog_trips: 0,
            fault_code: 0,
            state: DeviceState::Armed as u8,
            stimulator_state: DeviceState::Armed as u8,
            command_seq: 0,
            command_result: 0,
            command_reason: 0,
            reserved: [0; 6],
        }
    }

    fn force(seq: u64) -> ForceSample {
        ForceSample {
            seq,
            t_ns: 1,
            stim_seq: 0,
            force_n: 1.0,
            force: 0.01,
        }
    }

    fn running(_: u32) -> ProcState {
        ProcState::Running
    }

    /// A probe that finds process `pid` in `state` and every other one running.
    fn only(pid: u32, state: ProcState) -> impl Fn(u32) -> ProcState {
        move |p| if p == pid { state } else { ProcState::Running }
    }

    fn live(h: &mut HealthMonitor, t: u64) {
        h.on_stim_tick(&tick(t / MS + 1, t), t);
        h.on_driver_status(&status(t / MS + 1), t);
        h.on_force_sample(&force(t / MS + 1), t);
    }

    fn owners() -> ServiceOwners {
        ServiceOwners {
            stim_tick: vec![1],
            driver_status: vec![2],
        }
    }

    fn nodes() -> Vec<NodeObservation> {
        vec![
            NodeObservation {
                name: "rt-core".into(),
                pid: 100,
                id: 1,
                dead: false,
            },
            NodeObservation {
                name: "stim-driver".into(),
                pid: 200,
                id: 2,
                dead: false,
            },
        ]
    }

    #[test]
    fn waiting_until_heard_then_ok() {
        let mut h = HealthMonitor::new(HealthSettings::default());
        let e = h.ready().unwrap_err().to_string();
        assert!(e.contains("rt-core: not heard from yet"), "{e}");
        live(&mut h, 10 * MS);
        h.check(20 * MS, &running);
        assert!(h.ready().is_ok());
        assert!(h.take_events().is_empty());
    }

    /// One prescription across the stack: with rt-core's or stim-driver's TimingReport
    /// naming another prescription than the supervisor's, the arm is refused, naming the
    /// process and both fingerprints; once it reports the same one (restarted), it is not.
    /// A process that reports none (zeros) is not compared. Without a prescription of its
    /// own the supervisor compares the two processes with each other.
    #[test]
    fn a_process_enforcing_another_prescription_keeps_the_stack_from_arming() {
        use fes_rt::msg::LatencySummary;
        let report = |source: TimingSource, seq: u64, prescription: [u8; 6]| TimingReport {
            seq,
            t_ns: seq,
            ticks: 0,
            misses: 0,
            overruns: 0,
            queue_overflows: 0,
            hot_path_allocations: 0,
            rejected_inputs: 0,
            wake: LatencySummary::default(),
            input: LatencySummary::default(),
            compute: LatencySummary::default(),
            publish: LatencySummary::default(),
            ipc: LatencySummary::default(),
            source: source as u8,
            flags: 0,
            prescription,
        };
        let ours = [0xd6, 0x87, 0x38, 0xd6, 0x82, 0xb2];
        let old = [0x11, 0x22, 0x33, 0x44, 0x55, 0x66];
        let mut h = HealthMonitor::new(HealthSettings::default());
        h.set_prescription(ours);
        live(&mut h, 10 * MS);
        h.check(20 * MS, &running);
        assert!(h.ready().is_ok());
        h.on_timing(&report(TimingSource::StimDriver, 1, old));
        let e = h.ready().unwrap_err();
        assert!(
            matches!(
                e.problems.as_slice(),
                [Unready::Prescription { process: Process::StimDriver, found, expected }]
                    if found == "112233445566" && expected == "d68738d682b2"
            ),
            "{e:?}"
        );
        assert!(e.to_string().contains("restart every process"), "{e}");
        h.on_timing(&report(TimingSource::StimDriver, 2, ours));
        h.on_timing(&report(TimingSource::RtCore, 1, [0; 6]));
        assert!(h.ready().is_ok(), "{:?}", h.ready());
        // No prescription of the supervisor's: the two processes against each other.
        let mut h = HealthMonitor::new(HealthSettings::default());
        live(&mut h, 10 * MS);
        h.check(20 * MS, &running);
        h.on_timing(&report(TimingSource::RtCore, 1, ours));
        h.on_timing(&report(TimingSource::StimDriver, 1, old));
        assert!(h.ready().is_err());
        h.on_timing(&report(TimingSource::StimDriver, 2, ours));
        assert!(h.ready().is_ok());
    }

    /// rt-core's verdict on the References: a rejected one and a stale one are faults of
    /// rt-core, each raised once when its flag appears (not on every flagged tick), again
    /// after the flag cleared and came back.
    #[test]
    fn rejected_and_stale_references_are_faults_when_they_appear() {
        let flagged = |seq: u64, flags: u16| {
            let mut t = tick(seq, seq * MS);
            t.flags |= flags;
            t
        };
        for (flag, cause, words) in [
            (
                StimTick::FLAG_REFERENCE_REJECTED,
                Cause::ReferenceRejected,
                "rejected a Reference",
            ),
            (
                StimTick::FLAG_STALE_REFERENCE,
                Cause::ReferenceStale,
                "reference went stale",
            ),
        ] {
            let mut h = HealthMonitor::new(HealthSettings::default());
            h.on_stim_tick(&tick(1, MS), MS);
            assert!(h.take_events().is_empty());
            h.on_stim_tick(&flagged(2, flag), 2 * MS);
            h.on_stim_tick(&flagged(3, flag), 3 * MS);
            let ev = h.take_events();
            assert_eq!(ev.len(), 1, "{ev:?}");
            assert_eq!(
                (ev[0].process, ev[0].severity, ev[0].cause),
                (Process::RtCore, Severity::Fault, cause)
            );
            assert!(ev[0].message.contains(words), "{}", ev[0].message);
            assert!(h.ready().is_err());
        }
        assert!(Cause::ReferenceStale.is_timing() && !Cause::ReferenceRejected.is_timing());
    }

    /// A killed rt-core: its pid is gone; the message says who and why.
    #[test]
    fn dead_process_is_named_with_its_pid() {
        let mut h = HealthMonitor::new(HealthSettings::default());
        h.on_nodes(&nodes(), &owners());
        live(&mut h, 10 * MS);
        let probe = only(100, ProcState::Gone);
        h.on_driver_status(&status(50), 30 * MS);
        h.on_force_sample(&force(50), 30 * MS);
        h.check(30 * MS, &probe);
        let ev = h.take_events();
        assert_eq!(ev.len(), 1, "{ev:?}");
        assert_eq!(ev[0].process, Process::RtCore);
        assert_eq!(ev[0].severity, Severity::Fault);
        assert!(
            ev[0].message.starts_with("rt-core (pid 100) died"),
            "{}",
            ev[0].message
        );
        assert_eq!(h.statuses(30 * MS)[0].state, ProcessState::Dead);
        assert!(h.ready().is_err());
    }

    /// A SIGSTOPped driver is stalled, not dead; the silent stimulator behind it is not
    /// blamed.
    #[test]
    fn stopped_driver_is_stalled_and_blamed_first() {
        let mut h = HealthMonitor::new(HealthSettings::default());
        h.on_nodes(&nodes(), &owners());
        live(&mut h, 10 * MS);
        let probe = only(200, ProcState::Stopped);
        for t in (11..700).map(|k| k * MS) {
            h.on_stim_tick(&tick(t / MS + 1, t), t);
            h.check(t, &probe);
        }
        let ev = h.take_events();
        assert_eq!(ev.len(), 1, "{ev:?}");
        assert!(
            ev[0].message.starts_with("stim-driver (pid 200) stalled: stopped by a signal; no force sample forwarded for 101 ms"),
            "{}",
            ev[0].message
        );
    }

    /// The stimulator silent while the driver reports: the stimulator is named.
    #[test]
    fn silent_stimulator_is_named() {
        let mut h = HealthMonitor::new(HealthSettings::default());
        h.on_nodes(&nodes(), &owners());
        live(&mut h, 10 * MS);
        for t in (11..200).map(|k| k * MS) {
            h.on_stim_tick(&tick(t / MS + 1, t), t);
            if t % (10 * MS) == 0 {
                h.on_driver_status(&status(t / MS), t);
            }
            h.check(t, &running);
        }
        let ev = h.take_events();
        assert_eq!(ev.len(), 1, "{ev:?}");
        assert!(
            ev[0].message.starts_with("sim-muscle (stimulator) silent"),
            "{}",
            ev[0].message
        );
    }

    /// The driver's watchdog trip after rt-core went quiet is rt-core's fault; an EMCY of
    /// a faulted stimulator is the stimulator's.
    #[test]
    fn reported_faults_are_attributed() {
        let mut h = HealthMonitor::new(HealthSettings::default());
        live(&mut h, 10 * MS);
        let mut s = status(99);
        s.t_ns = 40 * MS;
        s.watchdog_trips = 1;
        s.fault_code = DriverStatus::FAULT_TICK_TIMEOUT;
        s.state = DeviceState::Fault as u8;
        h.on_driver_status(&s, 40 * MS);
        let ev = h.take_events();
        assert_eq!(ev[0].process, Process::RtCore, "{ev:?}");
        assert!(
            ev[0].message.contains("no StimTick for 30 ms"),
            "{}",
            ev[0].message
        );

        let mut h = HealthMonitor::new(HealthSettings::default());
        live(&mut h, 10 * MS);
        let mut s = status(99);
        s.fault_code = 0x8130;
        s.stimulator_state = DeviceState::Fault as u8;
        h.on_driver_status(&s, 11 * MS);
        let ev = h.take_events();
        assert_eq!(ev[0].process, Process::SimMuscle);
        assert_eq!(ev[0].message, "sim-muscle: EMCY 0x8130 heartbeat_lost");
        assert_eq!(ev[0].severity, Severity::Fault);
    }

    /// The supervisor's own loop late (CI: a 2-core host under load): the ticks from
    /// before rt-core's silence, the ticks after it and the driver's trip are all read in
    /// one pass at the same receive time. Judged by the messages' own stamps, rt-core is
    /// still the one that went quiet; a driver that tripped while the ticks kept coming is
    /// blamed itself.
    #[test]
    fn a_watchdog_trip_is_blamed_by_the_messages_stamps_not_by_when_they_were_read() {
        let trip = |gap_ms: u64, code: u16| {
            let mut h = HealthMonitor::new(HealthSettings::default());
            live(&mut h, 10 * MS);
            let read_at = 600 * MS;
            // Ticks every 1 ms up to 100 ms, then (gap_ms later) on again to 600 ms.
            let resumed = 100 + gap_ms;
            for (seq, k) in (11..=100).chain(resumed..=600).enumerate() {
                h.on_stim_tick(&tick(seq as u64 + 12, k * MS), read_at);
            }
            let mut s = status(99);
            s.t_ns = 125 * MS;
            s.watchdog_trips = 1;
            s.fault_code = code;
            s.state = DeviceState::Fault as u8;
            h.on_driver_status(&s, read_at);
            h.take_events()
        };
        let ev = trip(480, DriverStatus::FAULT_STALE_TICK);
        assert_eq!(ev[0].process, Process::RtCore, "{ev:?}");
        assert_eq!(
            ev[0].message,
            "rt-core: no StimTick for 480 ms (stim-driver's watchdog tripped)"
        );
        // No silence of rt-core: the driver itself is the one that stalled.
        let ev = trip(1, DriverStatus::FAULT_STALE_TICK);
        assert_eq!(ev[0].process, Process::StimDriver, "{ev:?}");
        assert!(
            ev[0]
                .message
                .starts_with("stim-driver: watchdog tripped: 0xFF24"),
            "{}",
            ev[0].message
        );
        // A silent stimulator is the stimulator's fault, whatever rt-core did meanwhile
        // (a SIGSTOPped sim-muscle was blamed on a 20 ms hiccup of rt-core's ticks).
        let ev = trip(20, DriverStatus::FAULT_STIMULATOR_SILENT);
        assert_eq!(ev[0].process, Process::SimMuscle, "{ev:?}");
    }

    /// A stopped stimulator (after a disarm) and the safe state the supervisor ordered are
    /// not faults; a stimulator or driver fault still is.
    #[test]
    fn ordered_stops_are_not_faults() {
        let mut h = HealthMonitor::new(HealthSettings::default());
        live(&mut h, 10 * MS);
        let mut s = status(99);
        s.state = DeviceState::PreOperational as u8;
        s.stimulator_state = DeviceState::Stopped as u8;
        h.on_driver_status(&s, 11 * MS);
        assert!(h.take_events().is_empty());
        s.state = DeviceState::Fault as u8;
        s.fault_code = DriverStatus::FAULT_CODE_SAFE_STOP_ORDERED;
        h.on_driver_status(&s, 12 * MS);
        assert!(h.take_events().is_empty());
        s.fault_code = 0xFF21;
        h.on_driver_status(&s, 13 * MS);
        let ev = h.take_events();
        assert!(
            ev.iter()
                .any(|e| e.process == Process::StimDriver && e.severity == Severity::Fault),
            "{ev:?}"
        );
    }

    /// Re-arming clears only processes that are live again.
    #[test]
    fn recovered_processes_clear_on_rearm() {
        let mut h = HealthMonitor::new(HealthSettings::default());
        live(&mut h, 10 * MS);
        h.check(200 * MS, &running);
        assert!(h.ready().is_err());
        h.clear_recovered(200 * MS, &running);
        assert!(h.ready().is_err(), "still silent");
        live(&mut h, 300 * MS);
        h.clear_recovered(300 * MS, &running);
        assert!(h.ready().is_ok());
    }

    /// A process killed just after its last message: that message is still "fresh" when
    /// the operator re-arms a moment later, but it predates the fault; the fault stays.
    /// (Found by the kill test on the host bus: the supervisor re-armed with a dead driver.)
    #[test]
    fn a_fresh_message_from_before_the_fault_does_not_clear_it() {
        let mut h = HealthMonitor::new(HealthSettings::default());
        h.on_nodes(&nodes(), &owners());
        live(&mut h, 10 * MS);
        let driver_gone = only(200, ProcState::Gone);
        h.check(11 * MS, &driver_gone);
        assert!(h.ready().unwrap_err().to_string().contains("stim-driver"));
        h.clear_recovered(12 * MS, &running);
        assert!(
            h.ready().is_err(),
            "cleared by a message from before the death"
        );
        // rt-core and the stimulator keep talking; the driver stays faulted.
        h.on_stim_tick(&tick(20, 20 * MS), 20 * MS);
        h.clear_recovered(21 * MS, &running);
        assert!(h.ready().unwrap_err().to_string().contains("stim-driver"));
        // A node seen dead is not cleared even by a late message.
        let mut dead = nodes();
        dead[1].dead = true;
        h.on_nodes(&dead, &owners());
        h.on_driver_status(&status(30), 30 * MS);
        h.clear_recovered(31 * MS, &running);
        assert!(h.ready().is_err());
        // The same process (pid 200) is never cleared, even if it seemed to come back.
        h.on_nodes(&nodes(), &owners());
        h.on_driver_status(&status(35), 35 * MS);
        h.clear_recovered(36 * MS, &running);
        assert!(h.ready().is_err(), "the dead pid 200 cleared");
        // A restarted driver (a new, live node publishing our service) is adopted and,
        // once heard from, cleared by a re-arm.
        let mut restarted = dead.clone();
        restarted.push(NodeObservation {
            name: "stim-driver".into(),
            pid: 201,
            id: 3,
            dead: false,
        });
        let mut owners = owners();
        owners.driver_status.push(3);
        h.on_nodes(&restarted, &owners);
        h.on_driver_status(&status(40), 40 * MS);
        h.clear_recovered(41 * MS, &running);
        assert!(h.ready().is_ok(), "{:?}", h.ready());
        assert_eq!(h.statuses(41 * MS)[1].pid, Some(201));
    }

    /// The stimulator process killed just after a FORCE frame: the driver forwards that
    /// frame after the supervisor saw the process gone. It is no sign of life: a re-arm
    /// stays refused. (Found by the kill test on a loaded CI machine: "sim-muscle:
    /// re-armed with a dead process".)
    #[test]
    fn a_frame_forwarded_after_the_stimulators_death_does_not_clear_it() {
        let settings = HealthSettings {
            stimulator_pid: Some(300),
            ..HealthSettings::default()
        };
        let mut h = HealthMonitor::new(settings);
        h.on_nodes(&nodes(), &owners());
        live(&mut h, 10 * MS);
        h.check(11 * MS, &only(300, ProcState::Zombie));
        assert!(h.ready().unwrap_err().to_string().contains("sim-muscle"));
        // The frame sent before the death, forwarded a millisecond later.
        h.on_force_sample(&force(12), 12 * MS);
        h.clear_recovered(13 * MS, &only(300, ProcState::Zombie));
        assert!(h.ready().unwrap_err().to_string().contains("died"));
        // Reaped (gone), and even a probe that misses it (pid reused): still refused.
        h.on_force_sample(&force(14), 14 * MS);
        h.clear_recovered(15 * MS, &only(300, ProcState::Gone));
        assert!(h.ready().is_err());
        h.clear_recovered(16 * MS, &running);
        assert!(h.ready().is_err(), "the pid that died was cleared");
    }

    #[test]
    fn a_stalled_supervisor_is_its_own_fault() {
        let s = HealthSettings::default();
        assert_eq!(s.self_stall(500 * MS), None);
        let m = s.self_stall(1250 * MS).unwrap();
        assert!(m.starts_with("supervisor stalled: 1250 ms"), "{m}");
        let bad = HealthSettings {
            self_stall_ms: 5,
            ..HealthSettings::default()
        };
        assert_eq!(bad.validate().unwrap_err().key, "self_stall_ms");
    }

    /// The driver's watchdog tripping because the stimulator went silent names the
    /// stimulator, with the driver's code by name (found by the seeded SIGSTOP test).
    #[test]
    fn a_stimulator_loss_is_the_stimulators_fault() {
        let mut h = HealthMonitor::new(HealthSettings::default());
        live(&mut h, 10 * MS);
        let mut s = status(20);
        s.watchdog_trips = 1;
        s.fault_code = DriverStatus::FAULT_STIMULATOR_SILENT;
        s.state = DeviceState::Fault as u8;
        h.on_driver_status(&s, 11 * MS);
        let ev = h.take_events();
        assert_eq!(ev[0].process, Process::SimMuscle, "{ev:?}");
        assert_eq!(
            ev[0].message,
            "sim-muscle (stimulator): 0xFF28 stimulator_silent (stim-driver's watchdog tripped)"
        );
        assert_eq!(emcy_name(0xFF27), "0xFF27 bus_off");
        assert_eq!(emcy_name(0x8130), "0x8130 heartbeat_lost");
        assert_eq!(emcy_name(0xFFFF), "0xFFFF");
    }

    /// Another stack's processes have nodes of the same names: only the publishers of
    /// this stack's services are adopted, so a dead stranger is not taken for ours (found
    /// by a bench run next to the test suite, which kills its own stim-drivers).
    #[test]
    fn nodes_of_another_stack_are_not_adopted() {
        let mut h = HealthMonitor::new(HealthSettings::default());
        let mut all = nodes();
        all.push(NodeObservation {
            name: "stim-driver".into(),
            pid: 900,
            id: 9,
            dead: false,
        });
        h.on_nodes(&all, &owners());
        live(&mut h, 10 * MS);
        // The stranger (higher pid) dies: not our driver.
        all[2].dead = true;
        h.on_nodes(&all, &owners());
        h.check(11 * MS, &only(900, ProcState::Zombie));
        assert!(h.ready().is_ok(), "{:?}", h.ready());
        // Nothing is adopted before our service has a publisher.
        let mut fresh = HealthMonitor::new(HealthSettings::default());
        fresh.on_nodes(&all, &ServiceOwners::default());
        live(&mut fresh, 20 * MS);
        fresh.check(21 * MS, &running);
        assert!(fresh.statuses(21 * MS).iter().all(|s| s.pid.is_none()));
    }
}
