//! State-machine tests: frames in, frames out, time passed in; the plant is the charge
//! integrator, so the FORCE stream shows exactly which pulses reached the output.

use super::*;
use crate::test_plant::ChargeIntegrator;
use fes_can::{AliveCounter, Frame, Nmt, decode};

const T0: u64 = 5_000_000_000;

fn settings() -> Settings {
    Settings {
        nodes: Nodes::DEFAULT,
        ceiling: StimLimits {
            max_amplitude_100ua: 1000,
            max_width_us: 500,
            min_ipi_ms: 2,
            max_pulses: 100,
            rate_window_ms: 1000,
            watchdog_ms: 100,
            max_charge_10nc: 5000,
        },
        channels: 1,
        heartbeat_ms: 100,
        host_heartbeat_ms: 10,
        test_fault_loose_config: false,
    }
}

/// A scripted host and a stimulator on a simulated 1 ms clock.
struct Bench {
    stim: Stimulator,
    plant: ChargeIntegrator,
    out: Outbox,
    sent: Vec<Message>,
    tick: u64,
    alive: AliveCounter,
    seq: u16,
}

impl Bench {
    fn new() -> Self {
        Self::with(settings())
    }

    fn with(s: Settings) -> Self {
        s.validate().unwrap();
        let mut out = Outbox::new();
        let stim = Stimulator::new(s, T0, &mut out);
        let mut b = Self {
            stim,
            plant: ChargeIntegrator::new(),
            out,
            sent: Vec::new(),
            tick: 0,
            alive: AliveCounter::new(),
            seq: 0,
        };
        b.collect();
        b
    }

    fn now(&self) -> u64 {
        T0 + TICK_NS + self.tick * TICK_NS
    }

    fn collect(&mut self) {
        for f in self.out.frames() {
            self.sent.push(
                decode(u32::from(f.id), f.payload()).expect("the stimulator sends valid frames"),
            );
        }
        self.out.clear();
    }

    fn frame(&mut self, f: Frame) {
        let now = self.now();
        self.stim
            .on_frame(now, u32::from(f.id), f.payload(), &mut self.out);
        self.collect();
    }

    fn send(&mut self, m: Message) {
        self.frame(m.encode().unwrap());
    }

    fn nmt(&mut self, command: NmtCommand) {
        self.send(Message::Nmt(Nmt {
            command,
            node: 0x10,
        }));
    }

    fn heartbeat(&mut self) {
        self.send(Message::HostHeartbeat(Heartbeat {
            state: NmtState::Operational,
        }));
    }

    fn next_pulse(&mut self, amplitude_100ua: u16, width_us: u16) -> Pulse {
        self.seq = self.seq.wrapping_add(1);
        Pulse {
            seq: self.seq,
            alive_counter: self.alive.next_value(),
            channel: 0,
            amplitude_100ua,
            width_us,
        }
    }

    fn pulse(&mut self, amplitude_100ua: u16, width_us: u16) -> Pulse {
        let p = self.next_pulse(amplitude_100ua, width_us);
        self.send(Message::Pulse(p));
        p
    }

    /// Runs `n` ticks, the host sending its heartbeat every 10 ticks when `hb`.
    fn run(&mut self, n: u64, hb: bool) {
        for _ in 0..n {
            if hb && self.tick.is_multiple_of(10) {
                self.heartbeat();
            }
            let t = Tick {
                index: self.tick,
                nominal_ns: self.now(),
                now_ns: self.now(),
            };
            self.stim.tick(t, &mut self.plant, &mut self.out);
            self.collect();
            self.tick += 1;
        }
    }

    fn emcys(&self) -> Vec<Emcy> {
        self.sent
            .iter()
            .filter_map(|m| {
                if let Message::Emcy(e) = m {
                    Some(*e)
                } else {
                    None
                }
            })
            .collect()
    }

    fn last_emcy(&self) -> Emcy {
        *self.emcys().last().expect("an EMCY was sent")
    }

    fn forces(&self) -> Vec<Force> {
        self.sent
            .iter()
            .filter_map(|m| {
                if let Message::Force(f) = m {
                    Some(*f)
                } else {
                    None
                }
            })
            .collect()
    }

    fn last_status(&self) -> Status {
        self.sent
            .iter()
            .rev()
            .find_map(|m| {
                if let Message::Status(s) = m {
                    Some(*s)
                } else {
                    None
                }
            })
            .expect("a STATUS was sent")
    }

    fn configure(&mut self, l: StimLimits, id: u8) {
        for c in l.to_pages(id) {
            self.send(Message::Config(c));
        }
    }

