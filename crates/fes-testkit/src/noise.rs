//! The host's own timing noise, measured beside a timing check.
//!
//! On a shared VM the host alone moves cyclictest's p99 from 40 us to over a millisecond
//! between hours, and at a noisy hour stalls a SCHED_FIFO thread for 20-35 ms every few
//! seconds. A check of a real-time loop's timing (periods missed, pulses late) therefore
//! says something only against what the host allowed in the same run: a [`NoiseProbe`]
//! runs cyclictest's loop (absolute 1 ms deadlines on CLOCK_MONOTONIC, at SCHED_FIFO when
//! allowed) in a thread while the check runs, and the check's bound is a function of the
//! [`HostNoise`] it measured. A loop that blocks or falls behind by itself still fails; a
//! host that stalls everything does not fail a correct loop.

use std::fmt;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;

use nix::sys::time::TimeSpec;
use nix::time::{ClockId, ClockNanosleepFlags, clock_gettime, clock_nanosleep};

const PERIOD_NS: u64 = 1_000_000;

/// What the host let a 1 ms SCHED_FIFO loop do over a time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct HostNoise {
    /// Periods of 1 ms that elapsed.
    pub periods: u64,
    /// Periods the probe missed: it woke a whole period or more after its deadline.
    pub missed: u64,
    /// Wake-ups more than 100 us after their deadline.
    pub late_100us: u64,
    /// Wake-ups more than 1 ms after their deadline.
    pub late_1ms: u64,
    /// The latest wake-up, ns after its deadline.
    pub max_late_ns: u64,
    /// The probe ran at SCHED_FIFO (else best-effort: its figures are the host's noise
    /// as a normal thread sees it).
    pub realtime: bool,
}

impl HostNoise {
    /// Fraction of the periods the probe missed.
    pub fn missed_fraction(&self) -> f64 {
        if self.periods == 0 {
            0.0
        } else {
            self.missed as f64 / self.periods as f64
        }
    }

    /// The most periods a loop measured beside this probe may miss of `periods` and still
    /// be judged to keep its period: twice the probe's missed fraction (two loops, two
    /// chances to be hit by a stall) plus 2 % (its own start-up, the other core's load).
    /// A loop that blocks misses nearly all; on a quiet host this is about 2 %.
    pub fn allowed_misses(&self, periods: u64) -> u64 {
        let fraction = (2.0 * self.missed_fraction() + 0.02).min(1.0);
        (fraction * periods as f64).ceil() as u64
    }

    /// The host was quiet enough to judge a sub-millisecond bound: at most 1 % of the
    /// wake-ups more than 100 us late and none a period late.
    pub fn is_quiet(&self) -> bool {
        self.late_100us * 100 <= self.periods && self.late_1ms == 0
    }
}

impl fmt::Display for HostNoise {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "host noise ({}): {} of {} 1 ms periods missed, {} wake-ups > 100 us and {} > 1 ms late, max {:.1} ms",
            if self.realtime {
                "SCHED_FIFO probe"
            } else {
                "best-effort probe"
            },
            self.missed,
            self.periods,
            self.late_100us,
            self.late_1ms,
            self.max_late_ns as f64 / 1e6
        )
    }
}

/// A thread measuring [`HostNoise`] until [`NoiseProbe::finish`].
#[derive(Debug)]
pub struct NoiseProbe {
    stop: Arc<AtomicBool>,
    handle: JoinHandle<HostNoise>,
}

impl NoiseProbe {
    /// Starts the probe at SCHED_FIFO `priority` (1..=99) when the process may, else as a
    /// normal thread. Give it the priority of the loop under test, so both meet the same
    /// competition.
    ///
    /// # Panics
    /// When the thread cannot be started.
    pub fn start(priority: u8) -> Self {
        Self::start_on(priority, None)
    }

