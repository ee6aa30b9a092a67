//! # stim-driver: StimTicks from iceoryx2 to PULSE frames on SocketCAN
//!
//! The last software between the controller and current in tissue. It subscribes to
//! rt-core's StimTicks, brings the stimulator up over CAN, and forwards each pulse decision
//! as one PULSE frame within the same millisecond, but only while armed and only after its
//! own interlocks ([`interlock`]) have passed it. A watchdog stops the stimulator (NMT
//! stop) when the ticks stop, go stale or their publisher dies, and the bus side stops it
//! on an EMCY, bus-off or a link going down; only an explicit Arm command re-arms.
//!
//! - [`interlock`]: the interlocks as a pure struct (ticks in, decisions out, time passed in).
//! - [`output`]: the stimulator output as a typestate (an unarmed handle cannot send PULSE).
//! - [`forward`]: the whole decision logic ([`forward::ForwardPath`]) without threads or clocks.
//! - [`tx`]: the write seam ([`tx::CanTx`]): SocketCAN, or a counting sink;
//!   [`serial_tx`]: its ScienceMode 2 implementation for a RehaStim 2 on a serial line,
//!   [`serial_rx`] its receive side (the device's answers as the bus events).
//! - [`event`], [`fault`]: what the threads exchange, and the fault and refusal reasons.
//! - [`config`]: the TOML configuration file.
//! - [`bus`]: the receive thread (FORCE, STATUS, EMCY, error frames, link state, and frames
//!   on the driver's own identifiers for [`intrusion`] detection).
//! - [`reconcile`]: STATUS reconciliation (delivered pulses against pulses written).
//! - [`applied`]: which pulses the stimulator applied (the per-pulse account of STATUS).
//! - [`runner`] (the real-time forward thread), [`report`] (logs, DriverStatus,
//!   TimingReport, the publishers' liveness through [`fes_rt::rt::liveness`]),
//!   [`telemetry`], [`txstamp`]: the process. systemd notification is rt-core's
//!   ([`fes_rt::rt::notify`]).
//! - [`safe_stop`]: the `safe-stop` subcommand; [`probe`]: the `probe` subcommand (a
//!   RehaStim 2's answer times).
#![deny(clippy::missing_safety_doc)]

pub mod applied;
pub mod bus;
pub mod config;
pub mod event;
pub mod fault;
pub mod forward;
pub mod interlock;
pub mod intrusion;
pub mod output;
pub mod probe;
pub mod reconcile;
pub mod report;
pub mod runner;
pub mod safe_stop;
pub mod serial_rx;
pub mod serial_tx;
pub mod telemetry;
pub mod tx;
pub mod txstamp;