    fn operational(&mut self) {
        self.nmt(NmtCommand::Start);
        assert_eq!(self.stim.state(), StimState::Armed);
    }
}

fn charge_uc(p: &Pulse) -> f64 {
    p.amplitude_ma() * f64::from(p.width_us) * 1e-3
}

#[test]
fn boots_into_pre_operational_with_a_boot_up_message() {
    let mut b = Bench::new();
    assert_eq!(
        b.sent,
        vec![Message::StimHeartbeat(Heartbeat {
            state: NmtState::BootUp
        })]
    );
    assert_eq!(b.stim.state(), StimState::PreOperational);
    b.run(1, false);
    let s = b.last_status();
    assert_eq!(
        (s.state, s.config_id, s.pulses_delivered),
        (StimState::PreOperational, 0, 0)
    );
}

#[test]
fn periodic_frames_keep_their_cycle_times() {
    let mut b = Bench::new();
    b.run(1000, true);
    let forces = b.forces();
    assert_eq!(forces.len(), 1000);
    for (i, f) in forces.iter().enumerate() {
        assert_eq!(f.seq, i as u16);
        let t_us = (T0 + TICK_NS + i as u64 * TICK_NS) / 1000;
        assert_eq!(f.sample_time_us, (t_us & 0xFF_FFFF) as u32);
    }
    let statuses = b
        .sent
        .iter()
        .filter(|m| matches!(m, Message::Status(_)))
        .count();
    let beats = b
        .sent
        .iter()
        .filter(|m| matches!(m, Message::StimHeartbeat(_)))
        .count();
    assert_eq!(statuses, 100);
    // The boot-up message, then one per 100 ms (ticks 100, 200, ..., 900).
    assert_eq!(beats, 1 + 9);
    let counters: Vec<u8> = b
        .sent
        .iter()
        .filter_map(|m| {
            if let Message::Status(s) = m {
                Some(s.counter)
            } else {
                None
            }
        })
        .collect();
    assert!(counters.windows(2).all(|w| w[1] == (w[0] + 1) % 16));
}

#[test]
fn pulse_in_pre_operational_is_rejected_and_not_applied() {
    let mut b = Bench::new();
    let p = b.pulse(200, 200);
    assert_eq!(
        b.last_emcy(),
        Emcy::new(
            ErrorCode::WrongState,
            StimState::PreOperational,
            p.seq,
            0x110
        )
    );
    b.run(5, true);
    assert_eq!(b.plant.pulses(), 0);
    assert!(b.forces().iter().all(|f| f.force_mn == 0));
    let s = b.last_status();
    assert_eq!(
        (s.pulses_delivered, s.rejected, s.last_error),
        (0, 1, ErrorCode::WrongState)
    );
}

#[test]
fn accepted_pulses_reach_the_plant_at_the_next_tick() {
    let mut b = Bench::new();
    b.operational();
    b.run(3, true);
    let p = b.pulse(200, 200); // 20 mA x 200 us = 4 uC
    assert!(b.stim.has_pending_pulse());
    b.run(1, true); // tick 3 applies it; its FORCE shows the force before the pulse
    b.run(1, true); // tick 4's FORCE shows the charge
    let f = b.forces();
    assert_eq!(f[3].force_mn, 0);
    assert_eq!(f[4].force_mn, (charge_uc(&p) * 1000.0).round() as i32);
    assert_eq!(b.stim.pulses_delivered(), 1);
    assert_eq!(b.stim.state(), StimState::Stimulating);
    assert!(b.emcys().is_empty());
    b.run(STIMULATING_HOLD_TICKS, true);
    assert_eq!(b.stim.state(), StimState::Armed);
}

#[test]
fn min_ipi_is_enforced_in_ticks() {
    let mut b = Bench::new();
    b.operational();
    b.pulse(100, 100);
    let second = b.pulse(100, 100); // same tick: IPI 0
    assert_eq!(
        b.last_emcy(),
        Emcy::new(ErrorCode::MinIpiViolation, StimState::Armed, second.seq, 0)
    );
    b.run(1, true); // first applied at tick 0
    let third = b.pulse(100, 100); // would be tick 1: IPI 1 < 2
    assert_eq!(b.last_emcy().code, ErrorCode::MinIpiViolation);
    assert_eq!((b.last_emcy().seq, b.last_emcy().detail), (third.seq, 1));
    b.run(1, true);
    b.pulse(100, 100); // tick 2: IPI 2, allowed
    b.run(2, true);
    assert_eq!(b.plant.pulses(), 2);
    assert_eq!(b.stim.rejected(), 2);
}

