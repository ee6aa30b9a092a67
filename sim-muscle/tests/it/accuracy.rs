//! The sampled Ding muscle against an independent high-accuracy integration of the same
//! equations: adaptive Dormand-Prince 5(4) (tolerance 1e-10) on CN, F (and, with fatigue,
//! A, Km, tau1) as plain ODEs, with the pulse sum of the CN equation evaluated directly.
//! Acceptance: every sample within 0.1 % of the peak force.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use sim_muscle::ding::{DingParams, FatigueParams, PulseWidthParams};
use sim_muscle::muscle::{Muscle, MuscleConfig};
use sim_muscle::pattern::{constant_train, from_samples};
use sim_muscle::plant::{MusclePlant, Pulse};
use sim_muscle::preset::Preset;
use sim_muscle::simulate::simulate;

const N: usize = 5;

/// The Ding equations as an ODE in y = [CN, F, A, Km, tau1], for the pulses at
/// `times[..active]` with enhancements `r[..active]`.
struct Ding<'a> {
    p: DingParams,
    fatigue: Option<FatigueParams>,
    times: &'a [f64],
    r: &'a [f64],
}

impl Ding<'_> {
    fn rhs(&self, active: usize, t: f64, y: &[f64; N]) -> [f64; N] {
        let p = &self.p;
        let sum: f64 = (0..active)
            .map(|i| self.r[i] * (-(t - self.times[i]) / p.tauc).exp())
            .sum();
        let (cn, f, a, km, tau1) = (y[0], y[1], y[2], y[3], y[4]);
        let s = cn / (km + cn);
        let mut d = [
            sum / p.tauc - cn / p.tauc,
            a * s - f / (tau1 + p.tau2 * s),
            0.0,
            0.0,
            0.0,
        ];
        if let Some(fp) = &self.fatigue {
            d[2] = -(a - p.a) / fp.tau_fat + fp.alpha_a * f;
            d[3] = -(km - p.km) / fp.tau_fat + fp.alpha_km * f;
            d[4] = -(tau1 - p.tau1) / fp.tau_fat + fp.alpha_tau1 * f;
        }
        d
    }
}

/// One adaptive Dormand-Prince 5(4) integration from t0 to t1 (the RHS is smooth there).
fn dopri5(
    f: &dyn Fn(f64, &[f64; N]) -> [f64; N],
    t0: f64,
    t1: f64,
    y0: [f64; N],
    tol: f64,
) -> [f64; N] {
    const C: [f64; 7] = [0.0, 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0, 1.0, 1.0];
    const A: [[f64; 6]; 7] = [
        [0.0; 6],
        [1.0 / 5.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0, 0.0],
        [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0, 0.0, 0.0, 0.0],
        [
            19372.0 / 6561.0,
            -25360.0 / 2187.0,
            64448.0 / 6561.0,
            -212.0 / 729.0,
            0.0,
            0.0,
        ],
        [
            9017.0 / 3168.0,
            -355.0 / 33.0,
            46732.0 / 5247.0,
            49.0 / 176.0,
            -5103.0 / 18656.0,
            0.0,
        ],
        [
            35.0 / 384.0,
            0.0,
            500.0 / 1113.0,
            125.0 / 192.0,
            -2187.0 / 6784.0,
            11.0 / 84.0,
        ],
    ];
    const B: [f64; 7] = [
        35.0 / 384.0,
        0.0,
        500.0 / 1113.0,
        125.0 / 192.0,
        -2187.0 / 6784.0,
        11.0 / 84.0,
        0.0,
    ];
    const B4: [f64; 7] = [
        5179.0 / 57600.0,
        0.0,
        7571.0 / 16695.0,
        393.0 / 640.0,
        -92097.0 / 339200.0,
        187.0 / 2100.0,
        1.0 / 40.0,
    ];
    let (mut t, mut y) = (t0, y0);
    let mut h = (t1 - t0) / 10.0;
    while t < t1 {
        h = h.min(t1 - t);
        let mut k = [[0.0; N]; 7];
        for s in 0..7 {
            let mut ys = y;
            for (j, kj) in k.iter().enumerate().take(s) {
                for i in 0..N {
                    ys[i] += h * A[s][j] * kj[i];
                }
            }
            k[s] = f(t + C[s] * h, &ys);
        }
        let mut y5 = y;
        let mut err: f64 = 0.0;
        for i in 0..N {
            let (mut d5, mut d4) = (0.0, 0.0);
            for s in 0..7 {
                d5 += B[s] * k[s][i];
                d4 += B4[s] * k[s][i];
            }
            y5[i] += h * d5;
            let scale = tol + tol * y[i].abs().max(y5[i].abs());
            err = err.max((h * (d5 - d4)).abs() / scale);
        }
        if err <= 1.0 {
            t += h;
            y = y5;
        }
        h *= (0.9 * err.max(1e-10).powf(-0.2)).clamp(0.2, 5.0);
    }
    y
}

