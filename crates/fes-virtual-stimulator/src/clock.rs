//! The stimulator's only timing primitives: CLOCK_MONOTONIC now, and an absolute-time
//! sleep (`clock_nanosleep` with TIMER_ABSTIME). Kept in one place so the loop can move
//! to the workspace's shared real-time module (`fes_rt::rt`) by changing only this file.

use nix::errno::Errno;
use nix::sys::time::TimeSpec;
use nix::time::{ClockId, ClockNanosleepFlags, clock_gettime, clock_nanosleep};

/// CLOCK_MONOTONIC in nanoseconds.
pub fn monotonic_ns() -> u64 {
    // CLOCK_MONOTONIC always exists on Linux; if the call failed anyway, time 0 makes the
    // loop run late rather than crash.
    clock_gettime(ClockId::CLOCK_MONOTONIC)
        .map(|t| timespec_ns(&t))
        .unwrap_or(0)
}

fn timespec_ns(t: &TimeSpec) -> u64 {
    u64::try_from(t.tv_sec()).unwrap_or(0) * 1_000_000_000 + u64::try_from(t.tv_nsec()).unwrap_or(0)
}

/// Sleeps until CLOCK_MONOTONIC reaches `deadline_ns` (absolute). Returns `Err(EINTR)`
/// when a signal interrupts the sleep, so the caller can look at its stop flag.
pub fn sleep_until(deadline_ns: u64) -> Result<(), Errno> {
    let secs = i64::try_from(deadline_ns / 1_000_000_000).unwrap_or(i64::MAX);
    let nanos = i64::try_from(deadline_ns % 1_000_000_000).unwrap_or(0);
    let ts = TimeSpec::new(secs, nanos);
    clock_nanosleep(
        ClockId::CLOCK_MONOTONIC,
        ClockNanosleepFlags::TIMER_ABSTIME,
        &ts,
    )
    .map(|_| ())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sleeps_until_the_deadline_not_before() {
        let start = monotonic_ns();
        let deadline = start + 3_000_000;
        while sleep_until(deadline) == Err(Errno::EINTR) {}
        let woke = monotonic_ns();
        assert!(woke >= deadline, "woke {} ns early", deadline - woke);
        // A deadline in the past returns at once.
        let t = monotonic_ns();
        sleep_until(start).unwrap();
        assert!(monotonic_ns() - t < 50_000_000);
    }
}
