//! Identification cost on the sim-muscle `fast` data set (30 training records of 590 ms):
//! one f64 free run of the training set, one exact Jacobian (normal equations J'J, J'r)
//! of a 4- and a 6-unit common-eigenvector network, and the whole simulation-mode fit.
//!
//! The data set is read from `$FES_FAST_DATA` (default `target/ident-data/fast`); record it
//! first with
//! `cargo run -p sim-muscle --release -- record --preset fast --seed 1 --out target/ident-data/fast`.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use criterion::{Criterion, criterion_group, criterion_main};
use fes_ident::ident::problem::{Horizon, ModelData, Problem, ThetaMap};
use fes_ident::ident::{Hooks, IdentOptions, RecordSet, identify};
use fes_model::model::params::ParamLayout;
use fes_model::model::simulate::simulate;
use std::hint::black_box;
use std::path::PathBuf;

fn records() -> RecordSet {
    let dir = std::env::var_os("FES_FAST_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/../../target/ident-data/fast"
            ))
        });
    RecordSet::load(&dir).unwrap_or_else(|e| {
        panic!(
            "{e}\nrecord the data set first: cargo run -p sim-muscle --release -- record --preset fast --seed 1 --out {}",
            dir.display()
        )
    })
}

fn bench(c: &mut Criterion) {
    let recs = records();
    let data = ModelData::new(&recs.train, 1).expect("down-sampling at factor 1");
    let mut g = c.benchmark_group("ident");
    g.sample_size(10);
    for m in [4usize, 6] {
        let opts = IdentOptions {
            units: m,
            max_iter: 0,
            ..IdentOptions::default()
        };
        // The start of the fit (linear fit copied into every unit) as the evaluation point.
        let start = identify(&recs, &opts, &Hooks::silent()).expect("start");
        let lmn = start.lmn;
        let layout = ParamLayout::new(&lmn);
        let theta = layout.theta(&lmn).expect("theta");
        let net = lmn.network().expect("network");
        if m == 4 {
            g.bench_function("free_run_training_set", |b| {
                b.iter(|| {
                    for r in &data.records {
                        let mut y = vec![0.0; r.u.len()];
                        simulate(&net, &r.u, &mut y).expect("simulate");
                        black_box(&y);
                    }
                })
            });
        }
        let problem = Problem::new(
            ThetaMap {
                template: &lmn,
                layout: &layout,
            },
            &data,
            Horizon::Simulation,
        );
        let cols: Vec<usize> = (0..theta.len()).collect();
        g.bench_function(format!("jacobian_ss_eig_common_m{m}"), |b| {
            b.iter(|| black_box(problem.normal(&theta, &cols).expect("normal")))
        });
        let opts = IdentOptions {
            units: m,
            ..IdentOptions::default()
        };
        g.bench_function(format!("fit_ss_eig_common_m{m}"), |b| {
            b.iter(|| black_box(identify(&recs, &opts, &Hooks::silent()).expect("fit")))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
