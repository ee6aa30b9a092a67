//! Property tests of the virtual stimulator's own safety (the stimulator side of the
//! interlocks, `fes_virtual_stimulator::machine`), which must hold whatever the host sends:
//! for arbitrary sequences of frames (valid PULSEs with any fields, corrupted ones, NMT
//! commands to any node, CONFIGs tighter or looser than the ceiling, host heartbeats, raw
//! frames on any identifier with any payload) and of ticks (on time, several frames per
//! tick, stalls of the loop with a catch-up), every pulse the stimulator applies
//!
//! * respects the limits in force (amplitude, width, channel) and the ceiling;
//! * keeps the minimum inter-pulse interval and the rate limit of the limits in force;
//! * comes while operational: once the output is off (stopped, fault, pre-operational,
//!   reset), no pulse is applied until an NMT start addressed to it arrives (it never
//!   re-arms itself);
//!
//! and an operational stimulator has heard the host (heartbeat or start) within its
//! watchdog time. A liveness property keeps the safety ones from holding by refusing
//! everything: a plain legal stream is applied pulse for pulse.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_can::counter::AliveCounter;
use fes_can::{
    Frame, Heartbeat, Message, Nmt, NmtCommand, NmtState, Nodes, Pulse, StimLimits, StimState,
};
use fes_virtual_stimulator::machine::{Settings, Stimulator, TICK_NS, Tick};
use fes_virtual_stimulator::outbox::Outbox;
use fes_virtual_stimulator::test_plant::ChargeIntegrator;
use proptest::prelude::*;

const NODES: Nodes = Nodes::DEFAULT;
const HOST_HEARTBEAT_MS: u16 = 10;

/// One thing the host (or the bus) does.
#[derive(Debug, Clone)]
enum Event {
    /// The host's heartbeat.
    Heartbeat,
    /// An NMT command to `node` (0: all; the stimulator's; another).
    Nmt(NmtCommand, u8),
    /// The two CONFIG pages of `limits` under `config_id`, or only the first.
    Config(StimLimits, u8, bool),
    /// A PULSE: sequence step, alive counter right or not, fields, a flipped CRC byte.
    Pulse {
        seq_step: u16,
        alive_ok: bool,
        channel: u8,
        amplitude_100ua: u16,
        width_us: u16,
        corrupt: bool,
    },
    /// Any frame on an identifier the host does not use for NMT or its heartbeat.
    Raw(u32, Vec<u8>),
}

/// One step of the run: events arriving during the coming tick period, then the tick
/// index advancing by `advance` (1 on time; more: a stall of the loop, caught up; 0: no
/// tick yet, more events follow first).
#[derive(Debug, Clone)]
struct Step {
    events: Vec<Event>,
    advance: u64,
}

fn command() -> impl Strategy<Value = NmtCommand> {
    prop_oneof![
        6 => Just(NmtCommand::Start),
        2 => Just(NmtCommand::Stop),
        2 => Just(NmtCommand::EnterPreOperational),
        1 => Just(NmtCommand::ResetNode),
        1 => Just(NmtCommand::ResetCommunication),
    ]
}

fn limits() -> impl Strategy<Value = StimLimits> {
    (
        1u16..1500,
        1u16..1000,
        1u16..50,
        1u16..300,
        1u16..3000,
        // The CONFIG signal's range starts at 20 ms (two host heartbeats of 10 ms).
        20u16..1000,
        1u16..15000,
    )
        .prop_map(
            |(
                max_amplitude_100ua,
                max_width_us,
                min_ipi_ms,
                max_pulses,
                rate_window_ms,
                watchdog_ms,
                max_charge_10nc,
            )| {
                StimLimits {
                    max_amplitude_100ua,
                    max_width_us,
                    min_ipi_ms,
                    max_pulses,
                    rate_window_ms,
                    watchdog_ms,
                    max_charge_10nc,
                }
            },
        )
}

fn event() -> impl Strategy<Value = Event> {
    prop_oneof![
        8 => Just(Event::Heartbeat),
        2 => (command(), prop_oneof![Just(0u8), Just(NODES.stim()), Just(0x21u8)])
            .prop_map(|(c, n)| Event::Nmt(c, n)),
        1 => (limits(), 1u8..=255, proptest::bool::weighted(0.9))
            .prop_map(|(l, id, both)| Event::Config(l, id, both)),
        10 => (
            prop_oneof![8 => Just(1u16), 1 => Just(0u16), 1 => 2u16..5],
            proptest::bool::weighted(0.95),
            prop_oneof![8 => Just(0u8), 1 => 0u8..16],
            prop_oneof![3 => 1u16..1000, 1 => 0u16..=1500],
            prop_oneof![3 => 1u16..500, 1 => 0u16..=1000],
            proptest::bool::weighted(0.05),
        )
            .prop_map(|(seq_step, alive_ok, channel, amplitude_100ua, width_us, corrupt)| {
                Event::Pulse { seq_step, alive_ok, channel, amplitude_100ua, width_us, corrupt }
            }),
        1 => (1u32..0x800, proptest::collection::vec(any::<u8>(), 0..=8))
            .prop_filter("not NMT, not the host heartbeat", |(id, _)| {
                *id != 0 && *id != 0x700 + u32::from(NODES.host())
            })
            .prop_map(|(id, d)| Event::Raw(id, d)),
    ]
}

