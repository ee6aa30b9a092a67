//! The pattern generator's closed loop (thesis Fig. 6.8 in the advanced form) against
//! independent truths: the linear closed loop `A_aug - b_aug K` (eq. C.27) for one unit,
//! and settling, gap and energy properties with the shaper on a muscle-like LMN.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_model::control::design::augmented;
use fes_model::control::design::plant_matrices;
use fes_model::control::file::{Controller, ControllerSettings};
use fes_model::control::lcn::AntiWindup;
use fes_model::control::lcn_design::UnitSpec;
use fes_model::control::pattern_generator::TickInput;
use fes_testkit::control::{DELAY, TS, fast_muscle, fast_muscle_with_offsets, table_6_1_specs};
use nalgebra::{Matrix3, RowVector3, Vector2, Vector3};

fn controller(lmn: fes_model::model::Lmn, specs: &[UnitSpec]) -> Controller {
    Controller::design(lmn, specs, ControllerSettings::default()).unwrap()
}

fn with_rule(lmn: fes_model::model::Lmn, specs: &[UnitSpec], rule: AntiWindup) -> Controller {
    let settings = ControllerSettings {
        anti_windup: rule,
        ..ControllerSettings::default()
    };
    Controller::design(lmn, specs, settings).unwrap()
}

#[test]
fn one_unit_unshaped_loop_follows_the_linear_closed_loop() {
    // One unit: rho = 1 everywhere, so the loop is LTI:
    // w[k+1] = w[k] + Ts ((A_aug - b_aug K) w[k] - [1; 0] r + [dy; dx]),  w = [x_I; z].
    // An output offset only (dx = 0): the rest state is z = 0, so u_raw starts at 0 and the
    // clamp never engages; the linear loop is then the exact truth.
    let c = controller(
        fast_muscle_with_offsets(1, false, true),
        &[UnitSpec::thesis(0.03, TS)],
    );
    let m = c.network.ss_unit(0).unwrap();
    let (a, b, cv) = plant_matrices(m);
    let (a_aug, b_aug) = augmented(&a, &b, &cv);
    let g = c.units[0].gains;
    let k = RowVector3::new(g.k_i, g.k_x[0], g.k_x[1]);
    let m_cl: Matrix3<f64> = a_aug - b_aug * k;
    let offs = Vector3::new(m.dy, m.dx[0], m.dx[1]);
    let r = 0.5;

    let mut pg = c.pattern_generator().unwrap();
    // Start: x_I = 0, z = the rest state (equilibrium for u = 0).
    let x0 = m.equilibrium(0.0).unwrap();
    let mut w = Vector3::new(0.0, x0[0], x0[1]);
    let mut y_hist = Vec::new();
    let mut worst = 0.0f64;
    for k in 0..3000 {
        let out = pg.tick_unshaped(&TickInput {
            reference: r,
            measured_force: None,
            resting: false,
            ..Default::default()
        });
        assert!(
            out.u_raw >= 0.0 && out.integrated,
            "clamp must stay inactive (k = {k})"
        );
        let got = Vector3::new(out.x_i, out.z[0], out.z[1]);
        worst = worst.max((got - w).norm() / w.norm().max(1.0));
        let y_core = cv.dot(&w.fixed_rows::<2>(1)) + m.dy;
        assert!((out.predicted_force - y_core).abs() <= 1e-9 * y_core.abs().max(1.0));
        y_hist.push(y_core);
        // Model force now = core output d samples ago (rest output before that).
        let want_now = if k >= DELAY {
            y_hist[k - DELAY]
        } else {
            cv.dot(&Vector2::from(x0)) + m.dy
        };
        assert!(
            (out.model_force - want_now).abs() <= 1e-9 * want_now.abs().max(1.0),
            "k {k}"
        );
        w += TS * (m_cl * w - Vector3::new(r, 0.0, 0.0) + offs);
    }
    assert!(worst < 1e-9, "max relative deviation {worst:e}");
    // Integral action: zero steady-state error despite the offsets (eq. C.29).
    let y_end = *y_hist.last().unwrap();
    assert!((y_end - r).abs() < 1e-6, "y = {y_end}");
}

fn run(
    pg: &mut fes_model::control::pattern_generator::PatternGenerator,
    r: f64,
    n: usize,
) -> (Vec<f64>, Vec<usize>) {
    let mut force = Vec::with_capacity(n);
    let mut pulses = Vec::new();
    for k in 0..n {
        let out = pg.tick(&TickInput {
            reference: r,
            measured_force: None,
            resting: false,
            ..Default::default()
        });
        force.push(out.model_force);
        if out.pulse {
            pulses.push(k);
        }
    }
    (force, pulses)
}

