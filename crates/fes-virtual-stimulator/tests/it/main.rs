//! fes-virtual-stimulator's integration tests, one binary: the virtual CAN stimulator's
//! safety properties under arbitrary host traffic.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod stimulator_props;
