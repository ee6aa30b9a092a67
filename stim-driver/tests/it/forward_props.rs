//! Property tests of the driver's forward path as a whole (`stim_driver::forward`), on
//! simulated time: after a normal bring-up, arbitrary sequences of StimTicks (any pulse
//! fields, late and stale ones, gaps), DriverCommands (Arm, Disarm, SafeStop, fresh or
//! stale), publisher and supervisor liveness changes, and stimulator and bus events
//! (STATUS of any state and config id, EMCY of any code, boot-up heartbeats, bus errors,
//! link down and up, lost events), with time advancing by 0-60 ms between them. From the
//! frames the path wrote (a recording transmitter) and its state after each input:
//!
//! * a PULSE is written only while armed, and carries the amplitude, width and channel of
//!   the StimTick it came from, within the interlock limits;
//! * it never arms itself: every transition into `Armed` is an Arm command's;
//! * every stop condition while armed ends it in that same call: Disarm, SafeStop, an
//!   EMCY with an error code, the stimulator's boot-up, bus-off, link down, lost bus
//!   events, the generator's or (watched) supervisor's publisher turning dead or gone;
//! * a frame on one of the driver's own identifiers that it did not write (an intrusion)
//!   ends in the safe state with the intrusion fault and an NMT stop written in that same
//!   call, in every mode (not only while armed);
//! * STATUS reconciliation: the model's stimulator applies every PULSE written at once,
//!   and a STATUS reports its count honestly, lagging (pulses missing) or with forged
//!   pulses added. While armed, a STATUS showing more pulses applied since the Arm than
//!   written plus the carry (pulses written within the window before the Arm, counted
//!   generously by the model), or fewer than written less those within the in-flight
//!   window (likewise), ends it; an honest STATUS, against an honest baseline and with no
//!   forged pulse since, never trips a delivery mismatch;
//! * armed after a timer pass means a StimTick arrived within the tick timeout, and the
//!   supervisor has been seen alive since the Arm or the Arm is younger than the arm
//!   confirmation time (the test found a driver armed while its supervisor watch said "no
//!   publisher", which then never tripped).
//!
//! The interlocks' own limits over whole trains are `interlock_props.rs`.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_can::{Emcy, ErrorCode, Message, MessageKind, NmtCommand, NmtState, Nodes, StimState};
use fes_rt::msg::{DriverCommand, DriverCommandKind, StimTick};
use fes_rt::rt::liveness::Liveness;
use proptest::prelude::*;
use stim_driver::config::DriverConfig;
use stim_driver::event::{BusErrorKind, BusEvent, DriverEvent, DriverState};
use stim_driver::fault::Fault;
use stim_driver::forward::{ForwardPath, ForwardSettings};

use crate::recording_bus;
use recording_bus::{Bus, status, status_delivered};

const MS: u64 = 1_000_000;
const T0: u64 = 1_000 * MS;

/// One input to the forward path.
#[derive(Debug, Clone)]
enum Input {
    /// A StimTick published `age_us` before it is taken, its seq `seq_step` after the last.
    Tick {
        seq_step: u64,
        age_us: u64,
        pulse: bool,
        amplitude_ua: u32,
        width_us: u16,
        channel: u8,
    },
    /// A command stamped `age_ms` before it is taken.
    Command(DriverCommandKind, u64),
    /// The StimTick publisher's liveness.
    Generator(Liveness),
    /// The DriverCommand publisher's liveness.
    Supervisor(Liveness),
    /// STATUS from the stimulator: state, our config id or another, and its count.
    Status(StimState, bool, Delivered),
    /// A frame of this kind on the driver's own identifier that it did not write.
    Intrusion(MessageKind),
    /// EMCY from the stimulator.
    Emcy(ErrorCode),
    /// The stimulator's heartbeat.
    Heartbeat(NmtState),
    /// A bus or link event.
    Bus(BusEvent),
    /// Only the timers.
    Poll,
}

/// What a STATUS reports as applied, against the model stimulator's true count (every
/// PULSE written, applied at once, plus the forged ones).
#[derive(Debug, Clone, Copy)]
enum Delivered {
    /// The true count.
    Honest,
    /// The true count less this many (pulses lost or still in flight).
    Lagging(u32),
    /// This many forged pulses applied first (they stay in the count).
    Forged(u32),
}

