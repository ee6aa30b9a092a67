//! A virtual Hasomed RehaStim 2: the device side of ScienceMode 2 (`fes-sciencemode`,
//! `docs/sciencemode.md`) as a pure state machine, driven by a 1 ms tick like the CAN
//! stimulator ([`super::machine`]) and applying its pulses to the same [`Plant`].
//!
//! What it does, as the device does:
//!
//! * announces itself with Init (protocol version 1) every [`Rehastim2Settings::init_period_ms`]
//!   (500 ms, the description's InitRepetitionTime, §2.3) until the host answers InitAck;
//!   before that it ignores every other command;
//! * answers GetStimulationMode, InitChannelListMode, StartChannelListMode (start or update),
//!   StopChannelListMode and SinglePulse with their acknowledgements, refusing values
//!   outside the device's range (`fes_sciencemode::limits`) with a parameter error and
//!   commands in the wrong mode with a wrong-mode error (§3.6 Fig. 4: SinglePulse only in
//!   start mode, before InitChannelListMode);
//! * generates currents in 2 mA steps (HASOMED: 0-126 mA in 2 mA steps): an odd mA is
//!   delivered, and logged, as the even mA below it;
//! * in channel list mode, fires each active channel's pulse (or doublet, triplet) every
//!   main interval, low-frequency channels every (factor + 1)-th interval, channels and
//!   repeated pulses the inter-pulse interval apart;
//! * its watchdog (§2.3 WatchdogTimeout, 1200 ms; §5.2): when the host sends nothing for
//!   [`Rehastim2Settings::watchdog_ms`], stimulation stops, every mode is reset and the
//!   connection is dropped: the device announces Init again every `init_period_ms` and
//!   ignores commands until a new InitAck;
//! * with [`Rehastim2Settings::motomed_actual_values`], a MOTOmed attached: ActualValues
//!   every 20 ms (§2.3 ActualValuesInterval, §4.4), numbered by the device's own packet
//!   counter (§2.2).
//!
//! Every delivered pulse and every watchdog expiry goes to the [`Event`] log. The plant is
//! the muscle under one channel ([`Rehastim2Settings::muscle_channel`]); pulses on the
//! others are logged only. At most one pulse per 1 ms step reaches the plant; a second one
//! due in the same step waits for the next.

use std::collections::VecDeque;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use fes_sciencemode::limits::{self, effective_width_us};
use fes_sciencemode::{
    AckResult, ChannelListInit, ChannelListUpdate, DecodeError, MAX_PACKET_LEN, Message,
    PROTOCOL_VERSION, Packet, StimulationMode,
};

use super::watchdog::HeartbeatWatchdog;
use crate::plant::{self, Plant};

/// The tick period, ns.
pub const TICK_NS: u64 = 1_000_000;

/// The virtual device's settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rehastim2Settings {
    /// Silence from the host after which channel list mode stops, ms.
    pub watchdog_ms: u16,
    /// Period of the Init announcement until the host answers, ms.
    pub init_period_ms: u16,
    /// The channel (1..=8) whose muscle the plant models.
    pub muscle_channel: u8,
    /// A fault to inject, for tests of a host (none on a real device's behalf).
    pub test_fault: Option<TestFault>,
    /// The device's latency in executing a command, ms: a packet is acted on (and
    /// answered) this long after it arrived (0: in the next tick). Hasomed gives 10-24 ms
    /// for the real device (`docs/sciencemode.md`).
    pub latency_ms: u16,
    /// A MOTOmed attached: the device sends ActualValues every 20 ms once connected.
    pub motomed_actual_values: bool,
    /// The device's mean time to process a command, ms (0: off, the command is acted on
    /// as [`Self::latency_ms`] says). §2.3: responses take up to 100 ms (MaxResponseTime),
    /// on average under 20 ms. When on, each command that has an acknowledgement takes
    /// 0.5..1.5 x this mean, or [`SLOW_PROCESSING_MS`] for [`SLOW_PROCESSING_PERCENT`] % of
    /// them, and is answered when done; a command arriving meanwhile is answered with -8
    /// busy (§5.1: "RehaStim2 is currently processing the last command").
    pub processing_mean_ms: u16,
}

/// The slow share of commands when [`Rehastim2Settings::processing_mean_ms`] is on, %.
pub const SLOW_PROCESSING_PERCENT: u32 = 3;
/// A slow command's processing time, ms (§2.3 MaxResponseTime).
pub const SLOW_PROCESSING_MS: u64 = 100;

/// The ActualValues interval with a MOTOmed attached, ms (§2.3 ActualValuesInterval).
pub const ACTUAL_VALUES_INTERVAL_MS: u64 = 20;

/// What [`TestFault`] makes the device do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TestFaultKind {
    /// The pulse is not fired and StimulationError -2 (electrode error) is sent instead of
    /// its acknowledgement.
    Electrode,
    /// The pulse is not fired and acknowledged with a parameter error (-2).
    ParameterError,
    /// The device answers nothing from this pulse on (it keeps reading).
    Silent,
}

/// A fault the virtual device injects at its `after_pulses + 1`-th SinglePulse
/// (`--test-fault KIND:N`: `electrode:N`, `parameter-error:N`, `silent:N`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TestFault {
    /// What happens.
    pub kind: TestFaultKind,
    /// SinglePulse commands served normally before it.
    pub after_pulses: u64,
}