#[test]
fn corrupt_and_stale_frames_are_dropped() {
    let mut b = Bench::new();
    b.operational();
    b.pulse(100, 100); // synchronises the alive counter
    b.run(3, true);
    // Bad CRC.
    let p = b.next_pulse(100, 100);
    let mut f = Message::Pulse(p).encode().unwrap();
    let good_crc = f.data[7];
    f.data[7] ^= 0x5A;
    b.frame(f);
    assert_eq!(
        b.last_emcy(),
        Emcy::new(
            ErrorCode::BadCrc,
            StimState::Stimulating,
            0,
            u16::from_be_bytes([good_crc ^ 0x5A, good_crc])
        )
    );
    // The corrupt frame did not advance the counters: the host's next frame skips one.
    let q = b.pulse(100, 100);
    assert_eq!(b.last_emcy().code, ErrorCode::BadAliveCounter);
    assert_eq!(b.last_emcy().seq, q.seq);
    // Resynchronised: the following frame is fine.
    b.run(1, true);
    b.pulse(100, 100);
    assert_eq!(b.emcys().len(), 2);
    assert_eq!(b.plant.pulses(), 1);
    // Replaying an old frame (old seq; its counter happens to be expected) is refused.
    b.run(3, true);
    let expected_counter = b.stim.alive.expected().unwrap();
    let replay = Pulse {
        seq: q.seq,
        alive_counter: expected_counter,
        channel: 0,
        amplitude_100ua: 100,
        width_us: 100,
    };
    b.send(Message::Pulse(replay));
    assert_eq!(b.last_emcy().code, ErrorCode::SequenceError);
    b.run(3, true);
    assert_eq!(b.plant.pulses(), 2);
    assert_eq!(b.stim.rejected(), 3);
}

#[test]
fn ceilings_and_channel_are_enforced() {
    let mut b = Bench::new();
    b.operational();
    b.pulse(1001, 100);
    assert_eq!(
        (b.last_emcy().code, b.last_emcy().detail),
        (ErrorCode::AmplitudeCeiling, 1001)
    );
    b.pulse(1000, 501);
    assert_eq!(
        (b.last_emcy().code, b.last_emcy().detail),
        (ErrorCode::WidthCeiling, 501)
    );
    let mut p = b.next_pulse(10, 10);
    p.channel = 3;
    b.send(Message::Pulse(p));
    assert_eq!(
        (b.last_emcy().code, b.last_emcy().detail),
        (ErrorCode::ChannelInvalid, 3)
    );
    // Out of the protocol's range: a decode error, quoting the (intact) frame's seq.
    let mut d = Message::Pulse(b.next_pulse(0, 0)).encode().unwrap();
    d.data[3..5].copy_from_slice(&2000u16.to_le_bytes());
    let body: [u8; 7] = d.data[..7].try_into().unwrap();
    d.data[7] = fes_can::crc::frame_crc(0x110, &body);
    b.frame(d);
    assert_eq!(b.last_emcy().code, ErrorCode::ValueOutOfRange);
    assert_eq!((b.last_emcy().seq, b.last_emcy().detail), (b.seq, 2000));
    b.run(2, true);
    assert_eq!(b.plant.pulses(), 0);
}

#[test]
fn rate_limit_over_the_window() {
    let mut b = Bench::new();
    let l = StimLimits {
        max_pulses: 3,
        rate_window_ms: 50,
        ..settings().ceiling
    };
    b.configure(l, 7);
    assert!(b.emcys().is_empty());
    assert_eq!(b.stim.config_id(), 7);
    b.operational();
    let mut accepted_at = Vec::new();
    for _ in 0..20 {
        let before = b.emcys().len();
        b.pulse(100, 100);
        if b.emcys().len() == before {
            accepted_at.push(b.stim.next_tick());
        } else {
            assert_eq!(b.last_emcy().code, ErrorCode::RateViolation);
            assert_eq!(b.last_emcy().detail, 3);
        }
        b.run(5, true);
    }
    // Independent count: every 50-tick window holds at most 3 applied pulses.
    for &t in &accepted_at {
        let n = accepted_at
            .iter()
            .filter(|&&a| a <= t && a + 50 > t)
            .count();
        assert!(n <= 3, "{n} pulses in the window ending at {t}");
    }
    // Pulses every 5 ticks for 100 ticks: 3 per 50 ticks get through = 6 (+1 edge).
    assert!((6..=7).contains(&accepted_at.len()), "{accepted_at:?}");
}

