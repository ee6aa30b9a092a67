//! The Local Model Network (thesis ch. 2, 5.4; App. A, D): the muscle model.
//!
//! - [`validity`]: B-spline validity functions rho_i(phi) (2.2.3, eq. 2.29-2.30).
//! - [`scheduling`]: the scheduling variable phi (5.4.1, eq. 5.1-5.4), exact ZOH prefilter.
//! - [`local_model`]: second-order delta-domain state-space local models and their
//!   parameterisations (2.2.2, eq. 2.13; 5.4.2, eq. 5.5-5.6).
//! - [`arx`]: local ARX models in shift and delta form (eq. 2.20-2.24, App. A.2, D.2).
//! - [`miso`]: ARX local models with several inputs, a delay per input and scheduling on
//!   a measured input (App. E: the heat-transfer process).
//! - [`miso_ss`]: state-space local models with several inputs in their eigensystem,
//!   general or with common eigenvectors (App. E.4.5).
//! - [`network`]: the undelayed LPV core (eq. 2.14-2.16, 2.24), generic over
//!   [`crate::num::Scalar`].
//! - [`forms`]: the thesis form (input delay line) and the advanced form (core state
//!   z\[k\] = x\[k+d\] plus an output ring) of the delayed network.
//! - [`simulate`]: free-run simulation, one-step prediction, MSE (App. B.1).
//! - [`lmn`]: a complete model described in its parameterisation (what the file stores).
//! - [`params`]: the free parameters as one flat vector theta, generic (identification).
//! - [`mod@file`]: the JSON model file `fes-lmn/1`, validated on load.
//!
//! Conventions and the file format are documented in `docs/model.md`.

pub mod arx;
pub mod file;
pub mod forms;
pub mod lmn;
pub mod local_model;
pub mod miso;
pub mod miso_ss;
pub mod network;
pub mod params;
pub mod scheduling;
pub mod simulate;
pub mod validity;

pub use forms::{AdvancedForm, AdvancedStep, DelayLine, ThesisForm};
pub use lmn::{Lmn, LocalModelSet, Structure};
pub use local_model::SsLocalModel;
pub use network::{CoreState, LocalModels, MAX_DELAY, Network, NetworkError};
pub use scheduling::{Prefilter, Scheduler, SchedulingSpec};
pub use validity::{Activation, KnotLayout, MAX_ORDER, MAX_UNITS, ValidityFunctions};

/// Default sampling period Ts in seconds (1 ms, thesis 5.2.2).
pub const DEFAULT_TS: f64 = 1e-3;
/// Default input delay d in samples (Td = 7 ms at 1 ms, thesis 5.2.2).
pub const DEFAULT_DELAY: usize = 7;