fn delivered() -> impl Strategy<Value = Delivered> {
    prop_oneof![
        12 => Just(Delivered::Honest),
        2 => (1u32..=4).prop_map(Delivered::Lagging),
        1 => (5u32..=100_000).prop_map(Delivered::Lagging),
        2 => (1u32..=4).prop_map(Delivered::Forged),
        1 => (5u32..=100_000).prop_map(Delivered::Forged),
    ]
}

fn liveness() -> impl Strategy<Value = Liveness> {
    prop_oneof![
        12 => Just(Liveness::Alive),
        1 => Just(Liveness::Dead),
        1 => Just(Liveness::NoPublisher),
        1 => Just(Liveness::Unknown),
    ]
}

fn input() -> impl Strategy<Value = Input> {
    prop_oneof![
        40 => (
            prop_oneof![20 => Just(1u64), 1 => Just(0u64), 1 => 2u64..30],
            prop_oneof![20 => 0u64..400, 1 => 400u64..100_000],
            proptest::bool::weighted(0.3),
            prop_oneof![8 => Just(20_000u32), 1 => 0u32..=250_000],
            prop_oneof![8 => Just(200u16), 1 => 0u16..=1000],
            prop_oneof![8 => Just(0u8), 1 => 0u8..=15],
        )
            .prop_map(|(seq_step, age_us, pulse, amplitude_ua, width_us, channel)| {
                Input::Tick { seq_step, age_us, pulse, amplitude_ua, width_us, channel }
            }),
        6 => (
            prop_oneof![
                4 => Just(DriverCommandKind::Arm),
                1 => Just(DriverCommandKind::Disarm),
                1 => Just(DriverCommandKind::SafeStop),
            ],
            prop_oneof![6 => 0u64..20, 1 => 20u64..500],
        )
            .prop_map(|(k, age)| Input::Command(k, age)),
        2 => liveness().prop_map(Input::Generator),
        2 => liveness().prop_map(Input::Supervisor),
        6 => (
            proptest::sample::select(StimState::ALL),
            proptest::bool::weighted(0.9),
            delivered(),
        )
            .prop_map(|(s, ours, d)| Input::Status(s, ours, d)),
        1 => proptest::sample::select(stim_driver::intrusion::OWN_KINDS.to_vec())
            .prop_map(Input::Intrusion),
        1 => proptest::sample::select(ErrorCode::ALL).prop_map(Input::Emcy),
        1 => prop_oneof![
            4 => Just(NmtState::Operational),
            1 => Just(NmtState::BootUp),
            1 => Just(NmtState::PreOperational),
            1 => Just(NmtState::Stopped),
        ]
        .prop_map(Input::Heartbeat),
        1 => prop_oneof![
            Just(BusEvent::BusError(BusErrorKind::BusOff)),
            Just(BusEvent::BusError(BusErrorKind::ErrorPassive)),
            Just(BusEvent::BusError(BusErrorKind::Restarted)),
            Just(BusEvent::LinkDown),
            Just(BusEvent::LinkUp),
            Just(BusEvent::EventsLost),
        ]
        .prop_map(Input::Bus),
        6 => Just(Input::Poll),
    ]
}

/// Time before an input, ns.
fn gap() -> impl Strategy<Value = u64> {
    prop_oneof![
        20 => Just(MS),
        4 => Just(0u64),
        2 => 1u64..MS,
        1 => 5 * MS..60 * MS,
    ]
}

fn settings() -> ForwardSettings {
    DriverConfig::with_defaults("vcan0", 40.0)
        .forward_settings()
        .expect("the default configuration is valid")
}

/// A started path whose stimulator confirmed the configuration: Disarmed.
fn configured(bus: &Bus) -> (ForwardPath<Bus>, u64) {
    let mut fp = ForwardPath::new(settings(), bus.clone());
    let mut ev: Vec<DriverEvent> = Vec::new();
    let mut now = T0;
    bus.now.set(now);
    fp.start(now, &mut ev);
    for config_id in [7u8, 8] {
        now += MS;
        bus.now.set(now);
        if config_id == 8 {
            // The stimulator reads back what it applied (CONFIG_APPLIED) before STATUS.
            for e in recording_bus::applied(&settings().stim_limits, 8) {
                fp.on_bus(e, now, &mut ev);
            }
        }
        fp.on_bus(status(StimState::PreOperational, config_id), now, &mut ev);
    }
    assert_eq!(fp.state(), DriverState::Disarmed, "{ev:?}");
    fp.on_liveness(Liveness::Alive, now, &mut ev);
    fp.on_supervisor_liveness(Liveness::Alive, now, &mut ev);
    (fp, now)
}

