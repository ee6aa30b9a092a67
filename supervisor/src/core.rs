//! The supervisor's state machine: operator commands, the profile, the outer loop, and
//! the stop-on-fault rule, without I/O (time is passed in).
//!
//! ```text
//!             arm (health ready)                 any fault
//!  DISARMED ---------------------> ARMED ----------------------> FAULT
//!     ^  <------------------------   |  <---------------------    |
//!     |            stop              |   arm (cause gone)         |
//!     +------------------------------+----------------------------+ stop keeps FAULT
//! ```
//!
//! - DISARMED and FAULT publish `Reference { force: 0, FLAG_STOP }` (no pulse at all);
//!   ARMED publishes the profile's setpoint (0 until one is given).
//! - `set` and `profile` need ARMED; a refused command changes nothing.
//! - A fault stops stimulation at once (reference stop, driver safe stop) and is cleared
//!   only by an operator `arm`, which is refused while the cause persists.

use std::collections::VecDeque;

use fes_rt::msg::{DriverStatus, Reference};

use crate::contraction::{BeatMeasurement, ContractionEstimator, ContractionSettings};
use crate::health::{Cause, HealthEvent, NotReady, Process};
use crate::limits::{ReferenceLimits, Rejection};
use crate::outer_loop::{OuterLoop, OuterLoopSettings, OuterLoopUpdate};
use crate::profile::{Beat, ProfileEvent, ProfileRunner, ProfileSpec, Setpoint};
use crate::protocol::Command;

/// Arming state.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ArmState {
    /// No stimulation; the driver is disarmed.
    Disarmed,
    /// Stimulation follows the profile.
    Armed,
    /// Stopped by a fault; needs an operator `arm`.
    Fault(Fault),
}

/// Why stimulation stopped: the typed cause a program acts on, and the words an operator
/// reads (`supervisor status`, the log).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Fault {
    /// What stopped it.
    pub cause: FaultCause,
    /// The same in words, starting with the process or the subsystem.
    pub message: String,
}

/// The typed cause of a [`Fault`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case", tag = "source")]
pub enum FaultCause {
    /// A watched process: which, its pid when known, and what happened to it.
    Process {
        /// The process.
        process: Process,
        /// Its pid, when known.
        pid: Option<u32>,
        /// What happened.
        cause: Cause,
    },
    /// The recording failed: no recording means no evidence.
    Recording,
    /// The supervisor's own loop stalled while armed.
    SelfStall,
    /// The driver's answer to an order ([`crate::command_link`]).
    Driver {
        /// What was wrong with it.
        problem: DriverProblem,
    },
}

/// What was wrong with the driver's answer to an order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DriverProblem {
    /// It refused the Arm.
    ArmRefused,
    /// It did not acknowledge the Arm in time.
    Unacknowledged,
    /// It did not acknowledge a stop (Disarm or SafeStop) in time: whether it stopped
    /// forwarding pulses is unknown (the stop is still re-sent).
    StopUnacknowledged,
    /// Its state contradicts the order it confirmed.
    StateMismatch,
}

impl FaultCause {
    /// A trip judged against time (stall, silence, watchdog, the supervisor's own stall).
    pub fn is_timing(self) -> bool {
        match self {
            FaultCause::Process { cause, .. } => cause.is_timing(),
            FaultCause::SelfStall => true,
            FaultCause::Recording => false,
            // The acknowledgement travels through the driver's report thread.
            FaultCause::Driver { problem } => matches!(
                problem,
                DriverProblem::Unacknowledged | DriverProblem::StopUnacknowledged
            ),
        }
    }
}

impl Fault {
    /// A fault of `cause`, described by `message`.
    pub fn new(cause: FaultCause, message: impl Into<String>) -> Self {
        Self {
            cause,
            message: message.into(),
        }
    }

    /// The fault a health event raises.
    pub fn from_event(e: &HealthEvent) -> Self {
        Self::new(
            FaultCause::Process {
                process: e.process,
                pid: e.pid,
                cause: e.cause,
            },
            e.message.clone(),
        )
    }
}

