//! Property tests of the supervisor's stop-on-fault rules (`supervisor::pass`, the
//! daemon's own decisions: the health monitor and the state machine), on simulated time,
//! over arbitrary runs of the three watched processes: messages on time, late, missing or
//! invalid; DriverStatus of any state, with any fault code or watchdog trip; SIGSTOP and
//! SIGCONT; SIGKILL of any process (a zombie, later reaped), after which the samples it
//! left queued may still arrive for a few milliseconds; node listings that show the truth;
//! and operator commands (arm, stop, set) at any moment. After every pass:
//!
//! * a fault found by the health check leaves the supervisor in FAULT, with a stop
//!   reference (zero force, `FLAG_STOP`) and, when it was armed, a safe stop for the driver;
//! * only an operator `arm` arms it;
//! * an `arm` is refused while any watched process is dead (the bug CI found: a FORCE the
//!   driver forwarded after the stimulator's death re-armed it);
//! * armed means every watched process was heard within its timeout.
//!
//! A liveness companion keeps these from holding by never arming.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_rt::msg::{DeviceState, DriverStatus, ForceSample, Reference, StimTick};
use fes_rt::rt::liveness::NodeObservation;
use proptest::prelude::*;
use supervisor::contraction::ContractionSettings;
use supervisor::core::{ArmState, DriverOrder, SupervisorCore};
use supervisor::health::{HealthMonitor, HealthSettings, ProcState, ServiceOwners, Severity};
use supervisor::limits::ReferenceLimits;
use supervisor::outer_loop::OuterLoopSettings;
use supervisor::pass::{check_health, serve_command};
use supervisor::protocol::Command;

const MS: u64 = 1_000_000;
const T0: u64 = 10_000 * MS;
/// How long after its death a process's queued samples may still be read.
const QUEUED_NS: u64 = 5 * MS;

/// The three watched processes.
const RT: usize = 0;
const DRIVER: usize = 1;
const STIM: usize = 2;
const PIDS: [u32; 3] = [100, 200, 300];
const NODE_IDS: [u128; 2] = [1, 2];

#[derive(Debug, Clone)]
enum Input {
    /// Time passes with every live, running process sending its messages (1 ms apart).
    Run(u64),
    /// Time passes with process `p` silent (the others send).
    Silent(usize, u64),
    /// An invalid message from process `p`.
    Invalid(usize),
    /// A DriverStatus with this device state and fault code, and a watchdog trip.
    Status(DeviceState, u16, bool),
    /// SIGSTOP / SIGCONT of process `p`.
    Stop(usize),
    Cont(usize),
    /// SIGKILL of process `p` (a zombie until reaped).
    Kill(usize),
    /// Its parent reaps it.
    Reap(usize),
    /// A node listing (what iceoryx2 shows; a dead node's resources cleaned or not).
    Listing(bool),
    /// An operator command.
    Arm,
    Disarm,
    Set,
}

fn process() -> impl Strategy<Value = usize> {
    0usize..3
}

fn input() -> impl Strategy<Value = Input> {
    prop_oneof![
        30 => (1u64..30).prop_map(Input::Run),
        3 => (process(), 10u64..700).prop_map(|(p, ms)| Input::Silent(p, ms)),
        1 => process().prop_map(Input::Invalid),
        3 => (
            proptest::sample::select(vec![
                DeviceState::Armed,
                DeviceState::Stimulating,
                DeviceState::PreOperational,
                DeviceState::Fault,
            ]),
            prop_oneof![
                6 => Just(0u16),
                1 => Just(DriverStatus::FAULT_CODE_SAFE_STOP_ORDERED),
                1 => 0xFF20u16..0xFF30,
                1 => any::<u16>(),
            ],
            proptest::bool::weighted(0.1),
        )
            .prop_map(|(s, c, t)| Input::Status(s, c, t)),
        1 => process().prop_map(Input::Stop),
        2 => process().prop_map(Input::Cont),
        1 => process().prop_map(Input::Kill),
        1 => process().prop_map(Input::Reap),
        4 => proptest::bool::ANY.prop_map(Input::Listing),
        8 => Just(Input::Arm),
        2 => Just(Input::Disarm),
        2 => Just(Input::Set),
    ]
}

/// The processes as they really are.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Proc {
    state: ProcState,
    /// When it died, ns.
    died_ns: Option<u64>,
    /// Last valid message the supervisor received from it, ns.
    heard_ns: Option<u64>,
}

struct World {
    now: u64,
    procs: [Proc; 3],
    seq: [u64; 3],
    trips: u32,
    /// Whether a dead node's resources were cleaned (it then leaves the listing).
    cleaned: [bool; 2],
}

impl World {
    fn can_send(&self, p: usize) -> bool {
        let q = &self.procs[p];
        match q.state {
            ProcState::Running => true,
            // Samples it left queued before its death.
            ProcState::Zombie | ProcState::Gone => q
                .died_ns
                .is_some_and(|d| self.now.saturating_sub(d) <= QUEUED_NS),
            ProcState::Stopped => false,
        }
    }