impl std::str::FromStr for TestFault {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let (kind, n) = s
            .split_once(':')
            .ok_or_else(|| format!("{s:?}: expected KIND:N"))?;
        let kind = match kind {
            "electrode" => TestFaultKind::Electrode,
            "parameter-error" => TestFaultKind::ParameterError,
            "silent" => TestFaultKind::Silent,
            other => {
                return Err(format!(
                    "{other:?}: expected electrode, parameter-error or silent"
                ));
            }
        };
        let after_pulses = n
            .parse()
            .map_err(|_| format!("{n:?}: expected a number of pulses"))?;
        Ok(TestFault { kind, after_pulses })
    }
}

impl Rehastim2Settings {
    /// The device's defaults (§2.3): 1200 ms watchdog, Init every 500 ms; the muscle on
    /// channel 1, no MOTOmed.
    pub const DEFAULT: Rehastim2Settings = Rehastim2Settings {
        watchdog_ms: 1200,
        init_period_ms: 500,
        muscle_channel: 1,
        test_fault: None,
        latency_ms: 0,
        motomed_actual_values: false,
        processing_mean_ms: 0,
    };
}

/// Why a pulse was fired.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PulseSource {
    /// A SinglePulse command.
    Single,
    /// Channel list mode.
    ChannelList,
}

