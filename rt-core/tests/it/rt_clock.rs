//! The periodic clock on the real CLOCK_MONOTONIC: absolute deadlines on one grid, no
//! early wake-ups, no drift (the grid does not accumulate lateness).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::time::Duration;

use fes_rt::rt::clock::{PeriodicClock, monotonic_ns};

#[test]
fn wakeups_stay_on_the_grid_without_drift() {
    const PERIOD_NS: u64 = 1_000_000;
    const N: u64 = 300;
    let mut clock = PeriodicClock::start(Duration::from_nanos(PERIOD_NS)).unwrap();
    let first = clock.schedule().next_deadline_ns();
    assert!(
        first.is_multiple_of(PERIOD_NS),
        "the grid is aligned to whole periods"
    );
    assert!(first > monotonic_ns());
    let mut served = 0;
    let mut last_grid = 0;
    for _ in 0..N {
        let w = clock.wait();
        assert!(w.wake_ns >= w.deadline_ns, "woke early");
        assert_eq!(w.lateness_ns, w.wake_ns - w.deadline_ns);
        assert!((w.grid_ns - first).is_multiple_of(PERIOD_NS));
        assert!(w.grid_ns <= w.wake_ns && w.wake_ns < w.grid_ns + PERIOD_NS);
        served += 1 + u64::from(w.missed_periods);
        last_grid = w.grid_ns;
    }
    // Exact: N wake-ups plus the skipped periods cover the grid from `first` to the last
    // served point, whatever the lateness on the way.
    assert_eq!(last_grid, first + (served - 1) * PERIOD_NS);
    assert_eq!(clock.schedule().next_deadline_ns(), last_grid + PERIOD_NS);
}
