//! The forward path's state machine on simulated time: bring-up, arming and its
//! preconditions, forwarding, the watchdog conditions, the bus faults, and what reaches
//! the (recorded) bus in each case. No CAN, no threads: every input carries its time.
//!
//! Then the same on a real bus: [`driver_on_the_bus`] runs the `stim-driver` binary in the
//! vcan harness against the virtual stimulator (module `on_bus`).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_can::{Emcy, ErrorCode, Message, NmtCommand, NmtState, Nodes, StimLimits, StimState};
use fes_rt::msg::{
    CommandAck, CommandRefusal, CommandResult, Contract, DriverCommand, DriverCommandKind,
    PulseFate, StimTick,
};
use fes_rt::rt::liveness::Liveness;
use stim_driver::config::DriverConfig;
use stim_driver::event::{BusErrorKind, BusEvent, DriverEvent, DriverState};
use stim_driver::fault::{ArmRefusal, Fault};
use stim_driver::forward::{ForwardPath, ForwardSettings};
use stim_driver::tx::TxError;

const MS: u64 = 1_000_000;
const T0: u64 = 1_000 * MS;

use crate::recording_bus;
use recording_bus::{Bus, status, status_delivered};

fn settings() -> ForwardSettings {
    DriverConfig::with_defaults("vcan0", 40.0)
        .forward_settings()
        .unwrap()
}

struct Rig {
    fp: ForwardPath<Bus>,
    bus: Bus,
    ev: Vec<DriverEvent>,
    now: u64,
    tick_seq: u64,
    cmd_seq: u64,
    config_id: u8,
    /// The last complete CONFIG the driver wrote (id, limits), collected from the bus.
    sent: Option<(u8, StimLimits)>,
    sent_pages: fes_can::ConfigAssembler,
    /// Answer a complete CONFIG with CONFIG_APPLIED pages of the same limits (a conforming
    /// stimulator) just before the STATUS that confirms it.
    auto_readback: bool,
}

fn tick(seq: u64, t_ns: u64, pulse: bool) -> StimTick {
    let quiet = StimTick::quiet(seq, t_ns);
    if pulse {
        quiet.firing(0, 20_000, 200)
    } else {
        quiet
    }
}

impl Rig {
    fn new(s: ForwardSettings) -> Self {
        let bus = Bus::default();
        bus.now.set(T0);
        let fp = ForwardPath::new(s, bus.clone());
        Self {
            fp,
            bus,
            ev: Vec::new(),
            now: T0,
            tick_seq: 0,
            cmd_seq: 0,
            config_id: 0,
            sent: None,
            sent_pages: fes_can::ConfigAssembler::new(),
            auto_readback: true,
        }
    }

    fn at(&mut self, t: u64) {
        self.now = t;
        self.bus.now.set(t);
    }

    fn advance(&mut self, dt: u64) {
        let t = self.now + dt;
        self.at(t);
    }

    fn poll(&mut self) {
        self.fp.poll(self.now, &mut self.ev);
    }

    fn bus_event(&mut self, e: BusEvent) {
        for (_, m) in self.bus.messages() {
            if let Message::Config(c) = m
                && let Some(done) = self.sent_pages.push(&c)
            {
                self.sent = Some(done);
            }
        }
        if let BusEvent::Status(s) = e
            && s.state == StimState::PreOperational
            && self.auto_readback
            && let Some((id, limits)) = self.sent
            && id == s.config_id
        {
            for a in recording_bus::applied(&limits, id) {
                self.fp.on_bus(a, self.now, &mut self.ev);
            }
        }
        self.fp.on_bus(e, self.now, &mut self.ev);
    }

    /// One StimTick on the 1 ms grid at the current time, then the timers.
    fn tick(&mut self, pulse: bool) {
        self.tick_seq += 1;
        let t = tick(self.tick_seq, self.now - 20_000, pulse);
        self.fp.on_tick(&t, self.now, &mut self.ev);
        self.poll();
    }

    fn command(&mut self, kind: DriverCommandKind) {
        self.cmd_seq += 1;
        let c = DriverCommand::new(self.cmd_seq, self.now - 1000, kind);
        self.fp.on_command(&c, self.now, &mut self.ev);
    }

    /// start + STATUS pre-op (stimulator's config 7) + STATUS confirming ours.
    fn configured(s: ForwardSettings) -> Self {
        let mut r = Self::new(s);
        r.fp.start(r.now, &mut r.ev);
        r.advance(MS);
        r.bus_event(status(StimState::PreOperational, 7));
        r.advance(MS);
        r.config_id = 8;
        r.bus_event(status(StimState::PreOperational, 8));
        assert_eq!(r.fp.state(), DriverState::Disarmed);
        r
    }

    /// Configured, ticks flowing, publisher and supervisor alive, armed and confirmed.
    fn armed(s: ForwardSettings) -> Self {
        let mut r = Self::configured(s);
        r.fp.on_liveness(Liveness::Alive, r.now, &mut r.ev);
        r.fp.on_supervisor_liveness(Liveness::Alive, r.now, &mut r.ev);
        for _ in 0..3 {
            r.advance(MS);
            r.tick(false);
        }
        r.command(DriverCommandKind::Arm);
        assert_eq!(r.fp.state(), DriverState::Armed, "{:?}", r.ev);
        r.advance(MS / 2);
        let id = r.config_id;
        r.bus_event(status(StimState::Armed, id));
        r
    }

    fn fault(&self) -> Option<Fault> {
        match self.fp.state() {
            DriverState::SafeState(f) => Some(f),
            _ => None,
        }
    }
}

#[test]
fn bring_up_sends_pre_operational_then_a_fresh_config_and_waits_for_status() {
    let mut r = Rig::new(settings());
    r.fp.start(r.now, &mut r.ev);
    let m = r.bus.messages();
    assert_eq!(
        m.iter().map(|(_, m)| *m).collect::<Vec<_>>(),
        vec![
            Message::HostHeartbeat(fes_can::Heartbeat {
                state: NmtState::BootUp
            }),
            Message::Nmt(fes_can::Nmt {
                command: NmtCommand::EnterPreOperational,
                node: 0x10
            }),
        ]
    );
    assert_eq!(r.fp.state(), DriverState::Starting);
    r.bus.clear();
    // A STATUS still showing the old (operational) state does not start the CONFIG.
    r.bus_event(status(StimState::Armed, 3));
    assert!(
        !r.bus
            .messages()
            .iter()
            .any(|(_, m)| matches!(m, Message::Config(_)))
    );
    r.bus.clear();
    r.bus_event(status(StimState::PreOperational, 255));
    // Id 255 is in use: ours is 1, both pages carry the configured limits.
    let pages: Vec<_> = r
        .bus
        .messages()
        .into_iter()
        .filter_map(|(_, m)| match m {
            Message::Config(c) => Some(c),
            _ => None,
        })
        .collect();
    assert_eq!(pages, StimLimits::DEFAULT.to_pages(1).to_vec());
    // The old id does not confirm; ours does.
    r.bus_event(status(StimState::PreOperational, 255));
    assert_eq!(r.fp.state(), DriverState::Starting);
    r.bus_event(status(StimState::PreOperational, 1));
    assert_eq!(r.fp.state(), DriverState::Disarmed);
    assert_eq!(r.fp.config_id(), Some(1));
}

#[test]
fn bring_up_starts_over_without_confirmation_and_stops_on_refusal() {
    let s = settings();
    let mut r = Rig::new(s);
    r.fp.start(r.now, &mut r.ev);
    r.bus.clear();
    r.at(T0 + s.bringup_retry_ns);
    r.poll();
    assert!(r.bus.nmt().is_empty(), "not before the retry time");
    r.at(T0 + s.bringup_retry_ns + 1);
    r.poll();
    assert_eq!(r.bus.nmt(), vec![(r.now, NmtCommand::EnterPreOperational)]);
    r.bus_event(status(StimState::PreOperational, 0));
    r.bus_event(BusEvent::Emcy(Emcy::new(
        ErrorCode::ConfigInvalid,
        StimState::PreOperational,
        0,
        2,
    )));
    assert_eq!(r.fp.state(), DriverState::ConfigRefused);
    r.command(DriverCommandKind::Arm);
    assert!(r.ev.iter().any(|e| matches!(
        e,
        DriverEvent::ArmRefused {
            refusal: ArmRefusal::NotConfigured,
            ..
        }
    )));
}

