//! Analysis of identified models (thesis 2.4, 5.4.3) and optimal stimulation patterns (ch. 6).
//!
//! - [`static_analysis`]: the network frozen at fixed phi: activations, interpolated local
//!   model, steady-state gain, poles, offset, stability margin; per-unit stability; the
//!   common-eigenvector test (2.4.1, 2.4.2).

pub mod static_analysis;
