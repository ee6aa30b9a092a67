//! heat-transfer's tests, one binary: the App. E study's acceptance numbers on seed 1.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod control;
mod dataset;
mod figures;
mod identification;
