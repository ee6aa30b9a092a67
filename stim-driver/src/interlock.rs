//! The driver's own interlocks: a pure struct, StimTicks in, decisions out, time passed in.
//!
//! They are independent of rt-core's pulse shaper (thesis 6.5.2, which already spaces pulses)
//! and of the stimulator's interlocks, and configured separately (docs/safety.md,
//! hazard H2: the interlocks are enforced in two independent places). A command that violates one is
//! **not** sent and is reported; it is never clamped or otherwise changed.
//!
//! Checks, in order, on every tick:
//!
//! 1. the message itself: [`Contract::validate`] (ranges, flags, consistency);
//! 2. its grid time `t_ns` must not be in the future of the driver's clock;
//! 3. ordering: `seq` must be newer than the last accepted tick's (a repeat is a duplicate,
//!    an older one is out of order) and `t_ns` must increase with it; a `seq` gap means
//!    ticks were lost, and a pulse on the first tick after a gap is refused;
//!
//! and, when the tick fires a pulse:
//!
//! 4. channel allowed; amplitude representable on the bus (a multiple of 0.1 mA: the
//!    driver never rounds); amplitude, width and charge per phase (amplitude x width)
//!    ceilings;
//! 5. delay: the pulse is refused when more than `max_pulse_delay` has passed since its grid
//!    time (a late pulse is a pulse moved in time);
//! 6. minimum inter-pulse interval and at most `max_pulses` in any sliding window of
//!    `rate_window`, both on grid times, against the pulses this struct let through.
//!
//! Interval limits use the grid times the generator intended (deterministic: delivery
//! jitter cannot make a legal pattern fail), and check 5 ties them to real time: for two
//! pulses let through, the time between their sends is at least `min_ipi - max_pulse_delay`.

use fes_rt::msg::{Contract, StimTick, ValidationError};

/// The largest `max_pulses` the rate history can hold (CONFIG's `max_pulses` range).
pub const MAX_RATE_PULSES: usize = 1000;

/// Bus amplitude step, µA (PULSE `amplitude` is in 0.1 mA).
pub const AMPLITUDE_STEP_UA: u32 = 100;

/// Limits of the driver's interlocks, in the driver's units (ns, µA, µs, nC).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InterlockLimits {
    /// Minimum inter-pulse interval on grid times, ns.
    pub min_ipi_ns: u64,
    /// Most pulses in any window of `rate_window_ns`, 1..=[`MAX_RATE_PULSES`].
    pub max_pulses: u16,
    /// Sliding window of the rate limit, ns.
    pub rate_window_ns: u64,
    /// Amplitude ceiling, µA.
    pub max_amplitude_ua: u32,
    /// Width ceiling, µs.
    pub max_width_us: u16,
    /// Charge-per-phase ceiling (amplitude x width), nC.
    pub max_charge_nc: u64,
    /// Bit `c` set = channel `c` may be stimulated.
    pub allowed_channels: u16,
    /// Longest time from a pulse's grid time to its send, ns.
    pub max_pulse_delay_ns: u64,
}

/// Invalid [`InterlockLimits`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LimitsError {
    /// `max_pulses` outside 1..=1000.
    #[error("interlocks.max_pulses = {0} is outside 1..={MAX_RATE_PULSES}")]
    MaxPulses(u16),
    /// A limit that must be positive is zero.
    #[error("interlocks.{0} must be greater than 0")]
    Zero(&'static str),
    /// No channel allowed.
    #[error("interlocks.channels is empty: no channel could ever be stimulated")]
    NoChannel,
}

impl InterlockLimits {
    /// Checks the limits.
    pub fn validate(&self) -> Result<(), LimitsError> {
        if self.max_pulses == 0 || usize::from(self.max_pulses) > MAX_RATE_PULSES {
            return Err(LimitsError::MaxPulses(self.max_pulses));
        }
        for (name, zero) in [
            ("min_ipi_us", self.min_ipi_ns == 0),
            ("rate_window_ms", self.rate_window_ns == 0),
            ("max_amplitude_ua", self.max_amplitude_ua == 0),
            ("max_width_us", self.max_width_us == 0),
            ("max_charge_nc", self.max_charge_nc == 0),
        ] {
            if zero {
                return Err(LimitsError::Zero(name));
            }
        }
        if self.allowed_channels == 0 {
            return Err(LimitsError::NoChannel);
        }
        Ok(())
    }
}

