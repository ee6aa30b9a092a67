//! # rt-core: the model, the controller and the real-time pattern generator
//!
//! One implementation of the thesis's equations (Gollee, *A non-linear approach to
//! modelling and control of electrically stimulated skeletal muscle*), shared by
//! identification, analysis, the 1 ms real-time loop and the simulator:
//!
//! - [`model`]: the Local Model Network (ch. 2, 5.4): validity functions, scheduling,
//!   input delay, local models, the network, and the model file.
//! - [`control`]: the Local Controller Network (ch. 3, 6.5, App. C), the pulse shaper
//!   (6.5.2) and the pattern-generator tick (Fig. 6.8).
//! - [`ident`]: identification (2.3, 5.3, 5.4, App. B).
//! - [`analysis`]: static analysis and optimal stimulation patterns (2.4, 5.4.3, ch. 6).
//! - [`dataset`]: the on-disk data-set format (records of pulses and force).
//! - [`msg`]: iceoryx2 message contracts shared by every process.
//! - [`rt`]: real-time thread plumbing (SCHED_FIFO, affinity, absolute-time sleeps,
//!   telemetry into HdrHistograms).
#![deny(missing_docs)]
#![deny(clippy::missing_safety_doc)]

pub mod analysis;
pub mod dataset;
pub mod ident;
pub mod rt;

/// The thesis's equations, from the `fes-model` crate (re-exported so that every path
/// `rt_core::{num, model, control}` keeps working).
pub use fes_model::{control, model, num};

/// The iceoryx2 message contracts, from the `fes-rt` crate (`rt_core::msg` unchanged).
pub use fes_rt::msg;
