//! Real-time plumbing shared by rt-core, stim-driver and sim-muscle (DESIGN.md "Real-time
//! rules").
//!
//! - [`config`] / [`realtime`]: [`RtConfig`] and [`enter_realtime`]: SCHED_FIFO, CPU
//!   affinity, `mlockall`, stack prefault, with a refuse / best-effort policy.
//! - [`clock`]: CLOCK_MONOTONIC and the absolute-deadline [`PeriodicClock`] (skip missed
//!   periods, keep the phase, no catch-up).
//! - [`telemetry`], [`histogram`], [`hlog`]: per-tick timing through a preallocated lock-free
//!   queue into bounded HdrHistograms and HdrHistogram interval logs.
//! - [`alloc`]: a counting global allocator proving the real-time thread takes nothing from
//!   the heap.
//! - [`source`], [`reference`](mod@reference), [`feedback`], [`generator`]: the pattern generator's tick
//!   without I/O ([`PatternLoop`] around a [`TickSource`]).
//! - [`process_config`], [`runner`], [`signals`]: the rt-core process (configuration file,
//!   real-time and telemetry threads over iceoryx2, SIGINT/SIGTERM); [`config_file`]: the
//!   reading, schema and range checks of the real-time processes' configuration files.
//! - [`probe`]: file formats of the `rt-probe` measurement process.
//! - [`mod@panic`]: a panicking thread aborts the process after its safe move.
//! - [`notify`], [`logging`]: running under systemd: READY/WATCHDOG notification fed only
//!   while the real-time loop makes progress, and logs to the journal.

pub use fes_rt::rt::{
    MissingRightsPolicy, PeriodicClock, PeriodicSchedule, RtConfig, RtError, RtShortfall, RtStatus,
    Wakeup, alloc, clock, config, config_file, enter_realtime, error_text, exit, histogram, hlog,
    logging, monotonic_ns, node, notify, panic, probe, realtime, signals, telemetry,
};

pub mod feedback;
pub mod generator;
pub mod process_config;
pub mod reference;
pub mod runner;
pub mod source;

pub use generator::{PatternLoop, PulseSettings};
pub use source::{ControllerSource, TestPattern, TickDecision, TickSource};
