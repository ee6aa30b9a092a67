//! The undelayed scheduling class (eq. 5.2 read literally: phi(t) = Gamma{u(t)} filters the
//! pulses as applied, the local models see u[k-d]) beside ours (phi filters u[k-d]).
//!
//! Independent truths: the prefilter's continuous step response in closed form (a one-sample
//! pulse through a zero-order hold gives phi samples s(kTs) - s((k-1)Ts)); the identity that
//! the two classes coincide when d = 0 or when every unit is the same model; the file
//! format's default for files written before the choice existed.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use super::control_support::{fast_muscle, table_6_1_specs};
use fes_model::control::file::{Controller, ControllerSettings};
use fes_model::control::pattern_generator::{FeedbackState, TickInput};
use fes_model::model::file;
use fes_model::model::lmn::{Lmn, Stability};
use fes_model::model::scheduling::{SchedulingInput, SchedulingSpec};
use fes_model::model::simulate::simulate;
use fes_model::model::{AdvancedForm, NetworkError, ThesisForm};

fn with_class(mut m: Lmn, class: SchedulingInput) -> Lmn {
    let SchedulingSpec::Input {
        scheduling_input, ..
    } = &mut m.scheduling
    else {
        panic!("the fixture uses input scheduling");
    };
    *scheduling_input = class;
    m
}

/// The prefilter's response to a unit step, s(t) = (K / w_n^2)(1 - e^{-w_n t}(1 + w_n t))
/// for the critically damped G_pre(s) = K / (s + w_n)^2 (eq. 5.4, K = 25000, w_n = 50).
fn step_response(t: f64) -> f64 {
    let (k, wn) = (25_000.0, 50.0);
    k / (wn * wn) * (1.0 - (-wn * t).exp() * (1.0 + wn * t))
}

/// phi\[k\] after one-sample pulses at the given samples (pulse at j contributes
/// s((k-j)Ts) - s((k-j-1)Ts) for k > j).
fn phi_closed_form(k: usize, pulses: &[usize]) -> f64 {
    let ts = 1e-3;
    pulses
        .iter()
        .filter(|&&j| k > j)
        .map(|&j| step_response((k - j) as f64 * ts) - step_response((k - j - 1) as f64 * ts))
        .sum()
}

/// Where the second pulse of a 2 ms doublet reaches the local models (k = 2 + d = 9), phi
/// carries both pulses in the undelayed class (~0.26) and only the first pulse's first
/// 2 ms in ours (~0.035): a different local model is active when the pulse lands.
#[test]
fn the_doublets_second_pulse_lands_at_the_phi_each_class_says() {
    let d = 7;
    let mut u = vec![0.0; 40];
    u[0] = 1.0;
    u[2] = 1.0;
    for (class, pulses_seen) in [
        (SchedulingInput::Undelayed, vec![0, 2]),
        (SchedulingInput::Delayed, vec![d, 2 + d]),
    ] {
        let net = with_class(fast_muscle(6), class).network().unwrap();
        let mut form = ThesisForm::new(net).unwrap();
        for (k, &uk) in u.iter().enumerate() {
            let want = phi_closed_form(k, &pulses_seen);
            let got = form.state().phi;
            assert!(
                (got - want).abs() < 1e-9,
                "{class:?} k={k}: phi {got} vs closed form {want}"
            );
            form.step(uk);
        }
    }
    let (undelayed, ours) = (
        phi_closed_form(2 + d, &[0, 2]),
        phi_closed_form(2 + d, &[d]),
    );
    assert!((undelayed - 0.256).abs() < 5e-4, "{undelayed}");
    assert!((ours - 0.0347).abs() < 5e-4, "{ours}");
}

fn pulses(n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| if k % 23 == 0 || k % 37 == 3 { 1.0 } else { 0.0 })
        .collect()
}