    fn probe(&self) -> impl Fn(u32) -> ProcState + '_ {
        move |pid| {
            PIDS.iter()
                .position(|&p| p == pid)
                .map_or(ProcState::Gone, |i| self.procs[i].state)
        }
    }

    fn dead(&self, p: usize) -> bool {
        matches!(self.procs[p].state, ProcState::Zombie | ProcState::Gone)
    }

    /// One message from `p` at `now`, valid or not, fed to the monitor.
    fn send(&mut self, h: &mut HealthMonitor, core: &mut SupervisorCore, p: usize, valid: bool) {
        self.seq[p] += 1;
        let seq = self.seq[p];
        let now = self.now;
        match p {
            RT => {
                let mut t = StimTick::quiet(seq, now);
                if !valid {
                    t.reference = f64::NAN;
                }
                h.on_stim_tick(&t, now);
                if t.fires() {
                    core.on_pulse(t.t_ns);
                }
            }
            DRIVER => h.on_driver_status(&self.status(seq, DeviceState::Armed, 0, valid), now),
            _ => {
                let f = ForceSample {
                    seq,
                    t_ns: now,
                    stim_seq: 0,
                    force_n: 1.0,
                    force: if valid { 0.02 } else { f64::NAN },
                };
                h.on_force_sample(&f, now);
                if valid {
                    core.on_force(now, f.force);
                }
            }
        }
        if valid {
            self.procs[p].heard_ns = Some(now);
        }
    }

    fn status(&self, seq: u64, state: DeviceState, fault_code: u16, valid: bool) -> DriverStatus {
        DriverStatus {
            seq,
            t_ns: self.now,
            ticks_received: seq,
            ticks_lost: 0,
            pulses_sent: 0,
            pulses_rejected: 0,
            can_tx_errors: 0,
            watchdog_trips: self.trips,
            fault_code,
            state: if valid { state as u8 } else { 250 },
            stimulator_state: DeviceState::Armed as u8,
            command_seq: 0,
            command_result: 0,
            command_reason: 0,
            reserved: [0; 6],
        }
    }

    /// What iceoryx2 lists: live nodes, and dead ones not yet cleaned up.
    fn listing(&self) -> Vec<NodeObservation> {
        [RT, DRIVER]
            .into_iter()
            .filter(|&p| !(self.dead(p) && self.cleaned[p]))
            .map(|p| NodeObservation {
                name: ["rt-core", "stim-driver"][p].into(),
                pid: PIDS[p],
                id: NODE_IDS[p],
                dead: self.dead(p),
            })
            .collect()
    }
}

fn owners() -> ServiceOwners {
    ServiceOwners {
        stim_tick: vec![NODE_IDS[RT]],
        driver_status: vec![NODE_IDS[DRIVER]],
    }
}