#[test]
fn arming_checks_every_precondition_and_sends_nmt_start() {
    let mut r = Rig::configured(settings());
    let refusal = |r: &Rig| {
        r.ev.iter().rev().find_map(|e| match e {
            DriverEvent::ArmRefused { refusal, .. } => Some(*refusal),
            _ => None,
        })
    };
    r.advance(MS);
    r.command(DriverCommandKind::Arm);
    assert_eq!(refusal(&r), Some(ArmRefusal::NoTicks));
    for _ in 0..3 {
        r.advance(MS);
        r.tick(true);
    }
    assert!(r.bus.pulses().is_empty(), "disarmed: nothing forwarded");
    // Ticks 1 ms apart: the second pulse breaks the 2 ms minimum IPI, the third passes.
    assert_eq!(r.fp.counters().pulses_not_armed, 2);
    assert_eq!(r.fp.counters().pulses_rejected, 1);
    r.command(DriverCommandKind::Arm);
    assert_eq!(refusal(&r), Some(ArmRefusal::PublisherNotAlive));
    r.fp.on_liveness(Liveness::Alive, r.now, &mut r.ev);
    // STATUS older than the stimulator timeout.
    let s = *r.fp.settings();
    let (t_status, now) = (r.now, r.now + s.stimulator_timeout_ns + MS);
    r.at(now);
    r.tick(false);
    r.command(DriverCommandKind::Arm);
    assert_eq!(refusal(&r), Some(ArmRefusal::StimulatorSilent));
    assert!(now > t_status);
    // Another configuration reported.
    r.bus_event(status(StimState::PreOperational, 9));
    assert_eq!(
        r.fp.state(),
        DriverState::Starting,
        "config lost: brought up again"
    );
    r.bus_event(status(StimState::PreOperational, 9));
    r.bus_event(status(StimState::PreOperational, 10));
    assert_eq!(r.fp.state(), DriverState::Disarmed);
    assert_eq!(r.fp.config_id(), Some(10));
    // A stale command.
    r.cmd_seq += 1;
    let old = DriverCommand::new(
        r.cmd_seq,
        r.now - s.command_max_age_ns - 1,
        DriverCommandKind::Arm,
    );
    r.fp.on_command(&old, r.now, &mut r.ev);
    assert_eq!(refusal(&r), Some(ArmRefusal::StaleCommand));
    // A command from the future.
    let future = DriverCommand::new(99, r.now + 2 * MS, DriverCommandKind::Arm);
    r.fp.on_command(&future, r.now, &mut r.ev);
    assert_eq!(refusal(&r), Some(ArmRefusal::StaleCommand));
    // An invalid command.
    let mut bad = DriverCommand::new(100, r.now, DriverCommandKind::Arm);
    bad.command = 7;
    r.advance(MS);
    r.fp.on_command(&bad, r.now, &mut r.ev);
    assert!(matches!(
        r.ev.last(),
        Some(DriverEvent::CommandInvalid { .. })
    ));
    r.bus.clear();
    r.advance(MS);
    r.tick(false);
    r.command(DriverCommandKind::Arm);
    assert_eq!(r.fp.state(), DriverState::Armed, "{:?}", refusal(&r));
    assert_eq!(r.bus.nmt(), vec![(r.now, NmtCommand::Start)]);
}

#[test]
fn armed_pulses_reach_the_bus_once_in_order_with_counters() {
    let mut r = Rig::armed(settings());
    r.bus.clear();
    let mut expected = Vec::new();
    for k in 0..50 {
        r.advance(MS);
        let fire = k % 5 == 0;
        r.tick(fire);
        if fire {
            expected.push(r.tick_seq);
        }
    }
    let pulses = r.bus.pulses();
    assert_eq!(pulses.len(), expected.len());
    for (i, (_, p)) in pulses.iter().enumerate() {
        assert_eq!(usize::from(p.seq), i + 1);
        assert_eq!(usize::from(p.alive_counter), i % 16);
        assert_eq!((p.amplitude_100ua, p.width_us, p.channel), (200, 200, 0));
    }
    let sent: Vec<u64> =
        r.ev.iter()
            .filter_map(|e| match e {
                DriverEvent::PulseSent { tick_seq, .. } => Some(*tick_seq),
                _ => None,
            })
            .collect();
    assert_eq!(sent, expected);
    assert_eq!(r.fp.counters().pulses_sent, 10);
}

#[test]
fn watchdog_trips_exactly_after_the_timeout_and_stays_stopped() {
    let s = settings();
    let mut r = Rig::armed(s);
    r.advance(MS);
    r.tick(true);
    let last = r.now;
    // The loop never sleeps past the watchdog's deadline.
    assert!(r.fp.next_deadline(r.now) <= last + s.tick_timeout_ns + 1);
    r.bus.clear();
    r.at(last + s.tick_timeout_ns);
    r.poll();
    assert_eq!(
        r.fp.state(),
        DriverState::Armed,
        "not at the timeout itself"
    );
    r.at(last + s.tick_timeout_ns + 1);
    r.poll();
    assert_eq!(
        r.fault(),
        Some(Fault::TickTimeout {
            silent_ns: s.tick_timeout_ns + 1
        })
    );
    assert_eq!(
        r.bus.nmt(),
        vec![(last + s.tick_timeout_ns + 1, NmtCommand::Stop)]
    );
    assert_eq!(r.fp.counters().watchdog_trips, 1);
    assert_eq!(r.fp.counters().fault_code, 0xFF21);
    // The publisher resumes (after a 100 ms stall): nothing is forwarded, no burst, and
    // the driver stays stopped.
    r.bus.clear();
    r.advance(100 * MS);
    for _ in 0..30 {
        r.advance(MS);
        r.tick(true);
    }
    assert!(r.bus.pulses().is_empty());
    assert!(r.fault().is_some());
    // Heartbeats report "stopped".
    assert!(r.bus.messages().iter().any(|(_, m)| *m
        == Message::HostHeartbeat(fes_can::Heartbeat {
            state: NmtState::Stopped
        })));
    // An explicit re-arm brings it back; the first tick after it sets the order again.
    let id = r.config_id;
    r.bus_event(status(StimState::Stopped, id));
    r.command(DriverCommandKind::Arm);
    assert_eq!(r.fp.state(), DriverState::Armed);
    r.advance(5 * MS);
    r.tick(true);
    assert_eq!(r.bus.pulses().len(), 1);
}

#[test]
fn stale_and_final_ticks_trip_and_block_arming() {
    let s = settings();
    let mut r = Rig::armed(s);
    r.advance(MS);
    r.tick_seq += 1;
    let mut t = tick(r.tick_seq, r.now - s.stale_after_ns - 1, true);
    t.t_publish_ns = t.t_ns;
    r.fp.on_tick(&t, r.now, &mut r.ev);
    assert_eq!(
        r.fault(),
        Some(Fault::StaleTick {
            age_ns: s.stale_after_ns + 1
        })
    );
    assert!(r.bus.pulses().is_empty());

    let mut r = Rig::armed(s);
    r.advance(MS);
    r.tick_seq += 1;
    let mut t = tick(r.tick_seq, r.now - 10_000, false);
    t.flags = StimTick::FLAG_FINAL;
    r.fp.on_tick(&t, r.now, &mut r.ev);
    assert_eq!(r.fault(), Some(Fault::GeneratorStopped));
    r.command(DriverCommandKind::Arm);
    assert!(r.ev.iter().any(|e| matches!(
        e,
        DriverEvent::ArmRefused {
            refusal: ArmRefusal::GeneratorStopped,
            ..
        }
    )));
}

#[test]
fn publisher_death_and_disappearance_trip() {
    for (l, f) in [
        (Liveness::Dead, Fault::PublisherDead),
        (Liveness::NoPublisher, Fault::PublisherGone),
    ] {
        let mut r = Rig::armed(settings());
        r.bus.clear();
        r.fp.on_liveness(l, r.now, &mut r.ev);
        assert_eq!(r.fault(), Some(f));
        assert_eq!(r.bus.nmt(), vec![(r.now, NmtCommand::Stop)]);
        assert!(f.is_watchdog());
    }
}

#[test]
fn supervisor_death_and_disappearance_trip_and_stay_tripped() {
    for (l, f) in [
        (Liveness::Dead, Fault::SupervisorDead),
        (Liveness::NoPublisher, Fault::SupervisorGone),
    ] {
        let mut r = Rig::armed(settings());
        r.fp.on_supervisor_liveness(Liveness::Alive, r.now, &mut r.ev);
        assert_eq!(r.fp.state(), DriverState::Armed, "alive changes nothing");
        r.bus.clear();
        r.advance(MS);
        r.fp.on_supervisor_liveness(l, r.now, &mut r.ev);
        assert_eq!(r.fault(), Some(f));
        assert!(f.is_watchdog());
        assert_eq!(r.fp.counters().fault_code, f.code());
        assert_eq!(r.bus.nmt(), vec![(r.now, NmtCommand::Stop)]);
        // Ticks keep coming: nothing is sent, and the supervisor coming back re-arms
        // nothing by itself.
        r.bus.clear();
        r.fp.on_supervisor_liveness(Liveness::Alive, r.now, &mut r.ev);
        for _ in 0..20 {
            r.advance(MS);
            r.tick(true);
        }
        assert!(r.bus.pulses().is_empty());
        assert_eq!(r.fault(), Some(f));
        // A live supervisor's Arm re-arms.
        r.command(DriverCommandKind::Arm);
        assert_eq!(r.fp.state(), DriverState::Armed, "{:?}", r.ev);
    }
}