#[test]
fn config_only_in_pre_operational_and_never_looser_than_the_ceiling() {
    let mut b = Bench::new();
    // Looser amplitude ceiling than the stimulator's own: refused, detail = field index 0.
    b.configure(
        StimLimits {
            max_amplitude_100ua: 1001,
            ..settings().ceiling
        },
        3,
    );
    assert_eq!(
        (b.last_emcy().code, b.last_emcy().detail),
        (ErrorCode::ConfigInvalid, 0)
    );
    assert_eq!(b.stim.config_id(), 0);
    // A watchdog of 19 ms is outside the protocol's range: a decode error.
    let [_, page1, _] = settings().ceiling.to_pages(4);
    let mut f = Message::Config(page1).encode().unwrap();
    f.data[6..8].copy_from_slice(&19u16.to_le_bytes());
    b.frame(f);
    assert_eq!(
        (b.last_emcy().code, b.last_emcy().detail),
        (ErrorCode::ValueOutOfRange, 19)
    );
    // Watchdog under two host heartbeat periods: refused, index 5.
    let s = Settings {
        host_heartbeat_ms: 30,
        ceiling: StimLimits {
            watchdog_ms: 100,
            ..settings().ceiling
        },
        ..settings()
    };
    let mut c = Bench::with(s);
    c.configure(
        StimLimits {
            watchdog_ms: 50,
            ..s.ceiling
        },
        4,
    );
    assert_eq!(
        (c.last_emcy().code, c.last_emcy().detail),
        (ErrorCode::ConfigInvalid, 5)
    );
    // A stricter configuration is applied and shows in STATUS.
    let strict = StimLimits {
        max_amplitude_100ua: 300,
        min_ipi_ms: 5,
        ..settings().ceiling
    };
    b.configure(strict, 9);
    assert_eq!((b.stim.config_id(), *b.stim.limits()), (9, strict));
    b.run(1, true);
    assert_eq!(b.last_status().config_id, 9);
    // In operational CONFIG is a wrong-state command.
    b.operational();
    b.configure(settings().ceiling, 10);
    assert_eq!(
        (b.last_emcy().code, b.last_emcy().detail),
        (ErrorCode::WrongState, 0x310)
    );
    assert_eq!(b.stim.config_id(), 9);
    // And the stricter amplitude ceiling now applies.
    b.pulse(301, 100);
    assert_eq!(b.last_emcy().code, ErrorCode::AmplitudeCeiling);
}

#[test]
fn a_partial_config_is_never_applied() {
    let mut b = Bench::new();
    let [page0, _, _] = StimLimits {
        max_amplitude_100ua: 10,
        ..settings().ceiling
    }
    .to_pages(5);
    b.send(Message::Config(page0));
    b.operational();
    b.nmt(NmtCommand::EnterPreOperational);
    let [_, page1, page2] = settings().ceiling.to_pages(5);
    b.send(Message::Config(page1));
    b.send(Message::Config(page2));
    assert_eq!(
        b.stim.config_id(),
        0,
        "page 0 was discarded on leaving pre-operational"
    );
}

#[test]
fn watchdog_stops_within_its_time_plus_one_tick_and_never_rearms() {
    let mut b = Bench::new();
    b.operational();
    b.run(50, true);
    // The host goes silent right after the heartbeat of tick 50.
    b.heartbeat();
    let last_hb = b.now();
    let p = b.pulse(100, 100);
    b.run(1, false); // applied
    let mut fault_at = None;
    for _ in 0..200 {
        b.run(1, false);
        if b.stim.state() == StimState::Fault {
            fault_at = Some(b.now() - TICK_NS);
            break;
        }
    }
    let fault_at = fault_at.expect("the watchdog fired");
    let latency = fault_at - last_hb;
    assert!(
        latency > 100 * 1_000_000 && latency <= 101 * 1_000_000,
        "latency {latency} ns"
    );
    let e = b.last_emcy();
    assert_eq!(
        (e.code, e.state, e.detail),
        (ErrorCode::HeartbeatLost, StimState::Fault, 101)
    );
    assert_eq!(b.plant.pulses(), 1);
    let _ = p;
    // Heartbeats and pulses resume: still in fault, pulses refused, none applied.
    for _ in 0..10 {
        b.heartbeat();
        b.pulse(100, 100);
        assert_eq!(b.last_emcy().code, ErrorCode::WrongState);
        b.run(20, true);
    }
    assert_eq!(b.stim.state(), StimState::Fault);
    assert_eq!(b.plant.pulses(), 1);
    assert_eq!(b.last_status().state, StimState::Fault);
    // An explicit NMT start clears the fault (EMCY "no error") and re-arms.
    b.nmt(NmtCommand::Start);
    assert_eq!(
        b.last_emcy(),
        Emcy::new(ErrorCode::NoError, StimState::Armed, 0, 0)
    );
    b.pulse(100, 100);
    b.run(2, true);
    assert_eq!(b.plant.pulses(), 2);
}

