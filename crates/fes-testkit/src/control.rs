//! The control tests' fixture (feature `control`): muscle-like Local Model Networks built
//! in code, for the tests, benches and examples of fes-model, fes-ident, rt-core and the
//! workbench.
//!
//! fes-model's own tests, which compile into its library's test binary, include this file
//! by path instead (`crates/fes-model/tests/it/main.rs`): linked, it would give them a
//! second fes-model whose types are not theirs. So it names fes-model only as `fes_model`.

use fes_model::control::lcn_design::UnitSpec;
use fes_model::model::lmn::{Lmn, LocalModelSet, Provenance};
use fes_model::model::local_model::EigCommonUnit;
use fes_model::model::{SchedulingSpec, ValidityFunctions};

/// Sampling period of every fixture, s.
pub const TS: f64 = 1e-3;
/// Input delay of every fixture, samples (thesis: 7 ms).
pub const DELAY: usize = 7;

/// A fast-muscle-like LMN with `m` units on phi in [0, 1], common eigenvectors (V = I),
/// the thesis's scheduling prefilter and delay. Unit i (centre phi_i = i/(m-1)) has a
/// twitch `k (e^{e1 t} - e^{e2 t})` with e1 = -(25 + 15 phi), e2 = -(150 + 60 phi) and a
/// steady-state gain G = 10 + 15 phi (force per unit pulse rate), i.e. mean force 0.2 at
/// 20 Hz, 0.4-0.7 at 30-40 Hz. No offsets (rest force 0).
pub fn fast_muscle(m: usize) -> Lmn {
    fast_muscle_with_offsets(m, false, false)
}

/// [`fast_muscle`] with small offsets: `dx` adds 0.01 of rest force through the state,
/// `dy` 0.01-0.02 directly.
pub fn fast_muscle_with_offsets(m: usize, dx: bool, dy: bool) -> Lmn {
    let units = (0..m)
        .map(|i| {
            let phi = if m > 1 {
                i as f64 / (m - 1) as f64
            } else {
                0.5
            };
            let e1 = -(25.0 + 15.0 * phi);
            let e2 = -(150.0 + 60.0 * phi);
            let gain = 10.0 + 15.0 * phi;
            // G = -c'A^-1 b = k (1/|e1| - 1/|e2|) with b = (1, 1), c = (k, -k).
            let k = gain / (1.0 / -e1 - 1.0 / -e2);
            EigCommonUnit {
                eigenvalues: [e1, e2],
                b: [1.0, 1.0],
                c: [k, -k],
                // Offsets: +0.01 of rest force through dx (x1 = 0.01/k), plus dy.
                dx: if dx { [0.01 * -e1 / k, 0.0] } else { [0.0; 2] },
                dy: if dy { 0.02 - 0.01 * phi } else { 0.0 },
            }
        })
        .collect();
    Lmn {
        ts: TS,
        delay: DELAY,
        scheduling: SchedulingSpec::default(),
        validity: ValidityFunctions::uniform(m, 0.0, 1.0).expect("valid validity functions"),
        local: LocalModelSet::SsEigCommon {
            units,
            reference_unit: 0,
        },
        zero_offsets: !(dx || dy),
        force_scale_n: 1.0,
        provenance: Provenance::default(),
    }
}

/// Thesis Table 6.1 rise times (fast muscle), repeated or cut to `m` units.
pub fn table_6_1_specs(m: usize) -> Vec<UnitSpec> {
    const TR: [f64; 6] = [0.100, 0.030, 0.030, 0.010, 0.020, 0.030];
    (0..m).map(|i| UnitSpec::thesis(TR[i % 6], TS)).collect()
}