#[test]
fn supervisor_watch_refuses_an_arm_while_dead_and_can_be_turned_off() {
    // Disarmed, supervisor seen dead: an Arm (a sample it left behind) is refused.
    let mut r = Rig::configured(settings());
    r.fp.on_liveness(Liveness::Alive, r.now, &mut r.ev);
    r.fp.on_supervisor_liveness(Liveness::Dead, r.now, &mut r.ev);
    for _ in 0..3 {
        r.advance(MS);
        r.tick(false);
    }
    r.command(DriverCommandKind::Arm);
    assert_eq!(r.fp.state(), DriverState::Disarmed);
    assert!(r.ev.iter().any(|e| matches!(
        e,
        DriverEvent::ArmRefused {
            refusal: ArmRefusal::SupervisorDead,
            ..
        }
    )));
    // Not yet checked, or no publisher listed yet (the check lags the command): accepted;
    // the supervisor must then be seen alive within the arm confirmation time, or the
    // driver trips (it used to stay armed: the unchanged "no publisher" never tripped).
    for (l, comes_alive) in [
        (Liveness::Unknown, true),
        (Liveness::NoPublisher, true),
        (Liveness::Unknown, false),
        (Liveness::NoPublisher, false),
    ] {
        let s = settings();
        let mut r = Rig::configured(s);
        r.fp.on_liveness(Liveness::Alive, r.now, &mut r.ev);
        r.fp.on_supervisor_liveness(l, r.now, &mut r.ev);
        for _ in 0..3 {
            r.advance(MS);
            r.tick(false);
        }
        r.command(DriverCommandKind::Arm);
        assert_eq!(r.fp.state(), DriverState::Armed, "{l:?}: {:?}", r.ev);
        let id = r.config_id;
        r.bus_event(status(StimState::Armed, id));
        if comes_alive {
            r.fp.on_supervisor_liveness(Liveness::Alive, r.now, &mut r.ev);
        }
        let steps = s.arm_confirm_ns / MS + 5;
        for _ in 0..steps {
            r.advance(MS);
            r.tick(false);
            r.fp.on_supervisor_liveness(
                if comes_alive { Liveness::Alive } else { l },
                r.now,
                &mut r.ev,
            );
            if r.fp.state() != DriverState::Armed {
                break;
            }
            if r.now.is_multiple_of(10 * MS) {
                r.bus_event(status(StimState::Armed, id));
            }
        }
        if comes_alive {
            assert_eq!(
                r.fp.state(),
                DriverState::Armed,
                "{l:?} then alive: {:?}",
                r.ev
            );
        } else {
            assert_eq!(
                r.fault(),
                Some(Fault::SupervisorGone),
                "{l:?} for {steps} ms after the Arm: {:?}",
                r.fp.state()
            );
        }
    }
    // Watch off: the supervisor's death changes nothing.
    let mut s = settings();
    s.supervisor_watch = false;
    let mut r = Rig::armed(s);
    r.fp.on_supervisor_liveness(Liveness::Dead, r.now, &mut r.ev);
    r.fp.on_supervisor_liveness(Liveness::NoPublisher, r.now, &mut r.ev);
    assert_eq!(r.fp.state(), DriverState::Armed);
    assert!(settings().supervisor_watch, "on by default");
}

#[test]
fn stimulator_emcy_reset_silence_and_unconfirmed_start_trip() {
    let s = settings();
    let mut r = Rig::armed(s);
    r.bus_event(BusEvent::Emcy(Emcy::new(
        ErrorCode::NoError,
        StimState::Armed,
        0,
        0,
    )));
    assert_eq!(
        r.fp.state(),
        DriverState::Armed,
        "'no error' is not a fault"
    );
    r.bus_event(BusEvent::Emcy(Emcy::new(
        ErrorCode::MinIpiViolation,
        StimState::Armed,
        4,
        1,
    )));
    assert_eq!(
        r.fault(),
        Some(Fault::StimulatorEmcy {
            code: ErrorCode::MinIpiViolation,
            detail: 1
        })
    );
    assert_eq!(r.fp.counters().fault_code, 0xFF01);

    let mut r = Rig::armed(s);
    r.bus_event(BusEvent::StimHeartbeat(NmtState::BootUp));
    assert_eq!(r.fault(), Some(Fault::StimulatorReset));
    assert_eq!(
        r.bus.nmt().last().map(|n| n.1),
        Some(NmtCommand::EnterPreOperational),
        "brought up again"
    );

    let mut r = Rig::armed(s);
    for _ in 0..(s.stimulator_timeout_ns / MS) + 1 {
        r.advance(MS);
        r.tick(false);
    }
    assert!(matches!(r.fault(), Some(Fault::StimulatorSilent { .. })));

    let mut r = Rig::configured(s);
    r.fp.on_liveness(Liveness::Alive, r.now, &mut r.ev);
    r.advance(MS);
    r.tick(false);
    r.command(DriverCommandKind::Arm);
    assert_eq!(r.fp.state(), DriverState::Armed);
    // STATUS keeps showing pre-operational: the start did not take.
    for _ in 0..(s.arm_confirm_ns / MS) + 1 {
        r.advance(MS);
        r.tick(false);
        if r.now.is_multiple_of(10 * MS) {
            let id = r.config_id;
            r.bus_event(status(StimState::PreOperational, id));
        }
    }
    assert_eq!(r.fault(), Some(Fault::StimulatorNotOperational));

    // Confirmed, then the stimulator leaves operational by itself.
    let mut r = Rig::armed(s);
    let id = r.config_id;
    r.bus_event(status(StimState::Fault, id));
    assert_eq!(r.fault(), Some(Fault::StimulatorNotOperational));
}

#[test]
fn link_down_trips_and_the_stop_is_sent_when_the_link_returns() {
    let mut r = Rig::armed(settings());
    r.bus.clear();
    r.bus.fail.set(Some(TxError::LinkDown {
        errno: libc::ENETDOWN,
    }));
    r.advance(MS);
    r.tick(true);
    assert_eq!(r.fault(), Some(Fault::LinkDown));
    assert!(r.bus.frames.borrow().is_empty());
    // Still down: arming is refused, nothing is sent.
    r.advance(MS);
    r.tick(false);
    r.command(DriverCommandKind::Arm);
    assert!(r.ev.iter().any(|e| matches!(
        e,
        DriverEvent::ArmRefused {
            refusal: ArmRefusal::LinkDown,
            ..
        }
    )));
    // Back up: the pending stop goes out first.
    r.bus.fail.set(None);
    r.advance(MS);
    r.bus_event(BusEvent::LinkUp);
    assert_eq!(r.bus.nmt(), vec![(r.now, NmtCommand::Stop)]);
    // Re-arm once the stimulator is heard again.
    r.advance(MS);
    let id = r.config_id;
    r.bus_event(status(StimState::Fault, id));
    r.tick(false);
    r.command(DriverCommandKind::Arm);
    assert_eq!(r.fp.state(), DriverState::Armed);
}

#[test]
fn bus_off_a_down_interface_and_lost_events_trip() {
    for (e, f) in [
        (BusEvent::BusError(BusErrorKind::BusOff), Fault::BusOff),
        (BusEvent::LinkDown, Fault::LinkDown),
        (BusEvent::EventsLost, Fault::BusEventsLost),
    ] {
        let mut r = Rig::armed(settings());
        r.bus_event(e);
        assert_eq!(r.fault(), Some(f));
    }
    let mut r = Rig::armed(settings());
    r.bus_event(BusEvent::BusError(BusErrorKind::ErrorPassive));
    assert_eq!(
        r.fp.state(),
        DriverState::Armed,
        "error-passive is reported only"
    );
}

/// A frame on one of the driver's own identifiers that it did not write: a trip in every
/// mode, NMT stop at once, the named fault with the COB-ID and kind in
/// `DriverStatus.fault_code` (0xFF30); every further one is stopped again without a new
/// trip; only an Arm leaves it.
#[test]
fn a_foreign_frame_on_an_own_identifier_trips_in_every_mode() {
    let nodes = Nodes::DEFAULT;
    for kind in [
        fes_can::MessageKind::Nmt,
        fes_can::MessageKind::Pulse,
        fes_can::MessageKind::Config,
        fes_can::MessageKind::HostHeartbeat,
    ] {
        let cob_id = nodes.id_of(kind);
        let intrusion = BusEvent::Intrusion { cob_id, kind };
        let starting = {
            let mut r = Rig::new(settings());
            r.fp.start(r.now, &mut r.ev);
            r
        };
        for (mode, mut r) in [
            ("starting", starting),
            ("disarmed", Rig::configured(settings())),
            ("armed", Rig::armed(settings())),
        ] {
            r.bus.clear();
            r.advance(MS);
            r.bus_event(intrusion);
            let fault = Fault::Intrusion { cob_id, kind };
            assert_eq!(r.fault(), Some(fault), "{kind:?} while {mode}");
            assert_eq!(r.fp.counters().fault_code, 0xFF30);
            assert_eq!(r.bus.nmt(), vec![(r.now, NmtCommand::Stop)], "{mode}");
            assert!(r.ev.contains(&DriverEvent::Tripped {
                fault,
                stop_sent: true
            }));
            assert!(
                fault.to_string().contains(&format!("{cob_id:#05x}")),
                "{fault}"
            );
            // Another one: stopped again at once, no second trip.
            let trips = r.fp.counters().trips;
            r.advance(MS);
            r.bus_event(intrusion);
            assert_eq!(r.fp.counters().trips, trips);
            assert_eq!(r.bus.nmt().len(), 2, "{mode}: stopped again");
            // Nothing re-arms by itself; pulses are not forwarded.
            for _ in 0..5 {
                r.advance(MS);
                r.tick(true);
            }
            assert_eq!(r.fault(), Some(fault));
            assert!(r.bus.pulses().is_empty());
        }
    }
    // An intrusion overrides an earlier, other safe state (the named fault is the
    // intrusion's).
    let mut r = Rig::armed(settings());
    r.command(DriverCommandKind::SafeStop);
    assert_eq!(r.fault(), Some(Fault::SafeStopCommand));
    r.bus_event(BusEvent::Intrusion {
        cob_id: 0x000,
        kind: fes_can::MessageKind::Nmt,
    });
    assert!(matches!(
        r.fault(),
        Some(Fault::Intrusion { cob_id: 0, .. })
    ));
}