/// Runs `inputs` after a healthy start; checks the properties after every pass. Returns
/// how many arms were accepted.
fn run(inputs: &[Input]) -> Result<u32, TestCaseError> {
    let settings = HealthSettings {
        stimulator_pid: Some(PIDS[STIM]),
        ..HealthSettings::default()
    };
    let timeouts = [
        settings.stim_tick_timeout_ms * MS,
        settings.driver_status_timeout_ms * MS,
        settings.force_timeout_ms * MS,
    ];
    let mut h = HealthMonitor::new(settings);
    let mut core = SupervisorCore::new(
        ReferenceLimits::default(),
        OuterLoopSettings::default(),
        ContractionSettings::default(),
    );
    let alive = Proc {
        state: ProcState::Running,
        died_ns: None,
        heard_ns: None,
    };
    let mut w = World {
        now: T0,
        procs: [alive; 3],
        seq: [0; 3],
        trips: 0,
        cleaned: [false; 2],
    };
    h.on_nodes(&w.listing(), &owners());
    let mut arms = 0;
    for input in inputs {
        let before = core.state().clone();
        let mut arm_result = None;
        match input {
            Input::Run(ms) | Input::Silent(_, ms) => {
                let quiet = match input {
                    Input::Silent(p, _) => Some(*p),
                    _ => None,
                };
                for _ in 0..*ms {
                    w.now += MS;
                    for p in [RT, DRIVER, STIM] {
                        // DriverStatus comes every 100 ms, the others every ms.
                        let due = p != DRIVER
                            || w.procs[p].heard_ns.is_none_or(|t| w.now - t >= 100 * MS);
                        if Some(p) != quiet && w.can_send(p) && due {
                            w.send(&mut h, &mut core, p, true);
                        }
                    }
                    // The daemon checks health at least every few ms.
                    if w.now.is_multiple_of(5 * MS) {
                        check(&mut w, &mut h, &mut core, &timeouts)?;
                    }
                }
            }
            Input::Invalid(p) => {
                if w.can_send(*p) {
                    w.send(&mut h, &mut core, *p, false);
                }
            }
            Input::Status(state, code, trip) => {
                if w.can_send(DRIVER) {
                    if *trip {
                        w.trips += 1;
                    }
                    w.seq[DRIVER] += 1;
                    let s = w.status(w.seq[DRIVER], *state, *code, true);
                    h.on_driver_status(&s, w.now);
                    w.procs[DRIVER].heard_ns = Some(w.now);
                }
            }
            Input::Stop(p) => {
                if w.procs[*p].state == ProcState::Running {
                    w.procs[*p].state = ProcState::Stopped;
                }
            }
            Input::Cont(p) => {
                if w.procs[*p].state == ProcState::Stopped {
                    w.procs[*p].state = ProcState::Running;
                }
            }
            Input::Kill(p) => {
                if !w.dead(*p) {
                    w.procs[*p].state = ProcState::Zombie;
                    w.procs[*p].died_ns = Some(w.now);
                }
            }
            Input::Reap(p) => {
                if w.procs[*p].state == ProcState::Zombie {
                    w.procs[*p].state = ProcState::Gone;
                }
            }
            Input::Listing(clean) => {
                for p in [RT, DRIVER] {
                    w.cleaned[p] |= *clean && w.dead(p);
                }
                h.on_nodes(&w.listing(), &owners());
            }
            Input::Arm => {
                let probe = w.probe();
                arm_result = Some(serve_command(
                    &mut core,
                    &mut h,
                    &Command::Arm,
                    w.now,
                    &probe,
                ));
            }
            Input::Disarm => {
                let probe = w.probe();
                let _ = serve_command(&mut core, &mut h, &Command::Stop, w.now, &probe);
            }
            Input::Set => {
                let probe = w.probe();
                let _ = serve_command(
                    &mut core,
                    &mut h,
                    &Command::Set {
                        force: 0.3,
                        rate_per_s: None,
                    },
                    w.now,
                    &probe,
                );
            }
        }
        let dead: Vec<usize> = (0..3).filter(|&p| w.dead(p)).collect();
        if let Some(Ok(_)) = &arm_result {
            arms += 1;
            prop_assert!(
                dead.is_empty(),
                "armed at {} ms with dead process(es) {dead:?}",
                (w.now - T0) / MS
            );
        }
        let after_serve = core.state().clone();
        if after_serve == ArmState::Armed && before != ArmState::Armed {
            prop_assert!(
                matches!(arm_result, Some(Ok(_))),
                "armed by {input:?}, not by an operator arm"
            );
        }
        check(&mut w, &mut h, &mut core, &timeouts)?;
    }
    Ok(arms)
}

/// One health check of the daemon's pass, and the properties that follow it.
fn check(
    w: &mut World,
    h: &mut HealthMonitor,
    core: &mut SupervisorCore,
    timeouts: &[u64; 3],
) -> Result<(), TestCaseError> {
    let before = core.state().clone();
    let probe = w.probe();
    let events = check_health(core, h, w.now, &probe);
    let orders = core.take_orders();
    let faulted = events.iter().any(|e| e.severity == Severity::Fault);
    if faulted {
        prop_assert!(
            matches!(core.state(), ArmState::Fault(_)),
            "a fault ({events:?}) left the supervisor {:?}",
            core.state()
        );
        if before == ArmState::Armed {
            prop_assert!(
                orders.contains(&DriverOrder::SafeStop),
                "armed, then a fault without a safe stop: {orders:?}"
            );
        }
    }
    if *core.state() != ArmState::Armed {
        let r = core.reference(w.now);
        prop_assert!(
            r.flags & Reference::FLAG_STOP != 0 && r.force == 0.0,
            "not armed ({:?}) but the reference is {r:?}",
            core.state()
        );
    } else {
        for (p, timeout) in timeouts.iter().enumerate() {
            let silent = w.procs[p].heard_ns.map_or(u64::MAX, |t| w.now - t);
            prop_assert!(
                silent <= *timeout,
                "armed at {} ms with process {p} silent for {} ms (timeout {} ms)",
                (w.now - T0) / MS,
                silent / MS,
                timeout / MS
            );
        }
    }
    Ok(())
}

/// Cases per run: 512 in CI; `HEALTH_PROPS_CASES` for a longer search.
fn cases() -> u32 {
    std::env::var("HEALTH_PROPS_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(512)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    /// The stop-on-fault rules over arbitrary runs (module documentation).
    #[test]
    fn no_run_leaves_stimulation_armed_against_the_health_rules(
        inputs in proptest::collection::vec(input(), 10..200),
    ) {
        run(&inputs)?;
    }
}

/// Liveness: healthy processes, an arm, and the supervisor stays armed: the properties do
/// not hold by never arming.
#[test]
fn a_healthy_stack_arms_and_stays_armed() {
    let mut inputs = vec![Input::Run(20), Input::Arm];
    inputs.extend(std::iter::repeat_n(Input::Run(25), 40));
    assert_eq!(run(&inputs).unwrap(), 1);
}