/// What the device did, for its log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// A pulse left the device.
    Pulse {
        /// Tick of delivery (ms since the device started).
        tick: u64,
        /// Channel, 1..=8.
        channel: u8,
        /// Width as generated, us.
        width_us: u16,
        /// Current, mA.
        current_ma: u8,
        /// Why.
        source: PulseSource,
        /// Whether it reached the plant (the muscle's channel).
        applied: bool,
    },
    /// The host fell silent: stimulation stopped, every mode reset, the connection dropped
    /// (the device announces Init again).
    WatchdogExpired {
        /// Tick of expiry.
        tick: u64,
        /// Silence, ms.
        silent_ms: u64,
    },
    /// A packet from the host could not be decoded.
    BadPacket {
        /// Tick of arrival.
        tick: u64,
        /// Why.
        error: DecodeError,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Scheduled {
    tick: u64,
    channel: u8,
    width_us: u16,
    current_ma: u8,
    source: PulseSource,
}

/// The virtual RehaStim 2.
#[derive(Debug)]
pub struct Rehastim2 {
    settings: Rehastim2Settings,
    connected: bool,
    mode: StimulationMode,
    init: Option<ChannelListInit>,
    list: Option<ChannelListUpdate>,
    /// Tick of the next main-interval cycle (channel list mode running).
    next_cycle_tick: u64,
    /// Index of the next cycle, for the low-frequency channels.
    cycle: u64,
    /// Sub-millisecond remainder of the cycle start, us (intervals are multiples of 0.5 ms).
    cycle_phase_us: u64,
    scheduled: VecDeque<Scheduled>,
    watchdog: HeartbeatWatchdog,
    next_init_tick: u64,
    /// The device's own packet counter (Init and information packets, §2.2).
    init_number: u8,
    /// Tick of the next ActualValues (with a MOTOmed).
    next_actual_tick: u64,
    tick: u64,
    events: Vec<Event>,
    force_n: f64,
    /// SinglePulse commands seen (for [`TestFault`]).
    single_pulses: u64,
    /// A [`TestFaultKind::Silent`] fault happened: nothing is answered any more.
    silent: bool,
    /// Packets waiting out the latency: (tick due, packet).
    pending: VecDeque<(u64, Packet)>,
    /// Processing a command until this tick ([`Rehastim2Settings::processing_mean_ms`]).
    busy_until: u64,
    /// The processing times' draws (seeded: a run repeats).
    rng: ChaCha8Rng,
    /// -8 busy acknowledgements sent.
    busy_sent: u64,
    /// Commands processed for [`SLOW_PROCESSING_MS`].
    slow_commands: u64,
    /// -3 wrong-mode acknowledgements sent.
    wrong_mode_sent: u64,
}

impl Rehastim2 {
    /// A device just switched on at tick 0.
    pub fn new(settings: Rehastim2Settings) -> Self {
        Rehastim2 {
            settings,
            connected: false,
            mode: StimulationMode::Start,
            init: None,
            list: None,
            next_cycle_tick: 0,
            cycle: 0,
            cycle_phase_us: 0,
            scheduled: VecDeque::with_capacity(64),
            watchdog: HeartbeatWatchdog::new(settings.watchdog_ms, 0),
            next_init_tick: 0,
            init_number: 0,
            next_actual_tick: 0,
            tick: 0,
            events: Vec::with_capacity(1024),
            force_n: 0.0,
            single_pulses: 0,
            silent: false,
            pending: VecDeque::with_capacity(256),
            busy_until: 0,
            rng: ChaCha8Rng::seed_from_u64(0x9E37_79B9_7F4A_7C15),
            busy_sent: 0,
            slow_commands: 0,
            wrong_mode_sent: 0,
        }
    }

    /// -8 busy acknowledgements the device has sent (a host that waits for each answer
    /// provokes none).
    pub const fn busy_sent(&self) -> u64 {
        self.busy_sent
    }

    /// Commands that took [`SLOW_PROCESSING_MS`] to process.
    pub const fn slow_commands(&self) -> u64 {
        self.slow_commands
    }

    /// -3 wrong-mode acknowledgements the device has sent.
    pub const fn wrong_mode_sent(&self) -> u64 {
        self.wrong_mode_sent
    }

    /// The processing time of the next command, ticks.
    fn draw_processing_ticks(&mut self) -> u64 {
        let mean = u64::from(self.settings.processing_mean_ms);
        if self.rng.random_ratio(SLOW_PROCESSING_PERCENT, 100) {
            self.slow_commands += 1;
            SLOW_PROCESSING_MS
        } else {
            (mean / 2 + self.rng.random_range(0..=mean)).max(1)
        }
    }

    /// Whether the host has answered Init.
    pub const fn connected(&self) -> bool {
        self.connected
    }

    /// The stimulation mode.
    pub const fn mode(&self) -> StimulationMode {
        self.mode
    }

    /// The force at the end of the last tick, N.
    pub const fn force_n(&self) -> f64 {
        self.force_n
    }

    /// Takes the events logged since the last call.
    pub fn drain_events(&mut self) -> std::vec::Drain<'_, Event> {
        self.events.drain(..)
    }

    fn now_ns(&self) -> u64 {
        self.tick * TICK_NS
    }

    /// A decode error on the line: logged (the device cannot tell what the packet was).
    pub fn on_decode_error(&mut self, error: DecodeError) {
        self.events.push(Event::BadPacket {
            tick: self.tick,
            error,
        });
    }

    /// A packet from the host, received during the current tick; the device's answer, if
    /// any, is appended to `out` as bytes on the line.
    pub fn on_packet(&mut self, packet: Packet, out: &mut Vec<u8>) {
        // Any packet is a sign of life, at once.
        self.watchdog.feed(self.now_ns());
        if self.settings.processing_mean_ms > 0
            && self.connected
            && let Some(busy) = busy_ack(&packet.message)
        {
            if self.tick < self.busy_until {
                // §5.1 -8: still processing the last command.
                self.busy_sent += 1;
                send(Packet::new(packet.number, busy), out);
                return;
            }
            // Answered in the tick that ends the processing time (the packet arrived
            // during this tick, before it ran); busy until then.
            let ticks = self.draw_processing_ticks();
            self.busy_until = self.tick + ticks;
            self.pending.push_back((self.tick + ticks - 1, packet));
            return;
        }
        if self.settings.latency_ms > 0 {
            let due = self.tick + u64::from(self.settings.latency_ms);
            self.pending.push_back((due, packet));
            return;
        }
        self.execute(packet, out);
    }

    /// Acts on `packet` and answers it.
    fn execute(&mut self, packet: Packet, out: &mut Vec<u8>) {
        let number = packet.number;
        let fault = match packet.message {
            Message::SinglePulse(_) if self.connected => {
                let f = self
                    .settings
                    .test_fault
                    .filter(|f| f.after_pulses == self.single_pulses)
                    .map(|f| f.kind);
                self.single_pulses += 1;
                f
            }
            _ => None,
        };
        if fault == Some(TestFaultKind::Silent) {
            self.silent = true;
        }
        if self.silent {
            return;
        }
        let reply = match packet.message {
            Message::InitAck { result } => {
                if result.is_ok() && !self.connected {
                    self.connected = true;
                    self.watchdog.feed(self.now_ns());
                    self.next_actual_tick = self.tick;
                }
                None
            }
            _ if !self.connected => None,
            Message::Watchdog => None,
            Message::GetStimulationMode => Some(Message::GetStimulationModeAck {
                result: AckResult::Ok,
                mode: Some(self.mode),
            }),
            Message::InitChannelListMode(init) => Some(Message::InitChannelListModeAck {
                result: self.init_channel_list(init),
            }),
            Message::StartChannelListMode(list) => Some(Message::StartChannelListModeAck {
                result: self.start_channel_list(list),
            }),
            Message::StopChannelListMode => {
                self.stop_channel_list();
                Some(Message::StopChannelListModeAck {
                    result: AckResult::Ok,
                })
            }
            Message::SinglePulse(_) if fault == Some(TestFaultKind::Electrode) => {
                Some(Message::StimulationError {
                    error: fes_sciencemode::StimulationError::Electrode,
                })
            }
            Message::SinglePulse(_) if fault == Some(TestFaultKind::ParameterError) => {
                Some(Message::SinglePulseAck {
                    result: AckResult::ParameterError,
                })
            }
            Message::SinglePulse(p) => {
                // §3.6 Fig. 4: SinglePulse belongs to the stimulation start mode; once
                // InitChannelListMode has been accepted it is the wrong mode.
                let result = if self.mode != StimulationMode::Start {
                    AckResult::WrongModeError
                } else if !p.in_range() {
                    AckResult::ParameterError
                } else {
                    self.schedule(Scheduled {
                        tick: self.tick + 1,
                        channel: p.channel + 1,
                        width_us: effective_width_us(p.pulse_width_us),
                        current_ma: generated_current_ma(p.current_ma),
                        source: PulseSource::Single,
                    });
                    AckResult::Ok
                };
                Some(Message::SinglePulseAck { result })
            }
            // The device's own messages, sent to it: not commands it knows. §4.1:
            // UnknownCommand echoes the packet number and the command byte.
            Message::Init { .. }
            | Message::UnknownCommand { .. }
            | Message::GetStimulationModeAck { .. }
            | Message::InitChannelListModeAck { .. }
            | Message::StartChannelListModeAck { .. }
            | Message::StopChannelListModeAck { .. }
            | Message::SinglePulseAck { .. }
            | Message::StimulationError { .. }
            | Message::PhaseResult(_)
            | Message::ActualValues { .. }
            | Message::MotomedCommandDone { .. }
            | Message::MotomedError { .. } => Some(Message::UnknownCommand {
                command: packet.message.command().id(),
            }),
        };
        if let Some(message) = reply {
            if message.ack_result() == Some(AckResult::WrongModeError) {
                self.wrong_mode_sent += 1;
            }
            send(Packet::new(number, message), out);
        }
    }

    /// Packet `number` whose command byte `command` the device does not know (the
    /// decoder's [`DecodeError::UnknownCommand`]): answered with UnknownCommand echoing
    /// both (§4.1, §5.2 "Unknown command error").
    pub fn on_unknown_command(&mut self, number: u8, command: u8, out: &mut Vec<u8>) {
        self.watchdog.feed(self.now_ns());
        if self.connected {
            send(
                Packet::new(number, Message::UnknownCommand { command }),
                out,
            );
        }
    }

    fn init_channel_list(&mut self, init: ChannelListInit) -> AckResult {
        if self.mode == StimulationMode::Started {
            return AckResult::WrongModeError;
        }
        if !init.in_range() {
            return AckResult::ParameterError;
        }
        self.init = Some(init);
        self.list = None;
        self.mode = StimulationMode::Initialised;
        AckResult::Ok
    }

    fn start_channel_list(&mut self, list: ChannelListUpdate) -> AckResult {
        let Some(init) = self.init else {
            return AckResult::WrongModeError;
        };
        if list.entries().len() != init.active_channels.count_ones() as usize
            || !list.entries().iter().all(|e| e.in_range())
        {
            return AckResult::ParameterError;
        }
        self.list = Some(list);
        if self.mode == StimulationMode::Initialised {
            self.mode = StimulationMode::Started;
            self.next_cycle_tick = self.tick + 1;
            self.cycle_phase_us = 0;
            self.cycle = 0;
        }
        AckResult::Ok
    }

    fn stop_channel_list(&mut self) {
        self.mode = StimulationMode::Start;
        self.init = None;
        self.list = None;
        self.scheduled
            .retain(|s| s.source != PulseSource::ChannelList);
    }

    fn schedule(&mut self, s: Scheduled) {
        let at = self
            .scheduled
            .iter()
            .position(|q| q.tick > s.tick)
            .unwrap_or(self.scheduled.len());
        self.scheduled.insert(at, s);
    }

    /// Plans the pulses of one main-interval cycle starting at `start_us` (us since tick 0).
    fn plan_cycle(&mut self, start_us: u64) {
        let (Some(init), Some(list)) = (self.init, self.list) else {
            return;
        };
        let ipi_us = u64::from(init.inter_pulse_interval_us());
        let low_due = self
            .cycle
            .is_multiple_of(u64::from(init.low_frequency_factor) + 1);
        let mut offset_us = 0;
        let mut entries = list.entries().iter();
        for channel in 1..=limits::CHANNELS {
            let bit = 1u8 << (channel - 1);
            if init.active_channels & bit == 0 {
                continue;
            }
            let Some(e) = entries.next() else { break };
            if init.low_frequency_channels & bit != 0 && !low_due {
                continue;
            }
            for _ in 0..e.mode.pulses() {
                let width_us = effective_width_us(e.pulse_width_us);
                if width_us > 0 && e.current_ma > 0 {
                    self.schedule(Scheduled {
                        tick: (start_us + offset_us).div_ceil(1000),
                        channel,
                        width_us,
                        current_ma: generated_current_ma(e.current_ma),
                        source: PulseSource::ChannelList,
                    });
                }
                offset_us += ipi_us;
            }
        }
    }

    /// Runs one 1 ms tick: Init announcements, the watchdog, channel list cycles, and one
    /// plant step with the pulse due (if any). Answers go to `out`.
    pub fn tick(&mut self, plant: &mut dyn Plant, out: &mut Vec<u8>) {
        while let Some(&(due, packet)) = self.pending.front()
            && due <= self.tick
        {
            self.pending.pop_front();
            self.execute(packet, out);
        }
        if !self.connected && self.tick >= self.next_init_tick {
            send(
                Packet::new(
                    self.init_number,
                    Message::Init {
                        version: PROTOCOL_VERSION,
                    },
                ),
                out,
            );
            self.init_number = self.init_number.wrapping_add(1);
            self.next_init_tick = self.tick + u64::from(self.settings.init_period_ms);
        }
        if self.connected
            && let Some(silent_ns) = self.watchdog.expired(self.now_ns())
        {
            // §5.2 "Data transfer physically broken / disturbed": stimulation stopped, all
            // modes reset, the device sends Init (again every InitRepetitionTime, §2.3,
            // until the host answers).
            self.events.push(Event::WatchdogExpired {
                tick: self.tick,
                silent_ms: silent_ns / 1_000_000,
            });
            self.stop_channel_list();
            self.scheduled.clear();
            self.pending.clear();
            self.connected = false;
            self.next_init_tick = self.tick;
        }
        if self.connected
            && self.settings.motomed_actual_values
            && self.tick >= self.next_actual_tick
        {
            // A crank turning forward at 30 rpm (0.18 degree per ms), 5 dNm active.
            send(
                Packet::new(
                    self.init_number,
                    Message::ActualValues {
                        angle_deg: ((self.tick * 18 / 100) % 360) as u16,
                        speed_rpm: 30,
                        torque_dnm: 5,
                    },
                ),
                out,
            );
            self.init_number = self.init_number.wrapping_add(1);
            self.next_actual_tick = self.tick + ACTUAL_VALUES_INTERVAL_MS;
        }
        if self.mode == StimulationMode::Started {
            while self.next_cycle_tick <= self.tick {
                let start_us = self.next_cycle_tick * 1000 + self.cycle_phase_us;
                self.plan_cycle(start_us);
                let interval_us = self
                    .init
                    .map_or(1_000_000, |i| u64::from(i.main_interval_us()));
                let next_us = start_us + interval_us;
                self.next_cycle_tick = next_us / 1000;
                self.cycle_phase_us = next_us % 1000;
                self.cycle += 1;
            }
        }
        let mut applied = None;
        while self.scheduled.front().is_some_and(|s| s.tick <= self.tick) {
            let Some(s) = self.scheduled.front().copied() else {
                break;
            };
            let to_plant = s.channel == self.settings.muscle_channel;
            if to_plant && applied.is_some() {
                // The plant takes one pulse per step: this one waits for the next tick.
                break;
            }
            self.scheduled.pop_front();
            if to_plant {
                applied = Some(plant::Pulse {
                    amplitude_ma: f64::from(s.current_ma),
                    width_us: f64::from(s.width_us),
                });
            }
            self.events.push(Event::Pulse {
                tick: self.tick,
                channel: s.channel,
                width_us: s.width_us,
                current_ma: s.current_ma,
                source: s.source,
                applied: to_plant,
            });
        }
        self.force_n = plant.step(applied);
        self.tick += 1;
    }
}