/// Charge per phase of a pulse, nC, rounded up (µA x µs = pC).
pub const fn charge_nc(amplitude_ua: u32, width_us: u16) -> u64 {
    (amplitude_ua as u64 * width_us as u64).div_ceil(1000)
}

/// Why a tick was refused. `Copy`, allocation-free, with the numbers that explain it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Violation {
    /// The message failed [`Contract::validate`].
    Invalid(ValidationError),
    /// `t_ns` lies after the driver's clock.
    FutureTimestamp {
        /// The tick's grid time, ns.
        t_ns: u64,
        /// The driver's clock, ns.
        now_ns: u64,
    },
    /// The same `seq` again.
    Duplicate {
        /// The repeated sequence number.
        seq: u64,
    },
    /// A `seq` older than the last accepted one.
    OutOfOrder {
        /// Last accepted sequence number.
        last: u64,
        /// The tick's.
        seq: u64,
    },
    /// `t_ns` did not increase with `seq`.
    TimeNotIncreasing {
        /// Last accepted grid time, ns.
        last_t_ns: u64,
        /// The tick's.
        t_ns: u64,
    },
    /// A pulse on the first tick after lost ticks.
    SequenceGap {
        /// The sequence number that was expected.
        expected: u64,
        /// The one received.
        seq: u64,
    },
    /// The channel is not in the allowed set.
    ChannelNotAllowed {
        /// The channel.
        channel: u8,
    },
    /// The amplitude is not a whole number of 0.1 mA (the bus step); never rounded.
    AmplitudeNotRepresentable {
        /// The amplitude, µA.
        amplitude_ua: u32,
    },
    /// Amplitude above the ceiling.
    AmplitudeCeiling {
        /// Requested, µA.
        amplitude_ua: u32,
        /// Ceiling, µA.
        max_ua: u32,
    },
    /// Width above the ceiling.
    WidthCeiling {
        /// Requested, µs.
        width_us: u16,
        /// Ceiling, µs.
        max_us: u16,
    },
    /// Charge per phase above the ceiling.
    ChargeCeiling {
        /// Requested, nC.
        charge_nc: u64,
        /// Ceiling, nC.
        max_nc: u64,
    },
    /// The pulse would leave too long after its grid time.
    Late {
        /// Time since the grid time, ns.
        delay_ns: u64,
        /// Limit, ns.
        max_ns: u64,
        /// The generator's share: its publish time (`t_publish_ns`) after the grid time,
        /// ns, so a refusal says whether rt-core or the transport and driver were late.
        published_after_ns: u64,
    },
    /// Closer to the previous pulse than the minimum inter-pulse interval.
    MinIpi {
        /// Interval to the previous pulse, ns.
        ipi_ns: u64,
        /// Minimum, ns.
        min_ns: u64,
    },
    /// The rate window already holds `max_pulses` pulses.
    Rate {
        /// Pulses already in the window.
        in_window: u16,
        /// Window, ns.
        window_ns: u64,
    },
}

impl Violation {
    /// A short name for counters and logs.
    pub const fn name(&self) -> &'static str {
        match self {
            Violation::Invalid(_) => "invalid_message",
            Violation::FutureTimestamp { .. } => "future_timestamp",
            Violation::Duplicate { .. } => "duplicate",
            Violation::OutOfOrder { .. } => "out_of_order",
            Violation::TimeNotIncreasing { .. } => "time_not_increasing",
            Violation::SequenceGap { .. } => "sequence_gap",
            Violation::ChannelNotAllowed { .. } => "channel_not_allowed",
            Violation::AmplitudeNotRepresentable { .. } => "amplitude_not_representable",
            Violation::AmplitudeCeiling { .. } => "amplitude_ceiling",
            Violation::WidthCeiling { .. } => "width_ceiling",
            Violation::ChargeCeiling { .. } => "charge_ceiling",
            Violation::Late { .. } => "late",
            Violation::MinIpi { .. } => "min_ipi",
            Violation::Rate { .. } => "rate",
        }
    }

    /// True for a defect of the tick stream itself (the tick does not count as a sign of
    /// life for the watchdog), false for a pulse refused by a limit.
    pub const fn is_stream_fault(&self) -> bool {
        matches!(
            self,
            Violation::Invalid(_)
                | Violation::FutureTimestamp { .. }
                | Violation::Duplicate { .. }
                | Violation::OutOfOrder { .. }
                | Violation::TimeNotIncreasing { .. }
        )
    }
}

