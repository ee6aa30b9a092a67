//! The four identification experiments of thesis App. E.2, run on the simulated plant,
//! filtered and normalised as the thesis did.
//!
//! - **Fast pseudo-random** (Fig. E.2a), 3 records of 50 s: the voltage jumps fast (every
//!   1-3 samples, +-1.5 V) around slower random levels (every 2-5 s), the angle takes a
//!   random level every 2-6 s.
//! - **Slow pseudo-random** (Fig. E.2b), 2 records of 50 s: a random voltage level every
//!   0.5-3 s, the angle as above.
//! - **Test-angle** (Fig. E.3a), 2 records of 50 s: the voltage constant for 25 s at a time,
//!   the angle random every 2-5 s.
//! - **Test-voltage** (Fig. E.3b), 2 records of 250 s: the angle held at 20, 40, 60, 90,
//!   120 deg for 50 s each, the same random voltage sequence (a level every 0.5-3 s) at
//!   every angle.
//!
//! Each record starts with the plant settled at its first inputs (the rig ran
//! continuously). The measured output is smoothed by the 2nd-order FIR mean filter
//! y_f\[k\] = (y\[k\] + y\[k-1\] + y\[k-2\]) / 3 and all signals are mapped to \[0, 1\] by one
//! fixed [`Normalisation`] for all records (alpha: 20-120 deg, u: 0-10 V, y: ambient to
//! the steady state at 20 deg and full voltage), so the model's scaling does not depend on
//! which record it is used on.

use crate::plant::{
    HeatParamError, HeatParams, HeatPlant, MAX_ANGLE_DEG, MIN_ANGLE_DEG, TEST_ANGLES_DEG,
};
use fes_dataset::Split;
use fes_dataset::signals::{Channel, SignalHeader, SignalRecord, SignalSet};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The four experiments of E.2.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Experiment {
    /// Fast pseudo-random data (Fig. E.2a).
    FastRandom,
    /// Slow pseudo-random data (Fig. E.2b).
    SlowRandom,
    /// Test-angle data (Fig. E.3a).
    TestAngle,
    /// Test-voltage data (Fig. E.3b).
    TestVoltage,
}

impl Experiment {
    /// The four, in the thesis's order.
    pub const ALL: [Experiment; 4] = [
        Self::FastRandom,
        Self::SlowRandom,
        Self::TestAngle,
        Self::TestVoltage,
    ];

    /// Name used in record names and data-set `kind`s.
    pub fn name(self) -> &'static str {
        match self {
            Self::FastRandom => "fast-random",
            Self::SlowRandom => "slow-random",
            Self::TestAngle => "test-angle",
            Self::TestVoltage => "test-voltage",
        }
    }

    /// Records recorded (E.2: 3, 2, 2, 2).
    pub fn records(self) -> usize {
        match self {
            Self::FastRandom => 3,
            _ => 2,
        }
    }

    /// Length of one record, s (E.2: 50 s; test-voltage 5 x 50 s).
    pub fn duration_s(self) -> f64 {
        match self {
            Self::TestVoltage => 250.0,
            _ => 50.0,
        }
    }
}

/// The fixed map of every signal to \[0, 1\] (E.2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalisation {
    /// Angle range, deg.
    pub alpha_deg: (f64, f64),
    /// Voltage range, V.
    pub u_v: (f64, f64),
    /// Output range, deg C.
    pub y_c: (f64, f64),
}

impl Normalisation {
    /// The plant's ranges: alpha 20-120 deg, u 0-u_max, y from ambient to the steady
    /// state at 20 deg and full voltage.
    pub fn of(p: &HeatParams) -> Self {
        Self {
            alpha_deg: (MIN_ANGLE_DEG, MAX_ANGLE_DEG),
            u_v: (0.0, p.u_max_v),
            y_c: (p.ambient_c, p.steady_output(MIN_ANGLE_DEG, p.u_max_v)),
        }
    }

    fn map(r: (f64, f64), v: f64) -> f64 {
        (v - r.0) / (r.1 - r.0)
    }

    fn unmap(r: (f64, f64), v: f64) -> f64 {
        r.0 + v * (r.1 - r.0)
    }

