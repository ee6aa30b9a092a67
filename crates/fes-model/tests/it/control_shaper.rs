//! The pulse shaper (thesis 6.5.2, eq. 6.7-6.8): energy bookkeeping, minimum gap and the
//! single-pulse-after-saturation safety property, checked against sums kept independently by the test.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_model::control::shaper::{PulseShaper, ShaperConfig, ShaperSum};
use proptest::prelude::*;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[test]
fn pulse_count_tracks_integral_of_u_cont_over_a_million_samples() {
    // eq. (6.7) with eta = 1 and the thesis's restart: each pulse spends eta plus the
    // overshoot of the sample that fired it (less than that sample's u), so
    // sum u / (eta + u_max) - 1 < pulses <= sum u / eta, and the balance with the dropped
    // remainders is exact.
    let mut rng = ChaCha8Rng::seed_from_u64(0x6_5_2);
    let mut s = PulseShaper::new(ShaperConfig::default()).unwrap();
    let mut sum = 0.0f64;
    let mut pulses = 0u64;
    let mut dropped = 0.0f64;
    for _ in 0..1_000_000 {
        let u: f64 = rng.random_range(0.0..0.5);
        let e_before = s.energy();
        sum += u;
        if s.step(u) {
            pulses += 1;
            let over = e_before + u - 1.0;
            assert!((0.0..u).contains(&over), "overshoot {over} for u {u}");
            dropped += over;
        }
    }
    let p = pulses as f64;
    assert!(
        p <= sum && p > sum / 1.5 - 1.0,
        "{pulses} pulses for sum u {sum}"
    );
    assert_eq!(
        s.stats().discarded,
        0.0,
        "u <= 0.5 never saturates the 2-sample IPI"
    );
    assert_eq!(s.stats().pulses, pulses);
    assert!((s.stats().dropped - dropped).abs() <= 1e-6 * dropped);
    assert!((sum - (p + s.energy() + s.stats().dropped)).abs() <= 1e-9 * sum);
}

#[test]
fn no_catch_up_burst_after_saturation() {
    for (eta, min_gap, e_max) in [(1.0, 1, 2.0), (1.0, 3, 5.5), (0.5, 2, 0.5)] {
        let cfg = ShaperConfig {
            eta,
            min_gap,
            e_max,
            ..ShaperConfig::default()
        };
        let mut s = PulseShaper::new(cfg).unwrap();
        for _ in 0..1000 {
            s.step(50.0); // saturated: the gap limits the rate
        }
        let after = (0..1000).filter(|_| s.step(0.0)).count();
        assert!(after <= 1, "{cfg:?}: {after} pulses after saturation");
        assert!(s.stats().discarded > 0.0);
    }
}

fn arb_config() -> impl Strategy<Value = ShaperConfig> {
    (
        0.1..5.0f64,
        1u32..6,
        1.0..4.0f64,
        prop_oneof![Just(ShaperSum::Clamped), Just(ShaperSum::Signed)],
    )
        .prop_map(|(eta, min_gap, f, sum)| ShaperConfig {
            eta,
            min_gap,
            e_max: eta * f,
            sum,
            e_min: None,
        })
}

/// Inputs spanning many orders of magnitude, including huge ones; negative ones too (the
/// signed sum takes them, the clamped one counts them as zero).
fn arb_input() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => 0.0..1.0f64,
        2 => 0.0..10.0f64,
        1 => 0.0..1e9f64,
        1 => Just(0.0),
        1 => (0.0..1.0f64).prop_map(|x| x * 1e15),
        2 => -2.0..0.0f64,
    ]
}

proptest! {
    #[test]
    fn energy_is_conserved_gap_holds_and_energy_stays_bounded(
        cfg in arb_config(),
        inputs in prop::collection::vec(arb_input(), 1..2000),
    ) {
        let mut s = PulseShaper::new(cfg).unwrap();
        let mut sum = 0.0f64;
        let mut low = 0.0f64;
        let mut last_pulse: Option<usize> = None;
        for (k, &u) in inputs.iter().enumerate() {
            let u = if cfg.sum == ShaperSum::Signed { u } else { u.max(0.0) };
            sum += u;
            low += u.min(0.0);
            if s.step(u) {
                if let Some(lp) = last_pulse {
                    prop_assert!(k - lp > cfg.min_gap as usize,
                        "pulses at {} and {} closer than gap {}", lp, k, cfg.min_gap);
                }
                last_pulse = Some(k);
            }
            let e = s.energy();
            // Below zero E goes only by the run of negative inputs since it last was >= 0.
            let floor = if cfg.sum == ShaperSum::Signed { low.min(0.0) - 1e-9 } else { 0.0 };
            prop_assert!(e <= cfg.e_max && e >= floor, "E = {} outside [{}, {}]", e, floor, cfg.e_max);
            if e >= 0.0 {
                low = 0.0;
            }
            let st = s.stats();
            let scale = sum.abs().max(1.0).max(-floor);
            let accounted = st.pulses as f64 * cfg.eta + e + st.dropped + st.discarded;
            prop_assert!((sum - accounted).abs() <= 1e-9 * scale,
                "sum u = {} but pulses*eta + E + dropped + discarded = {}", sum, accounted);
        }
    }

    #[test]
    fn negative_and_non_finite_inputs_count_as_zero(
        inputs in prop::collection::vec(
            prop_oneof![
                3 => 0.0..2.0f64,
                1 => -1e6..0.0f64,
                1 => Just(f64::NAN),
                1 => Just(f64::INFINITY),
                1 => Just(f64::NEG_INFINITY),
            ],
            1..500,
        )
    ) {
        let clamped = ShaperConfig { sum: ShaperSum::Clamped, ..ShaperConfig::default() };
        let mut s = PulseShaper::new(clamped).unwrap();
        let mut reference = PulseShaper::new(clamped).unwrap();
        let mut bad = 0u64;
        for &u in &inputs {
            let clean = if u.is_finite() && u >= 0.0 { u } else { bad += 1; 0.0 };
            prop_assert_eq!(s.step(u), reference.step(clean));
        }
        prop_assert_eq!(s.stats().rejected_inputs, bad);
        prop_assert_eq!(s.energy(), reference.energy());
    }
}
