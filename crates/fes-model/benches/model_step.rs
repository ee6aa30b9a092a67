//! One Local Model Network step (advanced form, the pattern generator's path) for
//! M = 1, 6, 10 units, plus a hand-written f64 baseline (no generics, no enums) of the same
//! M = 10 step to show the generic code costs nothing.
#![allow(clippy::needless_range_loop)] // index loops mirror the equations
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use fes_model::model::local_model::EigLocalUnit;
use fes_model::model::network::Network;
use fes_model::model::scheduling::{Prefilter, Scheduler, SchedulingSpec};
use fes_model::model::validity::ValidityFunctions;
use fes_model::model::{AdvancedForm, SsLocalModel, ThesisForm};
use std::hint::black_box;

const TS: f64 = 1e-3;

fn units(m: usize) -> Vec<SsLocalModel<f64>> {
    (0..m)
        .map(|i| {
            let f = i as f64;
            EigLocalUnit {
                eigenvalues: [-300.0 + 10.0 * f, -30.0 + f],
                eigenvector_angles: [0.2 + 0.1 * f, 1.7 - 0.05 * f],
                b: [1.0, 0.5 + 0.1 * f],
                c: [0.02, 0.01],
                dx: [0.1, -0.05 * f],
                dy: 0.001 * f,
            }
            .to_local_model()
            .unwrap()
        })
        .collect()
}

fn network(m: usize) -> Network<f64> {
    let vf = ValidityFunctions::uniform(m, 0.0, 1.0).unwrap();
    Network::state_space(
        TS,
        7,
        vf,
        Scheduler::new(&SchedulingSpec::default(), TS).unwrap(),
        &units(m),
    )
    .unwrap()
}

/// 1000 pulses-or-not, cycling: bursts of varying frequency so phi sweeps the units.
fn pattern() -> Vec<f64> {
    (0..4096u32)
        .map(|k| {
            if k % (2 + (k / 256) % 30) == 0 {
                1.0
            } else {
                0.0
            }
        })
        .collect()
}

/// The same step written out by hand in f64: clamped uniform quadratic B-splines (span by
/// scan, triangular recursion), interpolation of the 3 active units, delta-domain update,
/// prefilter update. Reference for the cost of the generic code only.
struct Baseline {
    knots: Vec<f64>,
    m: usize,
    units: Vec<SsLocalModel<f64>>,
    pf: Prefilter,
    x: [f64; 2],
    w: [f64; 2],
    phi: f64,
}

impl Baseline {
    #[inline(never)]
    fn step(&mut self, v: f64) -> f64 {
        let t = &self.knots;
        let phi = self.phi.clamp(t[2], t[self.m]);
        let mut s = 2;
        while s + 1 < self.m && t[s + 1] <= phi {
            s += 1;
        }
        let (l1, l2, r1, r2) = (phi - t[s], phi - t[s - 1], t[s + 1] - phi, t[s + 2] - phi);
        // order 2
        let tmp = 1.0 / (r1 + l1);
        let (n0, n1) = (r1 * tmp, l1 * tmp);
        // order 3
        let t0 = n0 / (r1 + l2);
        let a0 = r1 * t0;
        let saved = l2 * t0;
        let t1 = n1 / (r2 + l1);
        let rho = [a0, saved + r2 * t1, l1 * t1];
        let first = s - 2;
        let mut a = [[0.0; 2]; 2];
        let (mut b, mut c, mut dx, mut dy) = ([0.0; 2], [0.0; 2], [0.0; 2], 0.0);
        for (j, r) in rho.iter().enumerate() {
            let u = &self.units[first + j];
            for i in 0..2 {
                for k in 0..2 {
                    a[i][k] += r * u.a[i][k];
                }
                b[i] += r * u.b[i];
                c[i] += r * u.c[i];
                dx[i] += r * u.dx[i];
            }
            dy += r * u.dy;
        }
        let x = self.x;
        let y = c[0] * x[0] + c[1] * x[1] + dy;
        self.x = [
            x[0] + TS * (a[0][0] * x[0] + a[0][1] * x[1] + b[0] * v + dx[0]),
            x[1] + TS * (a[1][0] * x[0] + a[1][1] * x[1] + b[1] * v + dx[1]),
        ];
        self.pf.advance(&mut self.w, v);
        self.phi = self.pf.output(&self.w);
        y
    }
}

fn bench(c: &mut Criterion) {
    let u = pattern();
    let mut g = c.benchmark_group("lmn_step");
    for m in [1usize, 6, 10] {
        let mut adv = AdvancedForm::new(network(m)).unwrap();
        let mut k = 0usize;
        g.bench_with_input(BenchmarkId::new("advanced", m), &m, |bch, _| {
            bch.iter(|| {
                k = (k + 1) & 4095;
                black_box(adv.step(black_box(u[k])))
            })
        });
        let mut th = ThesisForm::new(network(m)).unwrap();
        let mut k = 0usize;
        g.bench_with_input(BenchmarkId::new("thesis", m), &m, |bch, _| {
            bch.iter(|| {
                k = (k + 1) & 4095;
                black_box(th.step(black_box(u[k])))
            })
        });
    }
    let net = network(10);
    let mut base = Baseline {
        knots: net.validity().knots().to_vec(),
        m: 10,
        units: units(10),
        pf: Prefilter::thesis(TS).unwrap(),
        x: [0.0; 2],
        w: [0.0; 2],
        phi: 0.0,
    };
    let mut st = net.rest_state().unwrap();
    base.x = st.ss_state();
    // Same arithmetic: the baseline reproduces the generic step (checked before timing).
    {
        let (mut s2, mut b2) = (
            st,
            Baseline {
                knots: base.knots.clone(),
                units: base.units.clone(),
                ..base
            },
        );
        for &v in &u {
            let (a, b) = (net.step(&mut s2, v), b2.step(v));
            assert!(
                (a - b).abs() <= 1e-12 * (1.0 + a.abs()),
                "baseline differs: {a} vs {b}"
            );
        }
    }
    let mut k = 0usize;
    g.bench_function("core_generic/10", |bch| {
        bch.iter(|| {
            k = (k + 1) & 4095;
            black_box(net.step(&mut st, black_box(u[k])))
        })
    });
    let mut k = 0usize;
    g.bench_function("hand_written_f64/10", |bch| {
        bch.iter(|| {
            k = (k + 1) & 4095;
            black_box(base.step(black_box(u[k])))
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
