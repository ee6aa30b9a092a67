//! Analysis of identified models (thesis 2.4, 5.4.3) and optimal stimulation patterns (ch. 6).
//!
//! - [`static_analysis`]: the network frozen at fixed phi: activations, interpolated local
//!   model, steady-state gain, poles, offset, stability margin; per-unit stability; the
//!   common-eigenvector test (2.4.1, 2.4.2).
//! - [`trace`]: a free run that records phi and the state (phi range of a data set, phase
//!   planes).
//! - [`force_frequency`]: the force-frequency curve (Fig. 5.26).
//! - [`validation`]: simulated against measured records and their MSSE (Fig. 5.24, eq. B.8).
//! - [`stabilise`]: replacing unstable local eigenvalues and re-estimating the unit's
//!   offsets (5.4.3, Tables 5.3-5.4).
//! - [`osp`]: FTI, FTIpP and the optimal-stimulation-pattern methods (ch. 6).

pub mod force_frequency;
pub mod osp;
pub mod stabilise;
pub mod static_analysis;
pub mod trace;
pub mod validation;