    /// Normalised angle.
    pub fn alpha(&self, deg: f64) -> f64 {
        Self::map(self.alpha_deg, deg)
    }
    /// Angle in degrees of a normalised angle.
    pub fn alpha_deg(&self, n: f64) -> f64 {
        Self::unmap(self.alpha_deg, n)
    }
    /// Normalised voltage.
    pub fn u(&self, v: f64) -> f64 {
        Self::map(self.u_v, v)
    }
    /// Voltage of a normalised voltage.
    pub fn u_v(&self, n: f64) -> f64 {
        Self::unmap(self.u_v, n)
    }
    /// Normalised output.
    pub fn y(&self, c: f64) -> f64 {
        Self::map(self.y_c, c)
    }
}

/// One record, normalised: the inputs as applied and the filtered measured output.
#[derive(Debug, Clone, PartialEq)]
pub struct HeatRecord {
    /// Record name, e.g. `fast-random-2`.
    pub name: String,
    /// Which experiment.
    pub experiment: Experiment,
    /// Valve angle, normalised.
    pub alpha: Vec<f64>,
    /// Heater voltage, normalised.
    pub u: Vec<f64>,
    /// Outlet temperature, mean-filtered and normalised.
    pub y: Vec<f64>,
}

/// The 2nd-order FIR mean filter of E.2: y_f\[k\] = (y\[k\] + y\[k-1\] + y\[k-2\]) / 3, the
/// first two samples averaged over the samples there are.
pub fn mean_filter(y: &[f64]) -> Vec<f64> {
    (0..y.len())
        .map(|k| {
            let lo = k.saturating_sub(2);
            y[lo..=k].iter().sum::<f64>() / (k - lo + 1) as f64
        })
        .collect()
}

/// A held random level: a new value from `level` every `hold` samples (both drawn).
fn held(
    rng: &mut ChaCha8Rng,
    n: usize,
    hold: (usize, usize),
    mut level: impl FnMut(&mut ChaCha8Rng) -> f64,
) -> Vec<f64> {
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let v = level(rng);
        let len = rng.random_range(hold.0..=hold.1);
        out.extend(std::iter::repeat_n(v, len.min(n - out.len())));
    }
    out
}

/// The inputs (alpha in deg, u in V) of record `index` of an experiment.
pub fn inputs(p: &HeatParams, e: Experiment, rng: &mut ChaCha8Rng) -> (Vec<f64>, Vec<f64>) {
    let per_s = 1.0 / p.ts_s;
    let n = (e.duration_s() * per_s).round() as usize;
    let s = |sec: f64| ((sec * per_s).round() as usize).max(1);
    let umax = p.u_max_v;
    let angle = |rng: &mut ChaCha8Rng| rng.random_range(MIN_ANGLE_DEG..=MAX_ANGLE_DEG);
    match e {
        Experiment::FastRandom => {
            let alpha = held(rng, n, (s(2.0), s(6.0)), angle);
            let slow = held(rng, n, (s(2.0), s(5.0)), |r| {
                r.random_range(1.5..=umax - 1.5)
            });
            let fast = held(rng, n, (1, 3), |r| r.random_range(-1.5..=1.5));
            let u = slow
                .iter()
                .zip(&fast)
                .map(|(a, b)| (a + b).clamp(0.0, umax))
                .collect();
            (alpha, u)
        }
        Experiment::SlowRandom => {
            let alpha = held(rng, n, (s(2.0), s(6.0)), angle);
            let u = held(rng, n, (s(0.5), s(3.0)), |r| r.random_range(0.0..=umax));
            (alpha, u)
        }
        Experiment::TestAngle => {
            let alpha = held(rng, n, (s(2.0), s(5.0)), angle);
            let u = held(rng, n, (s(25.0), s(25.0)), |r| r.random_range(3.0..=umax));
            (alpha, u)
        }
        Experiment::TestVoltage => {
            let per = n / TEST_ANGLES_DEG.len();
            let seq = held(rng, per, (s(0.5), s(3.0)), |r| r.random_range(0.0..=umax));
            let alpha = TEST_ANGLES_DEG
                .iter()
                .flat_map(|&a| std::iter::repeat_n(a, per))
                .collect();
            let u = (0..TEST_ANGLES_DEG.len())
                .flat_map(|_| seq.iter().copied())
                .collect();
            (alpha, u)
        }
    }
}

