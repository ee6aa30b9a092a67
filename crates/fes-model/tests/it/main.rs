//! fes-model's integration tests, one binary: the Local Model Network (validity,
//! scheduling, forms, parameters, the model file) and the Local Controller Network (design
//! against Tables 6.1/6.2, the shaper, the controller file, the measured-force loop), with
//! the no-allocation proofs of the network step and the pattern-generator tick under one
//! counting global allocator ([`alloc_count`]).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod alloc_count;
// The control tests' fixture, `fes_testkit::control`, compiled in here rather than linked:
// these tests are part of this crate's own test build, and through fes-testkit they would
// see a second fes-model, whose types are not this crate's.
#[path = "../../../fes-testkit/src/control.rs"]
mod control_support;
mod json_mutation;

mod control_design;
mod control_file;
mod control_io_design;
mod control_measured;
mod control_no_alloc;
mod control_planner;
mod control_shaper;
mod model_file;
mod model_forms;
mod model_miso_ss;
mod model_network;
mod model_no_alloc;
mod model_params;
mod model_scheduling;
mod model_scheduling_class;
mod model_validity;
