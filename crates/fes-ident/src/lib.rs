//! # fes-ident: identification and analysis of Local Model Networks
//!
//! Everything offline that turns recorded data into a model and a model into insight,
//! on top of the thesis's equations in `fes-model`:
//!
//! - [`ident`]: identification (2.3, 5.3, 5.4, App. B): knots, starts, Levenberg-Marquardt
//!   with the analytic Jacobian, sweeps over unit counts.
//! - [`analysis`]: static analysis and optimal stimulation patterns (2.4, 5.4.3, ch. 6).
//!
//! The equations are `fes_model`'s and the data-set format `fes_dataset`'s, named by those
//! crates (nothing is re-exported). Nothing here runs in real time or talks to another
//! process.
#![deny(clippy::missing_safety_doc)]

pub mod analysis;
pub mod ident;

// The integration tests (tests/it) compile into this crate's one test binary: they use only
// the public API, through the crate's own name (docs/architecture.md, "Tests").
#[cfg(test)]
extern crate self as fes_ident;
#[cfg(test)]
#[path = "../tests/it/main.rs"]
mod it;