fn step() -> impl Strategy<Value = Step> {
    (
        proptest::collection::vec(event(), 0..3),
        prop_oneof![20 => Just(1u64), 2 => Just(0u64), 1 => 2u64..40, 1 => 40u64..400],
    )
        .prop_map(|(events, advance)| Step { events, advance })
}

fn encode(m: Message) -> Frame {
    m.encode_for(&NODES).expect("a generated message encodes")
}

/// What the run tracks besides the stimulator: what the host did, when.
struct Host {
    seq: u16,
    alive: AliveCounter,
    /// Time of the last heartbeat or NMT start delivered, ns.
    last_heard_ns: u64,
    /// An NMT start addressed to the stimulator since its output was last seen off.
    started_since_off: bool,
}

/// Applied pulses: (tick, pulse, limits in force).
type Applied = Vec<(u64, Pulse, StimLimits)>;

/// Runs `steps` on a stimulator with `ceiling` and `channels`; checks the per-tick
/// properties and returns the applied pulses.
fn run(ceiling: StimLimits, channels: u8, steps: &[Step]) -> Result<Applied, TestCaseError> {
    let settings = Settings {
        nodes: NODES,
        ceiling,
        channels,
        heartbeat_ms: 100,
        host_heartbeat_ms: HOST_HEARTBEAT_MS,
        test_fault_loose_config: false,
    };
    settings.validate().expect("valid settings");
    let mut out = Outbox::new();
    let mut plant = ChargeIntegrator::new();
    let mut stim = Stimulator::new(settings, 0, &mut out);
    let mut host = Host {
        seq: 0,
        alive: AliveCounter::new(),
        last_heard_ns: 0,
        started_since_off: false,
    };
    let mut applied = Vec::new();
    let mut index = 1u64;
    let mut last_arrival = 0;
    for s in steps {
        let t0 = index * TICK_NS;
        let n = s.events.len() as u64 + 1;
        for (i, e) in s.events.iter().enumerate() {
            // Arrivals spread over the coming tick period (over the stall, if one follows;
            // a few microseconds apart when no tick follows), never going back in time.
            let span = if s.advance == 0 {
                n * 10_000
            } else {
                s.advance * TICK_NS
            };
            let now = (t0 + (i as u64 + 1) * span / n).max(last_arrival);
            last_arrival = now;
            deliver(&mut stim, &mut host, e, now, &mut out);
            out.clear();
        }
        if s.advance == 0 {
            continue;
        }
        index += s.advance;
        let now = index * TICK_NS;
        let was_off = !operational(stim.state());
        let in_force = *stim.limits();
        let report = stim.tick(
            Tick {
                index,
                nominal_ns: now,
                now_ns: now,
            },
            &mut plant,
            &mut out,
        );
        out.clear();
        let mut this_tick: Vec<(u64, Pulse)> =
            stim.caught_up().map(|c| (c.tick, c.pulse)).collect();
        if let Some(p) = report.applied {
            this_tick.push((index, p));
        }
        prop_assert!(
            !(was_off && !host.started_since_off && !this_tick.is_empty()),
            "pulses {this_tick:?} applied at tick {index} with the output off and no start since"
        );
        applied.extend(this_tick.into_iter().map(|(t, p)| (t, p, in_force)));
        if !operational(report.state) {
            host.started_since_off = false;
        } else {
            let silent_ms = (now - host.last_heard_ns) / 1_000_000;
            prop_assert!(
                silent_ms <= u64::from(stim.limits().watchdog_ms) + 1,
                "operational at tick {index} after {silent_ms} ms without the host (watchdog {} ms)",
                stim.limits().watchdog_ms
            );
        }
    }
    Ok(applied)
}

const fn operational(s: StimState) -> bool {
    matches!(s, StimState::Armed | StimState::Stimulating)
}

