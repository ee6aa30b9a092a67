//! sim-muscle's integration tests, one binary: the muscle models' accuracy and physiology,
//! the LMN plant, the CLI, the virtual stimulator's properties and its allocation-free
//! tick.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod support;

mod accuracy;
mod cli;
mod lmn_plant;
mod no_alloc;
mod physiology;
mod stimulator_props;
