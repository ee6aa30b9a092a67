//! sim-muscle's integration tests, one binary: the muscle models' accuracy and physiology,
//! the LMN plant, the CLI and the muscle's allocation-free step.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod support;

mod accuracy;
mod cli;
mod lmn_plant;
mod no_alloc;
mod physiology;
