//! STATUS reconciliation: the stimulator's delivered-pulse count against the PULSE frames
//! the driver wrote.
//!
//! STATUS carries `pulses_delivered`, the pulses the stimulator applied since its reset,
//! modulo 2^24. At each Arm the driver takes a baseline: the count of the last STATUS
//! (an Arm needs one younger than `stimulator_timeout_ms`) and its own count of PULSE
//! frames written. Every STATUS while armed must then satisfy
//!
//! ```text
//! sent - in_flight  <=  delivered  <=  sent + carry        (all since the Arm, mod 2^24)
//! ```
//!
//! * `in_flight`: the PULSE frames the driver wrote within the in-flight window before the
//!   STATUS was handled, the window being `stimulator_timeout_ms` (the time the driver
//!   already allows a STATUS to take): a frame written earlier than that must show as
//!   applied. Counted in [`PulseWindow`]'s 17 buckets of 1/16 window each, so the count
//!   may include pulses up to 1/16 window older (never fewer: no false trip from it).
//! * `carry`: the pulses written within the window before the Arm: those of an earlier
//!   armed period that the baseline STATUS may not show yet (applied after it was sent,
//!   or cancelled by the stop).
//!
//! More delivered than that is a pulse the driver never sent (a forged PULSE applied);
//! fewer is pulses lost or refused without an EMCY. Either trips
//! ([`crate::fault::Fault::DeliveryMismatch`]). The difference is taken modulo 2^24 and
//! read as signed, so the wrap of the count is harmless while the two are within 2^23
//! pulses of each other.

use crate::fault::Fault;

/// STATUS `pulses_delivered` is modulo 2^24.
pub const COUNT_MODULUS: u32 = 1 << 24;
const MASK: u32 = COUNT_MODULUS - 1;

/// Buckets of a [`PulseWindow`]: 16 per window, plus the current one.
const BUCKETS: usize = 17;

/// Counts of PULSE frames written, per 1/16 of a window, over the last window.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PulseWindow {
    bucket_ns: u64,
    epoch: [u64; BUCKETS],
    count: [u32; BUCKETS],
}

impl PulseWindow {
    /// A window of `window_ns` (at least 16 ns).
    pub const fn new(window_ns: u64) -> Self {
        let b = window_ns / 16;
        Self {
            bucket_ns: if b == 0 { 1 } else { b },
            epoch: [u64::MAX; BUCKETS],
            count: [0; BUCKETS],
        }
    }

    /// One PULSE written at `now_ns`.
    pub fn record(&mut self, now_ns: u64) {
        let e = now_ns / self.bucket_ns;
        let i = (e % BUCKETS as u64) as usize;
        if self.epoch[i] != e {
            self.epoch[i] = e;
            self.count[i] = 0;
        }
        self.count[i] = self.count[i].saturating_add(1);
    }

    /// PULSE frames written within the window before `now_ns` (and possibly up to one
    /// bucket earlier: never fewer than the true count).
    pub fn count(&self, now_ns: u64) -> u32 {
        let e = now_ns / self.bucket_ns;
        let oldest = e.saturating_sub(BUCKETS as u64 - 1);
        let mut n = 0u32;
        for (epoch, count) in self.epoch.iter().zip(&self.count) {
            if *epoch != u64::MAX && (oldest..=e).contains(epoch) {
                n = n.saturating_add(*count);
            }
        }
        n
    }
}

/// The baseline taken at an Arm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Baseline {
    /// `pulses_delivered` of the last STATUS before the Arm.
    pub delivered: u32,
    /// The driver's PULSE frames written at the Arm.
    pub sent: u64,
    /// PULSE frames written within the window before the Arm.
    pub carry: u32,
}