/// STATUS reconciliation: a stimulator that applied every PULSE written
/// since the Arm, or all but those written within the in-flight window
/// (`stimulator_timeout_ms`), passes; one pulse more than written, or one missing that
/// was written before the window, trips 0xFF31 with NMT stop.
#[test]
fn status_reconciles_delivered_pulses_with_pulses_written() {
    let s = settings();
    let window = s.stimulator_timeout_ns;
    // The stimulator had applied 1000 pulses before this driver armed.
    let armed = |r: &mut Rig| {
        let id = r.config_id;
        r.bus_event(status_delivered(StimState::PreOperational, id, 1000));
        r.advance(MS);
        r.tick(false);
        r.command(DriverCommandKind::Arm);
        assert_eq!(r.fp.state(), DriverState::Armed);
        r.advance(MS);
        r.bus_event(status_delivered(StimState::Armed, id, 1000));
    };
    // `n` pulses 50 ms apart, with a STATUS every 10 ms from a stimulator that applies
    // each at once.
    let pulses = |r: &mut Rig, n: u32| {
        let id = r.config_id;
        for _ in 0..n {
            for k in 0..50 {
                r.advance(MS);
                r.tick(k == 0);
                if k % 10 == 5 {
                    let applied = r.bus.pulses().len() as u32;
                    r.bus_event(status_delivered(StimState::Stimulating, id, 1000 + applied));
                }
            }
        }
        assert_eq!(r.fp.state(), DriverState::Armed, "{:?}", r.fault());
    };
    // Honest, with the pulses of the last window (the last 2, 50 ms apart) in flight.
    let mut r = Rig::configured(s);
    r.fp.on_liveness(Liveness::Alive, r.now, &mut r.ev);
    r.fp.on_supervisor_liveness(Liveness::Alive, r.now, &mut r.ev);
    armed(&mut r);
    pulses(&mut r, 10);
    assert_eq!(r.bus.pulses().len(), 10);
    let id = r.config_id;
    for delivered in [1008, 1009, 1010] {
        r.bus_event(status_delivered(StimState::Stimulating, id, delivered));
        assert_eq!(r.fp.state(), DriverState::Armed, "{delivered} delivered");
    }
    // One more than written: a pulse the driver never sent was applied.
    r.bus_event(status_delivered(StimState::Stimulating, id, 1011));
    assert_eq!(
        r.fault(),
        Some(Fault::DeliveryMismatch {
            sent: 10,
            delivered: 11,
            allowed: 0
        })
    );
    assert_eq!(r.fp.counters().fault_code, 0xFF31);
    assert_eq!(r.bus.nmt().last().map(|(_, c)| *c), Some(NmtCommand::Stop));

    // Fewer: fine while the missing ones are in flight, a trip once they are older.
    let mut r = Rig::configured(s);
    r.fp.on_liveness(Liveness::Alive, r.now, &mut r.ev);
    r.fp.on_supervisor_liveness(Liveness::Alive, r.now, &mut r.ev);
    armed(&mut r);
    pulses(&mut r, 4);
    let id = r.config_id;
    r.bus_event(status_delivered(StimState::Stimulating, id, 1003));
    assert_eq!(r.fp.state(), DriverState::Armed);
    // Quiet for the window and one bucket more (ticks keep the watchdog fed).
    let quiet_until = r.now + window + window / 16 + MS;
    while r.now < quiet_until {
        r.advance(MS);
        r.tick(false);
        r.bus_event(status_delivered(StimState::Armed, id, 1004));
    }
    assert_eq!(r.fp.state(), DriverState::Armed);
    r.bus_event(status_delivered(StimState::Armed, id, 1003));
    assert_eq!(
        r.fault(),
        Some(Fault::DeliveryMismatch {
            sent: 4,
            delivered: 3,
            allowed: 0
        })
    );

    // A quick re-arm: pulses of the last armed period applied after the baseline STATUS
    // are carried, not counted as forged.
    let mut r = Rig::configured(s);
    r.fp.on_liveness(Liveness::Alive, r.now, &mut r.ev);
    r.fp.on_supervisor_liveness(Liveness::Alive, r.now, &mut r.ev);
    armed(&mut r);
    pulses(&mut r, 1);
    let id = r.config_id;
    // The baseline STATUS does not show the pulse yet.
    r.bus_event(status_delivered(StimState::Stimulating, id, 1000));
    r.command(DriverCommandKind::Disarm);
    r.advance(MS);
    r.tick(false);
    r.command(DriverCommandKind::Arm);
    assert_eq!(r.fp.state(), DriverState::Armed);
    r.advance(MS);
    // The carry is the 1 pulse written within the window before the Arm: applied after
    // the baseline, it passes; one more does not.
    r.bus_event(status_delivered(StimState::Armed, id, 1001));
    assert_eq!(r.fp.state(), DriverState::Armed, "{:?}", r.fault());
    r.bus_event(status_delivered(StimState::Armed, id, 1002));
    assert_eq!(
        r.fault(),
        Some(Fault::DeliveryMismatch {
            sent: 0,
            delivered: 2,
            allowed: 1
        })
    );
}

#[test]
fn a_dropped_pulse_is_counted_and_does_not_trip() {
    let mut r = Rig::armed(settings());
    r.bus.fail.set(Some(TxError::Dropped { attempts: 5 }));
    r.advance(MS);
    r.tick(true);
    assert_eq!(r.fp.state(), DriverState::Armed);
    assert_eq!(r.fp.counters().can_tx_errors, 1);
    assert_eq!(r.fp.counters().tx_retries, 4);
    assert_eq!(r.fp.counters().pulses_sent, 0);
    r.bus.fail.set(None);
    r.advance(5 * MS);
    r.tick(true);
    let p = r.bus.pulses();
    assert_eq!(p.len(), 1);
    assert_eq!(
        (p[0].1.seq, p[0].1.alive_counter),
        (1, 0),
        "no gap left behind"
    );
}

#[test]
fn commands_disarm_and_safe_stop() {
    let mut r = Rig::armed(settings());
    r.bus.clear();
    r.command(DriverCommandKind::Disarm);
    assert_eq!(r.fp.state(), DriverState::Disarmed);
    assert_eq!(r.bus.nmt(), vec![(r.now, NmtCommand::Stop)]);
    r.advance(MS);
    r.tick(true);
    assert!(r.bus.pulses().is_empty());
    // SafeStop works from any state and is a fault until re-armed; an old one still stops.
    r.bus.clear();
    r.cmd_seq += 1;
    let old = DriverCommand::new(r.cmd_seq, r.now - 500 * MS, DriverCommandKind::SafeStop);
    r.fp.on_command(&old, r.now, &mut r.ev);
    assert_eq!(r.fault(), Some(Fault::SafeStopCommand));
    assert_eq!(r.bus.nmt(), vec![(r.now, NmtCommand::Stop)]);
    // Disarm does not clear the safe state.
    r.advance(MS);
    r.command(DriverCommandKind::Disarm);
    assert_eq!(r.fault(), Some(Fault::SafeStopCommand));
}

/// The supervisor re-sends SafeStop every 50 ms until it reads the acknowledgement: each
/// repeat while safe writes NMT stop again and is acknowledged, but is not a new trip, and
/// the fault that made the driver safe stays the named one (the boot test's starved guest
/// logged a dozen "SAFE STATE" errors for one stop).
#[test]
fn a_repeated_safe_stop_keeps_the_first_fault() {
    let mut r = Rig::armed(settings());
    r.bus_event(BusEvent::Intrusion {
        cob_id: 0x000,
        kind: fes_can::MessageKind::Nmt,
    });
    let fault = r.fault().expect("tripped");
    assert!(matches!(fault, Fault::Intrusion { .. }));
    let trips = r.fp.counters().trips;
    for _ in 0..3 {
        r.bus.clear();
        r.advance(50 * MS);
        r.command(DriverCommandKind::SafeStop);
        assert_eq!(
            r.bus.nmt(),
            vec![(r.now, NmtCommand::Stop)],
            "stopped again"
        );
        let c = r.fp.counters();
        assert_eq!(
            (c.command_seq, c.command_result),
            (r.cmd_seq, CommandResult::Accepted as u8),
            "acknowledged"
        );
    }
    assert_eq!(r.fp.counters().trips, trips, "no new trip");
    assert_eq!(r.fault(), Some(fault));
}

#[test]
fn a_stimulator_still_operational_while_disarmed_is_stopped_again() {
    let mut r = Rig::armed(settings());
    r.command(DriverCommandKind::Disarm);
    r.bus.clear();
    let id = r.config_id;
    r.advance(MS);
    r.bus_event(status(StimState::Stimulating, id));
    assert!(r.bus.nmt().is_empty(), "not within 10 ms of the last stop");
    r.advance(10 * MS);
    r.bus_event(status(StimState::Stimulating, id));
    assert_eq!(r.bus.nmt(), vec![(r.now, NmtCommand::Stop)]);
    assert!(r.ev.contains(&DriverEvent::StopResent));
}

#[test]
fn heartbeat_every_period_with_the_host_state_and_no_burst_after_a_stall() {
    let s = settings();
    let mut r = Rig::configured(s);
    r.bus.clear();
    let start = r.now;
    for _ in 0..100 {
        r.advance(MS);
        r.poll();
    }
    let beats: Vec<(u64, NmtState)> = r
        .bus
        .messages()
        .into_iter()
        .filter_map(|(t, m)| match m {
            Message::HostHeartbeat(h) => Some((t, h.state)),
            _ => None,
        })
        .collect();
    assert_eq!(beats.len(), 10);
    assert!(beats.iter().all(|b| b.1 == NmtState::PreOperational));
    for w in beats.windows(2) {
        assert_eq!(w[1].0 - w[0].0, s.heartbeat_ns);
    }
    assert!(beats[0].0 <= start + s.heartbeat_ns);
    // A 95 ms stall of the loop: one heartbeat, not nine.
    r.bus.clear();
    r.advance(95 * MS);
    r.poll();
    r.poll();
    assert_eq!(r.bus.messages().len(), 1);
    assert!(r.fp.next_deadline(r.now) <= r.now + s.heartbeat_ns);
    assert!(r.fp.next_deadline(r.now) <= r.now + s.max_wait_ns);
}

#[test]
fn shutdown_stops_the_stimulator_and_reports_stopped() {
    let mut r = Rig::armed(settings());
    r.bus.clear();
    r.fp.shutdown(r.now, &mut r.ev);
    let m = r.bus.messages();
    assert_eq!(m.len(), 2);
    assert_eq!(
        m[0].1,
        Message::Nmt(fes_can::Nmt {
            command: NmtCommand::Stop,
            node: Nodes::DEFAULT.stim()
        })
    );
    assert_eq!(
        m[1].1,
        Message::HostHeartbeat(fes_can::Heartbeat {
            state: NmtState::Stopped
        })
    );
    assert!(r.ev.contains(&DriverEvent::Shutdown { stop_sent: true }));
}

