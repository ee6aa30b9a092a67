//! The stimulator's own pulse interlocks: output channel, amplitude and width ceilings,
//! minimum inter-pulse interval and maximum pulse count over a sliding window.
//!
//! Time is counted in stimulator ticks (1 ms). A pulse is applied at the first tick after
//! its frame arrived (`k`); its IPI is `k` minus the tick of the last pulse applied or
//! accepted and still waiting, and the rate window covers ticks `k - window + 1 ..= k`,
//! counting both.

use fes_can::{ErrorCode, Pulse, StimLimits};

/// Capacity of the pulse-time ring: the largest `max_pulses` CONFIG can carry.
pub const RATE_RING_CAPACITY: usize = 1000;

/// Why a pulse was refused: the EMCY code and its detail word.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Refusal {
    /// EMCY error code.
    pub code: ErrorCode,
    /// EMCY detail (see `docs/can-protocol.md`).
    pub detail: u16,
}

/// Ticks of the most recent applied pulses, newest last; fixed capacity.
#[derive(Debug, Clone)]
struct PulseTimes {
    ticks: [u64; RATE_RING_CAPACITY],
    head: usize,
    len: usize,
}

impl PulseTimes {
    const fn new() -> Self {
        Self {
            ticks: [0; RATE_RING_CAPACITY],
            head: 0,
            len: 0,
        }
    }

    fn push(&mut self, tick: u64) {
        self.ticks[self.head] = tick;
        self.head = (self.head + 1) % RATE_RING_CAPACITY;
        self.len = (self.len + 1).min(RATE_RING_CAPACITY);
    }

    fn newest(&self) -> Option<u64> {
        (self.len > 0)
            .then(|| self.ticks[(self.head + RATE_RING_CAPACITY - 1) % RATE_RING_CAPACITY])
    }

    /// Pulses in the `window` ticks ending at `tick` (`tick - window < t <= tick`),
    /// scanning back from the newest.
    fn count_within(&self, tick: u64, window: u64) -> usize {
        (1..=self.len)
            .map(|back| self.ticks[(self.head + RATE_RING_CAPACITY - back) % RATE_RING_CAPACITY])
            .take_while(|&t| t + window > tick)
            .count()
    }
}

/// The pulse interlocks with the history they need.
#[derive(Debug, Clone)]
pub struct Interlock {
    channels: u8,
    applied: PulseTimes,
}

impl Interlock {
    /// Interlocks for a stimulator with `channels` output channels (1..=16).
    pub const fn new(channels: u8) -> Self {
        Self {
            channels,
            applied: PulseTimes::new(),
        }
    }

    /// Tick of the last applied pulse.
    pub fn last_pulse_tick(&self) -> Option<u64> {
        self.applied.newest()
    }

    /// Checks `pulse` for application at tick `tick` under `limits`; `queued` are the
    /// ticks of the pulses accepted and still waiting (in order, none after `tick`).
    pub fn check(
        &self,
        pulse: &Pulse,
        tick: u64,
        queued: &[u64],
        limits: &StimLimits,
    ) -> Result<(), Refusal> {
        if pulse.channel >= self.channels {
            return Err(Refusal {
                code: ErrorCode::ChannelInvalid,
                detail: u16::from(pulse.channel),
            });
        }
        if pulse.amplitude_100ua > limits.max_amplitude_100ua {
            return Err(Refusal {
                code: ErrorCode::AmplitudeCeiling,
                detail: pulse.amplitude_100ua,
            });
        }
        if pulse.width_us > limits.max_width_us {
            return Err(Refusal {
                code: ErrorCode::WidthCeiling,
                detail: pulse.width_us,
            });
        }
        // Charge per phase = amplitude x width: 0.1 mA x 1 us = 0.1 nC, the ceiling 10 nC.
        let charge_100pc = u32::from(pulse.amplitude_100ua) * u32::from(pulse.width_us);
        if charge_100pc > u32::from(limits.max_charge_10nc) * 100 {
            return Err(Refusal {
                code: ErrorCode::ChargeCeiling,
                detail: u16::try_from(charge_100pc / 100).unwrap_or(u16::MAX),
            });
        }
        let last = queued.last().copied().or(self.applied.newest());
        let ipi = last.map(|last| tick.saturating_sub(last));
        if let Some(ipi) = ipi
            && ipi < u64::from(limits.min_ipi_ms)
        {
            return Err(Refusal {
                code: ErrorCode::MinIpiViolation,
                detail: u16::try_from(ipi).unwrap_or(u16::MAX),
            });
        }
        let window = u64::from(limits.rate_window_ms);
        let in_window = self.applied.count_within(tick, window)
            + queued.iter().filter(|&&t| t + window > tick).count();
        if in_window >= usize::from(limits.max_pulses) {
            return Err(Refusal {
                code: ErrorCode::RateViolation,
                detail: u16::try_from(in_window).unwrap_or(u16::MAX),
            });
        }
        Ok(())
    }