/// With d = 0 the classes are one model; with d = 7 they differ, and they coincide again
/// when every unit is the same model (the scheduling value then does not matter).
#[test]
fn the_classes_coincide_exactly_where_they_must() {
    let u = pulses(600);
    let run = |m: Lmn| {
        let net = m.network().unwrap();
        let mut y = vec![0.0; u.len()];
        simulate(&net, &u, &mut y).unwrap();
        y
    };
    let no_delay = |c| Lmn {
        delay: 0,
        ..with_class(fast_muscle(6), c)
    };
    assert_eq!(
        run(no_delay(SchedulingInput::Delayed)),
        run(no_delay(SchedulingInput::Undelayed))
    );
    let a = run(with_class(fast_muscle(6), SchedulingInput::Delayed));
    let b = run(with_class(fast_muscle(6), SchedulingInput::Undelayed));
    let diff = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(
        diff > 1e-3,
        "the classes differ at d = 7: max |dy| = {diff}"
    );
    let one = |c| Lmn {
        validity: fes_model::model::ValidityFunctions::uniform(1, 0.0, 1.0).unwrap(),
        local: fast_muscle(1).local,
        ..with_class(fast_muscle(1), c)
    };
    assert_eq!(
        run(one(SchedulingInput::Delayed)),
        run(one(SchedulingInput::Undelayed))
    );
}

/// The field is written only for the undelayed class, read back as written, absent means
/// delayed, and output scheduling refuses it.
#[test]
fn the_model_file_stores_the_class_and_reads_old_files_as_delayed() {
    let delayed = fast_muscle(4);
    let text = file::to_json_string(&delayed).unwrap();
    assert!(!text.contains("scheduling_input"), "{text}");
    assert_eq!(
        file::from_json_str(&text, Stability::Require)
            .unwrap()
            .scheduling
            .scheduling_input(),
        SchedulingInput::Delayed
    );
    let undelayed = with_class(fast_muscle(4), SchedulingInput::Undelayed);
    let text = file::to_json_string(&undelayed).unwrap();
    assert!(
        text.contains("\"scheduling_input\": \"undelayed\""),
        "{text}"
    );
    let back = file::from_json_str(&text, Stability::Require).unwrap();
    assert_eq!(back.scheduling, undelayed.scheduling);
    let explicit = text.replace("\"undelayed\"", "\"delayed\"");
    assert_eq!(
        file::from_json_str(&explicit, Stability::Require)
            .unwrap()
            .scheduling,
        SchedulingSpec::default()
    );
    let bad = text.replace("\"undelayed\"", "\"later\"");
    assert!(file::from_json_str(&bad, Stability::Require).is_err());
}

/// The advanced form, the advanced loop and planning are refused on the undelayed class
/// with d > 0; the thesis's delayed loop runs on the model in the thesis's form, its gains
/// scheduled on phi(t) = Gamma{u(t)}: its model force and phi are those of the thesis form
/// driven by its own pulses.
#[test]
fn only_the_delayed_loop_runs_on_the_undelayed_class() {
    let lmn = with_class(fast_muscle(6), SchedulingInput::Undelayed);
    let net = lmn.network().unwrap();
    assert!(!net.can_run_ahead());
    assert_eq!(
        AdvancedForm::new(net).err(),
        Some(NetworkError::CannotRunAhead { delay: 7 })
    );
    let specs = table_6_1_specs(6);
    let advanced = Controller::design(lmn.clone(), &specs, ControllerSettings::default());
    let Err(err) = advanced else {
        panic!("the advanced loop is refused");
    };
    let err = err.to_string();
    assert!(err.contains("feedback_state"), "{err}");
    let settings = ControllerSettings {
        feedback_state: FeedbackState::Delayed,
        ..ControllerSettings::default()
    };
    let c = Controller::design(lmn, &specs, settings).unwrap();
    let mut pg = c.pattern_generator().unwrap();
    let mut plant = ThesisForm::new(net).unwrap();
    let mut fired = 0;
    for k in 0..400 {
        let r = if k < 300 { 0.3 } else { 0.0 };
        let phi_now = plant.state().phi;
        let out = pg.tick(&TickInput {
            reference: r,
            ..TickInput::default()
        });
        let y = plant.step(if out.pulse { 1.0 } else { 0.0 });
        fired += usize::from(out.pulse);
        assert_eq!(out.phi, phi_now, "k={k}: the gains are scheduled on phi[k]");
        assert_eq!(out.model_force, y, "k={k}");
        assert_eq!(
            out.predicted_force, y,
            "k={k}: no prediction in the thesis's form"
        );
    }
    assert!(fired > 3, "the loop stimulated: {fired} pulses");
}
