//! # rt-core: the 1 ms real-time pattern generator
//!
//! The process that runs the thesis's Local Controller Network and pulse shaper (Gollee,
//! *A non-linear approach to modelling and control of electrically stimulated skeletal
//! muscle*, ch. 6.5, Fig. 6.8) once per millisecond and publishes its pulse decisions:
//!
//! - [`rt`]: the pattern generator's tick without I/O, the process configuration and the
//!   runner (real-time and telemetry threads over iceoryx2), on the plumbing of `fes-rt`.
//! - [`model`], [`control`], [`num`]: the thesis's equations, re-exported from `fes-model`.
//! - [`msg`]: the iceoryx2 message contracts, re-exported from `fes-rt`.
//!
//! Identification, analysis and the data-set format live in `fes-ident`; nothing here
//! links them.
#![deny(missing_docs)]
#![deny(clippy::missing_safety_doc)]

pub mod rt;

/// The thesis's equations, from the `fes-model` crate (re-exported so that every path
/// `rt_core::{num, model, control}` keeps working).
pub use fes_model::{control, model, num};

/// The iceoryx2 message contracts, from the `fes-rt` crate (`rt_core::msg` unchanged).
pub use fes_rt::msg;
