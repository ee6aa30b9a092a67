//! Acceptance of issue 21 for E.4.7 (Fig. E.8) on seed 1: the LCN has no steady-state
//! error, overshoots by at most 2 % and rises within 15 % of the scheduled rise time at
//! alpha = 0.1, 0.5, 0.9, on its design model and on the simulated process itself; the
//! linear controller designed at alpha = 0.5 meets its specification there only. (Its
//! overshoot of more than 5 % at the small angle that the issue also asks for does not
//! happen on this plant: it is too fast there instead, see docs/heat-transfer.md.)

use super::identification::report;
use heat_transfer::control::ControllerResults;

fn meets_spec(c: &ControllerResults) {
    for s in [&c.small, &c.mid, &c.large] {
        assert!(s.steady_error < 1e-3, "{s:?}");
        assert!(s.overshoot_pct <= 2.0, "{s:?}");
        assert!((s.rise_s / s.rise_target_s - 1.0).abs() <= 0.15, "{s:?}");
    }
}

#[test]
fn lcn_meets_the_specification_at_every_angle() {
    let r = report();
    println!("{:#?}\n{:#?}", r.control, r.control_process);
    meets_spec(&r.control.lcn);
    meets_spec(&r.control_process.lcn);
}

#[test]
fn linear_controller_meets_it_only_where_it_was_designed() {
    for c in [&report().control, &report().control_process] {
        let l = &c.linear;
        let off = |s: &heat_transfer::control::StepResult| (s.rise_s / s.rise_target_s - 1.0).abs();
        assert!(
            off(&l.mid) <= 0.15 && l.mid.overshoot_pct <= 2.0,
            "{:?}",
            l.mid
        );
        assert!(
            l.small.rise_s < 0.85 * l.small.rise_target_s,
            "{:?}",
            l.small
        );
        assert!(
            l.large.rise_s > 1.15 * l.large.rise_target_s,
            "{:?}",
            l.large
        );
        assert!(l.small.steady_error < 1e-3 && l.large.steady_error < 1e-3);
    }
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