/// Reference force at t = k ts (k = 0..n) for pulses at `times` (s, increasing, any real
/// times): integrate to each pulse and each sample time, firing each pulse at its time.
fn reference(p: DingParams, fatigue: Option<FatigueParams>, times: &[f64], n: usize) -> Vec<f64> {
    let ts = 1e-3;
    let mut r = vec![0.0; times.len()];
    let mut y = [0.0, 0.0, p.a, p.km, p.tau1];
    let (mut t, mut next) = (0.0, 0);
    let mut out = Vec::with_capacity(n);
    let fire = |next: usize, y: &[f64; N], r: &mut Vec<f64>| {
        // R_i = 1 + (R0 - 1) exp(-(t_i - t_{i-1})/tauc), R0 = Km + (r0 - km) with fatigue.
        let r0 = if fatigue.is_some() {
            y[3] + (p.r0 - p.km)
        } else {
            p.r0
        };
        r[next] = match next {
            0 => 1.0,
            _ => 1.0 + (r0 - 1.0) * (-(times[next] - times[next - 1]) / p.tauc).exp(),
        };
    };
    for k in 0..n {
        let t_k = k as f64 * ts;
        while next < times.len() && times[next] < t_k {
            let model = Ding {
                p,
                fatigue,
                times,
                r: &r,
            };
            y = dopri5(&|tt, yy| model.rhs(next, tt, yy), t, times[next], y, 1e-10);
            t = times[next];
            fire(next, &y, &mut r);
            next += 1;
        }
        let model = Ding {
            p,
            fatigue,
            times,
            r: &r,
        };
        y = dopri5(&|tt, yy| model.rhs(next, tt, yy), t, t_k, y, 1e-10);
        t = t_k;
        out.push(y[1]);
        // A pulse at exactly t_k fires now; F is continuous, so after sampling is right.
        while next < times.len() && times[next] <= t_k {
            fire(next, &y, &mut r);
            next += 1;
        }
    }
    out
}

fn sampled(cfg: MuscleConfig, pulses: &[usize], n: usize) -> Vec<f64> {
    let mut m = Muscle::new(cfg).expect("valid config");
    simulate(&mut m, &from_samples(pulses, n), Pulse::SUPRAMAXIMAL)
}

/// Largest error relative to the reference's peak.
fn relative_error(model: &[f64], reference: &[f64]) -> f64 {
    let peak = reference.iter().cloned().fold(0.0, f64::max);
    assert!(peak > 0.0);
    model
        .iter()
        .zip(reference)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
        / peak
}