/// The -8 busy acknowledgement of a host command that has one (`None`: Watchdog, InitAck
/// and anything a host does not send).
fn busy_ack(m: &Message) -> Option<Message> {
    let result = AckResult::BusyError;
    Some(match m {
        Message::GetStimulationMode => Message::GetStimulationModeAck { result, mode: None },
        Message::InitChannelListMode(_) => Message::InitChannelListModeAck { result },
        Message::StartChannelListMode(_) => Message::StartChannelListModeAck { result },
        Message::StopChannelListMode => Message::StopChannelListModeAck { result },
        Message::SinglePulse(_) => Message::SinglePulseAck { result },
        _ => return None,
    })
}

/// The current the device generates for a requested `current_ma`: its output steps are
/// 2 mA (HASOMED: 0-126 mA in 2 mA steps; the user manual: 0-130 mA in 65 steps), and the
/// protocol description does not say which neighbour an odd value becomes. This device
/// takes the one below (never more than asked).
pub const fn generated_current_ma(current_ma: u8) -> u8 {
    current_ma & !1
}

fn send(packet: Packet, out: &mut Vec<u8>) {
    let mut buf = [0u8; MAX_PACKET_LEN];
    // Every device message fits a packet (one or two data bytes).
    if let Ok(n) = packet.encode(&mut buf) {
        out.extend_from_slice(&buf[..n]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_plant::ChargeIntegrator;
    use fes_sciencemode::{ChannelPulse, Decoder, PulseMode, SinglePulse};

    fn decode(bytes: &[u8]) -> Vec<Packet> {
        Decoder::new().feed(bytes).map(Result::unwrap).collect()
    }

    fn connected() -> (Rehastim2, ChargeIntegrator) {
        let mut d = Rehastim2::new(Rehastim2Settings::DEFAULT);
        let mut plant = ChargeIntegrator::new();
        let mut out = Vec::new();
        d.tick(&mut plant, &mut out);
        assert_eq!(decode(&out), [Packet::new(0, Message::Init { version: 1 })]);
        out.clear();
        // Commands before InitAck are ignored.
        d.on_packet(Packet::new(0, Message::GetStimulationMode), &mut out);
        assert!(out.is_empty());
        d.on_packet(
            Packet::new(
                0,
                Message::InitAck {
                    result: AckResult::Ok,
                },
            ),
            &mut out,
        );
        assert!(d.connected() && out.is_empty());
        (d, plant)
    }

    fn pulses(d: &mut Rehastim2) -> Vec<(u64, u8, u16, u8)> {
        d.drain_events()
            .filter_map(|e| match e {
                Event::Pulse {
                    tick,
                    channel,
                    width_us,
                    current_ma,
                    ..
                } => Some((tick, channel, width_us, current_ma)),
                _ => None,
            })
            .collect()
    }

    fn init(active: u8, lf: u8, factor: u8, main_ms: u16) -> ChannelListInit {
        ChannelListInit {
            low_frequency_factor: factor,
            active_channels: active,
            low_frequency_channels: lf,
            inter_pulse_interval_code: 1, // 2 ms
            main_interval_code: (main_ms - 1) * 2,
            channel_execution: 0,
        }
    }

    fn ack_of(out: &[u8]) -> AckResult {
        let p = decode(out);
        assert_eq!(p.len(), 1, "{p:?}");
        p[0].message.ack_result().unwrap()
    }

    /// The device's one acknowledgement to `packet`.
    fn answer(d: &mut Rehastim2, packet: Packet) -> AckResult {
        let mut out = Vec::new();
        d.on_packet(packet, &mut out);
        ack_of(&out)
    }

    #[test]
    fn announces_init_until_acknowledged() {
        let mut d = Rehastim2::new(Rehastim2Settings::DEFAULT);
        let mut plant = ChargeIntegrator::new();
        let mut out = Vec::new();
        // §2.3 InitRepetitionTime: 500 ms (ticks 0, 500, 1000).
        for _ in 0..1100 {
            d.tick(&mut plant, &mut out);
        }
        assert_eq!(
            decode(&out),
            (0..3)
                .map(|n| Packet::new(n, Message::Init { version: 1 }))
                .collect::<Vec<_>>()
        );
    }

    #[test]
    fn with_a_latency_a_command_is_executed_and_answered_that_much_later() {
        let (mut d, mut plant) = connected();
        d.settings.latency_ms = 5;
        let mut out = Vec::new();
        let pulse = Packet::new(
            7,
            Message::SinglePulse(SinglePulse {
                channel: 0,
                pulse_width_us: 200,
                current_ma: 20,
            }),
        );
        let arrived = d.tick;
        d.on_packet(pulse, &mut out);
        assert!(out.is_empty(), "not answered on arrival");
        let mut answered = None;
        for _ in 0..10 {
            d.tick(&mut plant, &mut out);
            if answered.is_none() && !out.is_empty() {
                answered = Some(d.tick);
                assert_eq!(ack_of(&out), AckResult::Ok);
            }
        }
        // Answered in the tick `arrived + 5` (the tick counter has advanced past it).
        assert_eq!(answered, Some(arrived + 5 + 1));
        let fired: Vec<u64> = pulses(&mut d).iter().map(|p| p.0).collect();
        assert_eq!(fired, [arrived + 5 + 1]);
        assert_eq!(plant.pulses(), 1);
    }

    #[test]
    fn an_injected_fault_strikes_at_its_pulse() {
        let pulse = Packet::new(
            5,
            Message::SinglePulse(SinglePulse {
                channel: 0,
                pulse_width_us: 200,
                current_ma: 20,
            }),
        );
        for (spec, after) in [
            (
                "electrode:2",
                Some(Message::StimulationError {
                    error: fes_sciencemode::StimulationError::Electrode,
                }),
            ),
            (
                "parameter-error:2",
                Some(Message::SinglePulseAck {
                    result: AckResult::ParameterError,
                }),
            ),
            ("silent:2", None),
        ] {
            let (mut d, mut plant) = connected();
            d.settings.test_fault = Some(spec.parse().unwrap());
            let mut out = Vec::new();
            for _ in 0..2 {
                out.clear();
                d.on_packet(pulse, &mut out);
                assert_eq!(ack_of(&out), AckResult::Ok, "{spec}");
                d.tick(&mut plant, &mut out);
                d.tick(&mut plant, &mut out);
            }
            assert_eq!(plant.pulses(), 2, "{spec}");
            out.clear();
            d.on_packet(pulse, &mut out);
            let got: Vec<Message> = decode(&out).into_iter().map(|p| p.message).collect();
            assert_eq!(got, after.into_iter().collect::<Vec<_>>(), "{spec}");
            d.tick(&mut plant, &mut out);
            d.tick(&mut plant, &mut out);
            assert_eq!(plant.pulses(), 2, "{spec}: the faulty pulse is not fired");
            if spec.starts_with("silent") {
                out.clear();
                d.on_packet(Packet::new(6, Message::GetStimulationMode), &mut out);
                assert!(out.is_empty(), "silent answers nothing");
            }
        }
        assert!("electrode".parse::<TestFault>().is_err());
        assert!("smoke:1".parse::<TestFault>().is_err());
    }

    #[test]
    fn single_pulses_reach_the_muscle_within_limits() {
        let (mut d, mut plant) = connected();
        let mut out = Vec::new();
        let pulse = |channel, w, c| {
            Packet::new(
                5,
                Message::SinglePulse(SinglePulse {
                    channel,
                    pulse_width_us: w,
                    current_ma: c,
                }),
            )
        };
        assert_eq!(answer(&mut d, pulse(0, 200, 20)), AckResult::Ok);
        d.tick(&mut plant, &mut out);
        d.tick(&mut plant, &mut out);
        assert_eq!(pulses(&mut d), [(2, 1, 200, 20)]);
        assert_eq!(plant.pulses(), 1);
        assert!((d.force_n() - 4.0).abs() < 1e-9);
        // Out of range: refused, nothing fires.
        for bad in [pulse(0, 501, 20), pulse(0, 200, 127), pulse(8, 200, 20)] {
            out.clear();
            d.on_packet(bad, &mut out);
            assert_eq!(ack_of(&out), AckResult::ParameterError, "{bad:?}");
        }
        // 1..=19 us is raised to 20 us; another channel is logged, not applied.
        out.clear();
        d.on_packet(pulse(0, 5, 10), &mut out);
        d.on_packet(pulse(3, 300, 10), &mut out);
        d.tick(&mut plant, &mut out);
        d.tick(&mut plant, &mut out);
        assert_eq!(pulses(&mut d), [(4, 1, 20, 10), (4, 4, 300, 10)]);
        assert_eq!(plant.pulses(), 2);
    }

    #[test]
    fn channel_list_mode_fires_each_interval_and_obeys_the_modes() {
        let (mut d, mut plant) = connected();
        let mut out = Vec::new();
        // Start before init: wrong mode.
        let list = ChannelListUpdate::new(&[ChannelPulse {
            mode: PulseMode::Single,
            pulse_width_us: 200,
            current_ma: 20,
        }])
        .unwrap();
        assert_eq!(
            answer(&mut d, Packet::new(1, Message::StartChannelListMode(list))),
            AckResult::WrongModeError
        );
        // An 8 ms main interval is the shortest; 7 ms is a parameter error.
        assert_eq!(
            answer(
                &mut d,
                Packet::new(2, Message::InitChannelListMode(init(0b1, 0, 0, 7)))
            ),
            AckResult::ParameterError
        );
        // Channels 1 (single) and 2 (doublet, low frequency, every 2nd), 20 ms.
        assert_eq!(
            answer(
                &mut d,
                Packet::new(3, Message::InitChannelListMode(init(0b11, 0b10, 1, 20)))
            ),
            AckResult::Ok
        );
        // One entry for two active channels: parameter error.
        assert_eq!(
            answer(&mut d, Packet::new(4, Message::StartChannelListMode(list))),
            AckResult::ParameterError
        );
        let two = ChannelListUpdate::new(&[
            ChannelPulse {
                mode: PulseMode::Single,
                pulse_width_us: 200,
                current_ma: 20,
            },
            ChannelPulse {
                mode: PulseMode::Doublet,
                pulse_width_us: 100,
                current_ma: 10,
            },
        ])
        .unwrap();
        d.on_packet(Packet::new(5, Message::StartChannelListMode(two)), &mut out);
        assert_eq!(ack_of(&out), AckResult::Ok);
        assert_eq!(d.mode(), StimulationMode::Started);
        for _ in 0..60 {
            d.tick(&mut plant, &mut out);
        }
        // Started at tick 1: cycles at ticks 2, 22, 42; channel 2's doublet (2 ms and 4 ms
        // after channel 1) in cycles 0 and 2 only.
        assert_eq!(
            pulses(&mut d),
            [
                (2, 1, 200, 20),
                (4, 2, 100, 10),
                (6, 2, 100, 10),
                (22, 1, 200, 20),
                (42, 1, 200, 20),
                (44, 2, 100, 10),
                (46, 2, 100, 10),
            ]
        );
        assert_eq!(plant.pulses(), 3);
        // SinglePulse while the list runs: wrong mode. Stop: back to start mode.
        out.clear();
        assert_eq!(
            answer(
                &mut d,
                Packet::new(
                    6,
                    Message::SinglePulse(SinglePulse {
                        channel: 0,
                        pulse_width_us: 100,
                        current_ma: 10,
                    }),
                )
            ),
            AckResult::WrongModeError
        );
        d.on_packet(Packet::new(7, Message::StopChannelListMode), &mut out);
        assert_eq!(ack_of(&out), AckResult::Ok);
        for _ in 0..50 {
            d.tick(&mut plant, &mut out);
        }
        assert_eq!(pulses(&mut d), []);
        assert_eq!(d.mode(), StimulationMode::Start);
    }

    #[test]
    fn the_watchdog_stops_channel_list_mode_when_the_host_falls_silent() {
        let (mut d, mut plant) = connected();
        let mut out = Vec::new();
        d.on_packet(
            Packet::new(1, Message::InitChannelListMode(init(0b1, 0, 0, 50))),
            &mut out,
        );
        let list = ChannelListUpdate::new(&[ChannelPulse {
            mode: PulseMode::Single,
            pulse_width_us: 200,
            current_ma: 20,
        }])
        .unwrap();
        d.on_packet(
            Packet::new(2, Message::StartChannelListMode(list)),
            &mut out,
        );
        // Watchdogs every 500 ms keep it going for 3 s.
        for t in 0..3000 {
            if t % 500 == 0 {
                d.on_packet(Packet::new(3, Message::Watchdog), &mut out);
            }
            d.tick(&mut plant, &mut out);
        }
        let before = pulses(&mut d).len();
        assert_eq!(before, 60);
        // Silence: the last packet came at tick 2501; the list stops when more than 1200 ms
        // (§2.3 WatchdogTimeout) have passed, at tick 3702.
        for _ in 0..2000 {
            d.tick(&mut plant, &mut out);
        }
        let events: Vec<_> = d.drain_events().collect();
        let expiry = events
            .iter()
            .find_map(|e| match e {
                Event::WatchdogExpired { tick, .. } => Some(*tick),
                _ => None,
            })
            .expect("watchdog expired");
        assert_eq!(expiry, 3702);
        let last_pulse = events
            .iter()
            .filter_map(|e| match e {
                Event::Pulse { tick, .. } => Some(*tick),
                _ => None,
            })
            .max()
            .unwrap();
        assert!(last_pulse < expiry, "pulse at {last_pulse} after {expiry}");
        assert_eq!(d.mode(), StimulationMode::Start);
        // §5.2: all modes reset, the connection dropped: Init at the expiry and every
        // 500 ms after (§2.3 InitRepetitionTime), commands ignored until InitAck.
        assert!(!d.connected());
        let inits: Vec<u8> = decode(&out)
            .into_iter()
            .filter(|p| matches!(p.message, Message::Init { .. }))
            .map(|p| p.number)
            .collect();
        // Ticks 3702, 4202, 4702 (the run ends at tick 5001).
        assert_eq!(inits.len(), 3, "{inits:?}");
        out.clear();
        d.on_packet(Packet::new(9, Message::GetStimulationMode), &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn while_processing_a_command_the_device_answers_busy() {
        // §2.3: responses within 100 ms, on average under 20 ms; §5.1 -8 "currently
        // processing the last command. Wait for the response packet."
        let (mut d, mut plant) = connected();
        d.settings.processing_mean_ms = 10;
        let mut out = Vec::new();
        let single = |n| {
            Packet::new(
                n,
                Message::SinglePulse(SinglePulse {
                    channel: 0,
                    pulse_width_us: 200,
                    current_ma: 20,
                }),
            )
        };
        d.on_packet(single(1), &mut out);
        assert!(out.is_empty(), "answered when processed");
        // A second command at once: busy, answered with -8 and its number.
        d.on_packet(single(2), &mut out);
        assert_eq!(
            decode(&out),
            [Packet::new(
                2,
                Message::SinglePulseAck {
                    result: AckResult::BusyError
                }
            )]
        );
        out.clear();
        // A Watchdog has no answer: never busy.
        d.on_packet(Packet::new(3, Message::Watchdog), &mut out);
        assert!(out.is_empty());
        let mut waited = 0;
        while out.is_empty() {
            d.tick(&mut plant, &mut out);
            waited += 1;
            assert!(waited <= 100, "MaxResponseTime");
        }
        assert_eq!(ack_of(&out), AckResult::Ok);
        assert_eq!(d.busy_sent(), 1);
        // A host that waits for each answer provokes no -8: 200 commands, each sent once
        // the previous one was answered. Processing times: 5..15 ms, some 100 ms.
        let mut times = Vec::new();
        for n in 0..200u8 {
            out.clear();
            d.on_packet(single(n), &mut out);
            let mut t = 0;
            while out.is_empty() {
                d.tick(&mut plant, &mut out);
                t += 1;
            }
            assert_eq!(ack_of(&out), AckResult::Ok);
            times.push(t);
        }
        assert_eq!(d.busy_sent(), 1);
        assert!(times.iter().all(|&t| t <= 100), "{times:?}");
        let mean = times.iter().sum::<u64>() as f64 / times.len() as f64;
        assert!((8.0..20.0).contains(&mean), "mean {mean} ms: {times:?}");
        assert!(times.contains(&100), "some slow commands");
        assert_eq!(d.wrong_mode_sent(), 0);
    }

    #[test]
    fn single_pulse_only_in_start_mode() {
        // §3.6 Fig. 4: SinglePulse is a command of the stimulation start mode; after
        // InitChannelListMode (initialised, not started) it is refused with -3 (§5.1).
        let (mut d, _plant) = connected();
        let mut out = Vec::new();
        let single = Packet::new(
            2,
            Message::SinglePulse(SinglePulse {
                channel: 0,
                pulse_width_us: 200,
                current_ma: 20,
            }),
        );
        assert_eq!(answer(&mut d, single), AckResult::Ok);
        assert_eq!(
            answer(
                &mut d,
                Packet::new(3, Message::InitChannelListMode(init(0b1, 0, 0, 20)))
            ),
            AckResult::Ok
        );
        assert_eq!(answer(&mut d, single), AckResult::WrongModeError);
        d.on_packet(Packet::new(4, Message::StopChannelListMode), &mut out);
        out.clear();
        d.on_packet(single, &mut out);
        assert_eq!(ack_of(&out), AckResult::Ok);
    }

    #[test]
    fn currents_are_generated_in_2_ma_steps() {
        // HASOMED: 0-126 mA in 2 mA steps. An odd mA is accepted and generated (and
        // logged) as the even mA below it.
        let (mut d, mut plant) = connected();
        let mut out = Vec::new();
        for (n, current_ma) in [(1u8, 21u8), (2, 22)] {
            d.on_packet(
                Packet::new(
                    n,
                    Message::SinglePulse(SinglePulse {
                        channel: 0,
                        pulse_width_us: 200,
                        current_ma,
                    }),
                ),
                &mut out,
            );
            d.tick(&mut plant, &mut out);
            d.tick(&mut plant, &mut out);
        }
        let currents: Vec<u8> = pulses(&mut d).into_iter().map(|p| p.3).collect();
        assert_eq!(currents, [20, 22]);
        assert_eq!(generated_current_ma(127), 126);
        assert_eq!(generated_current_ma(0), 0);
    }

    #[test]
    fn with_a_motomed_actual_values_come_every_20_ms_on_the_device_counter() {
        // §2.3 ActualValuesInterval 20 ms; §2.2: information packets carry the device's own
        // packet counter (here after Init 0).
        let (mut d, mut plant) = connected();
        d.settings.motomed_actual_values = true;
        let mut out = Vec::new();
        for _ in 0..100 {
            d.tick(&mut plant, &mut out);
        }
        let actual: Vec<Packet> = decode(&out)
            .into_iter()
            .filter(|p| p.message.is_motomed_information())
            .collect();
        assert_eq!(actual.len(), 5, "{actual:?}");
        assert_eq!(
            actual.iter().map(|p| p.number).collect::<Vec<_>>(),
            [1, 2, 3, 4, 5]
        );
    }
}
