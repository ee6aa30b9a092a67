//! # rt-core: the 1 ms real-time pattern generator
//!
//! The process that runs the thesis's Local Controller Network and pulse shaper (Gollee,
//! *A non-linear approach to modelling and control of electrically stimulated skeletal
//! muscle*, ch. 6.5, Fig. 6.8) once per millisecond and publishes its pulse decisions:
//!
//! - [`rt`]: the pattern generator's tick without I/O ([`rt::PatternLoop`] around a
//!   [`rt::TickSource`]), the reference tracker, the process configuration and the runner
//!   (real-time and telemetry threads over iceoryx2).
//!
//! Nothing else lives here, and nothing is re-exported: the thesis's equations are
//! `fes-model`'s (`fes_model::{model, control, num}`), the message contracts and the
//! real-time plumbing `fes-rt`'s (`fes_rt::{msg, rt}`), and every crate names the crate
//! that defines what it uses. Identification, analysis and the data-set format live in
//! `fes-ident`; nothing here links them.
#![deny(clippy::missing_safety_doc)]

pub mod rt;
