//! The latency tools' tests, one binary: cyclictest's histogram parser, and the latency
//! regression suite (its gate, and the short run against the checked-in baseline).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod support;

mod cyclictest;
mod latency_regression;
