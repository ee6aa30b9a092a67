//! iceoryx2 message contracts shared by every process (docs/realtime.md, "Message contracts").
//!
//! Every payload is `#[repr(C)]`, `Copy`, free of pointers, derives [`ZeroCopySend`] with an
//! explicit, versioned `#[type_name("fes::<Name>::v1")]`, and carries a sequence number `seq`
//! (1, 2, 3, ... per publisher; 0 is never sent) and a `CLOCK_MONOTONIC` stamp `t_ns` in
//! nanoseconds ([`crate::rt::clock::monotonic_ns`]). Layouts are pinned by size/offset tests:
//! changing one is a protocol change and needs a new `v2` type name.
//!
//! A receiver copies the payload out of shared memory and calls [`Contract::validate`] before
//! using it: a value from another process is external input. Enumerations travel as raw `u8`
//! (an out-of-range discriminant in a Rust enum read from shared memory would be undefined
//! behaviour) and are decoded by typed accessors.
//!
//! Service names and quality-of-service settings live in [`service`], in one place, so that
//! whichever process starts first creates each service with settings the others accept.

mod driver_command;
mod driver_status;
mod force_sample;
pub mod port;
mod pulse_outcome;
mod reference;
mod reference_preview;
pub mod service;
mod stim_tick;
mod timing_report;
mod validate;

pub use driver_command::{DriverCommand, DriverCommandKind};
pub use driver_status::{CommandAck, CommandRefusal, CommandResult, DeviceState, DriverStatus};
pub use force_sample::ForceSample;
pub use iceoryx2::prelude::ZeroCopySend;
pub use port::PortError;
pub use pulse_outcome::{PulseFate, PulseOutcome};
pub use reference::Reference;
pub use reference_preview::{PreviewEdge, ReferencePreview};
pub use service::{Contract, PubSubQos, ServiceError};
pub use stim_tick::StimTick;
pub use timing_report::{LatencySummary, TimingReport, TimingSource};
pub use validate::ValidationError;
