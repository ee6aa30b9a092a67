//! Acceptance for identification on seed 1: Table E.1's delays, E.4.2's
//! first-order ARX (pole in 0.85-0.97, the signs of Table E.2), the orderings of Tables
//! E.3-E.6, and Fig. E.7's shape (G_u falls, the pole moves inwards as the valve opens).

use heat_transfer::{Report, study};
use std::sync::OnceLock;

pub fn report() -> &'static Report {
    static R: OnceLock<Report> = OnceLock::new();
    R.get_or_init(|| study(1).unwrap())
}

#[test]
fn table_e1_delays_within_one_sample() {
    let r = report();
    for (a, d) in &r.delays_u_samples {
        let t = r.delays_u_table_e1[a];
        assert!(d.abs_diff(t) <= 1, "{a} deg: {d} vs {t}");
    }
}

#[test]
fn e42_pole_and_gain_signs() {
    let a = &report().arx1;
    println!("{a:#?}");
    for pole in [a.pole_prediction, a.pole_simulation] {
        assert!((0.85..=0.97).contains(&pole), "{pole}");
    }
    for c in [&a.prediction, &a.simulation] {
        assert!(c.g_alpha < 0.0 && c.b_alpha < 0.0, "{c:?}");
        assert!(c.g_u > 0.0 && c.b_u > 0.0, "{c:?}");
    }
}

#[test]
fn orderings_of_tables_e3_to_e6_on_seed_1() {
    let r = report();
    for row in &r.learning {
        println!("{row:?}");
    }
    let o = &r.orderings;
    println!("{o:?}");
    assert!(o.simulation_beats_prediction);
    assert!(o.global_beats_local_in_simulation);
    assert!(o.prediction_local_bias_and_regularisation);
    assert!(o.ten_units_generalise_worse);
}

/// Table E.5: the common-eigenvector network is close to the general one (the thesis:
/// "only slightly inferior"); both have real, stable eigenvalues by construction.
#[test]
fn table_e5_restricted_close_to_general() {
    let r = report();
    let [g, c] = [&r.state_space[0], &r.state_space[1]];
    println!("{g:?}\n{c:?}");
    assert_eq!(r.orderings.restricted_close_to_general, Some(true));
    assert!(
        c.train_mse >= 0.98 * g.train_mse,
        "the restriction cannot fit much better"
    );
    for e in g.eigenvalues.iter().chain(&c.eigenvalues).flatten() {
        assert!(*e < 0.0 && *e > -1.0 / 0.05, "{e}");
    }
    assert!(c.angles_rad.windows(2).all(|w| w[0] == w[1]));
}

#[test]
fn fig_e7_gain_falls_and_plant_speeds_up_as_the_valve_opens() {
    let s = &report().static_5;
    let (first, last) = (&s[0], &s[s.len() - 1]);
    println!("{first:?}\n{last:?}");
    assert!(first.g_u > last.g_u);
    assert!(first.pole > last.pole);
    assert!(s.iter().all(|p| p.g_u > 0.0));
    for w in s.windows(2) {
        assert!(w[1].g_u < w[0].g_u && w[1].pole < w[0].pole, "{w:?}");
    }
    // G_alpha: strongly negative nearly closed, small open (its sign in between is not
    // determined: b_alpha and the offsets trade off, docs/heat-transfer.md).
    assert!(first.g_alpha < 0.0 && first.g_alpha.abs() > 5.0 * last.g_alpha.abs());
}

/// E.4.1: scheduling on [alpha, u] (eq. E.1) captures the voltage's non-linearity (Joule
/// heating) that scheduling on alpha alone (eq. E.2) cannot.
#[test]
fn e41_two_dimensional_scheduling_beats_alpha_alone() {
    let r = report();
    let (t, g5) = (&r.scheduling_2d, &r.learning[0]);
    println!("{t:?}");
    assert_eq!(t.units, 9);
    assert!(t.train_mse < g5.sim_train_msse && t.test_mse < g5.sim_test_msse);
}