/// The liveness values the path was last given (a report thread hands over the current
/// value at every wake-up; the path acts on changes).
#[derive(Clone, Copy)]
struct Seen {
    generator: Liveness,
    supervisor: Liveness,
}

/// Whether `input` must leave an armed path not armed, given what it had `seen`.
fn stops(input: &Input, seen: Seen, supervisor_watch: bool) -> bool {
    let bad = |l: &Liveness| matches!(l, Liveness::Dead | Liveness::NoPublisher);
    match input {
        Input::Command(k, _) => *k != DriverCommandKind::Arm,
        Input::Emcy(code) => *code != ErrorCode::NoError,
        Input::Heartbeat(s) => *s == NmtState::BootUp,
        Input::Bus(BusEvent::BusError(BusErrorKind::BusOff))
        | Input::Bus(BusEvent::LinkDown)
        | Input::Bus(BusEvent::EventsLost) => true,
        Input::Generator(l) => bad(l) && *l != seen.generator,
        Input::Supervisor(l) => supervisor_watch && bad(l) && *l != seen.supervisor,
        _ => false,
    }
}

fn run(steps: &[(u64, Input)]) -> Result<usize, TestCaseError> {
    let bus = Bus::default();
    let (mut fp, mut now) = configured(&bus);
    let s = *fp.settings();
    let mut ev: Vec<DriverEvent> = Vec::new();
    let mut seq = 0u64;
    let mut cmd_seq = 0u64;
    let mut last_tick_taken: Option<u64> = None;
    let mut armed_at: Option<u64> = None;
    let mut supervisor_seen_armed = false;
    let mut seen = Seen {
        generator: Liveness::Alive,
        supervisor: Liveness::Alive,
    };
    let mut pulses = 0;
    // The reconciliation model: forged pulses applied so far, the count the last STATUS
    // reported, and per armed period its baseline (the count reported before the Arm,
    // PULSE frames written at the Arm, the Arm's time, and whether that count was honest
    // and no forged pulse came since).
    let mut forged = 0u32;
    let mut last_reported = 0u32;
    let mut last_report_honest = true;
    let mut baseline: Option<(u32, usize, u64, bool)> = None;
    // The in-flight window and a generous bound of what the path may count in it.
    let window = s.stimulator_timeout_ns;
    let generous = |t: u64| t.saturating_sub(window + 2 * (window / 16) + 1);
    for (gap, input) in steps {
        now += gap;
        bus.now.set(now);
        let before = fp.state();
        let written = bus.frames.borrow().len();
        let mut tick_sent: Option<StimTick> = None;
        match input {
            Input::Tick {
                seq_step,
                age_us,
                pulse,
                amplitude_ua,
                width_us,
                channel,
            } => {
                seq += seq_step;
                let t = now.saturating_sub(age_us * 1000);
                let quiet = StimTick::quiet(seq.max(1), t.saturating_sub(20_000));
                let tick = StimTick {
                    t_wake_ns: t.saturating_sub(10_000),
                    t_publish_ns: t,
                    ..if *pulse {
                        quiet.firing(*channel, *amplitude_ua, *width_us)
                    } else {
                        quiet
                    }
                };
                fp.on_tick(&tick, now, &mut ev);
                last_tick_taken = Some(now);
                tick_sent = Some(tick);
            }
            Input::Command(kind, age_ms) => {
                cmd_seq += 1;
                let c = DriverCommand::new(cmd_seq, now.saturating_sub(age_ms * MS), *kind);
                fp.on_command(&c, now, &mut ev);
            }
            Input::Generator(l) => fp.on_liveness(*l, now, &mut ev),
            Input::Supervisor(l) => fp.on_supervisor_liveness(*l, now, &mut ev),
            Input::Status(state, ours, d) => {
                let id = if *ours {
                    fp.config_id().unwrap_or(0)
                } else {
                    fp.config_id().unwrap_or(0).wrapping_add(1)
                };
                if let Delivered::Forged(k) = d {
                    forged = forged.wrapping_add(*k);
                    if let Some(b) = baseline.as_mut() {
                        b.3 = false;
                    }
                }
                let truth = (bus.pulses().len() as u32).wrapping_add(forged);
                let reported = match d {
                    Delivered::Lagging(k) => truth.wrapping_sub(*k),
                    _ => truth,
                } & 0xFF_FFFF;
                fp.on_bus(status_delivered(*state, id, reported), now, &mut ev);
                last_reported = reported;
                last_report_honest = !matches!(d, Delivered::Lagging(_));
            }
            Input::Intrusion(kind) => {
                let cob_id = Nodes::DEFAULT.id_of(*kind);
                fp.on_bus(
                    BusEvent::Intrusion {
                        cob_id,
                        kind: *kind,
                    },
                    now,
                    &mut ev,
                );
            }
            Input::Emcy(code) => fp.on_bus(
                BusEvent::Emcy(Emcy::new(*code, StimState::Armed, 0, 0)),
                now,
                &mut ev,
            ),
            Input::Heartbeat(state) => fp.on_bus(BusEvent::StimHeartbeat(*state), now, &mut ev),
            Input::Bus(e) => fp.on_bus(*e, now, &mut ev),
            Input::Poll => {}
        }
        fp.poll(now, &mut ev);
        ev.clear();
        let after = fp.state();

        // What this input made the path write.
        let new: Vec<Message> = bus.frames.borrow()[written..]
            .iter()
            .map(|(_, f)| fes_can::decode(u32::from(f.id), f.payload()).expect("decodes"))
            .collect();
        for m in &new {
            if let Message::Pulse(p) = m {
                pulses += 1;
                prop_assert_eq!(
                    before,
                    DriverState::Armed,
                    "PULSE {:?} written while {:?}",
                    p,
                    before
                );
                let t = tick_sent.expect("a PULSE only in answer to a StimTick");
                prop_assert!(t.fires(), "PULSE from a tick that does not fire: {t:?}");
                prop_assert_eq!(
                    (u32::from(p.amplitude_100ua) * 100, p.width_us, p.channel),
                    (t.amplitude_ua, t.width_us, t.channel),
                    "PULSE fields differ from the tick's"
                );
                prop_assert!(
                    t.amplitude_ua <= s.interlocks.max_amplitude_ua
                        && t.width_us <= s.interlocks.max_width_us,
                    "PULSE beyond the interlock limits: {t:?}"
                );
            }
        }
        if after == DriverState::Armed && before != DriverState::Armed {
            prop_assert!(
                matches!(input, Input::Command(DriverCommandKind::Arm, _)),
                "armed by {input:?}, not by an Arm command"
            );
        }
        if before == DriverState::Armed && stops(input, seen, s.supervisor_watch) {
            prop_assert_ne!(after, DriverState::Armed, "still armed after {:?}", input);
        }
        if let Input::Intrusion(kind) = input {
            let cob_id = Nodes::DEFAULT.id_of(*kind);
            prop_assert!(
                matches!(after, DriverState::SafeState(Fault::Intrusion { .. })),
                "{:?} from {:?} left the path {:?}",
                input,
                before,
                after
            );
            prop_assert!(
                matches!(after, DriverState::SafeState(Fault::Intrusion { cob_id: c, kind: k }) if c == cob_id && k == *kind)
                    || matches!(before, DriverState::SafeState(Fault::Intrusion { .. })),
                "the fault does not name the frame: {:?}",
                after
            );
            prop_assert!(
                new.iter()
                    .any(|m| matches!(m, Message::Nmt(n) if n.command == NmtCommand::Stop)),
                "no NMT stop written on {:?}",
                input
            );
        }
        // Reconciliation, for a STATUS with our configuration while armed.
        if let (Input::Status(_, true, d), DriverState::Armed, Some(b)) = (input, before, baseline)
        {
            let (base_reported, base_written, armed_ns, clean) = b;
            let times: Vec<u64> = bus.pulses().iter().map(|(t, _)| *t).collect();
            let sent = (times.len() - base_written) as u32;
            let delivered = last_reported.wrapping_sub(base_reported) & 0xFF_FFFF;
            let carry_max = times[..base_written]
                .iter()
                .filter(|&&t| t >= generous(armed_ns))
                .count() as u32;
            let in_flight_max = times.iter().filter(|&&t| t >= generous(now)).count() as u32;
            let lag = sent.wrapping_sub(delivered) & 0xFF_FFFF;
            let must_trip = if lag < 1 << 23 {
                lag > in_flight_max
            } else {
                (1 << 24) - lag > carry_max
            };
            if must_trip {
                prop_assert_ne!(
                    after,
                    DriverState::Armed,
                    "still armed after a STATUS of {} applied since the Arm, {} written ({:?})",
                    delivered,
                    sent,
                    d
                );
            }
            if clean && matches!(d, Delivered::Honest) {
                prop_assert!(
                    !matches!(
                        after,
                        DriverState::SafeState(Fault::DeliveryMismatch { .. })
                    ),
                    "an honest STATUS tripped: {:?} ({} written since the Arm)",
                    after,
                    sent
                );
            }
        }
        match input {
            Input::Generator(l) => seen.generator = *l,
            Input::Supervisor(l) => seen.supervisor = *l,
            _ => {}
        }
        if after != DriverState::Armed {
            armed_at = None;
            baseline = None;
        } else if before != DriverState::Armed {
            armed_at = Some(now);
            supervisor_seen_armed = seen.supervisor == Liveness::Alive;
            baseline = Some((
                last_reported,
                bus.pulses().len()
                    - new
                        .iter()
                        .filter(|m| matches!(m, Message::Pulse(_)))
                        .count(),
                now,
                last_report_honest,
            ));
        }
        supervisor_seen_armed |= seen.supervisor == Liveness::Alive;
        if let Some(t) = armed_at
            && s.supervisor_watch
            && !supervisor_seen_armed
        {
            prop_assert!(
                now - t <= s.arm_confirm_ns,
                "armed {} ms after the Arm without the supervisor seen alive",
                (now - t) / MS
            );
        }
        if after == DriverState::Armed {
            let silent = last_tick_taken.map_or(u64::MAX, |t| now - t);
            prop_assert!(
                silent <= s.tick_timeout_ns,
                "armed {} ms after the last StimTick (timeout {} ms)",
                silent / MS,
                s.tick_timeout_ns / MS
            );
        }
    }
    Ok(pulses)
}

