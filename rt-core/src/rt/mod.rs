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
//! - [`notify`], [`logging`]: running under systemd: READY/WATCHDOG notification fed only
//!   while the real-time loop makes progress, and logs to the journal.

pub mod alloc;
pub mod clock;
pub mod config;
pub mod config_file;
pub mod error_text;
pub mod feedback;
pub mod generator;
pub mod histogram;
pub mod hlog;
pub mod logging;
pub mod notify;
pub mod probe;
pub mod process_config;
pub mod realtime;
pub mod reference;
pub mod runner;
pub mod signals;
pub mod source;
pub mod telemetry;

pub use clock::{PeriodicClock, PeriodicSchedule, Wakeup, monotonic_ns};
pub use config::{MissingRightsPolicy, RtConfig};
pub use generator::{PatternLoop, PulseSettings};
pub use realtime::{RtError, RtShortfall, RtStatus, enter_realtime};
pub use source::{ControllerSource, TestPattern, TickDecision, TickSource};
