//! The plant against App. E.1 and E.3: delays (Table E.1), gain falling with the angle
//! (Fig. E.4a), Joule heating, noise reproducible from the seed.

use sim_heat::plant::{
    HeatParams, HeatPlant, StepInput, TABLE_E1_DELAY_ALPHA, TABLE_E1_DELAY_U, TEST_ANGLES_DEG,
    step_delay,
};

/// Acceptance: the delays read off the plant's step responses are within one
/// sample of Table E.1, for both inputs.
#[test]
fn delays_per_angle_within_one_sample_of_table_e1() {
    let p = HeatParams::default();
    for (i, &a) in TEST_ANGLES_DEG.iter().enumerate() {
        let du = step_delay(&p, a, StepInput::Voltage).unwrap();
        let da = step_delay(&p, a, StepInput::Angle).unwrap();
        println!(
            "alpha {a}: u->y {du} (table {}), alpha->y {da} (table {})",
            TABLE_E1_DELAY_U[i], TABLE_E1_DELAY_ALPHA[i]
        );
        assert!(
            du.abs_diff(TABLE_E1_DELAY_U[i]) <= 1,
            "u->y at {a} deg: {du} samples"
        );
        assert!(
            da.abs_diff(TABLE_E1_DELAY_ALPHA[i]) <= 1,
            "alpha->y at {a} deg: {da} samples"
        );
        assert!(da < du, "alpha->y is shorter than u->y at {a} deg");
    }
}

/// Fig. E.4(a): the response to the same 4 V step is larger at small angles, and the
/// steady state is Joule heating, ~u^2 (the 3->7 V step moves 4 times the 0->... power).
#[test]
fn gain_falls_as_the_valve_opens_and_heat_is_quadratic() {
    let p = HeatParams::default();
    let rise = |a: f64| p.steady_output(a, 7.0) - p.steady_output(a, 3.0);
    for w in TEST_ANGLES_DEG.windows(2) {
        assert!(rise(w[0]) > rise(w[1]), "{w:?}");
    }
    let d = p.steady_output(60.0, 10.0) - p.ambient_c;
    let half = p.steady_output(60.0, 5.0) - p.ambient_c;
    assert!((d / half - 4.0).abs() < 1e-12);
    // The simulated plant reaches that steady state.
    let mut plant = HeatPlant::new(
        HeatParams {
            noise_std_k: 0.0,
            ..p
        },
        0,
        60.0,
    )
    .unwrap();
    for _ in 0..600 {
        plant.step(60.0, 5.0);
    }
    assert!((plant.clean_output() - p.steady_output(60.0, 5.0)).abs() < 1e-6);
}

/// The same seed gives the same noise; another seed other noise of the stated size.
#[test]
fn noise_is_seeded_and_of_the_stated_size() {
    let p = HeatParams::default();
    let run = |seed| {
        let mut plant = HeatPlant::new(p, seed, 60.0).unwrap();
        plant.settle(60.0, 5.0);
        (0..2000).map(|_| plant.step(60.0, 5.0)).collect::<Vec<_>>()
    };
    let (a, b, c) = (run(1), run(1), run(2));
    assert_eq!(a, b);
    assert_ne!(a, c);
    let m = a.iter().sum::<f64>() / a.len() as f64;
    let sd = (a.iter().map(|y| (y - m).powi(2)).sum::<f64>() / a.len() as f64).sqrt();
    assert!((sd - p.noise_std_k).abs() < 0.1 * p.noise_std_k, "{sd}");
    assert!((m - p.steady_output(60.0, 5.0)).abs() < 0.05);
}

/// Bad parameters are refused with the field's name.
#[test]
fn invalid_parameters_are_named() {
    let p = HeatParams {
        valve_beta_deg: 100.0,
        ..HeatParams::default()
    };
    let e = HeatPlant::new(p, 0, 60.0).unwrap_err();
    assert!(e.to_string().contains("valve_beta_deg"), "{e}");
}