fn deliver(stim: &mut Stimulator, host: &mut Host, e: &Event, now: u64, out: &mut Outbox) {
    let frames: Vec<Frame> = match e {
        Event::Heartbeat => {
            host.last_heard_ns = now;
            vec![encode(Message::HostHeartbeat(Heartbeat {
                state: NmtState::Operational,
            }))]
        }
        Event::Nmt(command, node) => {
            if *command == NmtCommand::Start && (*node == 0 || *node == NODES.stim()) {
                host.last_heard_ns = now;
                host.started_since_off = true;
                host.alive = AliveCounter::new();
            }
            vec![encode(Message::Nmt(Nmt {
                command: *command,
                node: *node,
            }))]
        }
        Event::Config(l, id, both) => {
            let pages = l.to_pages(*id);
            let n = if *both { 2 } else { 1 };
            pages[..n]
                .iter()
                .map(|p| encode(Message::Config(*p)))
                .collect()
        }
        Event::Pulse {
            seq_step,
            alive_ok,
            channel,
            amplitude_100ua,
            width_us,
            corrupt,
        } => {
            host.seq = host.seq.wrapping_add(*seq_step);
            let alive = host.alive.next_value();
            let p = Pulse {
                seq: host.seq,
                alive_counter: if *alive_ok { alive } else { (alive + 7) % 16 },
                channel: *channel,
                amplitude_100ua: *amplitude_100ua,
                width_us: *width_us,
            };
            let mut f = encode(Message::Pulse(p));
            if *corrupt {
                f.data[7] ^= 0x5A;
            }
            vec![f]
        }
        Event::Raw(id, data) => vec![Frame {
            id: *id as u16,
            dlc: data.len() as u8,
            data: {
                let mut d = [0u8; 8];
                d[..data.len()].copy_from_slice(data);
                d
            },
        }],
    };
    for f in frames {
        stim.on_frame(now, u32::from(f.id), f.payload(), out);
    }
}

/// The limits properties over the applied train.
fn check_train(ceiling: &StimLimits, channels: u8, applied: &Applied) -> Result<(), TestCaseError> {
    for (i, (tick, p, l)) in applied.iter().enumerate() {
        prop_assert!(
            p.amplitude_100ua <= l.max_amplitude_100ua
                && p.amplitude_100ua <= ceiling.max_amplitude_100ua,
            "tick {tick}: {} x 0.1 mA beyond {l:?}",
            p.amplitude_100ua
        );
        prop_assert!(
            p.width_us <= l.max_width_us && p.width_us <= ceiling.max_width_us,
            "tick {tick}: {} us beyond {l:?}",
            p.width_us
        );
        let charge_100pc = u32::from(p.amplitude_100ua) * u32::from(p.width_us);
        prop_assert!(
            charge_100pc <= u32::from(l.max_charge_10nc) * 100
                && charge_100pc <= u32::from(ceiling.max_charge_10nc) * 100,
            "tick {tick}: {} x 0.1 nC per phase beyond {l:?}",
            charge_100pc
        );
        prop_assert!(p.channel < channels, "tick {tick}: channel {}", p.channel);
        if let Some((prev, _, _)) = i.checked_sub(1).map(|j| applied[j]) {
            prop_assert!(
                tick - prev >= u64::from(l.min_ipi_ms),
                "pulses at ticks {prev} and {tick}: closer than {} ms",
                l.min_ipi_ms
            );
        }
        let window = u64::from(l.rate_window_ms);
        let in_window = applied[..=i]
            .iter()
            .filter(|(t, _, _)| t + window > *tick)
            .count();
        prop_assert!(
            in_window <= usize::from(l.max_pulses),
            "{in_window} pulses in the {window} ms before tick {tick} (max {})",
            l.max_pulses
        );
    }
    Ok(())
}

/// Cases per run: 512 in CI (under a second); `STIMULATOR_PROPS_CASES=20000` for a long
/// search (20 000 cases passed, 28 s in release, on 2026-12-01).
fn cases() -> u32 {
    std::env::var("STIMULATOR_PROPS_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(512)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    /// Whatever arrives, the applied train keeps the limits and the stimulator never
    /// re-arms itself nor stays operational past its watchdog.
    #[test]
    fn no_input_makes_the_stimulator_apply_an_unsafe_pulse(
        ceiling in limits(),
        channels in 1u8..=4,
        steps in proptest::collection::vec(step(), 50..600),
    ) {
        let applied = run(ceiling, channels, &steps)?;
        check_train(&ceiling, channels, &applied)?;
    }
}

/// Liveness: a legal stream (start, heartbeats every 10 ms, a pulse every 25 ms within
/// the default limits) is applied pulse for pulse, so the safety property above does not
/// hold by refusing everything.
#[test]
fn a_legal_stream_is_applied_whole() {
    let mut steps = vec![Step {
        events: vec![Event::Nmt(NmtCommand::Start, NODES.stim())],
        advance: 1,
    }];
    for k in 1..2000u64 {
        let mut events = Vec::new();
        if k % 10 == 0 {
            events.push(Event::Heartbeat);
        }
        if k % 25 == 0 {
            events.push(Event::Pulse {
                seq_step: 1,
                alive_ok: true,
                channel: 0,
                amplitude_100ua: 200,
                width_us: 200,
                corrupt: false,
            });
        }
        steps.push(Step { events, advance: 1 });
    }
    let applied = run(StimLimits::DEFAULT, 1, &steps).unwrap();
    assert_eq!(applied.len(), 1999 / 25);
    check_train(&StimLimits::DEFAULT, 1, &applied).unwrap();
}