/// Checks one STATUS's `delivered` count against the baseline, `sent_total` (the driver's
/// PULSE frames written since it started) and `in_flight`: the fault, if they disagree.
pub fn check(base: &Baseline, delivered: u32, sent_total: u64, in_flight: u32) -> Option<Fault> {
    let sent = (sent_total.wrapping_sub(base.sent) & u64::from(MASK)) as u32;
    let delivered = delivered.wrapping_sub(base.delivered) & MASK;
    let lag = sent.wrapping_sub(delivered) & MASK;
    if lag < COUNT_MODULUS / 2 {
        // Fewer delivered than written (or as many).
        (lag > in_flight).then_some(Fault::DeliveryMismatch {
            sent,
            delivered,
            allowed: in_flight,
        })
    } else {
        // More delivered than written.
        let lead = COUNT_MODULUS - lag;
        (lead > base.carry).then_some(Fault::DeliveryMismatch {
            sent,
            delivered,
            allowed: base.carry,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn the_window_counts_the_last_window_and_at_most_one_bucket_more() {
        let mut w = PulseWindow::new(160 * MS);
        assert_eq!(w.count(1_000 * MS), 0);
        for k in 0..100u64 {
            w.record(1_000 * MS + k * MS);
        }
        let now = 1_099 * MS;
        assert_eq!(w.count(now), 100);
        // 160 ms later every pulse but those of the last 10 ms bucket has left.
        let later = now + 160 * MS;
        let n = w.count(later);
        assert!((0..=10).contains(&n), "{n}");
        // Never fewer than the pulses truly within the window.
        for dt in (0..300).map(|d| d * MS) {
            let t = now + dt;
            let truly = (0..100u64)
                .filter(|k| 1_000 * MS + k * MS + 160 * MS >= t)
                .count() as u32;
            assert!(w.count(t) >= truly, "at +{} ms", dt / MS);
        }
        assert_eq!(w.count(now + 400 * MS), 0);
    }

    #[test]
    fn honest_counts_pass_and_any_excess_or_old_shortfall_trips() {
        let base = Baseline {
            delivered: 500,
            sent: 40,
            carry: 0,
        };
        // All 10 written since the Arm applied.
        assert_eq!(check(&base, 510, 50, 0), None);
        // 3 still in flight, 3 allowed.
        assert_eq!(check(&base, 507, 50, 3), None);
        // One more missing than in flight.
        assert_eq!(
            check(&base, 506, 50, 3),
            Some(Fault::DeliveryMismatch {
                sent: 10,
                delivered: 6,
                allowed: 3
            })
        );
        // One pulse applied that the driver never wrote.
        assert_eq!(
            check(&base, 511, 50, 3),
            Some(Fault::DeliveryMismatch {
                sent: 10,
                delivered: 11,
                allowed: 0
            })
        );
        // The carry of an earlier armed period allows exactly that many more.
        let carried = Baseline { carry: 2, ..base };
        assert_eq!(check(&carried, 512, 50, 0), None);
        assert!(check(&carried, 513, 50, 0).is_some());
    }

    #[test]
    fn the_24_bit_wrap_is_harmless() {
        let base = Baseline {
            delivered: MASK - 2,
            sent: u64::from(u32::MAX) + 7,
            carry: 0,
        };
        // 5 written, the count wrapped past 2^24.
        let delivered = (MASK - 2).wrapping_add(5) & MASK;
        assert_eq!(delivered, 2);
        assert_eq!(check(&base, delivered, base.sent + 5, 0), None);
        assert!(check(&base, delivered + 1, base.sent + 5, 0).is_some());
        assert!(check(&base, delivered - 1, base.sent + 5, 0).is_some());
        // A stimulator whose count went back (reset to 0) is far off: trips.
        assert!(check(&base, 0, base.sent + 5, 0).is_some());
        // More than 2^24 written since the Arm: compared modulo 2^24.
        let long = base.sent + u64::from(COUNT_MODULUS) + 3;
        let d = (MASK - 2).wrapping_add(COUNT_MODULUS + 3) & MASK;
        assert_eq!(check(&base, d, long, 0), None);
    }
}