impl std::fmt::Display for Fault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl ArmState {
    /// `disarmed`, `armed` or `fault`.
    pub fn name(&self) -> &'static str {
        match self {
            ArmState::Disarmed => "disarmed",
            ArmState::Armed => "armed",
            ArmState::Fault(_) => "fault",
        }
    }
}

/// Why a command that needs stimulation armed (`set`, `profile`) was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NotArmed {
    /// Disarmed: the operator has not armed, or stopped.
    #[error("not armed: run `supervisor arm` first")]
    Disarmed,
    /// Stopped by a fault, which only an operator `arm` clears.
    #[error(
        "stimulation stopped by a fault ({fault}); `supervisor arm` re-arms once the cause is gone"
    )]
    Fault {
        /// The fault in force.
        fault: Fault,
    },
}

/// Why an operator command was refused; it changed nothing. The words are the control
/// protocol's `error` and the event log's.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandError {
    /// The setpoint or the profile is invalid or outside the limits.
    #[error(transparent)]
    Rejected {
        /// What is wrong with it.
        #[from]
        source: Rejection,
    },
    /// `set` or `profile` while not armed.
    #[error(transparent)]
    NotArmed {
        /// Why not armed.
        #[from]
        source: NotArmed,
    },
    /// `arm` while the health monitor says a process is not ready.
    #[error("cannot arm: {source}")]
    CannotArm {
        /// What is not ready.
        #[from]
        source: NotReady,
    },
}

/// An order for the stimulator driver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DriverOrder {
    /// Start forwarding pulses.
    Arm,
    /// Stop forwarding pulses (operator stop).
    Disarm,
    /// Emergency stop into the driver's safe state (fault).
    SafeStop,
}

/// A completed beat with the outer loop's reaction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeatRecord {
    /// What was measured.
    pub measurement: BeatMeasurement,
    /// What the outer loop did with it.
    pub update: OuterLoopUpdate,
}

/// The supervisor's state.
#[derive(Debug, Clone)]
pub struct SupervisorCore {
    limits: ReferenceLimits,
    state: ArmState,
    profile: Option<ProfileRunner>,
    outer: OuterLoop,
    contraction: ContractionEstimator,
    contraction_settings: ContractionSettings,
    last_contraction: Option<f64>,
    latest_force_ns: u64,
    /// The last driver status's time and refused-pulse count.
    driver_refusals: Option<(u64, u64)>,
    seq: u64,
    last: Option<Reference>,
    orders: Vec<DriverOrder>,
    beats: Vec<BeatRecord>,
    beat_starts: Vec<Beat>,
    events: VecDeque<String>,
    new_events: Vec<String>,
}

/// Events kept for `status`.
pub const EVENT_HISTORY: usize = 20;

impl SupervisorCore {
    /// Disarmed, no profile.
    pub fn new(
        limits: ReferenceLimits,
        outer: OuterLoopSettings,
        contraction: ContractionSettings,
    ) -> Self {
        Self {
            limits,
            state: ArmState::Disarmed,
            profile: None,
            outer: OuterLoop::new(outer),
            contraction: ContractionEstimator::new(contraction),
            contraction_settings: contraction,
            last_contraction: None,
            latest_force_ns: 0,
            driver_refusals: None,
            seq: 0,
            last: None,
            orders: Vec::new(),
            beats: Vec::new(),
            beat_starts: Vec::new(),
            events: VecDeque::new(),
            new_events: Vec::new(),
        }
    }

    /// The limits in force.
    pub fn limits(&self) -> &ReferenceLimits {
        &self.limits
    }

    /// The arming state.
    pub fn state(&self) -> &ArmState {
        &self.state
    }

    /// The running profile.
    pub fn profile(&self) -> Option<&ProfileRunner> {
        self.profile.as_ref()
    }

    /// The outer loop.
    pub fn outer_loop(&self) -> &OuterLoop {
        &self.outer
    }

    /// The last measured contraction (plateau mean).
    pub fn last_contraction(&self) -> Option<f64> {
        self.last_contraction
    }

    /// The last reference returned by [`SupervisorCore::reference`].
    pub fn last_reference(&self) -> Option<&Reference> {
        self.last.as_ref()
    }

