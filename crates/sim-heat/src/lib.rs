//! # sim-heat: the thesis's second plant, the heat-transfer process (App. E)
//!
//! An air heater with two inputs, the valve angle alpha and the heater voltage u, and one
//! output, the outlet temperature y, whose gain and delay change with the angle. The
//! thesis uses it to demonstrate every Part I concept (Examples E.4.1-E.4.7) before it
//! turns to muscle; here it is the proof that the LMN / LCN toolchain is not
//! muscle-specific.
//!
//! - [`plant`]: the first-principles model (E.1), its parameters with the table or figure
//!   each reproduces, and the step-response delay reading of Table E.1.
//! - [`experiment`]: the four identification experiments of E.2 (fast and slow
//!   pseudo-random, test-angle, test-voltage), the 2nd-order mean filter and the [0, 1]
//!   normalisation.

pub mod experiment;
pub mod plant;

pub use plant::{HeatParams, HeatPlant, StepInput, step_delay};

// The integration tests (tests/it) compile into this crate's one test binary.
#[cfg(test)]
extern crate self as sim_heat;
#[cfg(test)]
#[path = "../tests/it/main.rs"]
mod it;