    /// Records a pulse applied at tick `tick`.
    pub fn record(&mut self, tick: u64) {
        self.applied.push(tick);
    }
}

/// True when the limits `config` are at least as strict as the stimulator's own `ceiling`;
/// otherwise the index (0-6, CONFIG signal order) of the first looser limit.
///
/// The rate limit (n pulses per W ms) is at least as strict as (N per W_c) when
/// `n * ceil(W_c / W) <= N`: any W_c-long interval splits into `ceil(W_c / W)` pieces no
/// longer than W, each holding at most n pulses.
pub fn no_looser_than(config: &StimLimits, ceiling: &StimLimits) -> Result<(), u16> {
    if config.max_amplitude_100ua > ceiling.max_amplitude_100ua {
        return Err(0);
    }
    if config.max_width_us > ceiling.max_width_us {
        return Err(1);
    }
    if config.min_ipi_ms < ceiling.min_ipi_ms {
        return Err(2);
    }
    let pieces =
        u64::from(ceiling.rate_window_ms).div_ceil(u64::from(config.rate_window_ms.max(1)));
    if u64::from(config.max_pulses) * pieces > u64::from(ceiling.max_pulses) {
        return Err(3);
    }
    if config.watchdog_ms > ceiling.watchdog_ms {
        return Err(5);
    }
    if config.max_charge_10nc > ceiling.max_charge_10nc {
        return Err(6);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pulse(amplitude_100ua: u16, width_us: u16) -> Pulse {
        Pulse {
            seq: 0,
            alive_counter: 0,
            channel: 0,
            amplitude_100ua,
            width_us,
        }
    }

    fn limits() -> StimLimits {
        StimLimits {
            max_amplitude_100ua: 300,
            max_width_us: 400,
            min_ipi_ms: 3,
            max_pulses: 4,
            rate_window_ms: 20,
            watchdog_ms: 100,
            max_charge_10nc: 5000,
        }
    }

    #[test]
    fn ceilings_are_inclusive() {
        let i = Interlock::new(1);
        assert_eq!(i.check(&pulse(300, 400), 0, &[], &limits()), Ok(()));
        assert_eq!(
            i.check(&pulse(301, 400), 0, &[], &limits()),
            Err(Refusal {
                code: ErrorCode::AmplitudeCeiling,
                detail: 301
            })
        );
        assert_eq!(
            i.check(&pulse(300, 401), 0, &[], &limits()),
            Err(Refusal {
                code: ErrorCode::WidthCeiling,
                detail: 401
            })
        );
        let mut p = pulse(1, 1);
        p.channel = 1;
        assert_eq!(
            i.check(&p, 0, &[], &limits()),
            Err(Refusal {
                code: ErrorCode::ChannelInvalid,
                detail: 1
            })
        );
    }

    #[test]
    fn min_ipi_counts_ticks_from_the_last_applied_pulse() {
        let mut i = Interlock::new(1);
        i.record(10);
        assert_eq!(
            i.check(&pulse(1, 1), 12, &[], &limits()),
            Err(Refusal {
                code: ErrorCode::MinIpiViolation,
                detail: 2
            })
        );
        assert_eq!(i.check(&pulse(1, 1), 13, &[], &limits()), Ok(()));
        // A pulse already waiting for the tick makes the IPI zero.
        assert_eq!(
            i.check(&pulse(1, 1), 13, &[13], &limits()),
            Err(Refusal {
                code: ErrorCode::MinIpiViolation,
                detail: 0
            })
        );
    }

    /// Brute force: the rate check agrees with counting pulses in the window directly.
    #[test]
    fn rate_window_matches_direct_count() {
        let l = limits();
        let mut i = Interlock::new(1);
        let mut applied: Vec<u64> = Vec::new();
        let mut t = 0u64;
        let mut accepted = 0;
        // Try a pulse every 3 ticks (the min IPI): at most 4 per 20 ticks get through.
        for _ in 0..200 {
            let direct = applied
                .iter()
                .filter(|&&a| a + u64::from(l.rate_window_ms) > t)
                .count();
            let r = i.check(&pulse(1, 1), t, &[], &l);
            assert_eq!(r.is_ok(), direct < 4, "tick {t}: {r:?}, {direct} in window");
            if r.is_ok() {
                i.record(t);
                applied.push(t);
                accepted += 1;
            }
            t += 3;
        }
        // Independent truth: in 600 ticks at most 4 per 20 ticks can pass = 120.
        assert!(accepted <= 4 * 600 / 20 + 4);
        assert!(accepted >= 4 * 600 / 20 - 4);
    }

    #[test]
    fn ring_keeps_only_capacity_entries() {
        let mut i = Interlock::new(1);
        for t in 0..(RATE_RING_CAPACITY as u64 + 50) {
            i.record(t);
        }
        assert_eq!(
            i.applied
                .count_within(RATE_RING_CAPACITY as u64 + 49, 10_000),
            RATE_RING_CAPACITY
        );
        assert_eq!(i.last_pulse_tick(), Some(RATE_RING_CAPACITY as u64 + 49));
    }

    #[test]
    fn ring_capacity_equals_the_config_range() {
        assert_eq!(
            RATE_RING_CAPACITY as f64,
            fes_can::table::config::MAX_PULSES.max
        );
    }

    #[test]
    fn strictness_of_limits() {
        let c = limits();
        assert_eq!(no_looser_than(&c, &c), Ok(()));
        assert_eq!(
            no_looser_than(
                &StimLimits {
                    max_amplitude_100ua: 301,
                    ..c
                },
                &c
            ),
            Err(0)
        );
        assert_eq!(
            no_looser_than(&StimLimits { min_ipi_ms: 2, ..c }, &c),
            Err(2)
        );
        assert_eq!(
            no_looser_than(
                &StimLimits {
                    watchdog_ms: 101,
                    ..c
                },
                &c
            ),
            Err(5)
        );
        // 2 per 10 ms allows 4 per 20 ms: equal, accepted; 3 per 10 ms allows 6: looser.
        assert_eq!(
            no_looser_than(
                &StimLimits {
                    max_pulses: 2,
                    rate_window_ms: 10,
                    ..c
                },
                &c
            ),
            Ok(())
        );
        assert_eq!(
            no_looser_than(
                &StimLimits {
                    max_pulses: 3,
                    rate_window_ms: 10,
                    ..c
                },
                &c
            ),
            Err(3)
        );
        // 2 per 7 ms: ceil(20/7) = 3 pieces -> up to 6 pulses in 20 ms: looser.
        assert_eq!(
            no_looser_than(
                &StimLimits {
                    max_pulses: 2,
                    rate_window_ms: 7,
                    ..c
                },
                &c
            ),
            Err(3)
        );
        // 4 per 40 ms is stricter than 4 per 20 ms.
        assert_eq!(
            no_looser_than(
                &StimLimits {
                    rate_window_ms: 40,
                    ..c
                },
                &c
            ),
            Ok(())
        );
    }
}
