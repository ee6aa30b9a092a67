//! CLOCK_MONOTONIC time and the absolute-deadline periodic clock.
//!
//! [`PeriodicSchedule`] is the pure arithmetic of the period grid (time is passed in, so it is
//! tested with a mock clock); [`PeriodicClock`] adds the sleep: `clock_nanosleep` on
//! CLOCK_MONOTONIC with TIMER_ABSTIME, no relative sleeps, no spinning.
//!
//! Overrun policy: when a wake-up comes one or more whole periods late, the skipped periods
//! are counted, the caller is woken once (no catch-up), and the next deadline stays on the
//! original grid (the phase is kept).

use core::time::Duration;

/// Nanoseconds per second.
pub const NS_PER_S: u64 = 1_000_000_000;

/// Current CLOCK_MONOTONIC time in nanoseconds (vDSO: no system call, no allocation).
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux, so
    // the call cannot fail (its return value carries no information here).
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    timespec_to_ns(&ts)
}

fn timespec_to_ns(ts: &libc::timespec) -> u64 {
    // CLOCK_MONOTONIC is never negative.
    (ts.tv_sec as u64) * NS_PER_S + ts.tv_nsec as u64
}

fn ns_to_timespec(ns: u64) -> libc::timespec {
    libc::timespec {
        tv_sec: (ns / NS_PER_S) as libc::time_t,
        tv_nsec: (ns % NS_PER_S) as libc::c_long,
    }
}

/// Shortest accepted period.
pub const MIN_PERIOD: Duration = Duration::from_micros(100);
/// Longest accepted period.
pub const MAX_PERIOD: Duration = Duration::from_secs(1);

/// Invalid period.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("period {period_ns} ns is outside [{} us, {} s]", MIN_PERIOD.as_micros(), MAX_PERIOD.as_secs())]
pub struct PeriodError {
    /// The rejected period, ns.
    pub period_ns: u128,
}

/// One wake-up of a periodic loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Wakeup {
    /// The deadline that was slept for, ns.
    pub deadline_ns: u64,
    /// The grid point this wake-up serves: `deadline_ns + missed_periods * period`, the latest
    /// grid point not after `wake_ns`.
    pub grid_ns: u64,
    /// When the thread actually woke, ns.
    pub wake_ns: u64,
    /// `wake_ns - deadline_ns`: the wake-up lateness (cyclictest's "latency").
    pub lateness_ns: u64,
    /// Whole periods skipped because the wake-up came that late (0 normally).
    pub missed_periods: u32,
}

/// The period grid: deadlines `start + k * period`, advanced by observed wake times.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PeriodicSchedule {
    period_ns: u64,
    next_deadline_ns: u64,
}

impl PeriodicSchedule {
    /// A grid whose first deadline is `first_deadline_ns`.
    pub fn new(period: Duration, first_deadline_ns: u64) -> Result<Self, PeriodError> {
        if period < MIN_PERIOD || period > MAX_PERIOD {
            return Err(PeriodError {
                period_ns: period.as_nanos(),
            });
        }
        Ok(Self {
            period_ns: period.as_nanos() as u64,
            next_deadline_ns: first_deadline_ns,
        })
    }

    /// The period, ns.
    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }

    /// The deadline the loop must sleep until next, ns.
    pub fn next_deadline_ns(&self) -> u64 {
        self.next_deadline_ns
    }

    /// Accounts for a wake-up at `wake_ns` (which is at or after the next deadline: absolute
    /// sleeps never return early; an earlier time is treated as on time). Skipped periods are
    /// counted and the next deadline is the first grid point after `wake_ns`.
    pub fn advance(&mut self, wake_ns: u64) -> Wakeup {
        let deadline_ns = self.next_deadline_ns;
        let lateness_ns = wake_ns.saturating_sub(deadline_ns);
        let missed = lateness_ns / self.period_ns;
        let grid_ns = deadline_ns + missed * self.period_ns;
        self.next_deadline_ns = grid_ns + self.period_ns;
        Wakeup {
            deadline_ns,
            grid_ns,
            wake_ns: wake_ns.max(deadline_ns),
            lateness_ns,
            missed_periods: u32::try_from(missed).unwrap_or(u32::MAX),
        }
    }
}

