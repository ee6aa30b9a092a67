//! The measured-force mode (thesis Fig. 6.6(a)): the estimator corrects the delayed model
//! state from the measured force and the integral action sees the measured error. Checked
//! against the model mode (identical decisions when the "muscle" is the model itself) and
//! against the real force of a mismatched plant (simulated independently, thesis form).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use super::control_support;

use control_support::{TS, fast_muscle, table_6_1_specs};
use fes_model::control::design::EstimatorPoles;
use fes_model::control::file::{Controller, ControllerFileError, ControllerSettings};
use fes_model::control::pattern_generator::{FeedbackMode, PatternGenerator, TickInput};
use fes_model::control::poles::{Pole, dominant_pair};
use fes_model::model::ThesisForm;
use fes_model::model::lmn::{Lmn, LocalModelSet};

fn estimator_poles() -> EstimatorPoles {
    // Twice as fast as the fastest dominant pole of Table 6.1 (t_r = 10 ms -> 5 ms).
    let [p1, p2] = dominant_pair(0.005, 1.2, TS).unwrap();
    EstimatorPoles { p1, p2 }
}

fn controller(mode: FeedbackMode) -> Controller {
    let settings = ControllerSettings {
        mode,
        estimator_poles: Some(estimator_poles()),
        ..ControllerSettings::default()
    };
    Controller::design(fast_muscle(6), &table_6_1_specs(6), settings).unwrap()
}

/// The fast-muscle fixture with every output gain scaled: a "real muscle" weaker or
/// stronger than its model.
fn scaled_plant(scale: f64) -> Lmn {
    let mut lmn = fast_muscle(6);
    if let LocalModelSet::SsEigCommon { units, .. } = &mut lmn.local {
        for u in units {
            u.c = [u.c[0] * scale, u.c[1] * scale];
        }
    }
    lmn
}

/// A simulated muscle (thesis form, input delay d >= 1): its force `y[k]` does not depend
/// on the pulse `u[k]`, so it can be read before the decision.
struct Muscle(ThesisForm<f64>);

impl Muscle {
    fn new(lmn: &Lmn) -> Self {
        Self(ThesisForm::new(lmn.network().unwrap()).unwrap())
    }
    /// Force now, `y[k]`.
    fn force(&self) -> f64 {
        self.0.clone().step(0.0)
    }
    /// Apply the pulse `u[k]` and move to `k + 1`.
    fn apply(&mut self, pulse: bool) {
        let y = self.force();
        assert_eq!(self.0.step(if pulse { 1.0 } else { 0.0 }), y);
    }
}

/// Closed loop with a simulated muscle; returns the muscle's force and the pulse times.
fn run_with_plant(
    pg: &mut PatternGenerator,
    plant: &Lmn,
    r: f64,
    n: usize,
) -> (Vec<f64>, Vec<usize>) {
    let mut muscle = Muscle::new(plant);
    let mut force = Vec::with_capacity(n);
    let mut pulses = Vec::new();
    for k in 0..n {
        let y = muscle.force();
        force.push(y);
        let out = pg.tick(&TickInput {
            reference: r,
            measured_force: Some(y),
            resting: false,
            ..Default::default()
        });
        if out.pulse {
            pulses.push(k);
        }
        muscle.apply(out.pulse);
    }
    (force, pulses)
}

#[test]
fn with_a_perfect_model_the_measured_mode_makes_the_model_modes_decisions() {
    let model_mode = controller(FeedbackMode::Model);
    let measured = controller(FeedbackMode::MeasuredForce);
    let mut a = model_mode.pattern_generator().unwrap();
    let mut b = measured.pattern_generator().unwrap();
    let mut muscle = Muscle::new(&fast_muscle(6));
    for k in 0..2000 {
        let y = muscle.force();
        let r = if k < 1000 { 0.3 } else { 0.6 };
        let oa = a.tick(&TickInput {
            reference: r,
            measured_force: None,
            resting: false,
            ..Default::default()
        });
        let ob = b.tick(&TickInput {
            reference: r,
            measured_force: Some(y),
            resting: false,
            ..Default::default()
        });
        assert!(
            ob.innovation.abs() < 1e-12,
            "k {k}: innovation {}",
            ob.innovation
        );
        assert_eq!(oa.pulse, ob.pulse, "k {k}");
        assert!(
            (oa.u_cont - ob.u_cont).abs() <= 1e-9 * oa.u_cont.abs().max(1.0),
            "k {k}"
        );
        assert!(
            (oa.model_force - y).abs() < 1e-12,
            "k {k}: model force is the muscle's"
        );
        muscle.apply(ob.pulse);
    }
}

#[test]
fn measured_mode_removes_the_steady_state_error_of_a_mismatched_muscle() {
    let r = 0.3;
    for scale in [0.7, 1.3] {
        let plant = scaled_plant(scale);
        let mut open = controller(FeedbackMode::Model).pattern_generator().unwrap();
        let (f_open, _) = run_with_plant(&mut open, &plant, r, 3000);
        let mut closed = controller(FeedbackMode::MeasuredForce)
            .pattern_generator()
            .unwrap();
        let (f_closed, pulses) = run_with_plant(&mut closed, &plant, r, 3000);
        let mean = |f: &[f64]| f[2000..].iter().sum::<f64>() / 1000.0;
        let (m_open, m_closed) = (mean(&f_open), mean(&f_closed));
        eprintln!("scale {scale}: model mode {m_open:.4}, measured mode {m_closed:.4}");
        assert!(
            (m_open - r).abs() > 0.1 * r,
            "the mismatch must show in model mode: {m_open}"
        );
        assert!(
            (m_closed - r).abs() <= 0.05 * r,
            "measured mode: mean muscle force {m_closed}"
        );
        assert!(pulses.windows(2).all(|w| w[1] - w[0] >= 2));
    }
}

#[test]
fn missing_measurements_are_counted_and_survived() {
    let mut pg = controller(FeedbackMode::MeasuredForce)
        .pattern_generator()
        .unwrap();
    let mut muscle = Muscle::new(&fast_muscle(6));
    let mut missing = 0;
    for k in 0..3000 {
        let y = muscle.force();
        let measured = match k % 7 {
            0 => None,
            1 => Some(f64::NAN),
            2 => Some(1e6), // implausible
            _ => Some(y),
        };
        if !matches!(measured, Some(v) if v == y) {
            missing += 1;
        }
        let out = pg.tick(&TickInput {
            reference: 0.3,
            measured_force: measured,
            resting: false,
            ..Default::default()
        });
        assert!(out.u_cont.is_finite() && out.x_i.is_finite());
        muscle.apply(out.pulse);
    }
    assert_eq!(pg.stats().measurements_missing, missing);
}

#[test]
fn measured_mode_needs_estimator_poles() {
    let settings = ControllerSettings {
        mode: FeedbackMode::MeasuredForce,
        ..ControllerSettings::default()
    };
    let err = Controller::design(fast_muscle(6), &table_6_1_specs(6), settings).unwrap_err();
    assert!(
        matches!(&err, ControllerFileError::Invalid { field, .. } if field == "estimator_poles"),
        "{err}"
    );
    // Unstable estimator poles are refused by the design.
    let settings = ControllerSettings {
        mode: FeedbackMode::MeasuredForce,
        estimator_poles: Some(EstimatorPoles {
            p1: Pole::real(5.0),
            p2: Pole::real(-10.0),
        }),
        ..ControllerSettings::default()
    };
    let err = Controller::design(fast_muscle(6), &table_6_1_specs(6), settings).unwrap_err();
    assert!(err.to_string().contains("estimator p1"), "{err}");
}
