//! Real-time thread plumbing shared by the real-time processes: absolute-time periodic
//! clock, SCHED_FIFO / affinity / memory locking, the counting allocator, telemetry into
//! HdrHistograms and interval logs, systemd notification, journald logging, stop signals,
//! configuration-file reading and the sections the daemons' files share, and the iceoryx2
//! node (docs/realtime.md).

pub mod alloc;
pub mod clock;
pub mod config;
pub mod config_file;
pub mod error_text;
pub mod exit;
pub mod histogram;
pub mod hlog;
pub mod liveness;
pub mod logging;
pub mod node;
pub mod notify;
pub mod panic;
pub mod probe;
pub mod realtime;
pub mod signals;
pub mod telemetry;
pub mod unit;

pub use clock::{PeriodicClock, PeriodicSchedule, Wakeup, monotonic_ns};
pub use config::{MissingRightsPolicy, RtConfig};
pub use realtime::{RtError, RtShortfall, RtStatus, enter_realtime};