/// Cases per run: 512 in CI; `FORWARD_PROPS_CASES` for a longer search.
fn cases() -> u32 {
    std::env::var("FORWARD_PROPS_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(512)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    /// The forward path's safety over arbitrary input sequences (module documentation).
    #[test]
    fn no_input_sequence_makes_the_driver_forward_unsafely(
        steps in proptest::collection::vec((gap(), input()), 20..400),
    ) {
        run(&steps)?;
    }
}

/// Liveness: fresh ticks, an Arm, the stimulator's confirmation and then a pulse every
/// 20 ms are forwarded, so the safety property does not hold by forwarding nothing.
#[test]
fn a_healthy_stream_is_forwarded() {
    let mut steps = Vec::new();
    for _ in 0..3 {
        steps.push((
            MS,
            Input::Tick {
                seq_step: 1,
                age_us: 50,
                pulse: false,
                amplitude_ua: 0,
                width_us: 0,
                channel: 0,
            },
        ));
    }
    steps.push((0, Input::Command(DriverCommandKind::Arm, 1)));
    steps.push((
        MS / 2,
        Input::Status(StimState::Armed, true, Delivered::Honest),
    ));
    for k in 0..500u64 {
        steps.push((
            MS,
            Input::Tick {
                seq_step: 1,
                age_us: 50,
                pulse: k % 20 == 0,
                amplitude_ua: 20_000,
                width_us: 200,
                channel: 0,
            },
        ));
        if k % 10 == 0 {
            steps.push((
                0,
                Input::Status(StimState::Stimulating, true, Delivered::Honest),
            ));
        }
    }
    assert_eq!(run(&steps).unwrap(), 25);
}