#[test]
fn constant_reference_settles_within_5_percent_with_pulses() {
    let c = controller(fast_muscle(6), &table_6_1_specs(6));
    for r in [0.2, 0.3, 0.5, 0.7] {
        let mut pg = c.pattern_generator().unwrap();
        let (force, pulses) = run(&mut pg, r, 1500);
        let tail = &force[1000..];
        let mean = tail.iter().sum::<f64>() / tail.len() as f64;
        assert!(
            (mean - r).abs() <= 0.05 * r,
            "r = {r}: mean force over the last 500 ms {mean}"
        );
        let min_ipi = pulses.windows(2).map(|w| w[1] - w[0]).min().unwrap();
        assert!(min_ipi >= 2, "r = {r}: pulses {min_ipi} samples apart");
        eprintln!(
            "r = {r}: mean {mean:.4}, {} pulses, first IPIs {:?}",
            pulses.len(),
            pulses
                .windows(2)
                .take(8)
                .map(|w| w[1] - w[0])
                .collect::<Vec<_>>()
        );
    }
}

#[test]
fn reset_reproduces_the_run_and_bad_references_are_clamped() {
    let c = controller(fast_muscle(6), &table_6_1_specs(6));
    let mut pg = c.pattern_generator().unwrap();
    let (f1, p1) = run(&mut pg, 0.3, 600);
    pg.reset();
    let (f2, p2) = run(&mut pg, 0.3, 600);
    assert_eq!(f1, f2);
    assert_eq!(p1, p2);
    // A non-finite reference counts as 0, an out-of-range one is clamped; both counted.
    pg.reset();
    let mut reference = c.pattern_generator().unwrap();
    for (bad, good) in [
        (f64::NAN, 0.0),
        (7.0, 1.0),
        (-3.0, 0.0),
        (f64::INFINITY, 0.0),
    ] {
        for _ in 0..50 {
            let a = pg.tick(&TickInput {
                reference: bad,
                measured_force: None,
                resting: false,
                ..Default::default()
            });
            let b = reference.tick(&TickInput {
                reference: good,
                measured_force: None,
                resting: false,
                ..Default::default()
            });
            assert_eq!(a, b);
        }
    }
    assert_eq!(pg.stats().references_clamped, 200);
}

#[test]
fn anti_windup_holds_the_integrator_when_reference_drops() {
    // After a high plateau the reference drops to 0: u_raw goes negative, the integrator is
    // held (not wound further negative), and the force decays to rest without pulses once
    // the error is gone.
    let c = with_rule(
        fast_muscle(6),
        &table_6_1_specs(6),
        AntiWindup::IntegralSign,
    );
    let mut pg = c.pattern_generator().unwrap();
    run(&mut pg, 0.5, 800);
    let mut held = 0;
    let mut last_pulse = None;
    for k in 0..1500 {
        let out = pg.tick(&TickInput {
            reference: 0.0,
            measured_force: None,
            resting: false,
            ..Default::default()
        });
        if !out.integrated {
            held += 1;
            assert!(out.u_raw < 0.0, "held only while clamped");
        }
        if out.pulse {
            last_pulse = Some(k);
        }
    }
    assert!(held > 0, "the clamp must engage after the drop");
    assert!(
        last_pulse.is_none_or(|k| k < 50),
        "pulses long after the drop: {last_pulse:?}"
    );
    assert!(pg.lcn().x_i().is_finite());
}

#[test]
fn no_windup_during_a_pause_with_a_positive_rest_force() {
    // With offsets the model rests at a force above r = 0, so the error stays positive for
    // the whole pause. Without anti-windup x_I would grow without bound (about 0.03 per
    // second here) and delay the next contraction; with it, the next contraction starts as
    // from a fresh start.
    for rule in [AntiWindup::IntegralSign, AntiWindup::None] {
        let c = with_rule(
            fast_muscle_with_offsets(6, true, true),
            &table_6_1_specs(6),
            rule,
        );
        let mut fresh = c.pattern_generator().unwrap();
        let (_, fresh_pulses) = run(&mut fresh, 0.3, 300);
        let mut pg = c.pattern_generator().unwrap();
        run(&mut pg, 0.5, 500);
        let (rest, pause_pulses) = run(&mut pg, 0.0, 3000);
        assert!(rest[2999] > 0.0, "the fixture rests above zero force");
        assert!(
            pause_pulses.iter().all(|&k| k < 50),
            "{rule:?}: pulses during the pause: {pause_pulses:?}"
        );
        assert!(
            pg.lcn().x_i().abs() < 1e-3,
            "{rule:?}: x_I = {} after a 3 s pause",
            pg.lcn().x_i()
        );
        let (_, pulses) = run(&mut pg, 0.3, 300);
        assert!(
            pulses[0] <= fresh_pulses[0] + 2,
            "{rule:?}: first pulse {} ms after the pause vs {} ms from rest",
            pulses[0],
            fresh_pulses[0]
        );
    }
}