impl core::fmt::Display for Violation {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let us = |ns: u64| ns as f64 / 1000.0;
        match *self {
            Violation::Invalid(e) => write!(f, "invalid StimTick: {e}"),
            Violation::FutureTimestamp { t_ns, now_ns } => write!(
                f,
                "t_ns {t_ns} is {:.1} us in the future",
                us(t_ns - now_ns)
            ),
            Violation::Duplicate { seq } => write!(f, "duplicate tick seq {seq}"),
            Violation::OutOfOrder { last, seq } => {
                write!(f, "tick seq {seq} is older than the last accepted {last}")
            }
            Violation::TimeNotIncreasing { last_t_ns, t_ns } => write!(
                f,
                "t_ns {t_ns} does not increase (last accepted {last_t_ns})"
            ),
            Violation::SequenceGap { expected, seq } => write!(
                f,
                "pulse right after a sequence gap (expected seq {expected}, got {seq})"
            ),
            Violation::ChannelNotAllowed { channel } => {
                write!(f, "channel {channel} is not allowed")
            }
            Violation::AmplitudeNotRepresentable { amplitude_ua } => write!(
                f,
                "amplitude {amplitude_ua} uA is not a multiple of {AMPLITUDE_STEP_UA} uA"
            ),
            Violation::AmplitudeCeiling {
                amplitude_ua,
                max_ua,
            } => write!(
                f,
                "amplitude {amplitude_ua} uA above the ceiling {max_ua} uA"
            ),
            Violation::WidthCeiling { width_us, max_us } => {
                write!(f, "width {width_us} us above the ceiling {max_us} us")
            }
            Violation::ChargeCeiling { charge_nc, max_nc } => write!(
                f,
                "charge per phase {charge_nc} nC above the ceiling {max_nc} nC"
            ),
            Violation::Late {
                delay_ns,
                max_ns,
                published_after_ns,
            } => write!(
                f,
                "pulse {:.1} us after its grid time (limit {:.1} us; published {:.1} us after it)",
                us(delay_ns),
                us(max_ns),
                us(published_after_ns)
            ),
            Violation::MinIpi { ipi_ns, min_ns } => write!(
                f,
                "inter-pulse interval {:.3} ms below the minimum {:.3} ms",
                ipi_ns as f64 / 1e6,
                min_ns as f64 / 1e6
            ),
            Violation::Rate {
                in_window,
                window_ns,
            } => write!(
                f,
                "already {in_window} pulses in the last {:.1} ms",
                window_ns as f64 / 1e6
            ),
        }
    }
}

/// A pulse the interlocks let through, in bus units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PulseCommand {
    /// The StimTick that asked for it.
    pub tick_seq: u64,
    /// Its grid time, ns.
    pub t_ns: u64,
    /// When rt-core published it, ns.
    pub t_publish_ns: u64,
    /// Output channel.
    pub channel: u8,
    /// Amplitude in 0.1 mA steps (exact: see [`Violation::AmplitudeNotRepresentable`]).
    pub amplitude_100ua: u16,
    /// Width, µs.
    pub width_us: u16,
}

/// The decision for one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// A valid tick without a pulse.
    NoPulse,
    /// A pulse that passed every check (already counted in the interval history).
    Pulse(PulseCommand),
    /// Refused; `pulse` says whether the tick asked for a pulse.
    Rejected {
        /// Why.
        violation: Violation,
        /// The tick fired a pulse.
        pulse: bool,
    },
}

