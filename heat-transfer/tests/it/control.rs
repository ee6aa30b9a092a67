//! Acceptance for E.4.7 (Fig. E.8a) on seed 1: the LCN has no steady-state
//! error, overshoots by at most 2 % and rises within 15 % of the scheduled rise time at
//! alpha = 0.1, 0.5, 0.9 on its design model and on the simulated process;
//! the linear controller designed at alpha = 0.5 meets its specification there only and
//! overshoots by more than 5 % at the small valve angle.

use super::identification::report;
use heat_transfer::control::ControllerResults;

fn meets_spec(c: &ControllerResults, rise_tolerance: f64) {
    for s in [&c.small, &c.mid, &c.large] {
        assert!(s.steady_error < 1e-3, "{s:?}");
        assert!(s.overshoot_pct <= 2.0, "{s:?}");
        assert!(
            (s.rise_s / s.rise_target_s - 1.0).abs() <= rise_tolerance,
            "{s:?}"
        );
    }
}

#[test]
fn lcn_meets_the_specification_at_every_angle() {
    let r = report();
    println!("{:#?}\n{:#?}", r.control, r.control_process);
    meets_spec(&r.control.lcn, 0.15);
    // On the process too: the controllers invert the heater's u^2, so the model's gain is
    // the process's at every voltage (with the voltage as the model's input it rose 24 %
    // slow nearly closed).
    meets_spec(&r.control_process.lcn, 0.15);
}

#[test]
fn linear_controller_meets_it_only_where_it_was_designed() {
    // Tolerances as for the LCN: 15 % on the design model and on the process.
    for (c, tol) in [(&report().control, 0.15), (&report().control_process, 0.15)] {
        let l = &c.linear;
        let off = |s: &heat_transfer::control::StepResult| (s.rise_s / s.rise_target_s - 1.0).abs();
        assert!(
            off(&l.mid) <= tol && l.mid.overshoot_pct <= 2.0,
            "{:?}",
            l.mid
        );
        assert!(
            l.small.rise_s < (1.0 - tol) * l.small.rise_target_s,
            "{:?}",
            l.small
        );
        assert!(
            l.large.rise_s > (1.0 + tol) * l.large.rise_target_s,
            "{:?}",
            l.large
        );
        assert!(l.small.steady_error < 1e-3 && l.large.steady_error < 1e-3);
    }
    // Fig. E.8(a): the linear controller overshoots at the small valve angle, on the
    // design model and on the process.
    let small = &report().control.linear.small;
    assert!(small.overshoot_pct > 5.0, "{small:?}");
    let small = &report().control_process.linear.small;
    assert!(small.overshoot_pct > 5.0, "{small:?}");
}

/// Anti-reset-windup (the thesis's remedy for Fig. E.8's overshoot at 37 s): after an
/// unreachable reference the LCN with the applied input in its history settles at once;
/// without, it is still off 20 s later.
#[test]
fn anti_reset_windup_removes_the_wind_up() {
    let w = &report().windup;
    println!("{w:?}");
    assert!(w.with_s < 2.0, "{w:?}");
    assert!(w.without_s > 5.0 * w.with_s, "{w:?}");
}

/// Why the LCN meets its specification on the process: the design model's gain from the
/// heater power is the process's at every angle (within 5 %). (A model in the voltage had
/// 0.776 nearly closed against the process's 0.482 over the same step.)
#[test]
fn design_model_gain_is_the_process_gain_at_every_angle() {
    let g = &report().control_gains;
    println!("{g:#?}");
    assert_eq!(g.len(), 3);
    for c in g {
        assert!((c.model / c.process - 1.0).abs() < 0.05, "{c:?}");
    }
}