fn check(name: &str, cfg: MuscleConfig, pulses: &[usize], n: usize) -> f64 {
    let model = sampled(cfg, pulses, n);
    let times: Vec<f64> = pulses
        .iter()
        .map(|&k| k as f64 * 1e-3 + cfg.emd_s)
        .collect();
    let refr = reference(cfg.ding, cfg.fatigue, &times, n);
    assert_eq!(model.len(), refr.len());
    let e = relative_error(&model, &refr);
    println!("{name}: max |error| / peak = {e:.3e}");
    assert!(e < 1e-3, "{name}: error {e} exceeds 0.1 % of peak");
    e
}

fn no_emd(preset: Preset) -> MuscleConfig {
    MuscleConfig {
        emd_s: 0.0,
        ..MuscleConfig::preset(preset)
    }
}

#[test]
fn twitch_doublet_and_100hz_match_dormand_prince() {
    for preset in Preset::ALL {
        let cfg = no_emd(preset);
        check(&format!("{preset} twitch"), cfg, &[0], 600);
        let mut doublet = vec![0, 5];
        doublet.extend(constant_train(20.0, 55, 250, 1e-3).expect("train"));
        check(
            &format!("{preset} doublet-led 20 Hz train"),
            cfg,
            &doublet,
            600,
        );
        let tetanus = constant_train(100.0, 0, 300, 1e-3).expect("train");
        check(&format!("{preset} 100 Hz train"), cfg, &tetanus, 600);
    }
}

#[test]
fn fatigue_matches_dormand_prince() {
    for preset in Preset::ALL {
        let mut cfg = no_emd(preset);
        cfg.fatigue = Some(FatigueParams::for_muscle(&cfg.ding));
        let train = constant_train(33.0, 0, 1000, 1e-3).expect("train");
        check(&format!("{preset} fatigue 33 Hz 1 s"), cfg, &train, 1500);
    }
}

/// With emd = 7 ms the first nonzero force is 8 samples after the pulse and the whole
/// response is the emd = 0 response delayed by 7 samples; a non-integer delay (7.5 ms)
/// matches the reference with the pulses moved 7.5 ms.
#[test]
fn electromechanical_delay() {
    let cfg = MuscleConfig::preset(Preset::Fast);
    assert_eq!(cfg.emd_s, 7e-3);
    let pulses = [10, 15, 40];
    let delayed = sampled(cfg, &pulses, 300);
    let first = delayed.iter().position(|&f| f != 0.0).expect("force");
    assert_eq!(first, 10 + 8);
    let direct = sampled(no_emd(Preset::Fast), &pulses, 300);
    for k in 7..300 {
        assert!(
            (delayed[k] - direct[k - 7]).abs() <= 1e-12 * direct[k - 7].abs().max(1.0),
            "k = {k}"
        );
    }
    let half = MuscleConfig {
        emd_s: 7.5e-3,
        ..cfg
    };
    check("fast, emd 7.5 ms", half, &pulses, 300);
}

/// The pulse-width variant at the supramaximal 200 us is the base model bit for bit; a
/// train of narrower pulses scales the force by exactly the variant's gain (force is
/// linear in A without fatigue).
#[test]
fn pulse_width_variant_reduces_to_base_model() {
    let base = MuscleConfig::preset(Preset::Slow);
    let pw = MuscleConfig {
        pulse_width: Some(PulseWidthParams::DING_2007),
        ..base
    };
    let train = from_samples(&constant_train(25.0, 0, 300, 1e-3).expect("train"), 500);
    let run = |cfg: MuscleConfig, pulse: Pulse| {
        let mut m = Muscle::new(cfg).expect("valid");
        simulate(&mut m, &train, pulse)
    };
    assert_eq!(run(base, Pulse::SUPRAMAXIMAL), run(pw, Pulse::SUPRAMAXIMAL));
    let narrow = Pulse {
        width_us: 160.0,
        ..Pulse::SUPRAMAXIMAL
    };
    let gain = PulseWidthParams::DING_2007.gain(160.0);
    let full = run(base, Pulse::SUPRAMAXIMAL);
    let scaled = run(pw, narrow);
    for (a, b) in full.iter().zip(&scaled) {
        assert!((a * gain - b).abs() <= 1e-9 * a.abs().max(1.0));
    }
    // Below the threshold nothing is recruited; without the variant width is ignored.
    assert!(
        run(
            pw,
            Pulse {
                width_us: 100.0,
                ..Pulse::SUPRAMAXIMAL
            }
        )
        .iter()
        .all(|&f| f == 0.0)
    );
    assert_eq!(run(base, narrow), full);
    // A pulse without charge delivers nothing.
    assert!(
        run(
            base,
            Pulse {
                amplitude_ma: 0.0,
                ..Pulse::SUPRAMAXIMAL
            }
        )
        .iter()
        .all(|&f| f == 0.0)
    );
}

