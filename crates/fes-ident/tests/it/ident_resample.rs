//! Pulse-preserving down-sampling (thesis 5.2.2) and the interpolation back to the base
//! period, checked on random pulse trains.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_ident::ident::resample::{
    MAX_PULSE_SHIFT, ResampleError, coarse_len, downsample_output, downsample_pulses, interpolate,
};
use proptest::prelude::*;

fn pulse_train() -> impl Strategy<Value = Vec<f64>> {
    // Up to 600 samples with random IPIs >= 1 sample (the thesis's 1..70 ms).
    prop::collection::vec(1usize..70, 0..40).prop_map(|ipis| {
        let mut u = vec![0.0; 600];
        let mut k = 3;
        for ipi in ipis {
            if k >= u.len() {
                break;
            }
            u[k] = 1.0;
            k += ipi;
        }
        u
    })
}

proptest! {
    /// The pulse count is kept, every coarse sample holds at most one pulse, and no pulse
    /// moves further than its nearest coarse sample plus MAX_PULSE_SHIFT (a refusal names
    /// the pulse instead).
    #[test]
    fn pulses_are_kept_and_moved_boundedly(u in pulse_train(), factor in 1usize..=10) {
        match downsample_pulses(&u, factor) {
            Ok((c, shift)) => {
                let n: usize = u.iter().filter(|v| **v != 0.0).count();
                prop_assert_eq!(c.len(), coarse_len(u.len(), factor));
                prop_assert_eq!(c.iter().filter(|v| **v == 1.0).count(), n);
                prop_assert!(c.iter().all(|v| *v == 0.0 || *v == 1.0));
                prop_assert_eq!(shift.pulses, n);
                let bound = factor / 2 + MAX_PULSE_SHIFT * factor + factor;
                prop_assert!(shift.max_displacement <= bound, "{} > {}", shift.max_displacement, bound);
                if factor == 1 {
                    prop_assert_eq!(&c, &u);
                }
            }
            Err(ResampleError::TooDense { sample, .. }) => prop_assert!(u[sample] == 1.0),
            Err(e) => prop_assert!(false, "{e}"),
        }
    }

    /// Isolated pulses (IPI >= the coarse period, none after the last coarse sample) land on
    /// their nearest coarse sample: the displacement is at most half a coarse period.
    #[test]
    fn sparse_pulses_move_at_most_half_a_period(gaps in prop::collection::vec(10usize..40, 1..12)) {
        let mut u = vec![0.0; 520];
        let mut k = 0;
        for g in gaps {
            k += g;
            if k <= 510 {
                u[k] = 1.0;
            }
        }
        let (_, s) = downsample_pulses(&u, 10).expect("sparse");
        prop_assert_eq!(s.collisions, 0);
        prop_assert!(s.max_displacement <= 5);
    }

    /// Filtering then interpolating keeps a constant exactly and a straight line exactly away
    /// from the record ends (the normalised symmetric triangle reproduces degree-1 data).
    #[test]
    fn output_resampling_reproduces_lines(a in -1.0f64..1.0, b in -0.01f64..0.01, factor in 1usize..=10, n in 50usize..300) {
        let y: Vec<f64> = (0..n).map(|k| a + b * k as f64).collect();
        let c = downsample_output(&y, factor);
        let mut back = vec![0.0; n];
        interpolate(&c, factor, &mut back);
        let last = (c.len() - 1) * factor;
        for k in factor..last.saturating_sub(factor) {
            prop_assert!((back[k] - y[k]).abs() < 1e-12, "k {} of {}", k, n);
        }
        let flat = downsample_output(&vec![a; n], factor);
        prop_assert!(flat.iter().all(|v| (v - a).abs() < 1e-14));
    }
}