/// Plain integral action (the default) at a zero reference: the integrator is reset with
/// the shaper, so every contraction after a rest repeats the first one exactly, whatever
/// the contraction before it (here a higher plateau). Without the reset the integrator
/// would carry the relaxation's error into the next contraction.
#[test]
fn plain_integral_action_restarts_every_contraction_from_rest() {
    let c = controller(fast_muscle(6), &table_6_1_specs(6));
    assert_eq!(c.settings.anti_windup, AntiWindup::None);
    let mut fresh = c.pattern_generator().unwrap();
    let first = run(&mut fresh, 0.3, 400);
    let mut pg = c.pattern_generator().unwrap();
    run(&mut pg, 0.6, 500);
    let (_, rest_pulses) = run(&mut pg, 0.0, 400);
    assert!(rest_pulses.is_empty(), "pulses at rest: {rest_pulses:?}");
    assert_eq!(pg.lcn().x_i(), 0.0);
    let again = run(&mut pg, 0.3, 400);
    assert_eq!(again.1, first.1, "pulse times after a rest");
}

/// With plain integral action the pulsed loop has no bias: in a periodic steady state the
/// integrator returns to its value after every period, so the mean of `y[k+d] - r` over a
/// period is zero, and the model force (the same signal `d` samples later) has its mean at
/// `r` over whole inter-pulse intervals (`steady_mean`), down to levels where one twitch
/// overshoots the reference several times. The anti-windup rules that freeze the
/// integrator settle above `r` there (docs/control.md, section 3).
#[test]
fn plain_integral_action_holds_the_mean_at_every_level() {
    use fes_ident::analysis::osp::lcn::steady_mean;
    let c = controller(fast_muscle(6), &table_6_1_specs(6));
    let sign = with_rule(
        fast_muscle(6),
        &table_6_1_specs(6),
        AntiWindup::IntegralSign,
    );
    for r in [0.05, 0.1, 0.15, 0.2, 0.3, 0.5, 0.7] {
        let mut pg = c.pattern_generator().unwrap();
        let (force, pulses) = run(&mut pg, r, 4000);
        let mean = steady_mean(&force, &pulses, 2000).unwrap();
        assert!((mean - r).abs() <= 0.01 * r, "r = {r}: mean {mean}");
        if r <= 0.1 {
            let mut pg = sign.pattern_generator().unwrap();
            let (force, pulses) = run(&mut pg, r, 4000);
            let biased = steady_mean(&force, &pulses, 2000).unwrap();
            assert!(biased > 1.1 * r, "integral_sign, r = {r}: {biased}");
        }
    }
}

/// The rest gate: at a zero reference no pulse fires although the LCN still asks for
/// stimulation (its integral term outlives the contraction), the shaper's energy is
/// cleared; a positive reference fires again. Checked on cardiac-like beats (320 ms at 0.3
/// to 0.4, 480 ms at zero); the test also checks that the LCN did ask for stimulation at
/// rest, so that the gate had something to hold back.
#[test]
fn no_pulse_while_the_reference_is_zero() {
    let c = controller(fast_muscle(6), &table_6_1_specs(6));
    let mut pg = c.pattern_generator().unwrap();
    let mut asked_at_rest = 0;
    let mut pulses_on = 0;
    for beat in 0..6 {
        let amplitude = 0.3 + 0.02 * beat as f64;
        for k in 0..800 {
            let r = if k < 320 { amplitude } else { 0.0 };
            let out = pg.tick(&TickInput {
                reference: r,
                measured_force: None,
                resting: false,
                ..Default::default()
            });
            if r == 0.0 {
                assert!(!out.pulse, "beat {beat}: pulse at rest, {k} ms");
                assert_eq!(out.energy, 0.0, "beat {beat}: energy banked at rest");
                if out.u_cont > 0.0 {
                    asked_at_rest += 1;
                }
            } else if out.pulse {
                pulses_on += 1;
            }
        }
    }
    assert!(pulses_on >= 6, "{pulses_on} pulses in the contractions");
    assert!(
        asked_at_rest > 0,
        "the LCN never asked for stimulation at rest: the gate is untested"
    );
}