    /// As [`NoiseProbe::start`], pinned to CPU `core` when given: on a VM each virtual CPU
    /// is stalled by the host on its own, so a probe judges a loop best on the loop's core.
    ///
    /// # Panics
    /// When the thread cannot be started.
    pub fn start_on(priority: u8, core: Option<usize>) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let handle = std::thread::Builder::new()
            .name("noise-probe".into())
            .spawn(move || {
                if let Some(core) = core {
                    pin(core);
                }
                run(priority, &flag)
            })
            .unwrap_or_else(|e| panic!("start the noise probe: {e}"));
        Self { stop, handle }
    }

    /// Stops the probe and returns what it measured.
    ///
    /// # Panics
    /// When the probe's thread panicked.
    pub fn finish(self) -> HostNoise {
        self.stop.store(true, Ordering::Relaxed);
        self.handle
            .join()
            .unwrap_or_else(|_| panic!("the noise probe panicked"))
    }
}

/// Measures the host's noise for `seconds` in this thread's place (a probe started and
/// finished around a sleep).
pub fn measure(priority: u8, seconds: f64) -> HostNoise {
    let probe = NoiseProbe::start(priority);
    std::thread::sleep(std::time::Duration::from_secs_f64(seconds));
    probe.finish()
}

fn now_ns() -> u64 {
    clock_gettime(ClockId::CLOCK_MONOTONIC)
        .map(|t| t.tv_sec() as u64 * 1_000_000_000 + t.tv_nsec() as u64)
        .unwrap_or(0)
}

/// Pins this thread to CPU `core`; a core that does not exist leaves it unpinned.
fn pin(core: usize) {
    let mut set = nix::sched::CpuSet::new();
    if set.set(core).is_ok() {
        let _ = nix::sched::sched_setaffinity(nix::unistd::Pid::from_raw(0), &set);
    }
}

fn realtime(priority: u8) -> bool {
    use thread_priority::{
        RealtimeThreadSchedulePolicy, ThreadPriority, ThreadPriorityValue, ThreadSchedulePolicy,
        set_thread_priority_and_policy, thread_native_id,
    };
    let Ok(value) = ThreadPriorityValue::try_from(priority) else {
        return false;
    };
    set_thread_priority_and_policy(
        thread_native_id(),
        ThreadPriority::Crossplatform(value),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    )
    .is_ok()
}

fn run(priority: u8, stop: &AtomicBool) -> HostNoise {
    let mut noise = HostNoise {
        realtime: realtime(priority),
        ..HostNoise::default()
    };
    let start = now_ns();
    let mut deadline = start + PERIOD_NS;
    while !stop.load(Ordering::Relaxed) {
        let ts = TimeSpec::new(
            (deadline / 1_000_000_000) as i64,
            (deadline % 1_000_000_000) as i64,
        );
        // An interrupted sleep just wakes early; the lateness below is then zero.
        let _ = clock_nanosleep(
            ClockId::CLOCK_MONOTONIC,
            ClockNanosleepFlags::TIMER_ABSTIME,
            &ts,
        );
        let late = now_ns().saturating_sub(deadline);
        noise.max_late_ns = noise.max_late_ns.max(late);
        noise.late_100us += u64::from(late > 100_000);
        noise.late_1ms += u64::from(late > PERIOD_NS);
        // Skip the missed periods and keep the phase, as the project's loops do.
        let skipped = late / PERIOD_NS;
        noise.missed += skipped;
        deadline += (skipped + 1) * PERIOD_NS;
    }
    noise.periods = deadline.saturating_sub(start) / PERIOD_NS;
    noise
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bound_follows_the_probe() {
        let quiet = HostNoise {
            periods: 1000,
            ..HostNoise::default()
        };
        assert_eq!(quiet.allowed_misses(1000), 20);
        assert!(quiet.is_quiet());
        let noisy = HostNoise {
            periods: 1000,
            missed: 300,
            late_1ms: 20,
            ..HostNoise::default()
        };
        assert_eq!(noisy.allowed_misses(1000), 620);
        assert!(!noisy.is_quiet());
        // A blocked loop misses nearly everything: caught unless the host missed half.
        assert!(noisy.allowed_misses(1000) < 990);
    }

    #[test]
    fn a_probe_counts_the_periods_of_its_run() {
        let n = measure(1, 0.2);
        // 200 periods, give or take what a loaded host takes away at either end.
        assert!((150..=260).contains(&n.periods), "{n}");
        assert!(n.missed <= n.periods, "{n}");
    }
}