#[test]
fn watchdog_cancels_a_pending_pulse() {
    let mut b = Bench::new();
    b.operational();
    b.run(101, false); // no heartbeat for 101 ticks after start; not yet expired at tick 100
    assert_eq!(b.stim.state(), StimState::Armed);
    let p = b.pulse(100, 100);
    b.run(1, false);
    let e = b.emcys();
    assert_eq!(e[e.len() - 2].code, ErrorCode::HeartbeatLost);
    assert_eq!(
        (e[e.len() - 1].code, e[e.len() - 1].seq),
        (ErrorCode::WrongState, p.seq)
    );
    assert_eq!(b.plant.pulses(), 0);
}

#[test]
fn stop_cancels_output_and_nmt_to_other_nodes_is_ignored() {
    let mut b = Bench::new();
    b.operational();
    b.send(Message::Nmt(Nmt {
        command: NmtCommand::Stop,
        node: 0x11,
    }));
    assert_eq!(b.stim.state(), StimState::Armed);
    let p = b.pulse(100, 100);
    b.send(Message::Nmt(Nmt {
        command: NmtCommand::Stop,
        node: 0,
    }));
    assert_eq!(b.stim.state(), StimState::Stopped);
    assert_eq!(
        (b.last_emcy().code, b.last_emcy().seq),
        (ErrorCode::WrongState, p.seq)
    );
    b.run(3, true);
    assert_eq!(b.plant.pulses(), 0);
    b.run(200, true); // a stopped stimulator has no watchdog to trip
    assert_eq!(b.stim.state(), StimState::Stopped);
    assert_eq!(b.last_status().state, StimState::Stopped);
}

/// A reset node restores the protocol state, not the tissue: a host that resets and
/// restarts the stimulator between two pulses gets neither a shorter IPI nor a fresh rate
/// window. (Found by `tests/it/stimulator_props.rs`: the reset cleared the pulse history.)
#[test]
fn reset_node_keeps_the_minimum_ipi_and_the_rate_window() {
    let limits = StimLimits {
        min_ipi_ms: 50,
        max_pulses: 2,
        rate_window_ms: 1000,
        ..settings().ceiling
    };
    // Reset, configure the same limits again, restart.
    let restart = |b: &mut Bench| {
        b.nmt(NmtCommand::ResetNode);
        b.configure(limits, 3);
        b.operational();
    };
    let mut b = Bench::new();
    b.configure(limits, 3);
    b.operational();
    b.pulse(100, 100);
    b.run(2, true);
    assert_eq!(b.plant.pulses(), 1);
    // Restart, pulse 2 ms later: inside the IPI.
    restart(&mut b);
    let p = b.pulse(100, 100);
    assert_eq!(
        (b.last_emcy().code, b.last_emcy().seq),
        (ErrorCode::MinIpiViolation, p.seq)
    );
    b.run(60, true);
    assert_eq!(b.plant.pulses(), 1, "the IPI was reset");
    // The second pulse of the window, after the IPI: applied.
    b.pulse(100, 100);
    b.run(60, true);
    assert_eq!(b.plant.pulses(), 2);
    // A reset and restart do not open a new rate window: the third is refused.
    restart(&mut b);
    let p = b.pulse(100, 100);
    assert_eq!(
        (b.last_emcy().code, b.last_emcy().seq),
        (ErrorCode::RateViolation, p.seq)
    );
    b.run(5, true);
    assert_eq!(b.plant.pulses(), 2, "the rate window was reset");
}

#[test]
fn reset_node_restores_defaults_and_reboots() {
    let mut b = Bench::new();
    b.configure(
        StimLimits {
            max_width_us: 100,
            ..settings().ceiling
        },
        2,
    );
    b.operational();
    b.pulse(100, 100);
    b.run(2, true);
    b.pulse(5000 / 5, 100); // 100 mA: at the ceiling, accepted
    b.run(2, true);
    b.nmt(NmtCommand::ResetNode);
    assert_eq!(
        *b.sent.last().unwrap(),
        Message::StimHeartbeat(Heartbeat {
            state: NmtState::BootUp
        })
    );
    assert_eq!(
        (
            b.stim.state(),
            b.stim.config_id(),
            b.stim.pulses_delivered()
        ),
        (StimState::PreOperational, 0, 0)
    );
    b.run(10, true);
    let s = b.last_status();
    assert_eq!(
        (s.last_error, s.rejected, s.config_id),
        (ErrorCode::NoError, 0, 0)
    );
}

