//! The controller file loader on any text: an error, or a controller whose pattern
//! generator builds and runs from rest with finite outputs.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rt_core::control::file::Controller;
use rt_core::control::pattern_generator::TickInput;

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
        let d = g.tick(&TickInput {
            reference: r,
            measured_force: None,
            resting: false,
        });
        assert!(
            d.u_cont.is_finite() && d.energy.is_finite() && d.model_force.is_finite(),
            "non-finite output at step {k}: {d:?}"
        );
    }
});