    /// Records an event (kept for status, and handed to the recorder).
    pub fn note(&mut self, text: String) {
        if self.events.len() == EVENT_HISTORY {
            self.events.pop_front();
        }
        self.events.push_back(text.clone());
        self.new_events.push(text);
    }

    /// Recent events, oldest first.
    pub fn events(&self) -> impl Iterator<Item = &String> {
        self.events.iter()
    }

    /// Takes the events noted since the last call.
    pub fn take_new_events(&mut self) -> Vec<String> {
        std::mem::take(&mut self.new_events)
    }

    /// Takes the driver orders issued since the last call.
    pub fn take_orders(&mut self) -> Vec<DriverOrder> {
        std::mem::take(&mut self.orders)
    }

    /// Takes the beats completed since the last call.
    pub fn take_beats(&mut self) -> Vec<BeatRecord> {
        std::mem::take(&mut self.beats)
    }

    /// Takes the beats started since the last call.
    pub fn take_beat_starts(&mut self) -> Vec<Beat> {
        std::mem::take(&mut self.beat_starts)
    }

    /// Carries out an operator command at `now_ns`. `ready` is the health monitor's verdict
    /// (needed to arm). Returns what was done, or why nothing was done.
    pub fn command(
        &mut self,
        command: &Command,
        now_ns: u64,
        ready: Result<(), NotReady>,
    ) -> Result<String, CommandError> {
        let result = self.apply(command, now_ns, ready);
        if matches!(command, Command::Status) {
            return result;
        }
        match &result {
            Ok(m) => self.note(format!("command {}: {m}", command.name())),
            Err(e) => self.note(format!("command {} refused: {e}", command.name())),
        }
        result
    }

    fn require_armed(&self) -> Result<(), NotArmed> {
        match &self.state {
            ArmState::Armed => Ok(()),
            ArmState::Disarmed => Err(NotArmed::Disarmed),
            ArmState::Fault(f) => Err(NotArmed::Fault { fault: f.clone() }),
        }
    }

    fn apply(
        &mut self,
        command: &Command,
        now_ns: u64,
        ready: Result<(), NotReady>,
    ) -> Result<String, CommandError> {
        match command {
            Command::Status => Ok("status".into()),
            Command::Set { force, rate_per_s } => {
                let spec = ProfileSpec::Constant {
                    force: *force,
                    rate_per_s: *rate_per_s,
                };
                spec.validate(&self.limits)?;
                self.require_armed()?;
                let rate = rate_per_s.unwrap_or(self.limits.default_rate_per_s);
                self.start_profile(spec, now_ns);
                Ok(format!("reference {force} at {rate} /s"))
            }
            Command::Profile { profile } => {
                profile.validate(&self.limits)?;
                self.require_armed()?;
                if let ProfileSpec::Cardiac(c) = profile {
                    if let Some(on) = c.outer_loop {
                        self.outer.set_enabled(on);
                    }
                    if let Some(run) = &mut self.profile
                        && run.cardiac().is_some()
                    {
                        run.retune_cardiac(*c);
                        let amplitude = self.outer.amplitude(c.amplitude, self.limits.max_force);
                        run.set_next_amplitude(amplitude);
                        let next = run.beat().map_or(0, |b| b.index + 1);
                        return Ok(format!(
                            "cardiac profile retuned from beat {next}: {}",
                            profile.describe()
                        ));
                    }
                    self.outer.reset();
                }
                self.start_profile(profile.clone(), now_ns);
                Ok(format!("profile started: {}", profile.describe()))
            }
            Command::Stop => match &self.state {
                ArmState::Fault(f) => Ok(format!("already stopped by a fault: {f}")),
                _ => {
                    self.state = ArmState::Disarmed;
                    self.clear_profile();
                    self.orders.push(DriverOrder::Disarm);
                    Ok("stimulation stopped; driver disarmed".into())
                }
            },
            Command::Arm => {
                if self.state == ArmState::Armed {
                    return Ok("already armed".into());
                }
                ready?;
                self.state = ArmState::Armed;
                self.clear_profile();
                self.outer.reset();
                self.orders.push(DriverOrder::Arm);
                Ok("armed; reference 0 until a profile is given".into())
            }
            Command::OuterLoop { enabled } => {
                self.outer.set_enabled(*enabled);
                Ok(format!(
                    "outer loop {}",
                    if *enabled { "on" } else { "off" }
                ))
            }
        }
    }