/// What [`Interlocks::assess`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Assessment {
    /// The decision.
    pub verdict: Verdict,
    /// Ticks missing before this one (a `seq` gap), 0 normally.
    pub lost_ticks: u64,
}

/// Grid times of the most recent pulses let through (a fixed ring; never grows).
#[derive(Debug, Clone)]
struct RateHistory {
    times: [u64; MAX_RATE_PULSES],
    next: usize,
    len: usize,
}

impl RateHistory {
    const fn new() -> Self {
        Self {
            times: [0; MAX_RATE_PULSES],
            next: 0,
            len: 0,
        }
    }

    /// Pulses with grid time in `(t - window, t]`, counting back from the newest, at most
    /// `cap` of them (`cap` = `max_pulses`, so the answer saturates exactly at the limit).
    fn in_window(&self, t_ns: u64, window_ns: u64, cap: usize) -> usize {
        let mut n = 0;
        while n < self.len.min(cap) {
            let i = (self.next + MAX_RATE_PULSES - 1 - n) % MAX_RATE_PULSES;
            if t_ns.saturating_sub(self.times[i]) >= window_ns {
                break;
            }
            n += 1;
        }
        n
    }

    fn push(&mut self, t_ns: u64) {
        self.times[self.next] = t_ns;
        self.next = (self.next + 1) % MAX_RATE_PULSES;
        self.len = (self.len + 1).min(MAX_RATE_PULSES);
    }
}

/// The interlock state: the last accepted tick and the pulses let through.
#[derive(Debug, Clone)]
pub struct Interlocks {
    limits: InterlockLimits,
    last_seq: Option<u64>,
    last_t_ns: u64,
    last_pulse_t_ns: Option<u64>,
    history: RateHistory,
}

impl Interlocks {
    /// Interlocks with `limits` (validated by the caller; see [`InterlockLimits::validate`]).
    pub const fn new(limits: InterlockLimits) -> Self {
        Self {
            limits,
            last_seq: None,
            last_t_ns: 0,
            last_pulse_t_ns: None,
            history: RateHistory::new(),
        }
    }

    /// The limits.
    pub const fn limits(&self) -> &InterlockLimits {
        &self.limits
    }

    /// Forgets the tick order (the next valid tick sets it), keeping the pulse history: used
    /// when arming, so a restarted generator (whose `seq` starts again at 1) can be
    /// followed. The interval limits still count every pulse let through before.
    pub fn resync_sequence(&mut self) {
        self.last_seq = None;
    }

    /// Assesses one tick received at `now_ns` (CLOCK_MONOTONIC). A pulse that passes is
    /// entered in the interval history at once: the caller sends it or, if it cannot,
    /// the history stays conservative (a pulse not sent still counts).
    pub fn assess(&mut self, tick: &StimTick, now_ns: u64) -> Assessment {
        let fires = tick.fires();
        let reject = |violation| Assessment {
            verdict: Verdict::Rejected {
                violation,
                pulse: fires,
            },
            lost_ticks: 0,
        };
        if let Err(e) = tick.validate() {
            return reject(Violation::Invalid(e));
        }
        if tick.t_ns > now_ns {
            return reject(Violation::FutureTimestamp {
                t_ns: tick.t_ns,
                now_ns,
            });
        }
        let mut lost_ticks = 0;
        if let Some(last) = self.last_seq {
            if tick.seq == last {
                return reject(Violation::Duplicate { seq: tick.seq });
            }
            if tick.seq < last {
                return reject(Violation::OutOfOrder {
                    last,
                    seq: tick.seq,
                });
            }
            if tick.t_ns <= self.last_t_ns {
                return reject(Violation::TimeNotIncreasing {
                    last_t_ns: self.last_t_ns,
                    t_ns: tick.t_ns,
                });
            }
            lost_ticks = tick.seq - last - 1;
        }
        self.last_seq = Some(tick.seq);
        self.last_t_ns = tick.t_ns;
        let with_lost = |verdict| Assessment {
            verdict,
            lost_ticks,
        };
        if !fires {
            return with_lost(Verdict::NoPulse);
        }
        match self.check_pulse(tick, now_ns, lost_ticks) {
            Err(violation) => with_lost(Verdict::Rejected {
                violation,
                pulse: true,
            }),
            Ok(command) => {
                self.last_pulse_t_ns = Some(tick.t_ns);
                self.history.push(tick.t_ns);
                with_lost(Verdict::Pulse(command))
            }
        }
    }

