//! fes-sciencemode's integration tests, one binary: known byte vectors produced by
//! pyScienceMode, property-tested round trips and corruption detection, and the
//! allocation-free hot path.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod document;
mod no_alloc;
mod roundtrip;
mod support;
mod vectors;
