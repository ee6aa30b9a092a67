//! The network step never touches the heap: a counting global allocator observes zero
//! allocations (and zero bytes) over 100 000 steps of an M = 10 network, in both forms.
#![allow(clippy::needless_range_loop)] // index loops mirror the equations
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use super::alloc_count::measure;
use fes_model::model::local_model::EigLocalUnit;
use fes_model::model::network::Network;
use fes_model::model::scheduling::{Scheduler, SchedulingSpec};
use fes_model::model::validity::ValidityFunctions;
use fes_model::model::{AdvancedForm, ThesisForm};

fn network(m: usize, sched: SchedulingSpec) -> Network<f64> {
    let units: Vec<_> = (0..m)
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
        .collect();
    let vf = ValidityFunctions::uniform(m, 0.0, 1.0).unwrap();
    Network::state_space(1e-3, 7, vf, Scheduler::new(&sched, 1e-3).unwrap(), &units).unwrap()
}

#[test]
fn network_steps_do_not_allocate() {
    for sched in [SchedulingSpec::default(), SchedulingSpec::Output] {
        let net = network(10, sched);
        let mut thesis = ThesisForm::new(net).unwrap();
        let mut adv = AdvancedForm::new(net).unwrap();
        let mut st = net.rest_state().unwrap();
        let mut acc = 0.0;
        let c = measure(|| {
            for k in 0..100_000u32 {
                // A pattern that sweeps phi across all units (bursts of rising frequency).
                let period = 2 + (k / 1000) % 40;
                let u = if k % period == 0 { 1.0 } else { 0.0 };
                acc += thesis.step(u);
                let act = adv.activation();
                acc += adv.step_with_activation(&act, u).y;
                acc += net.step(&mut st, u);
            }
        });
        assert!(acc.is_finite());
        assert_eq!(
            (c.allocations, c.bytes),
            (0, 0),
            "{sched:?}: {} allocations ({} bytes) in 100 000 steps",
            c.allocations,
            c.bytes
        );
        // The counter is live: a heap allocation is seen.
        let v = measure(|| {
            std::hint::black_box(vec![1u8; 16]);
        });
        assert!(v.allocations >= 1);
    }
}