#[test]
fn wrong_length_and_bad_values_are_reported() {
    let mut b = Bench::new();
    b.frame(Frame {
        id: 0x701,
        dlc: 2,
        data: [5, 0, 0, 0, 0, 0, 0, 0],
    });
    assert_eq!(
        (b.last_emcy().code, b.last_emcy().detail),
        (ErrorCode::LengthError, 2)
    );
    b.frame(Frame {
        id: 0x000,
        dlc: 2,
        data: [0x03, 0x10, 0, 0, 0, 0, 0, 0],
    });
    assert_eq!(
        (b.last_emcy().code, b.last_emcy().detail),
        (ErrorCode::ValueOutOfRange, 3)
    );
    // Frames for other nodes or of other kinds are not this stimulator's business.
    b.frame(Frame {
        id: 0x111,
        dlc: 1,
        data: [0; 8],
    });
    b.frame(Frame {
        id: 0x190,
        dlc: 3,
        data: [0; 8],
    });
    assert_eq!(b.emcys().len(), 2);
    assert_eq!(b.stim.rejected(), 2);
}

#[test]
fn a_config_with_a_reserved_byte_set_is_refused_naming_the_byte() {
    let mut b = Bench::new();
    // The charge page uses bytes 0-3; byte 6 is reserved.
    let [_, _, charge] = settings().ceiling.to_pages(5);
    let mut f = Message::Config(charge).encode().unwrap();
    f.data[6] = 0x01;
    b.frame(f);
    assert_eq!(
        (b.last_emcy().code, b.last_emcy().detail),
        (ErrorCode::ValueOutOfRange, 6)
    );
    assert_eq!(b.stim.rejected(), 1);
    assert_eq!(b.stim.config_id(), 0);
}

#[test]
fn missed_ticks_advance_the_plant_without_extra_frames_or_pulses() {
    let mut b = Bench::new();
    b.operational();
    b.heartbeat();
    let p = b.pulse(100, 100);
    // The first tick comes as tick 5: ticks 0-4 were missed.
    let t = Tick {
        index: 5,
        nominal_ns: T0 + 6 * TICK_NS,
        now_ns: T0 + 6 * TICK_NS,
    };
    b.stim.tick(t, &mut b.plant, &mut b.out);
    b.collect();
    assert_eq!(b.plant.steps(), 6);
    assert_eq!(b.plant.pulses(), 1);
    assert_eq!(b.forces().len(), 1);
    assert_eq!(b.stim.diagnostics().missed_ticks, 5);
    assert_eq!(b.stim.next_tick(), 6);
    let _ = p;
}

#[test]
fn shutdown_turns_output_off_and_reports() {
    let mut b = Bench::new();
    b.operational();
    let p = b.pulse(100, 100);
    b.stim.shutdown(&mut b.out);
    b.collect();
    let n = b.sent.len();
    assert!(
        matches!(b.sent[n - 3], Message::Emcy(e) if e.code == ErrorCode::WrongState && e.seq == p.seq)
    );
    assert!(
        matches!(b.sent[n - 2], Message::Status(s) if s.state == StimState::Stopped && s.pulses_delivered == 0)
    );
    assert_eq!(
        b.sent[n - 1],
        Message::StimHeartbeat(Heartbeat {
            state: NmtState::Stopped
        })
    );
}

#[test]
fn settings_are_validated() {
    let s = settings();
    assert!(s.validate().is_ok());
    assert_eq!(
        Settings { channels: 0, ..s }.validate(),
        Err(SettingsError::Channels(0))
    );
    assert!(matches!(
        Settings {
            host_heartbeat_ms: 60,
            ..s
        }
        .validate(),
        Err(SettingsError::WatchdogTooShort { .. })
    ));
    assert!(matches!(
        Settings {
            ceiling: StimLimits {
                min_ipi_ms: 0,
                ..s.ceiling
            },
            ..s
        }
        .validate(),
        Err(SettingsError::Limits(_))
    ));
}

#[test]
fn two_hundred_pulses_at_random_legal_ipis_all_arrive() {
    // Deterministic pseudo-random IPIs in 2..=40 ticks (xorshift), amplitudes, widths.
    let mut x: u32 = 0x2545_F491;
    let mut rnd = move |n: u32| {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        x % n
    };
    let mut b = Bench::new();
    b.operational();
    let mut expected_uc = 0.0;
    for _ in 0..200 {
        let p = b.pulse(1 + rnd(1000) as u16, 1 + rnd(500) as u16);
        expected_uc += charge_uc(&p);
        b.run(u64::from(2 + rnd(39)), true);
    }
    b.run(10, true);
    assert!(b.emcys().is_empty(), "{:?}", b.emcys());
    assert_eq!(b.last_status().pulses_delivered, 200);
    let last = b.forces().last().unwrap().force_mn;
    // 200 roundings of 1 mN resolution are not involved: only the final value is rounded.
    assert!(
        (f64::from(last) - expected_uc * 1000.0).abs() <= 0.5 + 1e-6,
        "{last} mN vs {expected_uc} uC"
    );
}