#[test]
fn defective_ticks_are_refused_and_do_not_feed_the_watchdog() {
    let s = settings();
    let mut r = Rig::armed(s);
    r.advance(MS);
    r.tick(false);
    let last_good = r.now;
    // Duplicates of the last tick keep arriving: they are refused and the watchdog still
    // trips on time.
    for _ in 0..3 {
        r.advance(MS);
        let dup = tick(r.tick_seq, r.now - 20_000, false);
        r.fp.on_tick(&dup, r.now, &mut r.ev);
        r.poll();
    }
    r.at(last_good + s.tick_timeout_ns + 1);
    r.poll();
    assert!(matches!(r.fault(), Some(Fault::TickTimeout { .. })));
    assert_eq!(r.fp.counters().ticks_refused, 3);
}

#[test]
fn a_restarted_generator_is_followed_once_nothing_is_forwarded() {
    let mut r = Rig::armed(settings());
    for _ in 0..5 {
        r.advance(MS);
        r.tick(false);
    }
    // rt-core restarts: `seq` from 1 again. Armed, its ticks are refused as out of order
    // (they are no sign of life) and the watchdog trips after 3 ticks.
    r.tick_seq = 0;
    for _ in 0..4 {
        r.advance(MS);
        r.tick(false);
    }
    assert!(
        matches!(r.fault(), Some(Fault::TickTimeout { .. })),
        "{:?}",
        r.fp.state()
    );
    assert_eq!(r.fp.counters().ticks_refused, 4);
    // Not armed, the new order is taken up: its ticks are valid and an Arm succeeds.
    for _ in 0..3 {
        r.advance(MS);
        r.tick(false);
    }
    assert_eq!(r.fp.counters().ticks_refused, 4, "no more refusals");
    r.command(DriverCommandKind::Arm);
    assert_eq!(r.fp.state(), DriverState::Armed, "{:?}", r.ev);
}

use crate::on_bus;

/// The binary end to end on CAN, with the fault scenarios, in one harness run (one UML
/// boot): see `support/on_bus.rs`. Run it with `--ignored` (docs/stim-driver.md): on this
/// project's 2-core machines under a load average of 7-12, the UML guest stalls its 1 ms
/// loops by up to a second, and the virtual stimulator then reads queued PULSE frames
/// in one tick (an IPI violation at the stimulator) or misses the host heartbeat; the driver
/// handles each case correctly (refuses late pulses, trips, reports), but the scenario
/// cannot complete. On a native CAN bus or a quiet machine it is meant to run always.
#[test]
#[ignore = "needs a native CAN bus or a quiet machine: see the doc comment"]
fn driver_on_the_bus() {
    fes_testkit::vcan::with_vcan(on_bus::driver_on_the_bus);
}

/// The same scenarios (1-4; the link-down scenario needs a CAN interface) with the driver and
/// the virtual stimulator on the host bus (`fes_hostbus`: the same CAN frames over Unix
/// datagrams, docs/vcan.md), observed by its tap station: runs by default on hosts without
/// CAN, at the host's timing.
#[test]
fn driver_on_the_host_bus() {
    on_bus::driver_on_the_bus(&fes_testkit::vcan::CanEnv::host_bus("driver"));
}

/// Not a test: the scripted StimTick publisher process that [`driver_on_the_bus`] starts
/// (this binary re-executed with `--exact --ignored` and the script in the environment).
#[test]
#[ignore = "helper process of driver_on_the_bus; does nothing when run by itself"]
fn scripted_tick_publisher() {
    if let Ok(spec) = std::env::var(on_bus::ENV_PUBLISHER) {
        on_bus::run_publisher(&spec);
    }
}

/// A prescription that allows the driver's default limits (100 mA, 500 us, 50 uC, 2 ms,
/// 100 pulses/s).
const DEFAULT_LIMITS_PRESCRIPTION: &str = r#"format = "fes-prescription/1"
max_amplitude_ua = 100000
max_phase_width_us = 500
max_charge_per_phase_nc = 50000
min_ipi_us = 2000
max_pulses_per_s = 100
"#;

