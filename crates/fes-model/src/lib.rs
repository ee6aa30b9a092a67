//! The thesis's equations as a library: the numerics ([`num`]), the Local Model Network
//! ([`model`], thesis ch. 2, 5) and the Local Controller Network with the pulse shaper and the
//! pattern generator's tick ([`control`], ch. 3, 6.5, App. C). No I/O beyond reading and
//! writing the model and controller files, no threads, no processes: the identification
//! (`rt_core::ident`), the real-time loop (`rt_core::rt`), the simulators and the workbench
//! all build on it, so each equation has one implementation.
#![deny(missing_docs)]
#![deny(clippy::missing_safety_doc)]

pub mod control;
pub mod model;
pub mod num;