    fn clear_profile(&mut self) {
        self.profile = None;
        self.contraction.clear();
    }

    fn start_profile(&mut self, spec: ProfileSpec, now_ns: u64) {
        self.contraction = ContractionEstimator::new(self.contraction_settings);
        let run = ProfileRunner::start(spec, self.limits, now_ns);
        // Just started, the running beat is the first: announce it now.
        if let Some(b) = run.beat() {
            self.contraction.begin(b);
            self.beat_starts.push(b);
        }
        self.profile = Some(run);
    }

    /// Orders another safe stop (the driver still armed after confirming a stop), whatever
    /// the state.
    pub fn reissue_safe_stop(&mut self) {
        self.orders.push(DriverOrder::SafeStop);
    }

    /// Stops stimulation because of `fault`. Returns false when already in a fault (the
    /// first fault is kept).
    pub fn fault(&mut self, fault: Fault) -> bool {
        if let ArmState::Fault(_) = self.state {
            return false;
        }
        self.note(format!("FAULT: {fault}; stimulation stopped"));
        self.state = ArmState::Fault(fault);
        self.clear_profile();
        self.orders.push(DriverOrder::SafeStop);
        true
    }

    /// A measured force sample (normalised) taken at `t_ns`.
    pub fn on_force(&mut self, t_ns: u64, force: f64) {
        self.latest_force_ns = self.latest_force_ns.max(t_ns);
        self.contraction.add_force(t_ns, force);
    }

    /// A pulse fired at `t_ns`.
    pub fn on_pulse(&mut self, t_ns: u64) {
        self.contraction.add_pulse(t_ns);
    }

    /// A (validated) DriverStatus: pulses refused since the previous one are charged to
    /// the beats between the two reports' times (both on CLOCK_MONOTONIC).
    pub fn on_driver_status(&mut self, s: &DriverStatus) {
        if let Some((t_ns, refused)) = self.driver_refusals
            && s.pulses_rejected > refused
            && s.t_ns >= t_ns
        {
            self.contraction
                .add_refused(t_ns, s.t_ns, s.pulses_rejected - refused);
        }
        // A restarted driver counts from 0 again: its first report is the new origin.
        self.driver_refusals = Some((s.t_ns, s.pulses_rejected));
    }

    /// The pulse of the tick at `tick_t_ns` did not reach the muscle: the driver dropped
    /// it as late (its transport was still busy with the previous command; PulseOutcome
    /// `late`) or the stimulator did not apply it (`not_applied`). Charged to its beat like
    /// a refused one, so the outer loop does not learn from a beat that did not get the
    /// train the inner loop planned (an account that arrives after its beat has closed
    /// charges nothing). Interlock refusals come counted in DriverStatus instead.
    pub fn on_pulse_not_delivered(&mut self, tick_t_ns: u64) {
        self.contraction.add_refused(tick_t_ns, tick_t_ns, 1);
    }

    /// Advances the profile and the outer loop to `now_ns`.
    pub fn advance(&mut self, now_ns: u64) -> Option<Setpoint> {
        let run = self.profile.as_mut()?;
        let mut events = Vec::new();
        let setpoint = run.advance(now_ns, &mut events);
        for e in events {
            if let ProfileEvent::BeatStarted(b) = e {
                self.contraction.begin(b);
                self.beat_starts.push(b);
            }
        }
        for m in self.contraction.poll(self.latest_force_ns, now_ns) {
            // A beat with a refused pulse did not get the train the inner loop planned:
            // its error is not the model's, and the outer loop skips it.
            let measured = m.plateau_mean.filter(|_| m.pulses_refused == 0);
            let update = self
                .outer
                .update(m.beat.target, measured, self.limits.max_force);
            if let Some(c) = m.plateau_mean {
                self.last_contraction = Some(c);
            }
            if let Some(run) = &mut self.profile {
                let target = run.next_target().unwrap_or(m.beat.target);
                run.set_next_amplitude(self.outer.amplitude(target, self.limits.max_force));
            }
            self.beats.push(BeatRecord {
                measurement: m,
                update,
            });
        }
        Some(setpoint)
    }

