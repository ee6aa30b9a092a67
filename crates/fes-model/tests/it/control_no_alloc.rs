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
                    ..Default::default()
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

/// With planning on and a cardiac preview, the tick still allocates nothing: the planner's
/// buffers are made by `with_planning`, in both feedback modes, through replans (the
/// level changes every third beat) and a reset.
#[test]
fn planning_ticks_never_allocate_with_ten_units() {
    use fes_model::control::planner::PlanningConfig;
    use fes_model::control::preview::{Preview, PreviewPoint};

    let [p1, p2] = dominant_pair(0.005, 1.2, TS).unwrap();
    for mode in [FeedbackMode::Model, FeedbackMode::MeasuredForce] {
        let settings = ControllerSettings {
            mode,
            estimator_poles: Some(EstimatorPoles { p1, p2 }),
            planning: PlanningConfig::RECOMMENDED,
            ..ControllerSettings::default()
        };
        let c = Controller::design(fast_muscle(10), &table_6_1_specs(10), settings).unwrap();
        let mut pg = c.pattern_generator().unwrap();
        let (period, on) = (800usize, 320usize);
        let level = |beat: usize| [0.3, 0.7, 0.15][beat % 3];
        let setpoint = |k: usize| {
            if k % period < on {
                level(k / period)
            } else {
                0.0
            }
        };
        let mut r = 0.0f64;
        let n = allocations_in(|| {
            for k in 0..40_000usize {
                let start = k - k % period;
                let mut points = [PreviewPoint::default(); 4];
                points[0] = PreviewPoint {
                    at: 0,
                    force: setpoint(k),
                    rate_per_s: 50.0,
                };
                let mut len = 1;
                for edge in [start + on, start + period, start + period + on] {
                    if edge > k {
                        points[len] = PreviewPoint {
                            at: (edge - k) as u32,
                            force: setpoint(edge),
                            rate_per_s: 50.0,
                        };
                        len += 1;
                    }
                }
                let preview = Preview::new(&points[..len]).unwrap();
                let goal = setpoint(k);
                r = if goal > r {
                    (r + 0.05).min(goal)
                } else {
                    (r - 0.05).max(goal)
                };
                pg.tick(&TickInput {
                    reference: r,
                    measured_force: Some(0.25),
                    resting: goal == 0.0,
                    preview,
                });
                if k == 20_000 {
                    pg.reset();
                }
            }
        });
        assert_eq!(n, 0, "{mode:?}: {n} allocations in 40 000 planning ticks");
        let s = pg.stats().planner;
        assert!(s.planned_ticks > 3000, "{mode:?}: {s:?}");
    }
}