#[test]
fn advance_skips_to_the_next_grid_point() {
    assert_eq!(advance(100, 10, 99), 100);
    assert_eq!(advance(100, 10, 100), 110);
    assert_eq!(advance(100, 10, 135), 140);
}

/// Frames read late but stamped with their arrival: a stall of the stimulator's loop
/// (its process not scheduled) must not turn properly spaced pulses into a burst, and
/// pulses that really were sent too close stay violations.
#[test]
fn a_stalled_loop_applies_pulses_at_their_arrival_ticks() {
    let mut b = Bench::new();
    b.operational();
    b.run(1, true);
    // Ticks 1..=59 never run; meanwhile pulses arrive at ticks 10, 30 and 50 and the host
    // heartbeat every 10 ms, all read at once when the loop wakes for tick 60.
    let at = |tick: u64| T0 + TICK_NS + tick * TICK_NS + 300_000;
    let mut sent = Vec::new();
    for t in (10..60).step_by(10) {
        let hb = Message::HostHeartbeat(Heartbeat {
            state: NmtState::Operational,
        })
        .encode()
        .unwrap();
        b.stim
            .on_frame(at(t), u32::from(hb.id), hb.payload(), &mut b.out);
        if t % 20 == 10 {
            let p = b.next_pulse(100, 100);
            let f = Message::Pulse(p).encode().unwrap();
            b.stim
                .on_frame(at(t), u32::from(f.id), f.payload(), &mut b.out);
            sent.push(p);
        }
    }
    b.collect();
    assert!(b.emcys().is_empty(), "{:?}", b.emcys());
    assert!(b.stim.has_pending_pulse());
    b.tick = 60;
    let report = b.stim.tick(
        Tick {
            index: 60,
            nominal_ns: b.now(),
            now_ns: b.now(),
        },
        &mut b.plant,
        &mut b.out,
    );
    b.collect();
    assert_eq!(report.caught_up_pulses, 3);
    let caught: Vec<(u64, u16)> = b.stim.caught_up().map(|c| (c.tick, c.pulse.seq)).collect();
    assert_eq!(
        caught,
        sent.iter()
            .zip([10, 30, 50])
            .map(|(p, t)| (t, p.seq))
            .collect::<Vec<_>>(),
        "each applied at the tick period it arrived in"
    );
    assert_eq!(report.applied, None);
    assert_eq!(b.plant.pulses(), 3);
    assert_eq!(b.stim.pulses_delivered(), 3);
    assert!(!b.stim.has_pending_pulse());
    assert_eq!(b.stim.state(), StimState::Stimulating);
    // The charge integrator saw the three pulses (FORCE after the catch-up).
    b.run(1, true);
    let f = *b.forces().last().unwrap();
    let expected: f64 = sent.iter().map(charge_uc).sum();
    assert!((f.force_n() - expected).abs() < 1e-3, "{f:?} vs {expected}");

    // Two pulses that arrived 1 ms apart (min IPI 2 ms) and were read together later:
    // the second is refused, as on time.
    let base = b.tick + 20;
    let p1 = b.next_pulse(100, 100);
    let p2 = b.next_pulse(100, 100);
    for (p, t) in [(p1, base), (p2, base + 1)] {
        let f = Message::Pulse(p).encode().unwrap();
        b.stim
            .on_frame(at(t), u32::from(f.id), f.payload(), &mut b.out);
    }
    b.collect();
    assert_eq!(
        b.last_emcy(),
        Emcy::new(
            ErrorCode::MinIpiViolation,
            StimState::Stimulating,
            p2.seq,
            1
        )
    );
    // A stop that arrived after them cancels what has not been applied, and reports it.
    let before = b.plant.pulses();
    b.nmt(NmtCommand::Stop);
    assert!(!b.stim.has_pending_pulse());
    assert_eq!(b.last_emcy().code, ErrorCode::WrongState);
    b.run(30, true);
    assert_eq!(b.plant.pulses(), before);
}