/// Bad-input sweep of the binary's configuration: each malformed file
/// makes `run --config FILE --check` and a real `run` on a host bus exit 1 with a short
/// message naming the problem and no panic, and nothing reaches the bus.
#[test]
fn malformed_configurations_are_refused_clearly_without_a_panic() {
    use std::process::Command;
    const EXE: &str = env!("CARGO_BIN_EXE_stim-driver");
    let example = Command::new(EXE).arg("example-config").output().unwrap();
    assert!(example.status.success());
    let good = String::from_utf8(example.stdout).unwrap();
    let dir = fes_testkit::Scratch::new("stim-driver-badcfg");
    // The example's limits are the driver's defaults: a prescription that allows them.
    let prescription = dir.join("prescription.toml");
    std::fs::write(&prescription, DEFAULT_LIMITS_PRESCRIPTION).unwrap();
    let default_path = "prescription = \"/etc/fes/prescription.toml\"";
    assert!(
        good.contains(default_path),
        "example names the default prescription"
    );
    let good = good.replace(
        default_path,
        &format!("prescription = \"{}\"", prescription.display()),
    );
    let edit = |from: &str, to: &str| {
        assert!(good.contains(from), "example has no {from:?}");
        good.replacen(from, to, 1).into_bytes()
    };
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        (
            "schema",
            edit("fes-stim-driver/1", "fes-stim-driver/9"),
            "fes-stim-driver/9",
        ),
        ("nan", edit("max_n = 40.0", "max_n = nan"), "max_n"),
        ("inf", edit("max_n = 40.0", "max_n = inf"), "max_n"),
        ("negative", edit("max_n = 40.0", "max_n = -1.0"), "max_n"),
        (
            "negative time",
            edit("watchdog_ms = 100", "watchdog_ms = -100"),
            "watchdog_ms",
        ),
        (
            "zero time",
            edit("tick_period_us = 1000", "tick_period_us = 0"),
            "tick_period_us",
        ),
        (
            "huge",
            edit(
                "max_pulses = 100\nrate",
                "max_pulses = 99999999999999\nrate",
            ),
            "max_pulses",
        ),
        (
            "huge amplitude",
            edit(
                "max_amplitude_ua = 100000\nmax_width_us = 500\nmax_charge",
                "max_amplitude_ua = 4000000000\nmax_width_us = 500\nmax_charge",
            ),
            "max_amplitude_ua",
        ),
        (
            "channel",
            edit("channels = [0]", "channels = [99]"),
            "channels",
        ),
        ("unknown key", edit("[force]", "[force]\ntypo = 1"), "typo"),
        (
            "truncated",
            good.as_bytes()[..good.len() / 3].to_vec(),
            "configuration",
        ),
        (
            "non-UTF-8",
            [
                &good.as_bytes()[..40],
                &[0xFF, 0xFE][..],
                &good.as_bytes()[40..],
            ]
            .concat(),
            "UTF-8",
        ),
    ];
    // Each file is refused twice: by `--check`, and by a real `run` on a host bus with a
    // tap listening, which must see nothing (the configuration is refused before the bus
    // is touched).
    let bus = fes_testkit::bus::SilentBus::new("driver-badcfg");
    let refused = |name: &str, args: &[&str], needle: &str| {
        let out = Command::new(EXE)
            .args(args)
            .env("RUST_BACKTRACE", "0")
            .output()
            .unwrap();
        fes_testkit::assert_refused(name, &out, &[1], needle, 6);
        bus.assert_silent(name);
    };
    let path = dir.join("bad.toml");
    let config = path.to_str().expect("UTF-8 path");
    let iface = bus.iface();
    for (name, bytes, needle) in cases {
        std::fs::write(&path, &bytes).unwrap();
        refused(name, &["run", "--check", "--config", config], needle);
        let run = ["run", "--config", config, "--iface", &iface];
        refused(&format!("{name} (run)"), &run, needle);
    }
    // A good file with an interface that is not one.
    std::fs::write(&path, &good).unwrap();
    let relative = ["run", "--config", config, "--iface", "hostbus:relative/dir"];
    refused("relative host bus (run)", &relative, "can.iface");
    let missing = dir.join("missing.toml");
    let missing = missing.to_str().expect("UTF-8 path");
    let check_missing = ["run", "--check", "--config", missing];
    refused("missing file", &check_missing, "missing.toml");
    // The good file passes the same check (the sweep is not refusing everything).
    let path = dir.join("good.toml");
    std::fs::write(&path, &good).unwrap();
    let out = Command::new(EXE)
        .args(["run", "--check", "--config"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The driver's outcome of every pulse decision (what the recording records as
/// delivered): not armed before the Arm, sent while armed, refused by an interlock,
/// not armed again after a disarm; one outcome per tick that asked for a pulse, none for
/// the others.
#[test]
fn every_pulse_decision_gets_its_outcome() {
    let outcomes = |r: &Rig| -> Vec<(u64, PulseFate)> {
        r.ev.iter()
            .filter_map(|e| match e {
                DriverEvent::Outcome { tick_seq, fate, .. } => Some((*tick_seq, *fate)),
                _ => None,
            })
            .collect()
    };
    let mut r = Rig::configured(settings());
    r.fp.on_liveness(Liveness::Alive, r.now, &mut r.ev);
    r.fp.on_supervisor_liveness(Liveness::Alive, r.now, &mut r.ev);
    r.advance(MS);
    r.tick(true);
    let before_arm = r.tick_seq;
    r.advance(MS);
    r.tick(false);
    r.command(DriverCommandKind::Arm);
    r.advance(30 * MS);
    r.tick(true);
    let sent = r.tick_seq;
    // The next pulse 1 ms later breaks the minimum inter-pulse interval: refused.
    r.advance(MS);
    r.tick(true);
    let refused = r.tick_seq;
    r.command(DriverCommandKind::Disarm);
    r.advance(30 * MS);
    r.tick(true);
    let after_disarm = r.tick_seq;
    assert_eq!(
        outcomes(&r),
        vec![
            (before_arm, PulseFate::NotArmed),
            (sent, PulseFate::Sent),
            (refused, PulseFate::Refused),
            (after_disarm, PulseFate::NotArmed),
        ],
        "{:?}",
        r.ev
    );
    assert_eq!(r.bus.pulses().len(), 1);
}

/// Every command is acknowledged in the counters the DriverStatus carries: an Arm refused
/// with its reason, an Arm accepted, a Disarm and a SafeStop accepted, an invalid command
/// refused as invalid.
#[test]
fn every_command_is_acknowledged_with_its_outcome() {
    let ack = |r: &Rig| {
        let c = r.fp.counters();
        (c.command_seq, c.command_result, c.command_reason)
    };
    let mut r = Rig::configured(settings());
    assert_eq!(ack(&r), (0, 0, 0));
    // No ticks yet: the Arm is refused.
    r.command(DriverCommandKind::Arm);
    assert_eq!(
        ack(&r),
        (
            r.cmd_seq,
            CommandResult::Refused as u8,
            CommandRefusal::NoTicks as u8
        )
    );
    r.fp.on_liveness(Liveness::Alive, r.now, &mut r.ev);
    r.fp.on_supervisor_liveness(Liveness::Alive, r.now, &mut r.ev);
    for _ in 0..3 {
        r.advance(MS);
        r.tick(false);
    }
    r.command(DriverCommandKind::Arm);
    assert_eq!(r.fp.state(), DriverState::Armed);
    assert_eq!(ack(&r), (r.cmd_seq, CommandResult::Accepted as u8, 0));
    r.advance(MS);
    r.command(DriverCommandKind::Disarm);
    assert_eq!(ack(&r), (r.cmd_seq, CommandResult::Accepted as u8, 0));
    r.advance(MS);
    r.command(DriverCommandKind::SafeStop);
    assert_eq!(ack(&r), (r.cmd_seq, CommandResult::Accepted as u8, 0));
    r.cmd_seq += 1;
    let mut bad = DriverCommand::new(r.cmd_seq, r.now, DriverCommandKind::Arm);
    bad.reserved[0] = 1;
    r.fp.on_command(&bad, r.now, &mut r.ev);
    assert_eq!(
        ack(&r),
        (
            r.cmd_seq,
            CommandResult::Refused as u8,
            CommandRefusal::InvalidCommand as u8
        )
    );
    // What the DriverStatus carries validates and decodes to the same.
    let s = stim_driver::report::driver_status(1, r.now, r.fp.counters());
    assert_eq!(s.validate(), Ok(()));
    assert_eq!(
        s.command_ack(),
        Ok(CommandAck::Refused {
            seq: r.cmd_seq,
            reason: CommandRefusal::InvalidCommand
        })
    );
}

/// A liveness that stays unknown (the node's state unreadable) beyond the grace period
/// counts as dead while armed: the StimTick publisher's trips PublisherDead, the
/// supervisor's SupervisorDead; within the grace nothing trips, and an Arm is refused while
/// the supervisor's has been unknown too long.
#[test]
fn a_liveness_unknown_beyond_its_grace_counts_as_dead() {
    let s = settings();
    let grace = s.liveness_unknown_grace_ns;
    assert!(grace > 0);
    for supervisor in [false, true] {
        let mut r = Rig::armed(s);
        let id = r.config_id;
        if supervisor {
            r.fp.on_supervisor_liveness(Liveness::Unknown, r.now, &mut r.ev);
        } else {
            r.fp.on_liveness(Liveness::Unknown, r.now, &mut r.ev);
        }
        let since = r.now;
        // Ticks and STATUS keep coming: only the unknown liveness can trip.
        while r.now < since + grace {
            r.advance(MS);
            r.bus_event(status(StimState::Armed, id));
            r.tick(false);
            assert_eq!(r.fp.state(), DriverState::Armed, "within the grace");
        }
        assert!(r.fp.next_deadline(r.now) <= since + grace + 1);
        r.advance(MS);
        r.bus_event(status(StimState::Armed, id));
        r.tick(false);
        let expected = if supervisor {
            Fault::SupervisorDead
        } else {
            Fault::PublisherDead
        };
        assert_eq!(r.fault(), Some(expected), "supervisor: {supervisor}");
        if supervisor {
            r.command(DriverCommandKind::Arm);
            assert_eq!(r.fault(), Some(expected), "re-armed while unknown");
        }
    }
}

/// After CONFIG the stimulator reads back the limits it applied (CONFIG_APPLIED); the
/// driver arms only when they equal what it sent. A stimulator that
/// applied a looser amplitude ceiling than requested is refused at arm, with NMT start never
/// sent; one that read back nothing is refused too; an exact read-back arms.
#[test]
fn a_stimulator_that_applies_a_looser_limit_is_refused_at_arm() {
    // The prescription's dose as the run's CONFIG: 20 mA, 200 us, 4 uC per phase.
    let mut s = settings();
    s.stim_limits = StimLimits {
        max_amplitude_100ua: 200,
        max_width_us: 200,
        max_charge_10nc: 400,
        ..s.stim_limits
    };
    let ready = |r: &mut Rig| {
        r.fp.on_liveness(Liveness::Alive, r.now, &mut r.ev);
        r.fp.on_supervisor_liveness(Liveness::Alive, r.now, &mut r.ev);
        for _ in 0..3 {
            r.advance(MS);
            r.tick(false);
        }
        r.bus.clear();
        r.command(DriverCommandKind::Arm);
    };
    let refusal = |r: &Rig| {
        r.ev.iter().rev().find_map(|e| match e {
            DriverEvent::ArmRefused { refusal, .. } => Some(*refusal),
            _ => None,
        })
    };
    let bring_up = |readback: Option<StimLimits>| {
        let mut r = Rig::new(s);
        r.auto_readback = false;
        r.fp.start(r.now, &mut r.ev);
        r.advance(MS);
        r.bus_event(status(StimState::PreOperational, 7));
        if let Some(l) = readback {
            for e in recording_bus::applied(&l, 8) {
                r.bus_event(e);
            }
        }
        r.advance(MS);
        r.bus_event(status(StimState::PreOperational, 8));
        r
    };
    // The stimulator kept its own 100 mA ceiling and says so.
    let looser = StimLimits {
        max_amplitude_100ua: 1000,
        ..s.stim_limits
    };
    let mut r = bring_up(Some(looser));
    assert!(
        r.ev.iter().any(|e| matches!(
            e,
            DriverEvent::BringUp(stim_driver::event::BringUp::LimitsReadBack {
                config_id: 8,
                differs: Some("max_amplitude")
            })
        )),
        "{:?}",
        r.ev
    );
    assert_eq!(r.fp.state(), DriverState::ConfigRefused);
    ready(&mut r);
    assert_eq!(
        refusal(&r),
        Some(ArmRefusal::StimulatorLimitsDiffer {
            field: "max_amplitude"
        })
    );
    assert!(!r.fp.is_armed());
    assert!(r.bus.nmt().is_empty(), "no NMT start: {:?}", r.bus.nmt());
    // A looser charge ceiling alone is refused the same way.
    let mut r = bring_up(Some(StimLimits {
        max_charge_10nc: 401,
        ..s.stim_limits
    }));
    ready(&mut r);
    assert_eq!(
        refusal(&r),
        Some(ArmRefusal::StimulatorLimitsDiffer {
            field: "max_charge"
        })
    );
    // No read-back: STATUS confirms the id, but what is enforced is unknown.
    let mut r = bring_up(None);
    assert_eq!(r.fp.state(), DriverState::Disarmed);
    ready(&mut r);
    assert_eq!(refusal(&r), Some(ArmRefusal::LimitsNotReadBack));
    assert!(r.bus.nmt().is_empty());
    // The exact limits read back: armed, NMT start sent.
    let mut r = bring_up(Some(s.stim_limits));
    ready(&mut r);
    assert_eq!(r.fp.state(), DriverState::Armed, "{:?}", r.ev);
    assert_eq!(r.bus.nmt(), vec![(r.now, NmtCommand::Start)]);
}

/// While armed, the limits the stimulator reads back must stay the ones checked at the
/// Arm: a CONFIG_APPLIED with a looser ceiling (a CONFIG another sender wrote, or a
/// stimulator that changed what it enforces) trips the driver with 0xFF32 and NMT stop,
/// naming the limit; it stays in its safe state. The same read-back again changes
/// nothing. (Before, an armed driver only logged it.)
#[test]
fn limits_read_back_changing_while_armed_trip() {
    let s = settings();
    let mut r = Rig::new(s);
    r.auto_readback = false;
    r.fp.start(r.now, &mut r.ev);
    r.advance(MS);
    r.bus_event(status(StimState::PreOperational, 7));
    for e in recording_bus::applied(&s.stim_limits, 8) {
        r.bus_event(e);
    }
    r.advance(MS);
    r.bus_event(status(StimState::PreOperational, 8));
    r.fp.on_liveness(Liveness::Alive, r.now, &mut r.ev);
    r.fp.on_supervisor_liveness(Liveness::Alive, r.now, &mut r.ev);
    for _ in 0..3 {
        r.advance(MS);
        r.tick(false);
    }
    r.command(DriverCommandKind::Arm);
    assert!(r.fp.is_armed(), "{:?}", r.ev);
    // The same limits read back again: nothing happens.
    for e in recording_bus::applied(&s.stim_limits, 8) {
        r.bus_event(e);
    }
    assert!(r.fp.is_armed(), "{:?}", r.ev);
    r.bus.clear();
    let looser = StimLimits {
        max_amplitude_100ua: s.stim_limits.max_amplitude_100ua * 5,
        ..s.stim_limits
    };
    for e in recording_bus::applied(&looser, 8) {
        r.bus_event(e);
    }
    assert!(!r.fp.is_armed());
    assert_eq!(r.fp.counters().fault_code, 0xFF32);
    assert_eq!(r.bus.nmt(), vec![(r.now, NmtCommand::Stop)]);
    assert!(
        r.ev.iter().any(|e| matches!(
            e,
            DriverEvent::Tripped {
                fault: Fault::LimitsChanged {
                    field: "max_amplitude"
                },
                ..
            }
        )),
        "{:?}",
        r.ev
    );
}

/// A lost CONFIG_APPLIED page must not refuse every Arm until a restart: the retry time
/// after a confirmation whose read-back is incomplete, the configuration starts over with a
/// fresh id (NMT enter pre-operational, new CONFIG pages), and a complete read-back of that
/// attempt arms. Not before the retry time, and not when the read-back was complete.
#[test]
fn an_incomplete_read_back_starts_the_configuration_over() {
    let s = settings();
    let mut r = Rig::new(s);
    r.auto_readback = false;
    r.fp.start(r.now, &mut r.ev);
    r.advance(MS);
    r.bus_event(status(StimState::PreOperational, 7));
    // Only the first CONFIG_APPLIED page arrives.
    let pages = recording_bus::applied(&s.stim_limits, 8);
    assert!(pages.len() > 1, "{pages:?}");
    r.bus_event(pages[0]);
    r.advance(MS);
    r.bus_event(status(StimState::PreOperational, 8));
    assert_eq!(r.fp.config_id(), Some(8));
    let confirmed_at = r.now;
    r.bus.clear();
    r.at(confirmed_at + s.bringup_retry_ns);
    r.poll();
    assert!(r.bus.nmt().is_empty(), "not before the retry time");
    r.at(confirmed_at + s.bringup_retry_ns + 1);
    r.poll();
    assert_eq!(r.bus.nmt(), vec![(r.now, NmtCommand::EnterPreOperational)]);
    // The second attempt: a fresh id, read back completely this time, arms.
    r.auto_readback = true;
    r.advance(MS);
    r.bus_event(status(StimState::PreOperational, 8));
    r.advance(MS);
    r.bus_event(status(StimState::PreOperational, 9));
    assert_eq!(r.fp.config_id(), Some(9));
    r.config_id = 9;
    r.fp.on_liveness(Liveness::Alive, r.now, &mut r.ev);
    r.fp.on_supervisor_liveness(Liveness::Alive, r.now, &mut r.ev);
    for _ in 0..3 {
        r.advance(MS);
        r.tick(false);
    }
    r.command(DriverCommandKind::Arm);
    assert_eq!(r.fp.state(), DriverState::Armed, "{:?}", r.ev);
    // A complete read-back is never retried: disarmed long after, no new probe.
    r.command(DriverCommandKind::Disarm);
    r.bus.clear();
    for _ in 0..3 {
        r.advance(s.bringup_retry_ns);
        r.poll();
    }
    assert!(
        !r.bus
            .nmt()
            .iter()
            .any(|(_, c)| *c == NmtCommand::EnterPreOperational),
        "{:?}",
        r.bus.nmt()
    );
}

/// The driver's interlocks and the limits it would send in CONFIG may not exceed the
/// prescription: a configuration with any looser limit, or no readable
/// prescription, is refused at start (`run --check` and a real `run`, exit 1, naming the
/// prescription and the limit) before anything reaches the bus; the same limits cut to the
/// dose start.
#[test]
fn limits_looser_than_the_prescription_are_refused_at_start() {
    use std::process::Command;
    const EXE: &str = env!("CARGO_BIN_EXE_stim-driver");
    const DOSE: &str = r#"format = "fes-prescription/1"
max_amplitude_ua = 20000
max_phase_width_us = 200
max_charge_per_phase_nc = 4000
min_ipi_us = 2000
max_pulses_per_s = 100
"#;
    let dir = fes_testkit::Scratch::new("stim-driver-presc");
    std::fs::write(dir.join("dose.toml"), DOSE).unwrap();
    let example = Command::new(EXE).arg("example-config").output().unwrap();
    let example = String::from_utf8(example.stdout).unwrap();
    let example = example.replace(
        "prescription = \"/etc/fes/prescription.toml\"",
        "prescription = \"dose.toml\"",
    );
    // The example's limits cut to the dose, key by key.
    let dosed = example
        .replace("max_amplitude_ua = 100000", "max_amplitude_ua = 20000")
        .replace("max_width_us = 500", "max_width_us = 200")
        .replace("max_charge_nc = 50000", "max_charge_nc = 4000")
        .replace("max_charge_nc = 40000", "max_charge_nc = 4000");
    assert_eq!(dosed.matches("max_amplitude_ua = 20000").count(), 2);
    let bus = fes_testkit::bus::SilentBus::new("driver-presc");
    let iface = bus.iface();
    let path = dir.join("stim-driver.toml");
    let config = path.to_str().unwrap();
    let refused = |name: &str, text: &str, needles: &[&str]| {
        std::fs::write(&path, text).unwrap();
        for args in [
            vec!["run", "--check", "--config", config],
            vec!["run", "--config", config, "--iface", &iface],
        ] {
            let out = Command::new(EXE)
                .args(&args)
                .env("RUST_BACKTRACE", "0")
                .output()
                .unwrap();
            for needle in needles {
                fes_testkit::assert_refused(name, &out, &[1], needle, 6);
            }
            bus.assert_silent(name);
        }
    };
    let edit = |from: &str, to: &str, nth: usize| {
        let at = dosed.match_indices(from).nth(nth).expect(from).0;
        format!("{}{to}{}", &dosed[..at], &dosed[at + from.len()..])
    };
    // The example's own limits (100 mA interlocks and CONFIG) against the 20 mA dose.
    refused("defaults", &example, &["prescription", "amplitude"]);
    // One limit at a time above the dose: the CONFIG amplitude (a 5x slip), the interlock
    // width, the CONFIG charge, the interlock IPI and rate, the CONFIG rate.
    let cases = [
        (
            "stimulator amplitude",
            edit("max_amplitude_ua = 20000", "max_amplitude_ua = 100000", 0),
            "amplitude",
        ),
        (
            "interlock width",
            edit("max_width_us = 200", "max_width_us = 201", 1),
            "phase width",
        ),
        (
            "stimulator charge",
            edit("max_charge_nc = 4000", "max_charge_nc = 4010", 0),
            "charge per phase",
        ),
        (
            "interlock charge",
            edit("max_charge_nc = 4000", "max_charge_nc = 4001", 1),
            "charge per phase",
        ),
        (
            "interlock IPI",
            edit("min_ipi_us = 2000", "min_ipi_us = 1999", 0),
            "minimum IPI",
        ),
        (
            "interlock rate",
            edit("max_pulses = 100", "max_pulses = 101", 1),
            "pulses in any 1 s",
        ),
        (
            "stimulator rate",
            edit("rate_window_ms = 1000", "rate_window_ms = 999", 0),
            "pulses in any 1 s",
        ),
    ];
    for (name, text, needle) in &cases {
        refused(name, text, &["prescription", needle]);
    }
    // No prescription at all.
    refused(
        "missing prescription",
        &dosed.replace("dose.toml", "missing.toml"),
        &["missing.toml"],
    );
    // The dosed configuration starts (its check passes).
    std::fs::write(&path, &dosed).unwrap();
    let out = Command::new(EXE)
        .args(["run", "--check", "--config", config])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// ScienceMode 2's stop-and-wait reaches the forward path as a busy transport
/// (`TxError::Busy`): a pulse waits for it within the lateness bound and is written then;
/// past the bound, or when a newer decision comes, it is dropped as `late`; a pulse after
/// a late one keeps the stimulator's minimum interval at the write; none of it is a fault.
#[test]
fn a_pulse_waits_for_a_busy_transport_within_the_lateness_bound() {
    let mut s = settings();
    s.pulse_lateness_ns = 4 * MS;
    s.stim_limits.min_ipi_ms = 2;
    let mut r = Rig::armed(s);
    r.bus.clear();
    r.ev.clear();
    let outcomes = |r: &Rig| -> Vec<(u64, PulseFate)> {
        r.ev.iter()
            .filter_map(|e| match e {
                DriverEvent::Outcome { tick_seq, fate, .. } => Some((*tick_seq, *fate)),
                _ => None,
            })
            .collect()
    };
    let quiet = |r: &mut Rig, n: u32| {
        for _ in 0..n {
            r.advance(MS);
            r.tick(false);
        }
    };
    // Busy when decided, free 2 ms later: written then, no outcome before.
    r.bus.fail.set(Some(TxError::Busy));
    r.advance(MS);
    r.tick(true);
    let first = r.tick_seq;
    let decided = r.now;
    quiet(&mut r, 1);
    assert!(outcomes(&r).is_empty() && r.bus.pulses().is_empty());
    // While it waits the loop looks again within a fraction of a tick.
    assert!(r.fp.next_deadline(r.now) <= r.now + MS / 2);
    r.bus.fail.set(None);
    r.advance(MS);
    r.poll();
    assert_eq!(r.bus.pulses().len(), 1);
    assert_eq!(r.bus.pulses()[0].0, decided + 2 * MS);
    assert_eq!(outcomes(&r), [(first, PulseFate::Sent)]);
    // A pulse decided 1 ms after that late write (3 ms after the first decision: the
    // interlocks pass it) waits until the interval is kept.
    r.advance(MS);
    r.tick(true);
    let second = r.tick_seq;
    assert_eq!(r.bus.pulses().len(), 1, "held: 1 ms after the last write");
    r.advance(MS);
    r.poll();
    assert_eq!(r.bus.pulses().len(), 2);
    assert_eq!(r.bus.pulses()[1].0 - r.bus.pulses()[0].0, 2 * MS);
    // Busy beyond the bound: dropped as late.
    quiet(&mut r, 5);
    r.bus.fail.set(Some(TxError::Busy));
    r.advance(MS);
    r.tick(true);
    let third = r.tick_seq;
    quiet(&mut r, 5);
    // A newer decision takes the place of a waiting one (never a burst).
    r.advance(MS);
    r.tick(true);
    let fourth = r.tick_seq;
    quiet(&mut r, 2);
    r.advance(MS);
    r.tick(true);
    let fifth = r.tick_seq;
    r.bus.fail.set(None);
    r.advance(MS);
    r.poll();
    assert_eq!(
        outcomes(&r),
        [
            (first, PulseFate::Sent),
            (second, PulseFate::Sent),
            (third, PulseFate::Late),
            (fourth, PulseFate::Late),
            (fifth, PulseFate::Sent),
        ],
        "{:?}",
        r.ev
    );
    assert_eq!(r.bus.pulses().len(), 3);
    let c = r.fp.counters();
    assert_eq!((c.pulses_late, c.pulses_dropped_late), (3, 2));
    assert_eq!((c.can_tx_errors, c.trips), (0, 0));
    assert_eq!(r.fp.state(), DriverState::Armed);
    // The stimulator answered one of the written pulses busy (not executed): it is not
    // owed in STATUS reconciliation, past the in-flight window too.
    r.bus_event(BusEvent::DeviceBusy { pulse: true });
    status_for(&mut r, 2, s.stimulator_timeout_ns * 2);
    assert_eq!(r.fp.state(), DriverState::Armed, "{:?}", r.ev);
    assert_eq!(r.fp.counters().pulses_busy, 1);
}

/// Ticks every 1 ms and a STATUS showing `delivered` pulses every 10 ms, for `span_ns`.
fn status_for(r: &mut Rig, delivered: u32, span_ns: u64) {
    let end = r.now + span_ns;
    while r.now < end && r.fault().is_none() {
        r.advance(MS);
        r.tick(false);
        if (r.now / MS).is_multiple_of(10) {
            r.bus_event(status_delivered(StimState::Armed, r.config_id, delivered));
        }
    }
}

/// Without the busy answer's correction, the same STATUS is a delivery mismatch: the test
/// above would fail if busy pulses were still counted as owed.
#[test]
fn a_pulse_missing_from_status_without_a_busy_answer_still_trips() {
    let mut r = Rig::armed(settings());
    r.bus.clear();
    for k in 0..3 {
        r.advance(5 * MS);
        r.tick(k < 3);
    }
    status_for(&mut r, 2, settings().stimulator_timeout_ns * 2);
    assert!(
        matches!(r.fault(), Some(Fault::DeliveryMismatch { .. })),
        "{:?}",
        r.ev
    );
}

/// The newest valid tick's `FLAG_CONTRACTION_AHEAD` reaches the transmit side (which keeps
/// a one-command line free of queries meanwhile), armed or not.
#[test]
fn a_contraction_ahead_is_passed_to_the_transport() {
    let mut r = Rig::configured(settings());
    r.advance(MS);
    r.tick_seq += 1;
    let t = tick(r.tick_seq, r.now - 20_000, false);
    let ahead = StimTick {
        flags: StimTick::FLAG_CONTRACTION_AHEAD,
        ..t
    };
    r.fp.on_tick(&ahead, r.now, &mut r.ev);
    assert!(r.bus.ahead.get());
    r.advance(MS);
    r.tick(false);
    assert!(!r.bus.ahead.get());
}

/// A transport that delivers pulses at least `transport_min_interval_ns` apart (a RehaStim
/// 2 answering one command at a time) refuses to arm while the generator states a shorter
/// minimum interval (StimTick `min_gap_ticks`; 0, not stated, is shorter than any), naming
/// both; a generator designed with the interval arms.
#[test]
fn an_arm_is_refused_while_the_generator_fires_closer_than_the_transport_delivers() {
    let mut s = settings();
    s.transport_min_interval_ns = 20 * MS;
    s.tick_period_ns = MS;
    let mut r = Rig::configured(s);
    r.fp.on_liveness(Liveness::Alive, r.now, &mut r.ev);
    r.fp.on_supervisor_liveness(Liveness::Alive, r.now, &mut r.ev);
    let ticks = |r: &mut Rig, gap: u16| {
        for _ in 0..3 {
            r.advance(MS);
            r.tick_seq += 1;
            let t = StimTick {
                min_gap_ticks: gap,
                ..tick(r.tick_seq, r.now - 20_000, false)
            };
            r.fp.on_tick(&t, r.now, &mut r.ev);
            r.poll();
        }
    };
    for gap in [0, 2, 19] {
        ticks(&mut r, gap);
        r.command(DriverCommandKind::Arm);
        assert_eq!(r.fp.state(), DriverState::Disarmed, "gap {gap}");
        let refusal = r.ev.iter().rev().find_map(|e| match e {
            DriverEvent::ArmRefused { refusal, .. } => Some(*refusal),
            _ => None,
        });
        assert_eq!(
            refusal,
            Some(ArmRefusal::GeneratorGapTooShort {
                generator_us: u64::from(gap) * 1000,
                transport_us: 20_000
            })
        );
        assert_eq!(
            r.fp.counters().command_reason,
            CommandRefusal::GeneratorGapTooShort as u8
        );
        let text = refusal.unwrap().to_string();
        assert!(
            text.contains("20 ms") && text.contains("--min-interval-ms 20"),
            "{text}"
        );
    }
    ticks(&mut r, 20);
    r.command(DriverCommandKind::Arm);
    assert_eq!(r.fp.state(), DriverState::Armed, "{:?}", r.ev);
}

/// What the stimulator did with each pulse sent reaches the recording as a second outcome
/// per pulse, in the order written: applied as STATUS counts them, not applied when an
/// EMCY names the pulse (the count skips it) or when no STATUS counts it within the
/// confirmation window. Without the account every pulse would stay "sent".
#[test]
fn each_pulse_sent_is_accounted_applied_or_not_by_the_stimulator() {
    let confirmations = |r: &Rig| -> Vec<(u64, PulseFate)> {
        r.ev.iter()
            .filter_map(|e| match e {
                DriverEvent::Outcome { tick_seq, fate, .. } if fate.is_confirmation() => {
                    Some((*tick_seq, *fate))
                }
                _ => None,
            })
            .collect()
    };
    let mut r = Rig::armed(settings());
    r.bus.clear();
    let mut fired = Vec::new();
    for _ in 0..3 {
        r.advance(5 * MS);
        r.tick(true);
        fired.push(r.tick_seq);
    }
    let pulses = r.bus.pulses();
    assert_eq!(pulses.len(), 3);
    assert!(confirmations(&r).is_empty(), "nothing counted yet");
    // The stimulator rejects the second pulse by name and applies the other two.
    r.bus_event(BusEvent::Emcy(Emcy::new(
        ErrorCode::MinIpiViolation,
        StimState::Armed,
        pulses[1].1.seq,
        0,
    )));
    r.advance(MS);
    r.bus_event(status_delivered(StimState::Armed, r.config_id, 2));
    assert_eq!(
        confirmations(&r),
        vec![
            (fired[0], PulseFate::Applied),
            (fired[1], PulseFate::NotApplied),
            (fired[2], PulseFate::Applied),
        ]
    );
    assert_eq!(
        (
            r.fp.counters().pulses_applied,
            r.fp.counters().pulses_not_applied
        ),
        (2, 1)
    );

    // A pulse no STATUS counts is closed as not applied once the window has passed.
    let mut r = Rig::armed(settings());
    r.bus.clear();
    r.advance(5 * MS);
    r.tick(true);
    let first = r.tick_seq;
    r.advance(5 * MS);
    r.tick(true);
    let second = r.tick_seq;
    r.bus_event(status_delivered(StimState::Armed, r.config_id, 1));
    assert_eq!(confirmations(&r), vec![(first, PulseFate::Applied)]);
    r.advance(2 * settings().stimulator_timeout_ns + MS);
    r.poll();
    assert_eq!(
        confirmations(&r),
        vec![(first, PulseFate::Applied), (second, PulseFate::NotApplied)]
    );
}

/// A foreign publisher (its process outside the configured unit) is no supervisor and no
/// generator: armed, the driver trips with 0xFF33 naming which, and stops the stimulator;
/// an Arm is refused while the supervisor's publisher is foreign.
#[test]
fn a_foreign_publisher_trips_and_blocks_the_arm() {
    for supervisor in [true, false] {
        let mut r = Rig::armed(settings());
        r.bus.clear();
        r.advance(MS);
        if supervisor {
            r.fp.on_supervisor_liveness(Liveness::Foreign, r.now, &mut r.ev);
        } else {
            r.fp.on_liveness(Liveness::Foreign, r.now, &mut r.ev);
        }
        let f = Fault::ForeignPublisher { supervisor };
        assert_eq!(r.fault(), Some(f), "{:?}", r.ev);
        assert_eq!(r.fp.counters().fault_code, 0xFF33);
        assert_eq!(r.bus.nmt(), vec![(r.now, NmtCommand::Stop)]);
        // Still foreign: an Arm is refused.
        r.command(DriverCommandKind::Arm);
        assert_ne!(r.fp.state(), DriverState::Armed, "{:?}", r.ev);
    }
}
