//! The controller file loader on any text: an error, or a controller whose pattern
//! generator builds and runs from rest with finite outputs, with the contraction's
//! preview in every tick so that a file whose `planning` section is on runs the planner.
#![no_main]

use fes_model::control::file::Controller;
use fes_model::control::pattern_generator::TickInput;
use fes_model::control::preview::{Preview, PreviewPoint};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(c) = Controller::from_json_str(text) else {
        return;
    };
    let mut g = c
        .pattern_generator()
        .expect("an accepted controller builds its pattern generator");
    for k in 0..300u32 {
        let r = if (50..200).contains(&k) { 0.3 } else { 0.0 };
        let point = |at: u32, force: f64| PreviewPoint {
            at,
            force,
            rate_per_s: 0.0,
        };
        let points = match k {
            0..50 => vec![point(0, 0.0), point(50 - k, 0.3), point(200 - k, 0.0)],
            50..200 => vec![point(0, 0.3), point(200 - k, 0.0)],
            _ => vec![point(0, 0.0)],
        };
        let preview = Preview::new(&points).expect("a valid preview");
        let d = g.tick(&TickInput {
            reference: r,
            measured_force: None,
            resting: false,
            preview,
        });
        assert!(
            d.u_cont.is_finite() && d.energy.is_finite() && d.model_force.is_finite(),
            "non-finite output at step {k}: {d:?}"
        );
    }
});
