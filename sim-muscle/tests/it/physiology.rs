//! The presets show what the thesis's muscles show (4.2.3, 5.4.3, 6.3, 6.4): the fast
//! muscle's catch-like effect, the slow muscle's FTIpP <= 1, saturating force-frequency
//! curves, and, with the fatigue extension, a steady loss of force.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_ident::analysis::osp::ftipp;
use sim_muscle::ding::FatigueParams;
use sim_muscle::metrics::response_fti;
use sim_muscle::muscle::{Muscle, MuscleConfig};
use sim_muscle::pattern::{constant_train, from_samples};
use sim_muscle::plant::{MusclePlant, Pulse};
use sim_muscle::preset::Preset;
use sim_muscle::simulate::simulate;

/// Window for FTIs: 2 s, long enough for both presets' force to return to rest
/// (slowest decay tau1 = 90 ms: exp(-1 s / 90 ms) < 1e-4) after the last pulse at <= 1 s.
const WINDOW: usize = 2000;

fn muscle(preset: Preset) -> Muscle {
    Muscle::new(MuscleConfig::preset(preset)).expect("preset is valid")
}

fn train(hz: f64, len_ms: usize) -> Vec<usize> {
    constant_train(hz, 0, len_ms, 1e-3).expect("valid train")
}

/// Fast: a 5 ms doublet gives more than twice the twitch's FTI, and an initial doublet
/// adds more than one twitch's FTI to a 1 s, 12.5 Hz train.
#[test]
fn fast_muscle_has_catch_like_effect() {
    let mut m = muscle(Preset::Fast);
    let fti1 = response_fti(&mut m, &[0], WINDOW);
    let doublet = response_fti(&mut m, &[0, 5], WINDOW);
    println!(
        "fast: 5 ms doublet FTI = {:.3} x twitch FTI",
        doublet / fti1
    );
    assert!(doublet > 2.0 * fti1);
    let plain = train(12.5, 1000);
    let mut led = plain.clone();
    led.insert(1, 5);
    let gain = (response_fti(&mut m, &led, WINDOW) - response_fti(&mut m, &plain, WINDOW)) / fti1;
    println!("fast: initial doublet adds {gain:.3} twitch FTIs to a 12.5 Hz train");
    assert!(gain > 1.0);
    // Fig. 6.3(a) area A: a short high-frequency burst has FTIpP > 1.
    let burst = ftipp(response_fti(&mut m, &[0, 5, 10], WINDOW), fti1, 3).expect("ftipp");
    assert!(burst > 1.0, "triplet FTIpP {burst}");
}

/// Slow: every doublet (IPI 2..100 ms) and every constant-frequency train of 1..10
/// pulses (IPI 2..100 ms, thesis 6.3) has FTIpP <= 1. (With r0 = 1 and tau2 = 0 the
/// force-time integral is tau1 A times the integral of CN/(Km + CN), which is
/// sub-additive, so this holds for every pattern.)
#[test]
fn slow_muscle_ftipp_never_exceeds_one() {
    let mut m = muscle(Preset::Slow);
    let fti1 = response_fti(&mut m, &[0], WINDOW);
    let mut worst: f64 = 0.0;
    for ipi in 2..=100 {
        let p = ftipp(response_fti(&mut m, &[0, ipi], WINDOW), fti1, 2).expect("ftipp");
        assert!(p <= 1.0, "doublet IPI {ipi} ms: FTIpP {p}");
        worst = worst.max(p);
    }
    println!("slow: largest doublet FTIpP (IPI 2..100 ms) = {worst:.4}");
    for pulses in 2..=10 {
        for ipi in (2..=100).step_by(7) {
            let times: Vec<usize> = (0..pulses).map(|j| j * ipi).collect();
            let p = ftipp(response_fti(&mut m, &times, WINDOW), fti1, pulses).expect("ftipp");
            assert!(p <= 1.0, "{pulses} pulses at {ipi} ms: FTIpP {p}");
        }
    }
}

/// Force-frequency curve: mean force over 500..1000 ms of a 1 s train ("after the
/// rise", as thesis Fig. 5.26), 1..100 Hz. It rises strictly at every 1 Hz step and
/// saturates: the gain over the top 10 Hz (90 -> 100 Hz) is at most a third of the
/// largest gain over any 10 Hz band.
///
/// The thesis's two muscles only: `thesis-fast` stands in for the identified dynamics of
/// Table 5.3 (tau_c = 3 ms), and its curve still rises almost linearly at 90-100 Hz
/// (docs/sim-muscle.md).
#[test]
fn force_frequency_curves_rise_and_saturate() {
    for preset in [Preset::Fast, Preset::Slow] {
        let mut m = muscle(preset);
        let curve: Vec<f64> = (1..=100)
            .map(|hz| {
                m.reset();
                let f = simulate(
                    &mut m,
                    &from_samples(&train(hz as f64, 1000), 1000),
                    Pulse::SUPRAMAXIMAL,
                );
                f[500..].iter().sum::<f64>() / 500.0
            })
            .collect();
        for hz in 2..=100 {
            assert!(
                curve[hz - 1] > curve[hz - 2],
                "{preset}: F({hz} Hz) <= F({} Hz)",
                hz - 1
            );
        }
        let band = |lo: usize| curve[lo + 9] - curve[lo - 1];
        let steepest = (1..=90).map(band).fold(0.0, f64::max);
        let top = band(90);
        println!(
            "{preset}: F(100 Hz) = {:.1} N; top-band gain / steepest = {:.3}",
            curve[99],
            top / steepest
        );
        assert!(
            top <= steepest / 3.0,
            "{preset}: not saturating ({top} vs {steepest})"
        );
    }
}

/// Fatigue (Ding 2003, coefficients carried over per preset): 1 s on at 33 Hz / 1 s off
/// for 60 s. Every train's peak is below the previous one's, and the last is at most
/// 80 % of the first.
///
/// The thesis's two muscles only: at 33 Hz `thesis-fast` (tau_c = 3 ms) is unfused, so the
/// slower force decay of fatigue first raises its peaks, and they fall by 6 % in 60 s
/// (docs/sim-muscle.md).
#[test]
fn fatigue_reduces_force_steadily() {
    for preset in [Preset::Fast, Preset::Slow] {
        let mut cfg = MuscleConfig::preset(preset);
        cfg.fatigue = Some(FatigueParams::for_muscle(&cfg.ding));
        let mut m = Muscle::new(cfg).expect("valid");
        let cycle = from_samples(&train(33.0, 1000), 2000);
        let mut peaks = Vec::new();
        for _ in 0..30 {
            let f = simulate(&mut m, &cycle, Pulse::SUPRAMAXIMAL);
            m.step(None); // simulate advanced 1999 samples; keep the cycle at 2 s
            peaks.push(f.into_iter().fold(0.0, f64::max));
        }
        println!(
            "{preset}: peak {:.1} N -> {:.1} N over 60 s",
            peaks[0], peaks[29]
        );
        assert!(peaks.windows(2).all(|w| w[1] < w[0]), "{preset}: {peaks:?}");
        assert!(peaks[29] <= 0.8 * peaks[0]);
    }
}