/// A reference ramping down to rest (`resting`): the shaper rests from the first tick of
/// the ramp, although the reference is still high and the LCN asks for stimulation.
#[test]
fn no_pulse_while_the_reference_ramps_down_to_rest() {
    let c = controller(fast_muscle(6), &table_6_1_specs(6));
    let mut gated = c.pattern_generator().unwrap();
    let mut free = c.pattern_generator().unwrap();
    run(&mut gated, 0.5, 300);
    run(&mut free, 0.5, 300);
    let (mut asked, mut free_pulses) = (0, 0);
    for k in 0..40 {
        let r = 0.5 - 0.01 * k as f64;
        let g = gated.tick(&TickInput {
            reference: r,
            measured_force: None,
            resting: true,
            ..Default::default()
        });
        let f = free.tick(&TickInput {
            reference: r,
            measured_force: None,
            resting: false,
            ..Default::default()
        });
        assert!(!g.pulse, "pulse at {k} ms of the ramp to rest");
        assert_eq!(g.energy, 0.0);
        asked += usize::from(g.u_cont > 0.0);
        free_pulses += usize::from(f.pulse);
    }
    assert!(
        asked > 0 && free_pulses > 0,
        "{asked} {free_pulses}: the gate held nothing back"
    );
}

#[test]
fn output_clamp_rule_biases_the_pulsed_loop() {
    // The textbook rule (freeze whenever clamped and the error pushes down) sees only the
    // negative errors in pulsed operation, so the mean force settles too high: the reason
    // the default rule also requires the integral term to ask for negative stimulation.
    let settings = ControllerSettings {
        anti_windup: AntiWindup::OutputClamp,
        ..ControllerSettings::default()
    };
    let c = Controller::design(fast_muscle(6), &table_6_1_specs(6), settings).unwrap();
    let mut pg = c.pattern_generator().unwrap();
    let (force, _) = run(&mut pg, 0.3, 1500);
    let mean = force[1000..].iter().sum::<f64>() / 500.0;
    eprintln!("output-clamp rule, r = 0.3: mean force {mean:.4}");
    assert!(mean > 1.2 * 0.3, "mean {mean}");
}

/// The settling table of docs/control.md (fast-muscle fixture, M = 6, Table 6.1 rise
/// times): mean model force over 2-4 s, over whole inter-pulse intervals (`steady_mean`),
/// for each reference and anti-windup rule. It checks the documented values (to 0.002) so
/// the table cannot silently go stale; `cargo test -p fes-ident settling_table --
/// --nocapture` prints it.
#[test]
fn settling_table_of_the_docs() {
    use fes_ident::analysis::osp::lcn::steady_mean;
    const DOCUMENTED: [(f64, [f64; 3]); 7] = [
        // (r, [none, integral_sign, output_clamp])
        (0.05, [0.0500, 0.0934, 0.1536]),
        (0.1, [0.1000, 0.1290, 0.2193]),
        (0.15, [0.1500, 0.1590, 0.2791]),
        (0.2, [0.2000, 0.2000, 0.3315]),
        (0.3, [0.3000, 0.3000, 0.4309]),
        (0.5, [0.4999, 0.4999, 0.6081]),
        (0.7, [0.7001, 0.7001, 0.7996]),
    ];
    println!("| r | none (default) | pulses/s | integral_sign | output_clamp |");
    println!("|---|---|---|---|---|");
    let mut stale = Vec::new();
    for (r, want) in DOCUMENTED {
        let mut means = [0.0; 3];
        let mut rate = 0.0;
        for (j, rule) in [
            AntiWindup::None,
            AntiWindup::IntegralSign,
            AntiWindup::OutputClamp,
        ]
        .into_iter()
        .enumerate()
        {
            let c = with_rule(fast_muscle(6), &table_6_1_specs(6), rule);
            let mut pg = c.pattern_generator().unwrap();
            let (force, pulses) = run(&mut pg, r, 4000);
            means[j] = steady_mean(&force, &pulses, 2000).unwrap();
            if j == 0 {
                rate = pulses.iter().filter(|&&k| k >= 2000).count() as f64 / 2.0;
            }
        }
        println!(
            "| {r} | {:.4} | {rate} | {:.4} | {:.4} |",
            means[0], means[1], means[2]
        );
        if means.iter().zip(want).any(|(m, w)| (m - w).abs() >= 2e-3) {
            stale.push(r);
        }
    }
    assert!(stale.is_empty(), "documented rows stale for r = {stale:?}");
}
