//! sim-heat's tests, one binary: the plant against Table E.1 and Fig. E.4, the
//! experiments of E.2.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod experiment;
mod plant;
