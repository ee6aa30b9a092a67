//! The pattern-generator process's own parts, on the real-time plumbing of `fes_rt::rt`
//! (clock, real time, telemetry, hlog, allocation counting, notify, logging, signals) and
//! the thesis's equations of `fes_model` (docs/realtime.md, "The rules"):
//!
//! - [`source`], [`reference`](mod@reference), [`feedback`], [`generator`]: the pattern
//!   generator's tick without I/O ([`PatternLoop`] around a [`TickSource`]).
//! - [`process_config`], [`runner`]: the rt-core process (configuration file, real-time and
//!   telemetry threads over iceoryx2).

pub mod feedback;
pub mod generator;
pub mod process_config;
pub mod reference;
pub mod runner;
pub mod source;

pub use generator::{PatternLoop, PulseSettings};
pub use source::{ControllerSource, TestPattern, TickDecision, TickSource};
