//! Writes the controller the latency measurements run (docs/realtime.md): the fast-muscle
//! fixture network of the control tests with `UNITS` units (default 10) and the Table 6.1
//! rise times, designed with the default settings, saved as `fes-lcn/1` at `PATH`.
//!
//! `cargo run -p rt-core --example demo_controller -- PATH [UNITS]`
#![allow(clippy::unwrap_used, clippy::expect_used)] // a tool: a failed step ends it with its message

use fes_model::control::file::{Controller, ControllerSettings};
use fes_testkit::control;

fn main() {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next() else {
        eprintln!("usage: demo_controller PATH [UNITS]");
        std::process::exit(2);
    };
    let units: usize = args.next().map_or(10, |u| {
        u.parse().unwrap_or_else(|e| panic!("UNITS {u:?}: {e}"))
    });
    let controller = Controller::design(
        control::fast_muscle(units),
        &control::table_6_1_specs(units),
        ControllerSettings::default(),
    )
    .unwrap_or_else(|e| panic!("design: {e}"));
    controller
        .save(&path)
        .unwrap_or_else(|e| panic!("{path}: {e}"));
    println!("{path}: {units}-unit controller");
}