/// Runs the plant over given inputs (alpha in deg, u in V) from its steady state at the
/// first inputs; returns the raw measured outputs, deg C.
pub fn run(plant: &mut HeatPlant, alpha_deg: &[f64], u_v: &[f64]) -> Vec<f64> {
    if let (Some(&a), Some(&u)) = (alpha_deg.first(), u_v.first()) {
        plant.settle(a, u);
    }
    alpha_deg
        .iter()
        .zip(u_v)
        .map(|(&a, &u)| plant.step(a, u))
        .collect()
}

/// Every record of the four experiments (E.2), in the order fast 1-3, slow 1-2,
/// test-angle 1-2, test-voltage 1-2, from `seed` (inputs and noise).
pub fn all_records(p: &HeatParams, seed: u64) -> Result<Vec<HeatRecord>, HeatParamError> {
    let norm = Normalisation::of(p);
    let mut out = Vec::new();
    for (ei, e) in Experiment::ALL.into_iter().enumerate() {
        for r in 0..e.records() {
            let stream = (ei * 16 + r) as u64;
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(stream);
            let (alpha, u) = inputs(p, e, &mut rng);
            let mut plant =
                HeatPlant::new(*p, seed.wrapping_mul(1000).wrapping_add(stream), alpha[0])?;
            let y = mean_filter(&run(&mut plant, &alpha, &u));
            out.push(HeatRecord {
                name: format!("{}-{}", e.name(), r + 1),
                experiment: e,
                alpha: alpha.iter().map(|&a| norm.alpha(a)).collect(),
                u: u.iter().map(|&v| norm.u(v)).collect(),
                y: y.iter().map(|&c| norm.y(c)).collect(),
            });
        }
    }
    Ok(out)
}

/// The train / test split of [`all_records`]'s order: the first record of each
/// experiment (and the second fast one) train, the others test, so that both halves see
/// every kind of excitation.
pub fn split() -> (Vec<usize>, Vec<usize>) {
    (vec![0, 1, 3, 5, 7], vec![2, 4, 6, 8])
}

/// Every record of [`all_records`] as a `fes-dataset/2` data set: inputs `alpha` and `u`,
/// output `y`, all normalised (each channel's `range` gives the physical values of 0 and 1),
/// Ts = 50 ms, the split of [`split`]; the plant's parameters and the seed in the header.
pub fn dataset(p: &HeatParams, seed: u64) -> Result<SignalSet, HeatParamError> {
    let norm = Normalisation::of(p);
    let records = all_records(p, seed)?
        .into_iter()
        .map(|r| SignalRecord {
            file: format!("{}.csv", r.name),
            kind: r.experiment.name().into(),
            t0_s: 0.0,
            inputs: vec![r.alpha, r.u],
            outputs: vec![r.y],
        })
        .collect();
    let (train, test) = split();
    let parameters = [
        ("ambient_c", p.ambient_c),
        ("u_max_v", p.u_max_v),
        ("gain_k", p.gain_k),
        ("flow_ratio", p.flow_ratio),
        ("tau_heater_s", p.tau_heater_s),
        ("conduction_delay_s", p.conduction_delay_s),
        ("transport_s", p.transport_s),
        ("valve_beta_deg", p.valve_beta_deg),
        ("sensor_tau_s", p.sensor_tau_s),
        ("noise_std_k", p.noise_std_k),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    Ok(SignalSet {
        header: SignalHeader {
            source: format!("sim-heat {}", env!("CARGO_PKG_VERSION")),
            seed: Some(seed),
            parameters,
            protocol: serde_json::json!({
                "experiments": "thesis App. E.2: fast / slow pseudo-random, test-angle, test-voltage",
                "filter": "2nd-order FIR mean filter on y",
            }),
            ts_s: p.ts_s,
            inputs: vec![
                Channel::new("alpha", "normalised").with_range(norm.alpha_deg.0, norm.alpha_deg.1),
                Channel::new("u", "normalised").with_range(norm.u_v.0, norm.u_v.1),
            ],
            outputs: vec![Channel::new("y", "normalised").with_range(norm.y_c.0, norm.y_c.1)],
            split: Split { train, test },
        },
        records,
    })
}
