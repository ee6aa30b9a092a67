//! The thesis's equations as a library: the numerics ([`num`]), the Local Model Network
//! ([`model`], thesis ch. 2, 5) and the Local Controller Network with the pulse shaper and the
//! pattern generator's tick ([`control`], ch. 3, 6.5, App. C). No I/O beyond reading and
//! writing the model and controller files, no threads, no processes: the identification
//! (`fes_ident::ident`), the real-time loop (`rt_core::rt`), the simulators and the workbench
//! all build on it, so each equation has one implementation.
//!
//! # Features and `no_std`
//!
//! - `std` (default): the standard library. It adds the file I/O, the functions that read or
//!   write a file by path (`model::file::{load, load_allow_unstable, save}` and
//!   `control::file::Controller::{load, save}`) with the `Io` variants of their errors, and
//!   the f64 math is std's.
//!
//! With default features off the crate is `#![no_std]` and needs only `alloc`; none of its
//! dependencies has its `std` feature on (`check-no-std.sh` checks both). Only the file I/O
//! is left out: everything else stays, including the text of both file formats
//! (`to_json_string`, `from_json_str`). The f64 math (`exp`, `ln`, `sqrt`, `sin`, `cos`, ...)
//! then comes from the `libm` crate (the crate's own through a private extension trait in
//! `num::math`, nalgebra's through its `libm` feature), so results may differ from a `std`
//! build in the last bits; a `std` build uses std's methods only.
#![cfg_attr(not(feature = "std"), no_std)]
#![deny(clippy::missing_safety_doc)]

extern crate alloc;

pub mod control;
pub mod model;
pub mod num;

// The integration tests (tests/it) compile into this crate's one test binary: they use only
// the public API, through the crate's own name (docs/architecture.md, "Tests").
#[cfg(test)]
extern crate self as fes_model;
#[cfg(test)]
#[path = "../tests/it/main.rs"]
mod it;