    fn check_pulse(
        &self,
        tick: &StimTick,
        now_ns: u64,
        lost_ticks: u64,
    ) -> Result<PulseCommand, Violation> {
        let l = &self.limits;
        if lost_ticks > 0 {
            return Err(Violation::SequenceGap {
                expected: tick.seq - lost_ticks,
                seq: tick.seq,
            });
        }
        if tick.channel >= 16 || l.allowed_channels & (1 << tick.channel) == 0 {
            return Err(Violation::ChannelNotAllowed {
                channel: tick.channel,
            });
        }
        if !tick.amplitude_ua.is_multiple_of(AMPLITUDE_STEP_UA) {
            return Err(Violation::AmplitudeNotRepresentable {
                amplitude_ua: tick.amplitude_ua,
            });
        }
        if tick.amplitude_ua > l.max_amplitude_ua {
            return Err(Violation::AmplitudeCeiling {
                amplitude_ua: tick.amplitude_ua,
                max_ua: l.max_amplitude_ua,
            });
        }
        if tick.width_us > l.max_width_us {
            return Err(Violation::WidthCeiling {
                width_us: tick.width_us,
                max_us: l.max_width_us,
            });
        }
        let charge = charge_nc(tick.amplitude_ua, tick.width_us);
        if charge > l.max_charge_nc {
            return Err(Violation::ChargeCeiling {
                charge_nc: charge,
                max_nc: l.max_charge_nc,
            });
        }
        let delay_ns = now_ns - tick.t_ns;
        if delay_ns > l.max_pulse_delay_ns {
            return Err(Violation::Late {
                delay_ns,
                max_ns: l.max_pulse_delay_ns,
                published_after_ns: tick.t_publish_ns.saturating_sub(tick.t_ns),
            });
        }
        if let Some(last) = self.last_pulse_t_ns {
            // A tick stamped before the last pulse (possible right after a resync, which
            // forgets the tick order but not the pulse history) is an interval of 0.
            let ipi_ns = tick.t_ns.saturating_sub(last);
            if ipi_ns < l.min_ipi_ns {
                return Err(Violation::MinIpi {
                    ipi_ns,
                    min_ns: l.min_ipi_ns,
                });
            }
        }
        let cap = usize::from(l.max_pulses);
        let in_window = self.history.in_window(tick.t_ns, l.rate_window_ns, cap);
        if in_window >= cap {
            return Err(Violation::Rate {
                in_window: l.max_pulses,
                window_ns: l.rate_window_ns,
            });
        }
        let amplitude_100ua =
            u16::try_from(tick.amplitude_ua / AMPLITUDE_STEP_UA).map_err(|_| {
                Violation::AmplitudeCeiling {
                    amplitude_ua: tick.amplitude_ua,
                    max_ua: l.max_amplitude_ua,
                }
            })?;
        Ok(PulseCommand {
            tick_seq: tick.seq,
            t_ns: tick.t_ns,
            t_publish_ns: tick.t_publish_ns,
            channel: tick.channel,
            amplitude_100ua,
            width_us: tick.width_us,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    pub(crate) fn limits() -> InterlockLimits {
        InterlockLimits {
            min_ipi_ns: 5 * MS,
            max_pulses: 3,
            rate_window_ns: 100 * MS,
            max_amplitude_ua: 50_000,
            max_width_us: 400,
            max_charge_nc: 10_000,
            allowed_channels: 0b101,
            max_pulse_delay_ns: MS / 2,
        }
    }

    fn tick(seq: u64, t_ms: u64, pulse: bool) -> StimTick {
        let quiet = StimTick::quiet(seq, t_ms * MS);
        if pulse {
            quiet.firing(0, 20_000, 200)
        } else {
            quiet
        }
    }

    fn verdict(i: &mut Interlocks, t: &StimTick) -> Verdict {
        i.assess(t, t.t_ns + 10_000).verdict
    }

    fn rejected(v: Verdict) -> Violation {
        match v {
            Verdict::Rejected { violation, .. } => violation,
            other => panic!("expected a rejection, got {other:?}"),
        }
    }

    #[test]
    fn a_legal_pulse_is_converted_exactly() {
        let mut i = Interlocks::new(limits());
        let v = verdict(&mut i, &tick(1, 10, true));
        assert_eq!(
            v,
            Verdict::Pulse(PulseCommand {
                tick_seq: 1,
                t_ns: 10 * MS,
                t_publish_ns: 10 * MS,
                channel: 0,
                amplitude_100ua: 200,
                width_us: 200,
            })
        );
    }

    #[test]
    fn min_ipi_is_on_grid_time_and_counts_from_the_last_pulse_let_through() {
        let mut i = Interlocks::new(limits());
        assert!(matches!(
            verdict(&mut i, &tick(1, 10, true)),
            Verdict::Pulse(_)
        ));
        assert_eq!(
            rejected(verdict(&mut i, &tick(2, 14, true))),
            Violation::MinIpi {
                ipi_ns: 4 * MS,
                min_ns: 5 * MS
            }
        );
        // Exactly the minimum passes; the refused pulse at 14 did not move the reference.
        assert!(matches!(
            verdict(&mut i, &tick(3, 15, true)),
            Verdict::Pulse(_)
        ));
    }

    #[test]
    fn a_pulse_stamped_before_the_last_one_after_a_resync_is_refused_not_a_panic() {
        // Found by the forward-path property test: a pulse, an Arm (resync), then a
        // tick whose grid time precedes that pulse's underflowed the interval.
        let mut i = Interlocks::new(limits());
        assert!(matches!(
            verdict(&mut i, &tick(1, 10, true)),
            Verdict::Pulse(_)
        ));
        i.resync_sequence();
        assert_eq!(
            rejected(verdict(&mut i, &tick(2, 9, true))),
            Violation::MinIpi {
                ipi_ns: 0,
                min_ns: 5 * MS
            }
        );
    }

    #[test]
    fn rate_window_is_sliding() {
        let mut i = Interlocks::new(limits());
        for (seq, t) in [(1, 0), (2, 10), (3, 20)] {
            assert!(matches!(
                verdict(&mut i, &tick(seq, 1000 + t, true)),
                Verdict::Pulse(_)
            ));
        }
        // Fourth pulse 99 ms after the first: the window (100 ms) still holds three.
        assert!(matches!(
            rejected(verdict(&mut i, &tick(4, 1099, true))),
            Violation::Rate { in_window: 3, .. }
        ));
        // 100 ms after the first, the first has left the window.
        assert!(matches!(
            verdict(&mut i, &tick(5, 1100, true)),
            Verdict::Pulse(_)
        ));
    }

    #[test]
    fn ceilings_channel_and_representability() {
        let mut i = Interlocks::new(limits());
        let mut t = tick(1, 10, true);
        t.channel = 1;
        assert_eq!(
            rejected(verdict(&mut i, &t)),
            Violation::ChannelNotAllowed { channel: 1 }
        );
        let mut t = tick(2, 20, true);
        t.amplitude_ua = 20_050;
        assert_eq!(
            rejected(verdict(&mut i, &t)),
            Violation::AmplitudeNotRepresentable {
                amplitude_ua: 20_050
            }
        );
        let mut t = tick(3, 30, true);
        t.amplitude_ua = 50_100;
        assert!(matches!(
            rejected(verdict(&mut i, &t)),
            Violation::AmplitudeCeiling { .. }
        ));
        let mut t = tick(4, 40, true);
        t.width_us = 401;
        assert!(matches!(
            rejected(verdict(&mut i, &t)),
            Violation::WidthCeiling { .. }
        ));
        // 40 mA x 300 us = 12 uC > 10 uC, each within its own ceiling.
        let mut t = tick(5, 50, true);
        t.amplitude_ua = 40_000;
        t.width_us = 300;
        assert_eq!(
            rejected(verdict(&mut i, &t)),
            Violation::ChargeCeiling {
                charge_nc: 12_000,
                max_nc: 10_000
            }
        );
        // Channel 2 is allowed.
        let mut t = tick(6, 60, true);
        t.channel = 2;
        assert!(matches!(verdict(&mut i, &t), Verdict::Pulse(_)));
    }

    #[test]
    fn ordering_duplicates_gaps_and_time() {
        let mut i = Interlocks::new(limits());
        assert_eq!(verdict(&mut i, &tick(5, 10, false)), Verdict::NoPulse);
        assert_eq!(
            rejected(verdict(&mut i, &tick(5, 11, false))),
            Violation::Duplicate { seq: 5 }
        );
        assert_eq!(
            rejected(verdict(&mut i, &tick(4, 12, true))),
            Violation::OutOfOrder { last: 5, seq: 4 }
        );
        assert_eq!(
            rejected(verdict(&mut i, &tick(6, 10, false))),
            Violation::TimeNotIncreasing {
                last_t_ns: 10 * MS,
                t_ns: 10 * MS
            }
        );
        let a = i.assess(&tick(9, 20, true), 20 * MS);
        assert_eq!(a.lost_ticks, 3);
        assert_eq!(
            rejected(a.verdict),
            Violation::SequenceGap {
                expected: 6,
                seq: 9
            }
        );
        // The stream continues from 9.
        assert!(matches!(
            verdict(&mut i, &tick(10, 30, true)),
            Verdict::Pulse(_)
        ));
        i.resync_sequence();
        assert_eq!(verdict(&mut i, &tick(1, 31, false)), Verdict::NoPulse);
        // ... but the interval history survives the resync.
        assert!(matches!(
            rejected(verdict(&mut i, &tick(2, 32, true))),
            Violation::MinIpi { .. }
        ));
    }

    #[test]
    fn late_future_and_invalid() {
        let mut i = Interlocks::new(limits());
        let mut t = tick(1, 10, true);
        t.t_publish_ns = t.t_ns + 300_000;
        let late = rejected(i.assess(&t, 10 * MS + MS / 2 + 1).verdict);
        assert_eq!(
            late,
            Violation::Late {
                delay_ns: MS / 2 + 1,
                max_ns: MS / 2,
                published_after_ns: 300_000,
            }
        );
        assert_eq!(
            late.to_string(),
            "pulse 500.0 us after its grid time (limit 500.0 us; published 300.0 us after it)"
        );
        let t = tick(2, 20, true);
        assert!(matches!(
            rejected(i.assess(&t, 20 * MS - 1).verdict),
            Violation::FutureTimestamp { .. }
        ));
        let mut t = tick(3, 30, true);
        t.width_us = 0;
        assert!(matches!(
            rejected(verdict(&mut i, &t)),
            Violation::Invalid(ValidationError::Inconsistent(_))
        ));
        let mut t = tick(4, 40, false);
        t.phi = f64::NAN;
        let v = verdict(&mut i, &t);
        assert!(matches!(
            v,
            Verdict::Rejected {
                violation: Violation::Invalid(ValidationError::NotFinite { .. }),
                pulse: false
            }
        ));
        assert!(rejected(v).is_stream_fault());
    }

    #[test]
    fn charge_rounds_up() {
        assert_eq!(charge_nc(1, 1), 1);
        assert_eq!(charge_nc(20_000, 200), 4_000);
        assert_eq!(charge_nc(150_000, 1000), 150_000);
    }

    #[test]
    fn limits_validation() {
        assert_eq!(limits().validate(), Ok(()));
        let l = InterlockLimits {
            max_pulses: 1001,
            ..limits()
        };
        assert_eq!(l.validate(), Err(LimitsError::MaxPulses(1001)));
        let l = InterlockLimits {
            allowed_channels: 0,
            ..limits()
        };
        assert_eq!(l.validate(), Err(LimitsError::NoChannel));
        let l = InterlockLimits {
            min_ipi_ns: 0,
            ..limits()
        };
        assert_eq!(l.validate(), Err(LimitsError::Zero("min_ipi_us")));
    }
}
