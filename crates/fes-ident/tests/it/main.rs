//! fes-ident's integration tests, one binary: identification (Jacobian against finite
//! differences, estimation, resampling), the data-set format (its reader and a mutation
//! fuzz), static analysis, stabilisation, force-frequency, optimal stimulation patterns
//! and the closed loop judged with the analysis's measures.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod analysis_support;
mod dataset_support;

mod analysis_force_frequency;
mod analysis_osp;
mod analysis_stabilise;
mod control_loop;
mod dataset_format;
mod dataset_fuzz;
mod dataset_import;
mod dataset_merge;
mod dataset_signals;
mod ident_estimation;
mod ident_jacobian;
mod ident_miso;
mod ident_resample;
mod ident_validation;
mod model_analysis;
