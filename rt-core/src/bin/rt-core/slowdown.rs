//! Test-only slowdown hook: `FES_TEST_TICK_BUSY_US=N` makes every tick busy-wait N µs
//! after the tick source has run.
//!
//! It exists so that the latency regression suite and the systemd watchdog tests can
//! prove they catch a slow or stalled loop. The variable is read once at start-up; when it
//! is unset the loop runs the plain source (the wrapper is a different monomorphisation of
//! `run_pattern_loop`, chosen before the loop starts), so the hot path of a normal run
//! contains no trace of it. When set, rt-core says so in a warning and in its systemd
//! status. Never set it on a rig.

use anyhow::bail;
use fes_rt::rt::clock::monotonic_ns;
use rt_core::rt::reference::Target;
use rt_core::rt::source::{TickDecision, TickSource};

/// The environment variable.
pub const ENV_TICK_BUSY_US: &str = "FES_TEST_TICK_BUSY_US";
/// Largest accepted value, µs (10 s: enough to stall any watchdog).
const MAX_BUSY_US: u64 = 10_000_000;

/// Reads [`ENV_TICK_BUSY_US`]: `None` when unset, else the busy time per tick, µs.
pub fn from_env() -> anyhow::Result<Option<u64>> {
    let Some(value) = std::env::var_os(ENV_TICK_BUSY_US) else {
        return Ok(None);
    };
    let text = value.to_string_lossy();
    match text.trim().parse::<u64>() {
        Ok(us) if (1..=MAX_BUSY_US).contains(&us) => Ok(Some(us)),
        _ => bail!(
            "{ENV_TICK_BUSY_US}={text:?}: expected a whole number of microseconds in \
             1..={MAX_BUSY_US} (a test-only slowdown; unset it for a normal run)"
        ),
    }
}

/// A tick source that busy-waits after every tick of the source it wraps.
pub struct Slowed<S> {
    inner: S,
    busy_ns: u64,
}

impl<S> Slowed<S> {
    /// Wraps `inner`, adding `busy_us` of busy waiting to each tick.
    pub fn new(inner: S, busy_us: u64) -> Self {
        Self {
            inner,
            busy_ns: busy_us.saturating_mul(1000),
        }
    }
}

impl<S: TickSource> TickSource for Slowed<S> {
    fn tick(&mut self, target: &Target, measured_force: Option<f64>) -> TickDecision {
        let decision = self.inner.tick(target, measured_force);
        let until = monotonic_ns().saturating_add(self.busy_ns);
        while monotonic_ns() < until {
            std::hint::spin_loop();
        }
        decision
    }

    fn missed(&mut self, periods: u32, target: &Target) {
        self.inner.missed(periods, target);
    }

    fn reset(&mut self) {
        self.inner.reset();
    }

    fn min_pulse_gap_ticks(&self) -> u32 {
        self.inner.min_pulse_gap_ticks()
    }

    fn summary(&self) -> Option<String> {
        self.inner.summary()
    }
}