/// A periodic clock on CLOCK_MONOTONIC that sleeps until absolute deadlines.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PeriodicClock {
    schedule: PeriodicSchedule,
}

impl PeriodicClock {
    /// A clock whose first deadline is one period from now, rounded up to a whole multiple of
    /// the period in CLOCK_MONOTONIC (so that two loops with the same period share a grid).
    pub fn start(period: Duration) -> Result<Self, PeriodError> {
        let probe = PeriodicSchedule::new(period, 0)?;
        let p = probe.period_ns();
        let first = (monotonic_ns() / p + 2) * p;
        Ok(Self {
            schedule: PeriodicSchedule::new(period, first)?,
        })
    }

    /// A clock with an explicit first deadline, ns.
    pub fn with_first_deadline(
        period: Duration,
        first_deadline_ns: u64,
    ) -> Result<Self, PeriodError> {
        Ok(Self {
            schedule: PeriodicSchedule::new(period, first_deadline_ns)?,
        })
    }

    /// The underlying grid.
    pub fn schedule(&self) -> &PeriodicSchedule {
        &self.schedule
    }

    /// Sleeps until the next deadline (TIMER_ABSTIME; a signal interrupting the sleep resumes
    /// it towards the same deadline) and returns the wake-up.
    pub fn wait(&mut self) -> Wakeup {
        sleep_until(self.schedule.next_deadline_ns());
        self.schedule.advance(monotonic_ns())
    }
}

/// Sleeps until CLOCK_MONOTONIC reaches `deadline_ns` (absolute; returns at once if it has
/// passed).
pub fn sleep_until(deadline_ns: u64) {
    let ts = ns_to_timespec(deadline_ns);
    loop {
        // SAFETY: `ts` is a valid timespec; the remaining-time pointer may be null with
        // TIMER_ABSTIME.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                core::ptr::null_mut(),
            )
        };
        // clock_nanosleep returns the error number directly; only EINTR warrants a retry
        // (EINVAL cannot happen with a normalised timespec on CLOCK_MONOTONIC).
        if rc != libc::EINTR {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn on_time_wakeups_walk_the_grid() {
        let mut s = PeriodicSchedule::new(Duration::from_millis(1), 5_000_000).unwrap();
        for k in 0..10u64 {
            let d = 5_000_000 + k * 1_000_000;
            let w = s.advance(d + 20_000);
            assert_eq!(w.deadline_ns, d);
            assert_eq!(w.grid_ns, d);
            assert_eq!(w.lateness_ns, 20_000);
            assert_eq!(w.missed_periods, 0);
        }
    }

    #[test]
    fn a_stall_skips_whole_periods_and_keeps_the_phase() {
        let mut s = PeriodicSchedule::new(Duration::from_millis(1), 1_000_000).unwrap();
        // Woken 100.3 ms after the deadline: 100 periods were skipped.
        let w = s.advance(1_000_000 + 100_300_000);
        assert_eq!(w.missed_periods, 100);
        assert_eq!(w.lateness_ns, 100_300_000);
        assert_eq!(w.grid_ns, 101_000_000);
        // Next deadline back on the original grid, one period after the served grid point.
        assert_eq!(s.next_deadline_ns(), 102_000_000);
        assert_eq!((s.next_deadline_ns() - 1_000_000) % 1_000_000, 0);
        let w = s.advance(102_000_500);
        assert_eq!(w.missed_periods, 0);
        assert_eq!(w.lateness_ns, 500);
    }

    #[test]
    fn exactly_one_period_late_counts_one_miss() {
        let mut s = PeriodicSchedule::new(Duration::from_micros(500), 0).unwrap();
        let w = s.advance(500_000);
        assert_eq!(w.missed_periods, 1);
        assert_eq!(w.grid_ns, 500_000);
        assert_eq!(s.next_deadline_ns(), 1_000_000);
    }

    #[test]
    fn periods_outside_the_range_are_refused() {
        assert!(PeriodicSchedule::new(Duration::from_micros(99), 0).is_err());
        assert!(PeriodicSchedule::new(Duration::from_millis(1001), 0).is_err());
        assert!(PeriodicSchedule::new(Duration::from_micros(100), 0).is_ok());
    }
}