/// After a stall of the loop, frames are judged as of their arrival: a pulse that arrived
/// when the host's heartbeat had been missing for longer than the watchdog time trips the
/// watchdog and is not applied (found by the seeded SIGSTOP test of the whole stack).
#[test]
fn a_pulse_that_arrived_after_the_heartbeat_expired_is_refused_in_the_catch_up() {
    let mut b = Bench::new();
    b.operational();
    b.run(1, true);
    let watchdog_ms = u64::from(StimLimits::DEFAULT.watchdog_ms);
    let at = |tick: u64| T0 + TICK_NS + tick * TICK_NS + 300_000;
    // One pulse while the heartbeat is fresh, one after the heartbeat's absence passed
    // the watchdog time; all read at once later.
    let hb = Message::HostHeartbeat(Heartbeat {
        state: NmtState::Operational,
    })
    .encode()
    .unwrap();
    b.stim
        .on_frame(at(5), u32::from(hb.id), hb.payload(), &mut b.out);
    let early = b.next_pulse(100, 100);
    let f = Message::Pulse(early).encode().unwrap();
    b.stim
        .on_frame(at(10), u32::from(f.id), f.payload(), &mut b.out);
    let late = b.next_pulse(100, 100);
    let f = Message::Pulse(late).encode().unwrap();
    b.stim.on_frame(
        at(5 + watchdog_ms + 10),
        u32::from(f.id),
        f.payload(),
        &mut b.out,
    );
    b.collect();
    assert_eq!(b.stim.state(), StimState::Fault);
    let codes: Vec<ErrorCode> = b.emcys().iter().map(|e| e.code).collect();
    assert!(codes.contains(&ErrorCode::HeartbeatLost), "{codes:?}");
    // The fault turned the output off: the early pulse, still waiting, is cancelled too.
    assert!(!b.stim.has_pending_pulse());
    b.tick = 5 + watchdog_ms + 20;
    let report = b.stim.tick(
        Tick {
            index: b.tick,
            nominal_ns: b.now(),
            now_ns: b.now(),
        },
        &mut b.plant,
        &mut b.out,
    );
    assert_eq!(report.caught_up_pulses, 0);
    assert_eq!(b.plant.pulses(), 0);
}

#[test]
fn the_charge_ceiling_is_enforced_per_phase() {
    // The prescription's 4 uC per phase (20 mA x 200 us), under 100 mA and 500 us ceilings.
    let mut b = Bench::new();
    let dose = StimLimits {
        max_charge_10nc: 400,
        ..settings().ceiling
    };
    b.configure(dose, 3);
    assert_eq!((b.stim.config_id(), *b.stim.limits()), (3, dose));
    b.operational();
    // 20.1 mA x 200 us = 4.02 uC: each within its own ceiling, the product above.
    b.pulse(201, 200);
    assert_eq!(
        (b.last_emcy().code, b.last_emcy().detail),
        (ErrorCode::ChargeCeiling, 402)
    );
    // 40 mA x 101 us = 4.04 uC.
    b.pulse(400, 101);
    assert_eq!(b.last_emcy().code, ErrorCode::ChargeCeiling);
    b.run(3, true);
    assert_eq!(b.plant.pulses(), 0);
    // Exactly the dose passes.
    b.pulse(200, 200);
    b.run(3, true);
    assert_eq!(b.plant.pulses(), 1);
    // A CONFIG may not loosen the stimulator's own charge ceiling (index 6).
    let mut c = Bench::new();
    c.configure(
        StimLimits {
            max_charge_10nc: 5001,
            ..settings().ceiling
        },
        4,
    );
    assert_eq!(
        (c.last_emcy().code, c.last_emcy().detail),
        (ErrorCode::ConfigInvalid, 6)
    );
}

fn applied_pages(b: &Bench) -> Vec<fes_can::Config> {
    b.sent
        .iter()
        .filter_map(|m| match m {
            Message::ConfigApplied(c) => Some(*c),
            _ => None,
        })
        .collect()
}

#[test]
fn config_applied_reports_the_limits_in_force() {
    let strict = StimLimits {
        max_amplitude_100ua: 200,
        max_width_us: 200,
        max_charge_10nc: 400,
        ..settings().ceiling
    };
    let mut b = Bench::new();
    b.configure(strict, 7);
    assert_eq!(applied_pages(&b), strict.to_pages(7).to_vec());
    // A refused CONFIG is not reported as applied.
    let mut c = Bench::new();
    c.configure(
        StimLimits {
            max_amplitude_100ua: 1001,
            ..settings().ceiling
        },
        8,
    );
    assert!(applied_pages(&c).is_empty());
    // The test fault: the stimulator keeps its own amplitude ceiling and says so.
    let mut f = Bench::with(Settings {
        test_fault_loose_config: true,
        ..settings()
    });
    f.configure(strict, 9);
    let looser = StimLimits {
        max_amplitude_100ua: 1000,
        ..strict
    };
    assert_eq!(*f.stim.limits(), looser);
    assert_eq!(applied_pages(&f), looser.to_pages(9).to_vec());
}
