//! Input-output pole placement (thesis C.1, `control::io_design`): the closed loop of an
//! ARX plant with offset and its controller is exactly the designed servo response
//! s_0 B'(q) / (q^{n_p - 2} A_m(q)): no steady-state error, the dominant pair's rise time.

use fes_model::control::io_design::{PolyLcn, design_arx, dominant_polynomial};
use fes_model::model::arx::ArxUnit;

/// Runs plant y_k = b0 u_{k-d} + b1 u_{k-d-1} - a y.. + c with the controller, from the
/// steady state at r0, reference stepped to r1 at k = 0; returns y.
fn closed_loop(
    plant: &ArxUnit,
    n: usize,
    d: usize,
    ctl: &mut PolyLcn,
    r0: f64,
    r1: f64,
    len: usize,
) -> Vec<f64> {
    let a1: f64 = 1.0 + plant.a[..n].iter().sum::<f64>();
    let b1: f64 = plant.b[..n].iter().sum();
    let u0 = (r0 * a1 - plant.d) / b1;
    ctl.settle(u0, r0);
    let hist = 64;
    let mut u = vec![u0; hist + len];
    let mut y = vec![r0; hist + len];
    for k in hist..hist + len {
        let mut yk = plant.d;
        for l in 0..n {
            yk += plant.b[l] * u[k - d - l] - plant.a[l] * y[k - 1 - l];
        }
        y[k] = yk;
        u[k] = ctl.step(0.5, y[k - 1], r1);
    }
    y[hist..].to_vec()
}

#[test]
fn closed_loop_is_the_designed_servo_response() {
    let ts = 0.05;
    for (n, d, plant) in [
        (
            1,
            5,
            ArxUnit {
                a: [-0.93, 0.0, 0.0],
                b: [0.045, 0.0, 0.0],
                d: 0.004,
            },
        ),
        (
            2,
            2,
            ArxUnit {
                a: [-1.5, 0.56, 0.0],
                b: [0.02, 0.015, 0.0],
                d: -0.01,
            },
        ),
    ] {
        let c = design_arx(&plant, n, d, 0.9, 1.2, ts).unwrap();
        let np = n + d;
        assert_eq!(c.h.len(), np + 1);
        assert!(
            c.h.iter().sum::<f64>().abs() < 1e-12,
            "H(1) = 0: integral action"
        );
        let mut ctl = PolyLcn::single(c.clone(), (-1e9, 1e9)).unwrap();
        let (r0, r1) = (0.2, 0.35);
        let y = closed_loop(&plant, n, d, &mut ctl, r0, r1, 400);
        // The reference model: (q^{np-2} A_m) y = s0 B' r, on deviations from r0.
        let am = dominant_polynomial(0.9, 1.2, ts).unwrap();
        let mut den = am.to_vec();
        den.extend(std::iter::repeat_n(0.0, np - 2));
        let hist = 64;
        let mut e = vec![0.0; hist + 400];
        for k in hist..hist + 400 {
            // den[0] e_k + den[1] e_{k-1} + ... = s0 sum_l b_l (r1 - r0) [k - 1 - l - (np - 1 - (n - 1)) >= hist]
            let mut v = 0.0;
            for (j, dj) in den.iter().enumerate().skip(1) {
                v -= dj * e[k - j];
            }
            let lag = den.len() - 1 - (n - 1);
            for l in 0..n {
                if k >= hist + lag + l {
                    v += c.s0 * plant.b[l] * (r1 - r0);
                }
            }
            e[k] = v;
        }
        for k in 0..400 {
            assert!(
                (y[k] - r0 - e[hist + k]).abs() < 1e-9,
                "n={n} k={k}: {} vs {}",
                y[k] - r0,
                e[hist + k]
            );
        }
        assert!((y[399] - r1).abs() < 1e-9, "no steady-state error");
        assert!(y.iter().all(|&v| v <= r1 + 1e-9), "xi = 1.2: no overshoot");
    }
}

/// Anti-reset-windup: a reference the clamped input cannot reach, then a reachable one. With
/// the applied input fed back the output settles at the new reference within the designed
/// response; with the computed input the history winds up and the output stays high.
#[test]
fn applied_input_feedback_prevents_windup() {
    let ts = 0.05;
    let plant = ArxUnit {
        a: [-0.93, 0.0, 0.0],
        b: [0.045, 0.0, 0.0],
        d: 0.0,
    };
    let (n, d) = (1, 5);
    let c = design_arx(&plant, n, d, 0.9, 1.2, ts).unwrap();
    let run = |mut ctl: PolyLcn| {
        // y_ss = 0.045 / 0.07 u: u in [0, 1] reaches at most 0.643.
        ctl.settle(0.3 * 0.07 / 0.045, 0.3);
        let len = 1200;
        let (mut u, mut y) = (vec![0.3 * 0.07 / 0.045; len + 8], vec![0.3; len + 8]);
        for k in 8..len + 8 {
            y[k] = plant.b[0] * u[k - d] - plant.a[0] * y[k - 1];
            let r = if k < 408 { 0.9 } else { 0.3 };
            u[k] = ctl.step(0.5, y[k - 1], r);
        }
        // Time (s) from the reference's drop until the output stays within 0.01 of it.
        let last_out = (408..len + 8)
            .rev()
            .find(|&k| (y[k] - 0.3).abs() >= 0.01)
            .unwrap();
        (last_out + 1 - 408) as f64 * ts
    };
    let with = run(PolyLcn::single(c.clone(), (0.0, 1.0)).unwrap());
    let without = run(PolyLcn::single(c, (0.0, 1.0))
        .unwrap()
        .without_anti_windup());
    println!("settling after the drop: {with:.2} s with, {without:.2} s without anti-windup");
    assert!(with < 2.5, "{with}");
    assert!(
        without > with + 2.0,
        "wind-up delays the return: {without} vs {with}"
    );
}