/// reset returns to rest (the same response again); rest(30 s) without fatigue is a reset.
#[test]
fn reset_and_rest() {
    let cfg = MuscleConfig::preset(Preset::Fast);
    let train = from_samples(&[0, 3, 30, 60], 200);
    let mut m = Muscle::new(cfg).expect("valid");
    let a = simulate(&mut m, &train, Pulse::SUPRAMAXIMAL);
    m.reset();
    let b = simulate(&mut m, &train, Pulse::SUPRAMAXIMAL);
    m.rest(30.0);
    let c = simulate(&mut m, &train, Pulse::SUPRAMAXIMAL);
    assert_eq!(a, b);
    assert_eq!(a, c);
}

/// The force integrator has fourth order: halving the RK4 substep (1 ms -> 0.5 ms)
/// divides the error against the reference by about 2^4 = 16 (accepted 11..22).
#[test]
fn rk4_converges_with_fourth_order() {
    let pulses = [0, 5, 30, 55];
    let cfg = no_emd(Preset::Fast);
    let times: Vec<f64> = pulses.iter().map(|&k| k as f64 * 1e-3).collect();
    let refr = reference(cfg.ding, None, &times, 300);
    let err = |h: f64| {
        relative_error(
            &sampled(
                MuscleConfig {
                    max_substep_s: h,
                    ..cfg
                },
                &pulses,
                300,
            ),
            &refr,
        )
    };
    let ratio = err(1e-3) / err(0.5e-3);
    println!("error ratio 1 ms / 0.5 ms substeps: {ratio:.2}");
    assert!((11.0..22.0).contains(&ratio), "ratio {ratio}");
}

/// Rest with fatigue: once the force has decayed, the fatigued A, Km and tau1 recover
/// towards their rested values as exp(-t / tau_fat) (closed form of the fatigue
/// equations with F = 0): compare a 30 s rest with the deficit after the train.
#[test]
fn fatigue_recovers_with_tau_fat() {
    let mut cfg = no_emd(Preset::Slow);
    let fatigue = FatigueParams::for_muscle(&cfg.ding);
    cfg.fatigue = Some(fatigue);
    let mut m = Muscle::new(cfg).expect("valid");
    simulate(
        &mut m,
        &from_samples(&constant_train(40.0, 0, 5000, 1e-3).expect("train"), 5000),
        Pulse::SUPRAMAXIMAL,
    );
    // Let the force decay (2 s), then read the deficit and rest 30 s more.
    m.rest(2.0);
    let (a0, km0, t0) = m.model().current_a_km_tau1();
    m.rest(30.0);
    let (a1, km1, t1) = m.model().current_a_km_tau1();
    let w = (-30.0 / fatigue.tau_fat).exp();
    let p = cfg.ding;
    assert!(p.a - a0 > 100.0, "the train fatigued the muscle");
    assert!(((a1 - p.a) - (a0 - p.a) * w).abs() < 1e-6 * p.a);
    assert!(((km1 - p.km) - (km0 - p.km) * w).abs() < 1e-9);
    assert!(((t1 - p.tau1) - (t0 - p.tau1) * w).abs() < 1e-9);
}
