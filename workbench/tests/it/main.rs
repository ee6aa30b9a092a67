//! The workbench's integration tests, one binary: the `fes` commands (identify, analyse,
//! modify, design, osp), the LCN's targets on the simulated muscles, the outer loop, and
//! the four-process stack on the host bus (recording, fault injection); the bench on
//! both transports (timing).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod analysis_support;
mod stack_support;

mod analysis_analyse;
mod analysis_design;
mod analysis_modify;
mod analysis_osp;
mod dataset_import_cli;
mod dataset_v2_cli;
mod fault_injection;
mod ident_cli;
mod lcn_targets;
mod planning_bench;
mod readers;
mod runtime_canlog;
mod runtime_outer_loop;
mod runtime_recording;
mod timing;