    /// The reference to publish at `now_ns` (a new `seq` each call).
    pub fn reference(&mut self, now_ns: u64) -> Reference {
        let setpoint = self.advance(now_ns);
        self.seq += 1;
        let mut r = Reference::new(self.seq, now_ns, 0.0);
        match (&self.state, setpoint) {
            (ArmState::Armed, Some(sp)) => {
                r.force = sp.force;
                r.max_rate_per_s = sp.rate_per_s;
            }
            (ArmState::Armed, None) => {
                r.max_rate_per_s = self.limits.max_rate_per_s;
            }
            _ => r.flags = Reference::FLAG_STOP,
        }
        self.last = Some(r);
        r
    }

    /// The setpoint changes scheduled after `now_ns` ([`crate::profile::ProfileRunner::preview`]),
    /// into `out`; none unless armed with a profile. Call after [`Self::reference`] for
    /// the same time.
    pub fn preview(&self, now_ns: u64, out: &mut [fes_rt::msg::PreviewEdge]) -> usize {
        match (&self.state, &self.profile) {
            (ArmState::Armed, Some(run)) => run.preview(now_ns, out),
            _ => 0,
        }
    }

    /// When the reference next changes by itself (a profile edge), if it does.
    pub fn next_change_ns(&self, now_ns: u64) -> Option<u64> {
        match self.state {
            ArmState::Armed => self.profile.as_ref()?.next_change_ns(now_ns),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::health::Unready;
    use crate::profile::CardiacSpec;

    const MS: u64 = 1_000_000;

    fn core() -> SupervisorCore {
        SupervisorCore::new(
            ReferenceLimits::default(),
            OuterLoopSettings::default(),
            ContractionSettings::default(),
        )
    }

    fn cardiac(amplitude: f64) -> Command {
        Command::Profile {
            profile: ProfileSpec::Cardiac(CardiacSpec {
                bpm: 75.0,
                duty: 0.4,
                amplitude,
                edge_rate_per_s: None,
                outer_loop: None,
                start_rest_ms: Some(0.0),
            }),
        }
    }

    /// The health monitor's verdict with the one `problem`.
    fn not_ready(problem: Unready) -> NotReady {
        NotReady {
            problems: vec![problem],
        }
    }

    /// Armed, running the cardiac profile at `amplitude` from t = 0.
    fn armed_with_cardiac(amplitude: f64) -> SupervisorCore {
        let mut c = core();
        c.command(&Command::Arm, 0, Ok(())).unwrap();
        c.command(&cardiac(amplitude), 0, Ok(())).unwrap();
        c
    }

    #[test]
    fn a_fault_cause_reads_as_documented_json_and_back() {
        let died = FaultCause::Process {
            process: Process::RtCore,
            pid: Some(7),
            cause: Cause::Died,
        };
        let json = serde_json::to_value(died).unwrap();
        assert_eq!(
            json,
            serde_json::json!({"source": "process", "process": "RtCore", "pid": 7,
                               "cause": {"kind": "died"}})
        );
        assert_eq!(serde_json::from_value::<FaultCause>(json).unwrap(), died);
        let emcy = FaultCause::Process {
            process: Process::SimMuscle,
            pid: None,
            cause: Cause::Emcy { code: 0x8130 },
        };
        let back: FaultCause =
            serde_json::from_str(&serde_json::to_string(&emcy).unwrap()).unwrap();
        assert_eq!(back, emcy);
        assert!(!emcy.is_timing() && !died.is_timing());
        assert!(FaultCause::SelfStall.is_timing());
        assert_eq!(
            serde_json::to_value(FaultCause::Recording).unwrap(),
            serde_json::json!({"source": "recording"})
        );
    }

    #[test]
    fn disarmed_publishes_stop_and_refuses_set() {
        let mut c = core();
        let r = c.reference(MS);
        assert!(r.is_stop());
        assert_eq!(r.force, 0.0);
        let e = c
            .command(
                &Command::Set {
                    force: 0.3,
                    rate_per_s: None,
                },
                MS,
                Ok(()),
            )
            .unwrap_err();
        assert!(e.to_string().contains("not armed"), "{e}");
        let waiting = Unready::Waiting {
            process: Process::RtCore,
        };
        let e = c.command(&Command::Arm, MS, Err(not_ready(waiting)));
        assert_eq!(
            e.unwrap_err().to_string(),
            "cannot arm: rt-core: not heard from yet"
        );
        assert_eq!(c.state(), &ArmState::Disarmed);
        assert!(c.take_orders().is_empty());
    }

    /// Invalid commands are refused with the reason and change nothing: the reference
    /// stays exactly what it was.
    #[test]
    fn invalid_commands_change_nothing() {
        let mut c = core();
        c.command(&Command::Arm, 0, Ok(())).unwrap();
        c.command(
            &Command::Set {
                force: 0.3,
                rate_per_s: Some(2.0),
            },
            0,
            Ok(()),
        )
        .unwrap();
        let before = c.reference(10 * MS);
        for bad in [
            Command::Set {
                force: 1.2,
                rate_per_s: None,
            },
            Command::Set {
                force: f64::NAN,
                rate_per_s: None,
            },
            Command::Set {
                force: 0.5,
                rate_per_s: Some(500.0),
            },
            Command::Set {
                force: -0.1,
                rate_per_s: None,
            },
            cardiac(1.5),
        ] {
            assert!(
                c.command(&bad, 15 * MS, Ok(())).is_err(),
                "{bad:?} accepted"
            );
        }
        let after = c.reference(20 * MS);
        assert_eq!(
            (after.force, after.max_rate_per_s, after.flags),
            (before.force, before.max_rate_per_s, before.flags)
        );
        assert_eq!(after.seq, before.seq + 1);
    }

    /// A fault stops stimulation at once and orders a safe stop; `arm` is refused while
    /// the cause persists and re-arms after.
    #[test]
    fn fault_stops_and_needs_rearm() {
        let mut c = core();
        c.command(&Command::Arm, 0, Ok(())).unwrap();
        c.command(&cardiac(0.3), 0, Ok(())).unwrap();
        assert_eq!(c.reference(MS).force, 0.3);
        assert_eq!(c.take_orders(), vec![DriverOrder::Arm]);
        let died = FaultCause::Process {
            process: Process::RtCore,
            pid: Some(7),
            cause: Cause::Died,
        };
        assert!(c.fault(Fault::new(died, "rt-core (pid 7) died")));
        assert!(!c.fault(Fault::new(FaultCause::Recording, "second")));
        let r = c.reference(2 * MS);
        assert!(r.is_stop());
        assert_eq!(c.take_orders(), vec![DriverOrder::SafeStop]);
        let e = c.command(&cardiac(0.3), 3 * MS, Ok(())).unwrap_err();
        assert!(e.to_string().contains("rt-core (pid 7) died"), "{e}");
        let dead = Unready::Faulted {
            process: Process::RtCore,
            reason: "rt-core (pid 7) died".into(),
        };
        assert!(
            c.command(&Command::Arm, 4 * MS, Err(not_ready(dead)))
                .is_err()
        );
        c.command(&Command::Arm, 5 * MS, Ok(())).unwrap();
        let r = c.reference(6 * MS);
        assert!(!r.is_stop());
        assert_eq!(r.force, 0.0);
    }

    /// The outer loop closes per beat: a muscle that gives 80 % of the reference makes
    /// the amplitude climb towards target / 0.8.
    #[test]
    fn outer_loop_raises_the_amplitude_on_a_weak_muscle() {
        let mut c = armed_with_cardiac(0.4);
        let mut amp = 0.0f64;
        for k in 0..(40 * 800u64) {
            let t = k * MS;
            let r = c.reference(t);
            // A muscle following the reference exactly, 7 ms later, at 80 %.
            c.on_force(t + 7 * MS, 0.8 * r.force);
            amp = amp.max(r.force);
        }
        let beats = c.take_beats();
        assert!(beats.len() >= 38, "{}", beats.len());
        let last = beats.last().unwrap();
        let m = last.measurement.plateau_mean.unwrap();
        assert!((m - 0.4).abs() < 0.01, "measured {m}");
        assert!(
            (last.update.amplitude - 0.5).abs() < 0.01,
            "{:?}",
            last.update
        );
    }

    /// A beat in which the driver refused a pulse is not learned from: the correction
    /// stays what it was, however weak that beat's contraction; the beats before and
    /// after it are corrected as usual. The refusal reaches the core as the DriverStatus
    /// count rising between two 100 ms reports.
    #[test]
    fn a_beat_with_a_refused_pulse_leaves_the_outer_loop_correction_unchanged() {
        use fes_rt::msg::DeviceState;
        let status = |seq: u64, t_ns: u64, rejected: u64| DriverStatus {
            seq,
            t_ns,
            ticks_received: seq,
            ticks_lost: 0,
            pulses_sent: 0,
            pulses_rejected: rejected,
            can_tx_errors: 0,
            watchdog_trips: 0,
            fault_code: 0,
            state: DeviceState::Armed as u8,
            stimulator_state: DeviceState::Armed as u8,
            command_seq: 0,
            command_result: 0,
            command_reason: 0,
            reserved: [0; 6],
        };
        // Beat 6 of the profile ([4.8 s, 5.6 s)) has its pulse refused at about 4.95 s,
        // and its contraction falls to half; every other beat gets 80 % of the reference.
        let run = |report: bool| {
            let mut c = armed_with_cardiac(0.4);
            let mut rejected = 0;
            for k in 0..(10 * 800u64) {
                let t = k * MS;
                let r = c.reference(t);
                let hit = (4800..5600).contains(&k);
                c.on_force(t + 7 * MS, if hit { 0.4 } else { 0.8 } * r.force);
                if k % 100 == 0 && k > 0 {
                    if k == 5000 {
                        rejected = 1;
                    }
                    if report {
                        c.on_driver_status(&status(k / 100, t, rejected));
                    }
                }
            }
            c.take_beats()
        };
        let (reported, unreported) = (run(true), run(false));
        // A pulse dropped as late (PulseOutcome) is charged to its beat the same way.
        let late = {
            let mut c = armed_with_cardiac(0.4);
            for k in 0..(10 * 800u64) {
                let t = k * MS;
                let r = c.reference(t);
                let hit = (4800..5600).contains(&k);
                c.on_force(t + 7 * MS, if hit { 0.4 } else { 0.8 } * r.force);
                if k == 4950 {
                    c.on_pulse_not_delivered(t);
                }
            }
            c.take_beats()
        };
        let six = |beats: &[BeatRecord]| {
            *beats
                .iter()
                .find(|b| b.measurement.beat.index == 6)
                .unwrap()
        };
        let (with, without) = (six(&reported), six(&unreported));
        assert_eq!(six(&late).measurement.pulses_refused, 1);
        assert_eq!(six(&late).update.measured, None, "skipped");
        assert_eq!(with.measurement.pulses_refused, 1);
        assert_eq!(without.measurement.pulses_refused, 0);
        // The weak beat is measured alike in both runs; only the reported one is skipped.
        assert_eq!(
            with.measurement.plateau_mean,
            without.measurement.plateau_mean
        );
        assert!(with.measurement.plateau_mean.unwrap() < 0.25);
        let before = reported
            .iter()
            .find(|b| b.measurement.beat.index == 5)
            .unwrap();
        assert_eq!(with.update.measured, None);
        assert_eq!(with.update.correction, before.update.correction, "skipped");
        assert!(
            without.update.correction > before.update.correction + 0.02,
            "integrated"
        );
        for b in reported.iter().filter(|b| b.measurement.beat.index != 6) {
            assert_eq!(
                b.measurement.pulses_refused, 0,
                "beat {}",
                b.measurement.beat.index
            );
            assert!(b.update.measured.is_some());
        }
        let next = reported
            .iter()
            .find(|b| b.measurement.beat.index == 7)
            .unwrap();
        assert!(
            next.update.correction > with.update.correction,
            "learning resumes"
        );
    }
}
