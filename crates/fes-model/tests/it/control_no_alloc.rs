//! The pattern-generator tick allocates nothing: a counting global allocator watches
//! 100 000 ticks with M = 10 units, in both feedback modes, plus `reset`.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use super::control_support;

use control_support::{TS, fast_muscle, table_6_1_specs};
use fes_model::control::design::EstimatorPoles;
use fes_model::control::file::{Controller, ControllerSettings};
use fes_model::control::pattern_generator::{FeedbackMode, TickInput};
use fes_model::control::poles::dominant_pair;

use super::alloc_count::allocations_in;

#[test]
fn tick_and_reset_never_allocate_with_ten_units() {
    let [p1, p2] = dominant_pair(0.005, 1.2, TS).unwrap();
    for mode in [FeedbackMode::Model, FeedbackMode::MeasuredForce] {
        let settings = ControllerSettings {
            mode,
            estimator_poles: Some(EstimatorPoles { p1, p2 }),
            ..ControllerSettings::default()
        };
        let c = Controller::design(fast_muscle(10), &table_6_1_specs(10), settings).unwrap();
        let mut pg = c.pattern_generator().unwrap();
        let mut pulses = 0u64;
        let n = allocations_in(|| {
            for k in 0..100_000u32 {
                // Steps through the whole force range, plus bad references and samples.
                let reference = match (k / 500) % 6 {
                    0 => 0.2,
                    1 => 0.9,
                    2 => 0.0,
                    3 => 0.5,
                    4 => f64::NAN,
                    _ => 2.0,
                };
                let measured_force = match k % 11 {
                    0 => None,
                    1 => Some(f64::INFINITY),
                    _ => Some(0.3),
                };
                let out = pg.tick(&TickInput {
                    reference,
                    measured_force,
                    resting: false,
                });
                pulses += out.pulse as u64;
                if k == 50_000 {
                    pg.reset();
                }
            }
        });
        assert_eq!(n, 0, "{mode:?}: {n} allocations in 100 000 ticks");
        assert!(
            pulses > 100,
            "{mode:?}: the run must exercise the shaper ({pulses} pulses)"
        );
    }
}
